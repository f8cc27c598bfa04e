"""Statistics of a benchmark across seeds (mean and IQM with percentile-bootstrap CIs, paired
differences) and the marl-eval raw-data export.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from vdtn_marl.config import BenchConfig, BenchmarkConfig
from vdtn_marl.leaderboard.grid import METRICS, Cell, Metric, complete_summary
from vdtn_marl.results import is_finite

MIN_RUNS_FOR_IQM = 5
IQM_TRIM = 0.25  # IQM: mean of the middle 50% (scipy.stats.trim_mean with 25% cut each side)

STAT_KEYS = ("n", "mean", "ci_low", "ci_high", "std", "iqm", "iqm_ci_low", "iqm_ci_high")


def _iqm(values: Any, axis: int = -1) -> Any:
    from scipy.stats import trim_mean

    return trim_mean(values, IQM_TRIM, axis=axis)


def _mean(values: Any, axis: int = -1) -> Any:
    import numpy as np

    return np.mean(values, axis=axis)


def bootstrap_ci(
    values: Sequence[float],
    statistic: Any,
    resamples: int = 10_000,
    confidence: float = 0.95,
    seed: int = 0,
) -> tuple[float, float, float]:
    """(point estimate, low, high): percentile bootstrap over runs (scipy.stats.bootstrap).

    The point estimate is ``statistic`` of ``values``; the interval is widened to contain it
    when the percentile interval misses it (possible only for tiny or degenerate samples). One
    value, or identical values, give a zero-width interval."""
    import numpy as np
    from scipy.stats import bootstrap

    x = np.asarray(values, dtype=float)
    if x.size == 0:
        raise ValueError("no values")
    point = float(statistic(x))
    if x.size == 1 or np.ptp(x) == 0.0:
        return point, point, point
    result = bootstrap(
        (x,),
        statistic,
        n_resamples=resamples,
        confidence_level=confidence,
        method="percentile",
        vectorized=True,
        rng=np.random.default_rng(seed),
    )
    low = float(result.confidence_interval.low)
    high = float(result.confidence_interval.high)
    return point, min(low, point), max(high, point)


def aggregate(
    values: Sequence[Any], resamples: int = 10_000, confidence: float = 0.95, seed: int = 0
) -> dict[str, Any]:
    """Statistics of one metric across runs (non-finite values and None are left out):
    ``n``, ``mean`` with its bootstrap ``ci_low``/``ci_high``, ``std`` (sample), and ``iqm``
    with ``iqm_ci_low``/``iqm_ci_high`` when n >= :data:`MIN_RUNS_FOR_IQM` (else None)."""
    import numpy as np

    x = [float(v) for v in values if is_finite(v)]
    out: dict[str, Any] = dict.fromkeys(STAT_KEYS)
    out["n"] = len(x)
    if not x:
        return out
    mean, low, high = bootstrap_ci(x, _mean, resamples, confidence, seed)
    out.update(mean=mean, ci_low=low, ci_high=high)
    out["std"] = float(np.std(x, ddof=1)) if len(x) > 1 else 0.0
    if len(x) >= MIN_RUNS_FOR_IQM:
        iqm, low, high = bootstrap_ci(x, _iqm, resamples, confidence, seed)
        out.update(iqm=iqm, iqm_ci_low=low, iqm_ci_high=high)
    return out


def collect_runs(cfg: BenchConfig, cells: Sequence[Cell], composed: Mapping) -> list[dict]:
    """One row per complete cell: scenario, method, seed, the summary's scalar metrics."""
    from vdtn_marl.results import flatten, metrics_of

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
                )
                for m in METRICS
            }
    return out


def paired_differences(
    rows: Sequence[Mapping[str, Any]], benchmark: BenchmarkConfig
) -> dict[str, dict[str, Any]]:
    """``{scenario: {"a", "b", "differences": {metric: aggregate(a − b)}}}`` for the two
    ``trace_methods``: per seed, both methods were evaluated on the same held-out scenarios, so
    the difference of a metric is paired by seed and its interval leaves out the spread
    between the seeds' scenario sets."""
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
                diffs, benchmark.bootstrap_resamples, benchmark.confidence
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


def marl_eval_data(
    rows: Sequence[Mapping[str, Any]], benchmark: BenchmarkConfig
) -> tuple[dict, list[str]]:
    """marl-eval raw data, ``{env: {task: {algorithm: {run: {step_1, absolute_metrics}}}}}``.

    env = ``vdtn-<benchmark>-v<version>``, task = scenario, algorithm = method, run =
    ``seed_<k>``; one logging step (the final evaluation) whose ``step_count`` is the run's
    total PPO iterations; every metric is a one-element list (a value over all evaluation
    episodes). marl-eval needs the same metrics in every run: a metric that is not finite in
    some run (CAM latency of a run that delivered no CAM) is left out; the second value lists
    those."""
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
