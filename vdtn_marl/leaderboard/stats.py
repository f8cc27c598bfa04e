"""Statistics of a benchmark across seeds (mean with a Student-t or bootstrap CI, IQM with a
bootstrap CI, paired differences) and the marl-eval raw-data export.

Intervals (``benchmark.interval``, :data:`INTERVALS`):

- ``t`` (default): mean ± t_{n−1, (1+c)/2} · s/√n (``scipy.stats.t``). With the few seeds of
  a benchmark (5) it holds its level for roughly normal data, where a percentile bootstrap of
  the mean covers only about 84 % at a nominal 95 % (it ignores the uncertainty of s).
- ``bca``: bias-corrected and accelerated bootstrap (``scipy.stats.bootstrap``,
  ``method="BCa"``).
- ``percentile``: percentile bootstrap (what rliable computes).

The IQM (interquartile mean, 25 % trimmed mean) is reported only from
:data:`MIN_RUNS_FOR_IQM` runs on: of fewer runs it trims away too little to differ from the
mean in any useful way. Its interval is a bootstrap (a t interval is not defined for it):
BCa under ``t`` and ``bca``, percentile under ``percentile``.

Degenerate samples: one value, or identical values, give a zero-width interval. BCa is
undefined when the jackknife values of the statistic are all equal (e.g. the IQM of runs that
are all equal but one or two, such as collision rates of 0); the interval then falls back to
the percentile bootstrap, and ``ci_method``/``iqm_ci_method`` of the statistic say
``percentile`` instead of ``bca``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from vdtn_marl.experiment.config import BENCHMARK_INTERVALS, BenchConfig, BenchmarkConfig
from vdtn_marl.experiment.metrics import METRICS, Metric
from vdtn_marl.leaderboard.grid import Cell, complete_summary
from vdtn_marl.reporting.tables import is_finite

INTERVALS = BENCHMARK_INTERVALS  # ("t", "bca", "percentile")
DEFAULT_INTERVAL = "t"
MIN_RUNS_FOR_IQM = 10
IQM_TRIM = 0.25  # IQM: mean of the middle 50% (scipy.stats.trim_mean with 25% cut each side)

STAT_KEYS = (
    "n", "mean", "ci_low", "ci_high", "ci_method", "std",
    "iqm", "iqm_ci_low", "iqm_ci_high", "iqm_ci_method",
)  # fmt: skip


def _iqm(values: Any, axis: int = -1) -> Any:
    from scipy.stats import trim_mean

    return trim_mean(values, IQM_TRIM, axis=axis)


def _mean(values: Any, axis: int = -1) -> Any:
    import numpy as np

    return np.mean(values, axis=axis)


def _check_interval(method: str, allowed: tuple[str, ...] = INTERVALS) -> None:
    if method not in allowed:
        raise ValueError(f"interval={method!r} is not allowed; choose one of {', '.join(allowed)}")


def iqm_interval(interval: str) -> str:
    """The bootstrap that gives the IQM's CI under ``interval``: ``percentile`` under
    ``percentile``, else ``bca`` (a t interval is not defined for the IQM)."""
    _check_interval(interval)
    return "percentile" if interval == "percentile" else "bca"


def _bootstrap(
    x: Any, statistic: Any, resamples: int, confidence: float, seed: int, method: str
) -> tuple[float, float, str]:
    """(low, high, method used) of a bootstrap CI; BCa falls back to the percentile bootstrap
    where it is undefined (non-finite bounds)."""
    import warnings

    import numpy as np
    from scipy.stats import bootstrap

    def run(name: str) -> tuple[float, float]:
        with warnings.catch_warnings():
            # scipy warns (DegenerateDataWarning, a 0/0 in the acceleration) and returns NaN
            # bounds when BCa is undefined; the NaN is handled below
            warnings.simplefilter("ignore")
            result = bootstrap(
                (x,),
                statistic,
                n_resamples=resamples,
                confidence_level=confidence,
                method={"bca": "BCa", "percentile": "percentile"}[name],
                vectorized=True,
                rng=np.random.default_rng(seed),
            )
        return float(result.confidence_interval.low), float(result.confidence_interval.high)

    low, high = run(method)
    if method == "bca" and not (np.isfinite(low) and np.isfinite(high)):
        method = "percentile"
        low, high = run(method)
    return low, high, method


def bootstrap_ci(
    values: Sequence[float],
    statistic: Any,
    resamples: int = 10_000,
    confidence: float = 0.95,
    seed: int = 0,
    method: str = "percentile",
) -> tuple[float, float, float]:
    """(point estimate, low, high): bootstrap over runs (scipy.stats.bootstrap), ``method``
    ``percentile`` or ``bca`` (BCa; where it is undefined, the percentile bootstrap).

    The point estimate is ``statistic`` of ``values``; the interval is widened to contain it
    when the interval misses it (possible only for tiny or degenerate samples). One value, or
    identical values, give a zero-width interval."""
    return _bootstrap_ci(values, statistic, resamples, confidence, seed, method)[:3]


def _bootstrap_ci(
    values: Sequence[float],
    statistic: Any,
    resamples: int,
    confidence: float,
    seed: int,
    method: str,
) -> tuple[float, float, float, str]:
    import numpy as np

    _check_interval(method, ("bca", "percentile"))
    x = np.asarray(values, dtype=float)
    if x.size == 0:
        raise ValueError("no values")
    point = float(statistic(x))
    if x.size == 1 or np.ptp(x) == 0.0:
        return point, point, point, method
    low, high, used = _bootstrap(x, statistic, resamples, confidence, seed, method)
    return point, min(low, point), max(high, point), used


def t_ci(values: Sequence[float], confidence: float = 0.95) -> tuple[float, float, float]:
    """(mean, low, high): Student-t interval mean ± t_{n−1, (1+confidence)/2} · s/√n (s: the
    sample standard deviation). One value, or identical values, give a zero-width interval."""
    import numpy as np
    from scipy.stats import t

    x = np.asarray(values, dtype=float)
    if x.size == 0:
        raise ValueError("no values")
    mean = float(np.mean(x))
    if x.size == 1 or np.ptp(x) == 0.0:
        return mean, mean, mean
    half = float(t.ppf((1.0 + confidence) / 2.0, x.size - 1) * np.std(x, ddof=1) / np.sqrt(x.size))
    return mean, mean - half, mean + half


def mean_ci(
    values: Sequence[float],
    confidence: float = 0.95,
    interval: str = DEFAULT_INTERVAL,
    resamples: int = 10_000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """(mean, low, high) of ``values`` with the ``interval`` CI (:data:`INTERVALS`): ``t``
    (:func:`t_ci`), ``bca`` or ``percentile`` (:func:`bootstrap_ci` with ``resamples``)."""
    _check_interval(interval)
    if interval == "t":
        return t_ci(values, confidence)
    return bootstrap_ci(values, _mean, resamples, confidence, seed, interval)


def describe_interval(
    interval: str, confidence: float = 0.95, resamples: int = 10_000
) -> dict[str, str]:
    """Plain words for the report: ``{"short", "mean", "iqm"}``, e.g. ``95% Student-t CI``,
    the mean's interval and the IQM's interval in full."""
    iqm = iqm_interval(interval)
    names = {"t": "Student-t", "bca": "BCa bootstrap", "percentile": "percentile-bootstrap"}
    boot = f"{resamples} resamples, scipy.stats.bootstrap"
    mean = {
        "t": f"{confidence:.0%} Student-t CI (mean ± t(n−1) · s/√n, scipy.stats.t)",
        "bca": f"{confidence:.0%} BCa bootstrap CI ({boot}, method='BCa'; percentile where "
        "BCa is undefined)",
        "percentile": f"{confidence:.0%} percentile-bootstrap CI ({boot})",
    }[interval]
    iqm_text = (
        f"{confidence:.0%} BCa bootstrap CI ({boot}; percentile where BCa is undefined"
        + ("; a t interval is not defined for the IQM)" if interval == "t" else ")")
        if iqm == "bca"
        else f"{confidence:.0%} percentile-bootstrap CI ({boot})"
    )
    return {"short": f"{confidence:.0%} {names[interval]} CI", "mean": mean, "iqm": iqm_text}


def aggregate(
    values: Sequence[Any],
    resamples: int = 10_000,
    confidence: float = 0.95,
    seed: int = 0,
    interval: str = DEFAULT_INTERVAL,
) -> dict[str, Any]:
    """Statistics of one metric across runs (non-finite values and None are left out):
    ``n``, ``mean`` with its ``interval`` CI ``ci_low``/``ci_high`` (``ci_method``: the
    interval used; None from one run), ``std`` (sample; None from one run), and ``iqm`` with
    its bootstrap CI ``iqm_ci_low``/``iqm_ci_high`` (``iqm_ci_method``) when
    n >= :data:`MIN_RUNS_FOR_IQM` (else None)."""
    import numpy as np

    _check_interval(interval)
    x = [float(v) for v in values if is_finite(v)]
    out: dict[str, Any] = dict.fromkeys(STAT_KEYS)
    out["n"] = len(x)
    if not x:
        return out
    if len(x) == 1:  # one run: a mean, but no interval and no spread to report
        out["mean"] = x[0]
        return out
    if interval == "t":
        mean, low, high = t_ci(x, confidence)
        used = "t"
    else:
        mean, low, high, used = _bootstrap_ci(x, _mean, resamples, confidence, seed, interval)
    out.update(mean=mean, ci_low=low, ci_high=high, ci_method=used)
    out["std"] = float(np.std(x, ddof=1))
    if len(x) >= MIN_RUNS_FOR_IQM:
        iqm, low, high, used = _bootstrap_ci(
            x, _iqm, resamples, confidence, seed, iqm_interval(interval)
        )
        out.update(iqm=iqm, iqm_ci_low=low, iqm_ci_high=high, iqm_ci_method=used)
    return out


def collect_runs(cfg: BenchConfig, cells: Sequence[Cell], composed: Mapping) -> list[dict]:
    """One row per complete cell: scenario, method, seed, the summary's scalar metrics."""
    from vdtn_marl.reporting.tables import flatten, metrics_of

    rows = []
    for cell in cells:
        cell_dir = cell.directory(cfg.out_dir)
        summary = complete_summary(cell_dir, composed[cell][0])
        if summary is None:
            continue
        scalars = {
            k: v
            for k, v in flatten(metrics_of(summary)).items()
            if k != "plots" and not isinstance(v, list | tuple)
        }
        row = {
            "benchmark": cfg.benchmark.name,
            "version": cfg.benchmark.version,
            "scenario": cell.scenario,
            "method": cell.method,
            "seed": cell.seed,
            **{k: v for k, v in scalars.items() if k not in ("scenario", "seed")},
            "run_dir": str(cell_dir),
        }
        rows.append(row)
    return rows


