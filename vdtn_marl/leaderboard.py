"""The leaderboard: run a benchmark grid, aggregate it across seeds, and report it.

A benchmark (``conf/benchmark/*.yaml``, schema :class:`vdtn_marl.config.BenchmarkConfig`) is
scenarios × methods × seeds. Every *cell* is one ``vdtn-marl jocc`` run: its config is composed
by Hydra exactly as the command line composes it (``scenario=S experiment=E <overrides>
<method> <budget> seed=K``), validated by :func:`vdtn_marl.cli.to_run_config`, and run by
:func:`vdtn_marl.algos.api.jocc` in ``<out_dir>/<scenario>/<method>/seed<k>/``. Evaluation is
seeded by the run's seed only (``EVAL_SEED_OFFSET + seed``), so every method of a scenario is
evaluated on the same held-out leader traces, initial states and channel draws.

:func:`run_benchmark` runs the grid cell by cell (``shard``/``num_shards`` split it between the
jobs of a Hydra sweep), skipping every cell whose ``summary.json`` is complete, so rerunning the
same command resumes it; an interrupted cell continues from its last checkpoint. Then
:func:`write_report` aggregates every metric per scenario × method across seeds (mean with a
percentile-bootstrap confidence interval, and the interquartile mean, IQM, with its interval
where there are at least :data:`MIN_RUNS_FOR_IQM` runs) and writes, into ``report_dir``:

- ``LEADERBOARD.md``: one table per scenario, the best mean per column in bold, the version
  and the exact command on top, the two ``trace_methods`` compared paired by seed (both see
  the same held-out scenarios per seed), and the plots;
- ``leaderboard.json`` (statistics and runs), ``leaderboard_marl_eval.json`` (the raw-data
  format of InstaDeep's marl-eval), ``leaderboard.csv`` (statistics, one row per scenario ×
  method × metric) and ``leaderboard_runs.csv`` (one row per run);
- PNGs per scenario: gap/speed error traces of two methods on the same evaluation scenario,
  V2I throughput per link and CAM delivery with CIs, CAM latency CDFs, the κ1 Pareto front,
  training curves.

Every file carries the benchmark's name and version.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import math
import os
import platform
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from vdtn_marl import __version__
from vdtn_marl.config import BenchConfig, BenchmarkConfig
from vdtn_marl.runs import (
    CONFIG_FILE,
    METRICS_FILE,
    SUMMARY_FILE,
    atomic_write_json,
    atomic_write_text,
    read_json,
)
from vdtn_marl.runs import RAW_EVALUATION_FILE as RAW_EVAL_FILE

MANIFEST_FILE = "benchmark.json"
REPORT_FILE = "LEADERBOARD.md"
STATS_JSON = "leaderboard.json"
MARL_EVAL_JSON = "leaderboard_marl_eval.json"
STATS_CSV = "leaderboard.csv"
RUNS_CSV = "leaderboard_runs.csv"
MIN_RUNS_FOR_IQM = 5
IQM_TRIM = 0.25  # IQM: mean of the middle 50% (scipy.stats.trim_mean with 25% cut each side)
#: Config keys a resumed cell may change (the rest must match the cell's own run).
FREE_KEYS = ("resume", "progress", "device", "threads", "checkpoint")


class LeaderboardError(Exception):
    """A benchmark that cannot run or resume as asked; the message says why and what to do."""


@dataclass(frozen=True)
class Metric:
    key: str  # summary.json key
    label: str  # column header, with the unit
    better: str | None  # "min", "max" or None (no "best" is marked)
    table: bool = True  # shown in LEADERBOARD.md (every metric is in the JSON and CSV)


METRICS = (
    Metric("control_cost", "control cost", "min"),
    Metric("gap_error_abs_m", "\\|gap error\\| (m)", "min"),
    Metric("speed_error_abs_mps", "\\|speed error\\| (m/s)", "min"),
    Metric("collision_rate", "collisions (fraction of scenarios)", "min"),
    Metric("cam_delivery_rate", "CAM delivery rate", "max"),
    Metric("cam_latency_ms_mean", "CAM latency mean (ms)", "min", table=False),
    Metric("cam_latency_ms_p50", "CAM latency p50 (ms)", "min"),
    Metric("cam_latency_ms_p95", "CAM latency p95 (ms)", "min"),
    Metric("v2i_throughput_mbps_per_link", "V2I throughput per link (Mbps)", "max"),
    Metric("evoi", "EVoI", None),
    Metric("evoi_ci_low", "EVoI CI low (within run)", None, table=False),
    Metric("evoi_ci_high", "EVoI CI high (within run)", None, table=False),
    Metric("optimal_control_cost", "control cost of π*", None, table=False),
)
METRIC_KEYS = tuple(m.key for m in METRICS)
#: Metrics that are undefined (null) when a run delivered no CAM at all.
CAM_LATENCY_KEYS = ("cam_latency_ms_mean", "cam_latency_ms_p50", "cam_latency_ms_p95")
STAT_KEYS = ("n", "mean", "ci_low", "ci_high", "std", "iqm", "iqm_ci_low", "iqm_ci_high")


@dataclass(frozen=True)
class Cell:
    """One run of the grid."""

    scenario: str
    method: str
    seed: int
    overrides: tuple[str, ...]

    @property
    def name(self) -> str:
        return f"{self.scenario}/{self.method}/seed{self.seed}"

    def directory(self, out_dir: str | Path) -> Path:
        return Path(out_dir) / self.scenario / self.method / f"seed{self.seed}"


# --- the grid -------------------------------------------------------------------------------


def cell_overrides(
    benchmark: BenchmarkConfig, scenario: str, method: str, seed: int | None = None
) -> list[str]:
    """The ``vdtn-marl jocc`` overrides of one cell (``seed=None``: leave the seed out)."""
    overrides = [
        f"scenario={scenario}",
        f"experiment={benchmark.experiment}",
        *benchmark.overrides,
        *benchmark.methods[method],
        *benchmark.budgets.get(method, ()),
    ]
    if seed is not None:
        overrides.append(f"seed={seed}")
    return [str(o) for o in overrides]


def plan(cfg: BenchConfig) -> list[Cell]:
    """Every cell, seed by seed (so a partial run has every method on the first seeds)."""
    b = cfg.benchmark
    return [
        Cell(scenario, method, int(seed), tuple(cell_overrides(b, scenario, method, seed)))
        for seed in b.seeds
        for scenario in b.scenarios
        for method in b.methods
    ]


def bench_config(data: Mapping[str, Any]) -> BenchConfig:
    """Plain composed data of ``conf/bench.yaml`` → :class:`BenchConfig` (not yet validated)."""
    values = dict(data)
    benchmark = BenchmarkConfig(**dict(values.pop("benchmark")))
    return BenchConfig(benchmark=benchmark, **values)


@contextlib.contextmanager
def _hydra_compose() -> Iterator[None]:
    """Hydra's compose API: inside a Hydra app it is ready; elsewhere initialise it here."""
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    from vdtn_marl import cli
    from vdtn_marl.config import register_configs

    if GlobalHydra.instance().is_initialized():
        yield
        return
    register_configs()
    with initialize_config_module(config_module=cli.CONFIG_PACKAGE, version_base="1.3"):
        yield


def compose_cell(cell: Cell, device: str) -> tuple[dict, Any]:
    """(composed config as plain data, validated RunConfig) of a cell, through the CLI's own
    composition and validation (:func:`vdtn_marl.cli.to_run_config`)."""
    from vdtn_marl import cli

    overrides = [*cell.overrides, f"device={device}", "resume=true", "progress=false"]
    try:
        data = cli._job_config(cli._compose("config", overrides))
        return data, cli.to_run_config(data, "jocc")
    except Exception as exc:
        raise LeaderboardError(
            f"cell {cell.name}: {cli._translate(exc, 'config', overrides)}"
        ) from exc


def check_eval_pairing(cells_data: Mapping[Cell, Mapping[str, Any]]) -> None:
    """Every method of a scenario must see the same held-out scenarios (eval budget, model)."""
    from vdtn_marl.results import flatten

    reference: dict[str, tuple[Cell, dict]] = {}
    for cell, data in cells_data.items():
        flat = flatten(data)
        keys = {k: v for k, v in flat.items() if k.startswith(("scenario.", "experiment.eval_"))}
        if cell.scenario not in reference:
            reference[cell.scenario] = (cell, keys)
            continue
        first, expected = reference[cell.scenario]
        for key in sorted(set(expected) | set(keys)):
            if expected.get(key) != keys.get(key):
                raise LeaderboardError(
                    f"benchmark method {cell.method!r} sets {key}={keys.get(key)!r} but "
                    f"{first.method!r} has {key}={expected.get(key)!r} on scenario "
                    f"{cell.scenario}: every method of a scenario must be evaluated on the same "
                    "held-out scenarios; allowed: budgets that leave scenario.* and "
                    "experiment.eval_* alone"
                )