def statistics(
    rows: Sequence[Mapping[str, Any]], benchmark: BenchmarkConfig
) -> dict[str, dict[str, dict[str, dict[str, Any]]]]:
    """``{scenario: {method: {metric: aggregate(...)}}}`` in the benchmark's order."""
    out: dict[str, dict[str, dict[str, dict[str, Any]]]] = {}
    for scenario in benchmark.scenarios:
        for method in benchmark.methods:
            runs = [r for r in rows if r["scenario"] == scenario and r["method"] == method]
            if not runs:
                continue
            out.setdefault(scenario, {})[method] = {
                m.key: aggregate(
                    [r.get(m.key) for r in runs],
                    benchmark.bootstrap_resamples,
                    benchmark.confidence,
                    interval=benchmark.interval,
                )
                for m in METRICS
            }
    return out


def paired_differences(
    rows: Sequence[Mapping[str, Any]], benchmark: BenchmarkConfig
) -> dict[str, dict[str, Any]]:
    """``{scenario: {"a", "b", "seeds", "differences": {metric: aggregate(a − b)}}}`` for the
    two ``trace_methods``: per seed, both methods were evaluated on the same held-out
    scenarios, so the difference of a metric is paired by seed and its interval
    (``benchmark.interval``, a one-sample interval of the n differences) leaves out the spread
    between the seeds' scenario sets. Only the seeds both methods have are paired (with
    ``extra_seeds`` one method may have more runs)."""
    if len(benchmark.trace_methods) != 2:
        return {}
    a, b = benchmark.trace_methods
    out: dict[str, dict[str, Any]] = {}
    for scenario in benchmark.scenarios:
        runs = {
            m: {r["seed"]: r for r in rows if r["scenario"] == scenario and r["method"] == m}
            for m in (a, b)
        }
        seeds = sorted(set(runs[a]) & set(runs[b]))
        if not seeds:
            continue
        differences = {}
        for metric in METRICS:
            values = (
                [runs[a][k].get(metric.key) for k in seeds],
                [runs[b][k].get(metric.key) for k in seeds],
            )
            diffs = [x - y for x, y in zip(*values, strict=True) if is_finite(x) and is_finite(y)]
            differences[metric.key] = aggregate(
                diffs,
                benchmark.bootstrap_resamples,
                benchmark.confidence,
                interval=benchmark.interval,
            )
        out[scenario] = {"a": a, "b": b, "seeds": seeds, "differences": differences}
    return out