# --- state of the output directory ----------------------------------------------------------


#: Fields of a benchmark that decide its runs: an out_dir holds runs of one set of them.
RUN_FIELDS = ("experiment", "overrides", "scenarios", "methods", "budgets", "seeds")


def manifest(cfg: BenchConfig) -> dict[str, Any]:
    b = cfg.benchmark
    return {"name": b.name, "version": b.version, "benchmark": asdict(b)}


def check_out_dir(cfg: BenchConfig) -> None:
    """``out_dir`` is empty or holds this very benchmark definition (else: bump the version)."""
    path = Path(cfg.out_dir) / MANIFEST_FILE
    if not path.is_file():
        return
    try:
        old = read_json(path)
    except (OSError, ValueError) as exc:
        raise LeaderboardError(
            f"{path} cannot be read ({exc}); remove it or pick another out_dir"
        ) from exc
    new = manifest(cfg)
    from vdtn_marl.results import flatten

    a, b = flatten(old.get("benchmark", {})), flatten(new["benchmark"])
    keys = {k for k in set(a) | set(b) if k.split(".")[0] in RUN_FIELDS}
    differ = sorted(k for k in keys if a.get(k) != b.get(k))
    if differ:
        key = differ[0]
        raise LeaderboardError(
            f"out_dir={cfg.out_dir} holds benchmark {old.get('name')!r} version "
            f"{old.get('version')!r} with benchmark.{key}={a.get(key)!r}, not {b.get(key)!r}; "
            "a changed definition needs a new benchmark.version (and so a new out_dir) or "
            "another out_dir"
        )


def complete_summary(cell_dir: Path, data: Mapping[str, Any]) -> dict | None:
    """The cell's summary if the cell is finished (else None). A finished cell whose config
    differs from ``data`` (outside :data:`FREE_KEYS`) raises :class:`LeaderboardError`."""
    from vdtn_marl.results import flatten

    path = cell_dir / SUMMARY_FILE
    if not path.is_file():
        return None
    try:
        summary = read_json(path)
    except (OSError, ValueError):
        return None
    if not isinstance(summary, dict) or not all(k in summary for k in METRIC_KEYS):
        return None
    iterations = data.get("experiment", {}).get("jocc_iterations")
    if summary.get("iterations") != iterations:
        return None
    old, new = flatten(summary.get("config") or {}), flatten(dict(data))
    for key in sorted(set(old) & set(new)):
        if key.split(".")[0] not in FREE_KEYS and old[key] != new[key]:
            raise LeaderboardError(
                f"{path} was run with {key}={old[key]!r}, the benchmark now gives "
                f"{key}={new[key]!r}; bump benchmark.version (a new out_dir) or remove "
                f"{cell_dir} to run it again"
            )
    return summary


# --- running --------------------------------------------------------------------------------


def run_cell(cell: Cell, data: dict, run_cfg: Any, out_dir: str | Path) -> dict:
    """Run (or continue) one cell in its directory and return its summary."""
    from omegaconf import OmegaConf

    from vdtn_marl.algos import api

    cell_dir = cell.directory(out_dir)
    cell_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(cell_dir / CONFIG_FILE, OmegaConf.to_yaml(OmegaConf.create(data)))
    return api.jocc(run_cfg, cell_dir)  # also writes evaluation_raw.npz for the plots


@dataclass
class BenchmarkResult:
    done: list[Cell]  # complete cells of this job (run now or before)
    ran: list[Cell]  # cells this job ran (or continued)
    failed: list[tuple[Cell, str]]
    pending: list[Cell]  # cells of the whole grid still without a complete summary
    report: dict[str, Path] | None = None


def run_benchmark(cfg: BenchConfig, command: str = "") -> BenchmarkResult:
    """Run or resume this job's share of the grid, then write the report (see module doc).

    A cell that fails is reported and the others go on; the report covers the complete cells
    and says how many are missing.
    """
    from vdtn_marl.runs import progress

    cells = plan(cfg)
    mine = cells[cfg.shard :: cfg.num_shards]
    out_dir = Path(cfg.out_dir)
    check_out_dir(cfg)
    atomic_write_json(out_dir / MANIFEST_FILE, manifest(cfg))
    done, ran, failed = [], [], []
    with _hydra_compose():
        composed = {cell: compose_cell(cell, cfg.device) for cell in cells}
        check_eval_pairing({cell: data for cell, (data, _) in composed.items()})
        title = f"bench {cfg.benchmark.name} v{cfg.benchmark.version}"
        if cfg.num_shards > 1:
            title += f" shard {cfg.shard}/{cfg.num_shards}"
        with progress(len(mine), title, cfg.progress) as bar:
            for cell in mine:
                data, run_cfg = composed[cell]
                cell_dir = cell.directory(out_dir)
                bar.set_postfix_str(cell.name)
                if complete_summary(cell_dir, data) is not None:
                    done.append(cell)
                    bar.update(1)
                    continue
                try:
                    run_cell(cell, data, run_cfg, out_dir)
                except Exception as exc:  # one failing cell does not stop the grid
                    failed.append((cell, f"{type(exc).__name__}: {exc}"))
                    bar.write(f"cell {cell.name} failed: {type(exc).__name__}: {exc}")
                else:
                    ran.append(cell)
                    done.append(cell)
                bar.update(1)
        pending = [
            c for c in cells if complete_summary(c.directory(out_dir), composed[c][0]) is None
        ]
    result = BenchmarkResult(done=done, ran=ran, failed=failed, pending=pending)
    if cfg.report and len(pending) < len(cells):
        result.report = write_report(cfg, command=command, cells=cells, composed=composed)
    return result


# --- statistics -----------------------------------------------------------------------------


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


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

    x = [float(v) for v in values if _finite(v)]
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
            diffs = [x - y for x, y in zip(*values, strict=True) if _finite(x) and _finite(y)]
            differences[metric.key] = aggregate(
                diffs, benchmark.bootstrap_resamples, benchmark.confidence
            )
        out[scenario] = {"a": a, "b": b, "seeds": seeds, "differences": differences}
    return out


def best_methods(stats: Mapping[str, Mapping[str, Any]], metric: Metric) -> set[str]:
    """Methods whose mean of ``metric`` is the best of the table (ties included; none when
    every method has the same mean)."""
    means = {m: s[metric.key]["mean"] for m, s in stats.items() if _finite(s[metric.key]["mean"])}
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
    dropped = sorted(k for k in keys if any(not _finite(r.get(k)) for r in rows))
    keys = [k for k in keys if k not in dropped]
    env = f"vdtn-{benchmark.name}-v{benchmark.version}"
    data: dict[str, Any] = {env: {}}
    for row in rows:
        steps = sum(v for k, v in row.items() if k.startswith("trainer_iterations.") and _finite(v))
        metrics = {k: [float(row[k])] for k in keys}
        data[env].setdefault(row["scenario"], {}).setdefault(row["method"], {})[
            f"seed_{row['seed']}"
        ] = {
            "step_1": {"step_count": int(steps), **metrics},
            "absolute_metrics": dict(metrics),
        }
    return data, dropped


def _fmt(value: Any) -> str:
    if not _finite(value):
        return "–"
    value = float(value)
    if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e5):
        return f"{value:.3e}"
    return f"{value:.4g}"


def _stat_cell(stat: Mapping[str, Any], prefix: str = "", bold: bool = False) -> str:
    mean = stat.get(prefix or "mean")
    if not _finite(mean):
        return "–"
    text = _fmt(mean)
    if bold:
        text = f"**{text}**"
    low, high = (
        stat.get(f"{prefix}_ci_low" if prefix else "ci_low"),
        stat.get(f"{prefix}_ci_high" if prefix else "ci_high"),
    )
    return f"{text}<br>[{_fmt(low)}, {_fmt(high)}]"


def _budget_lines(
    cfg: BenchConfig, composed: Mapping, rows: Sequence[Mapping[str, Any]]
) -> list[str]:
    b = cfg.benchmark
    first = next(iter(composed.values()))[0]
    e, a = first["experiment"], first["algo"]
    seconds = [float(r["seconds"]) for r in rows if _finite(r.get("seconds"))]
    lines = [
        f"- **budget**: `experiment={b.experiment}`"
        + (f" with `{' '.join(b.overrides)}`" if b.overrides else "")
        + f"; {e['jocc_iterations']} JOCC iteration(s) per run; a PPO iteration collects "
        f"{a['num_envs']} scenarios × {a['rollout_steps']} control intervals (π*, π̃) or "
        f"{a.get('rra_num_envs', a['num_envs'])} scenarios × {a['rra_rollout_steps']} "
        "subframes (RRA agents); the Methods table lists the PPO iterations of each method",
        f"- **evaluation**: {e['eval_episodes']} held-out scenarios × {e['eval_intervals']} "
        f"control intervals ({e['eval_intervals'] * 0.05:g} s) per run, the same scenarios for "
        "every method (evaluation seed = run seed + 10⁹)",
        f"- **seeds**: {', '.join(str(s) for s in b.seeds)} ({len(b.seeds)} runs per scenario "
        "× method)",
    ]
    if seconds:
        lines.append(
            f"- **compute**: {len(seconds)} runs, {sum(seconds) / 60:.1f} min of run time in "
            "total, summed over the runs (wall time is shorter when shards run in parallel), "
            f"on {platform.machine()}, "
            f"{os.cpu_count()} CPU cores"
        )
    return lines