def best_methods(stats: Mapping[str, Mapping[str, Any]], metric: Metric) -> set[str]:
    """Methods whose mean of ``metric`` is the best of the table (ties included; none when
    every method has the same mean)."""
    means = {m: s[metric.key]["mean"] for m, s in stats.items() if is_finite(s[metric.key]["mean"])}
    if metric.better is None or len(set(means.values())) < 2:
        return set()
    best = min(means.values()) if metric.better == "min" else max(means.values())
    return {m for m, v in means.items() if v == best}


# --- exports --------------------------------------------------------------------------------


def is_extra_run(row: Mapping[str, Any], benchmark: BenchmarkConfig) -> bool:
    """Whether a run is one of ``benchmark.extra_seeds`` (not of ``benchmark.seeds``)."""
    extra = (benchmark.extra_seeds or {}).get(row["scenario"], {}).get(row["method"], [])
    return int(row["seed"]) in {int(s) for s in extra}


def marl_eval_data(
    rows: Sequence[Mapping[str, Any]], benchmark: BenchmarkConfig
) -> tuple[dict, list[str]]:
    """marl-eval raw data, ``{env: {task: {algorithm: {run: {step_1, absolute_metrics}}}}}``.

    env = ``vdtn-<benchmark>-v<version>``, task = scenario, algorithm = method, run =
    ``seed_<k>``; one logging step (the final evaluation) whose ``step_count`` is the run's
    total PPO iterations; every metric is a one-element list (a value over all evaluation
    episodes). marl-eval needs the same metrics in every run: a metric that is not finite in
    some run (CAM latency of a run that delivered no CAM) is left out; the second value lists
    those. It needs the same runs in every task and algorithm too, so only the runs of
    ``benchmark.seeds`` are exported (those of ``extra_seeds`` are left out,
    :func:`is_extra_run`)."""
    rows = [r for r in rows if not is_extra_run(r, benchmark)]
    keys = [m.key for m in METRICS]
    dropped = sorted(k for k in keys if any(not is_finite(r.get(k)) for r in rows))
    keys = [k for k in keys if k not in dropped]
    env = f"vdtn-{benchmark.name}-v{benchmark.version}"
    data: dict[str, Any] = {env: {}}
    for row in rows:
        steps = sum(
            v for k, v in row.items() if k.startswith("trainer_iterations.") and is_finite(v)
        )
        metrics = {k: [float(row[k])] for k in keys}
        data[env].setdefault(row["scenario"], {}).setdefault(row["method"], {})[
            f"seed_{row['seed']}"
        ] = {
            "step_1": {"step_count": int(steps), **metrics},
            "absolute_metrics": dict(metrics),
        }
    return data, dropped