def _png(path: Path) -> str:
    return path.name


def load_raw_evaluation(cell_dir: Path) -> dict[str, Any] | None:
    """The arrays of a cell's ``evaluation_raw.npz`` (None when it has none)."""
    import numpy as np

    path = Path(cell_dir) / RAW_EVAL_FILE
    if not path.is_file():
        return None
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def write_plots(
    cfg: BenchConfig,
    rows: Sequence[Mapping[str, Any]],
    stats: Mapping[str, Any],
    report_dir: Path,
) -> dict[str, dict[str, Path]]:
    """The leaderboard's plots per scenario; returns ``{scenario: {kind: path}}``."""
    import numpy as np
    import pandas as pd

    from vdtn_marl import results

    b = cfg.benchmark
    note = f"vdtn-marl {__version__} · benchmark {b.name} v{b.version}"
    out: dict[str, dict[str, Path]] = {}
    for scenario, by_method in stats.items():
        plots: dict[str, Path] = {}
        prefix = f"leaderboard_{scenario}_"
        scenario_rows = [r for r in rows if r["scenario"] == scenario]
        n_runs = {m: by_method[m]["control_cost"]["n"] for m in by_method}

        def raw(method: str, seed: int, scenario: str = scenario) -> dict | None:
            return load_raw_evaluation(Cell(scenario, method, seed, ()).directory(cfg.out_dir))

        # 1. error traces of the trace methods, same scenario and seed
        pair = [m for m in b.trace_methods if m in by_method]
        for seed in b.seeds:
            traces = {m: raw(m, seed) for m in pair}
            if pair and all(t is not None and "gap_error_abs_m" in t for t in traces.values()):
                interval = float(next(iter(traces.values()))["interval_s"])
                plots["error_traces"] = results.plot_error_trace_comparison(
                    {
                        m: (t["gap_error_abs_m"], t["speed_error_abs_mps"])
                        for m, t in traces.items()
                    },
                    interval,
                    report_dir / f"{prefix}error_traces.png",
                    title=f"{scenario}: {' vs '.join(pair)}, seed {seed}, evaluation scenario 0",
                    note=note,
                )
                break

        # 2. bars with CIs
        for key, kind, ylabel in (
            (results.V2I_THROUGHPUT, "v2i_throughput", "V2I throughput per link (Mbps)"),
            ("cam_delivery_rate", "cam_delivery", "CAM delivery rate (fraction within interval)"),
            ("control_cost", "control_cost", "control cost (dimensionless; lower is better)"),
        ):
            bars = [
                {
                    "label": method,
                    **by_method[method][key],
                    "values": [r.get(key) for r in scenario_rows if r["method"] == method],
                }
                for method in by_method
            ]
            plots[kind] = results.plot_metric_bars(
                bars,
                report_dir / f"{prefix}{kind}.png",
                ylabel,
                title=f"{scenario}: mean over seeds, {b.confidence:.0%} bootstrap CI, dots = runs",
                note=note,
            )

        # 3. CAM latency CDF, every run's delivered CAMs pooled per method
        latencies: dict[str, Any] = {}
        interval_s = None
        for method in by_method:
            pooled = []
            for seed in b.seeds:
                data = raw(method, seed)
                if data is not None and "cam_latency_ms" in data:
                    pooled.append(data["cam_latency_ms"])
                    interval_s = float(data["interval_s"])
            if pooled:
                delivered = by_method[method]["cam_delivery_rate"]["mean"]
                share = f"{100 * delivered:.1f}%" if _finite(delivered) else "–"
                label = f"{method} ({share} of CAMs delivered)"
                latencies[label] = np.concatenate(pooled)
        if latencies and interval_s is not None:
            plots["cam_latency_cdf"] = results.plot_latency_cdf(
                latencies,
                interval_s * 1000.0,
                report_dir / f"{prefix}cam_latency_cdf.png",
                title=f"{scenario}: latency of delivered CAMs, all runs pooled",
                note=note,
            )

        # 4. κ1 Pareto front of the learned-RRA methods with learned control
        pareto_rows = []
        for row in scenario_rows:
            cfg_file = Path(row["run_dir"]) / CONFIG_FILE
            config = results._read_yaml(cfg_file) if cfg_file.is_file() else {}
            flat = results.flatten(config or {})
            if (
                flat.get("rra.name") in ("jocc", "throughput")
                and flat.get("control.name") == "learned"
            ):
                pareto_rows.append(
                    {
                        **{k: flat.get(k) for k in results.CONFIG_COLUMNS},
                        **row,
                        "rra.kappa1": flat.get("rra.kappa1"),
                    }
                )
        table = pd.DataFrame(pareto_rows)
        if len(table) and table["rra.kappa1"].nunique() > 1:
            with contextlib.suppress(ValueError):
                plots["pareto_kappa1"] = results.plot_kappa1_pareto(
                    table,
                    report_dir / f"{prefix}pareto_kappa1.png",
                    title=f"{scenario}: κ1 of the RRA reward (learned control)",
                    note=note,
                )

        # 5. training curves of the methods with a learned RRA policy
        curves: dict[str, list[Path]] = {}
        for method in by_method:
            files = [
                Cell(scenario, method, s, ()).directory(cfg.out_dir) / METRICS_FILE for s in b.seeds
            ]
            files = [f for f in files if f.is_file()]
            rra_learned = any(
                r.get("trainer_iterations.rra") for r in scenario_rows if r["method"] == method
            )
            if files and rra_learned:
                curves[f"{method} (n={n_runs[method]})"] = files
        if curves:
            plots["training_curves"] = results.plot_training_curves(
                curves,
                report_dir / f"{prefix}training_curves.png",
                title=f"{scenario}: mean over seeds (band: min–max)",
                note=note,
            )
        out[scenario] = plots
    return out


def _markdown(
    cfg: BenchConfig,
    rows: Sequence[Mapping[str, Any]],
    stats: Mapping[str, Any],
    paired: Mapping[str, Any],
    plots: Mapping[str, Mapping[str, Path]],
    command: str,
    composed: Mapping,
    n_cells: int,
    n_done: int,
    dropped: Sequence[str],
) -> str:
    b = cfg.benchmark
    table_metrics = [m for m in METRICS if m.table]
    lines = [
        f"# Leaderboard: `{b.name}` v{b.version}",
        "",
        f"- **benchmark**: `{b.name}`, version `{b.version}` (conf/benchmark/{b.name}.yaml)"
        + (f": {b.description.strip()}" if b.description else ""),
        f"- **command**: `{command}`" if command else "- **command**: (not recorded)",
        f"- **vdtn-marl**: {__version__}; written {_dt.date.today().isoformat()} on "
        f"{platform.machine()} ({platform.python_implementation()} "
        f"{platform.python_version()})",
        *_budget_lines(cfg, composed, rows),
        f"- **statistics**: per scenario × method across seeds: mean with its "
        f"{b.confidence:.0%} percentile-bootstrap CI ({b.bootstrap_resamples} resamples, "
        "scipy.stats.bootstrap), IQM (interquartile mean) with its CI where there are "
        f"≥ {MIN_RUNS_FOR_IQM} runs. Every method is evaluated on the same held-out scenarios "
        "(same evaluation seed per run seed). **Bold**: best mean of a column (↓ lower is "
        "better, ↑ higher); EVoI = J̃ − J* (discounted return of the acting system minus that "
        "of π* with perfect observation, per follower) has no best.",
    ]
    if n_done < n_cells:
        lines.append(
            f"- **incomplete**: {n_done} of {n_cells} runs are complete; rerun the command to "
            "finish the others"
        )
    lines += [
        "",
        "## Methods",
        "",
        "| method | overrides (method; budget) | PPO iterations per run: π*, π̃, RRA |",
        "|---|---|---|",
    ]
    for method, overrides in b.methods.items():
        extra = b.budgets.get(method, [])
        text = f"`{' '.join(overrides)}`" + (f"; `{' '.join(extra)}`" if extra else "")
        done = [r for r in rows if r["method"] == method]
        counts = "–"
        if done:
            counts = ", ".join(
                str(int(done[0].get(f"trainer_iterations.{k}") or 0))
                for k in ("pi_star", "pi_tilde", "rra")
            )
        lines.append(f"| {method} | {text} | {counts} |")
    for scenario, by_method in stats.items():
        lines += ["", f"## {scenario}", ""]
        header = ["method", "n"] + [
            m.label + {"min": " ↓", "max": " ↑"}.get(m.better or "", "") for m in table_metrics
        ]
        lines.append("| " + " | ".join(header) + " |")
        lines.append("|" + "|".join(["---"] + ["--:"] * (len(header) - 1)) + "|")
        best = {m.key: best_methods(by_method, m) for m in table_metrics}
        for method, metrics in by_method.items():
            cells = [method, str(metrics["control_cost"]["n"])]
            cells += [_stat_cell(metrics[m.key], bold=method in best[m.key]) for m in table_metrics]
            lines.append("| " + " | ".join(cells) + " |")
        if any(metrics["control_cost"]["iqm"] is not None for metrics in by_method.values()):
            lines += [
                "",
                "<details><summary>IQM (interquartile mean) [95% CI]</summary>",
                "",
                "| method | " + " | ".join(m.label for m in table_metrics) + " |",
                "|" + "|".join(["---"] + ["--:"] * len(table_metrics)) + "|",
            ]
            for method, metrics in by_method.items():
                cells = [method] + [_stat_cell(metrics[m.key], "iqm") for m in table_metrics]
                lines.append("| " + " | ".join(cells) + " |")
            lines += ["", "</details>"]
        pair = paired.get(scenario)
        if pair:
            lines += [
                "",
                f"Paired by seed (same held-out scenarios): **{pair['a']} − {pair['b']}**, "
                f"mean difference over {len(pair['seeds'])} seeds [{b.confidence:.0%} "
                "bootstrap CI]:",
                "",
                "| " + " | ".join(m.label for m in table_metrics) + " |",
                "|" + "|".join(["--:"] * len(table_metrics)) + "|",
                "| "
                + " | ".join(_stat_cell(pair["differences"][m.key]) for m in table_metrics)
                + " |",
            ]
        missing_latency = [
            method
            for method, metrics in by_method.items()
            if metrics["cam_latency_ms_p50"]["n"] < metrics["control_cost"]["n"]
        ]
        if missing_latency:
            lines += [
                "",
                "CAM latency is undefined for a run that delivered no CAM; those runs are left "
                "out of the latency columns (their n is smaller): "
                + ", ".join(
                    f"{m} ({by_method[m]['cam_latency_ms_p50']['n']} of "
                    f"{by_method[m]['control_cost']['n']})"
                    for m in missing_latency
                )
                + ".",
            ]
        scenario_plots = plots.get(scenario, {})
        captions = {
            "error_traces": "Gap and speed errors over time",
            "v2i_throughput": "V2I throughput per link",
            "cam_delivery": "CAM delivery rate",
            "cam_latency_cdf": "CAM latency CDF",
            "pareto_kappa1": "κ1 Pareto front",
            "control_cost": "Control cost",
            "training_curves": "Training curves",
        }
        if scenario_plots:
            lines.append("")
            for kind, caption in captions.items():
                if kind in scenario_plots:
                    lines.append(f"![{scenario}: {caption}]({_png(scenario_plots[kind])})")
    lines += [
        "",
        "## Files",
        "",
        f"- `{STATS_JSON}`: the statistics above and every run's metrics",
        f"- `{STATS_CSV}`: statistics, one row per scenario × method × metric",
        f"- `{RUNS_CSV}`: one row per run (all summary metrics)",
        f"- `{MARL_EVAL_JSON}`: the runs in marl-eval's raw-data format",
    ]
    if dropped:
        lines[-1] += f" (left out, not finite in every run: {', '.join(dropped)})"
    return "\n".join(lines) + "\n"


def write_report(
    cfg: BenchConfig,
    command: str = "",
    cells: Sequence[Cell] | None = None,
    composed: Mapping | None = None,
) -> dict[str, Path]:
    """Aggregate the complete cells of ``cfg.out_dir`` and write the report files (see the
    module doc) into ``cfg.report_dir`` (default ``out_dir``); returns ``{kind: path}``."""
    import pandas as pd

    cells = list(cells if cells is not None else plan(cfg))
    if composed is None:
        with _hydra_compose():
            composed = {cell: compose_cell(cell, cfg.device) for cell in cells}
    report_dir = Path(cfg.report_dir or cfg.out_dir)
    report_dir.mkdir(parents=True, exist_ok=True)
    b = cfg.benchmark
    rows = collect_runs(cfg, cells, composed)
    if not rows:
        raise LeaderboardError(f"no complete run in {cfg.out_dir}; nothing to report")
    stats = statistics(rows, b)
    paired = paired_differences(rows, b)
    plots = write_plots(cfg, rows, stats, report_dir)
    marl_eval, dropped = marl_eval_data(rows, b)
    header = {
        "benchmark": b.name,
        "version": b.version,
        "vdtn_marl_version": __version__,
        "command": command,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "definition": asdict(b),
    }
    written: dict[str, Path] = {}
    written["json"] = atomic_write_json(
        report_dir / STATS_JSON,
        {
            **header,
            "statistics_method": {
                "interval": f"{b.confidence:.0%} percentile bootstrap across seeds "
                "(scipy.stats.bootstrap)",
                "resamples": b.bootstrap_resamples,
                "iqm": f"scipy.stats.trim_mean(values, {IQM_TRIM}) where n >= {MIN_RUNS_FOR_IQM}",
                "non_finite": "left out (n counts the finite values)",
            },
            "cells": {"total": len(cells), "complete": len(rows)},
            "metrics": {
                m.key: {"label": m.label.replace("\\", ""), "better": m.better} for m in METRICS
            },
            "statistics": stats,
            "paired_differences": paired,
            "runs": rows,
        },
    )
    written["marl_eval"] = atomic_write_json(report_dir / MARL_EVAL_JSON, marl_eval)
    stat_rows = [
        {
            "benchmark": b.name,
            "version": b.version,
            "scenario": scenario,
            "method": method,
            "metric": metric,
            **values,
        }
        for scenario, by_method in stats.items()
        for method, metrics in by_method.items()
        for metric, values in metrics.items()
    ]
    written["csv"] = atomic_write_text(
        report_dir / STATS_CSV, pd.DataFrame(stat_rows).to_csv(index=False)
    )
    written["runs_csv"] = atomic_write_text(
        report_dir / RUNS_CSV, pd.DataFrame(rows).to_csv(index=False)
    )
    written["markdown"] = atomic_write_text(
        report_dir / REPORT_FILE,
        _markdown(
            cfg, rows, stats, paired, plots, command, composed, len(cells), len(rows), dropped
        ),
    )
    for scenario, kinds in plots.items():
        for kind, path in kinds.items():
            written[f"{scenario}/{kind}"] = path
    return written


def print_leaderboard(path: str | Path, console: Any = None) -> None:
    """Print the mean [CI] of the main metrics per scenario from ``leaderboard.json``."""
    import sys

    from rich.console import Console
    from rich.table import Table

    data = read_json(path)
    console = console or Console(width=None if sys.stdout.isatty() else 160)
    shown = (
        "control_cost",
        "gap_error_abs_m",
        "cam_delivery_rate",
        "v2i_throughput_mbps_per_link",
        "evoi",
    )
    labels = {m.key: m.label.replace("\\", "") for m in METRICS}
    for scenario, by_method in data["statistics"].items():
        table = Table(title=f"{data['benchmark']} v{data['version']}: {scenario}")
        table.add_column("method")
        table.add_column("n", justify="right")
        for key in shown:
            table.add_column(labels[key], justify="right")
        for method, metrics in by_method.items():
            cells = [method, str(metrics["control_cost"]["n"])]
            for key in shown:
                s = metrics[key]
                cells.append(
                    f"{_fmt(s['mean'])} [{_fmt(s['ci_low'])}, {_fmt(s['ci_high'])}]"
                    if _finite(s["mean"])
                    else "–"
                )
            table.add_row(*cells)
        console.print(table)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m vdtn_marl.leaderboard ARGS`` = ``vdtn-marl bench ARGS``."""
    import sys

    from vdtn_marl import cli

    return cli.main(["bench", *(sys.argv[1:] if argv is None else argv)])


__all__ = [
    "BenchmarkResult",
    "Cell",
    "LeaderboardError",
    "METRICS",
    "aggregate",
    "bootstrap_ci",
    "cell_overrides",
    "marl_eval_data",
    "plan",
    "run_benchmark",
    "statistics",
    "write_report",
]


if __name__ == "__main__":
    raise SystemExit(main())
