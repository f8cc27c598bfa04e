"""The leaderboard: run a benchmark grid, aggregate it across seeds, and report it.

A benchmark (``conf/benchmark/*.yaml``, schema :class:`vdtn_marl.experiment.config.BenchmarkConfig`)
is scenarios × methods × seeds. Every *cell* is one ``vdtn-marl jocc`` run: its config is composed
by Hydra exactly as the command line composes it (``scenario=S experiment=E <overrides> <method>
<budget> seed=K``), validated by :func:`vdtn_marl.experiment.compose.to_run_config`, and run by
:func:`vdtn_marl.experiment.api.jocc` in ``<out_dir>/<scenario>/<method>/seed<k>/``. Evaluation is
seeded by the run's seed only (``EVAL_SEED_OFFSET + seed``), so every method of a
scenario is evaluated on the same held-out leader traces, initial states and channel draws.

:func:`run_benchmark` runs the grid cell by cell (``shard``/``num_shards`` split it between the
jobs of a Hydra sweep), skipping every cell whose ``summary.json`` is complete, so rerunning the
same command resumes it; an interrupted cell continues from its last checkpoint. Then
:func:`write_report` aggregates every metric per scenario × method across seeds (mean with a
confidence interval chosen by ``benchmark.interval``: Student-t by default, or the BCa or
percentile bootstrap; the interquartile mean, IQM, with a bootstrap interval where there are
at least :data:`~vdtn_marl.leaderboard.stats.MIN_RUNS_FOR_IQM` runs; see
:mod:`~vdtn_marl.leaderboard.stats`) and writes, into ``report_dir``:

- ``LEADERBOARD.md``: one table per scenario, the best mean per column in bold, the version
  and the exact command on top, the verdict on ``benchmark.target`` (where set), the two
  ``trace_methods`` compared paired by seed (both see the same held-out scenarios per seed),
  and the plots;
- ``leaderboard.json`` (statistics and runs), ``leaderboard_marl_eval.json`` (the raw-data
  format of InstaDeep's marl-eval), ``leaderboard.csv`` (statistics, one row per scenario ×
  method × metric) and ``leaderboard_runs.csv`` (one row per run);
- PNGs per scenario: gap/speed error traces of two methods on the same evaluation scenario,
  V2I throughput per link and CAM delivery with CIs, CAM latency CDFs, the κ1 Pareto front,
  training curves.

Every file carries the benchmark's name and version.

Modules: :mod:`~vdtn_marl.leaderboard.grid` (metrics, cells, their configs, the output
directory's state), :mod:`~vdtn_marl.leaderboard.runner` (running the grid),
:mod:`~vdtn_marl.leaderboard.pi_star` (the π* the cells share, ``benchmark.pi_star``),
:mod:`~vdtn_marl.leaderboard.stats` (statistics across seeds, marl-eval export),
:mod:`~vdtn_marl.leaderboard.target` (the check of ``benchmark.target``, the headline claim),
:mod:`~vdtn_marl.leaderboard.plots` and :mod:`~vdtn_marl.leaderboard.report` (the report).
"""

from __future__ import annotations

from vdtn_marl.errors import LeaderboardError
from vdtn_marl.experiment.metrics import (
    AOI_KEYS,
    CAM_LATENCY_KEYS,
    METRIC_KEYS,
    METRICS,
    NO_DELIVERY_KEYS,
    Metric,
)
from vdtn_marl.leaderboard.grid import (
    MANIFEST_FILE,
    Cell,
    bench_config,
    cell_overrides,
    check_eval_pairing,
    check_out_dir,
    complete_summary,
    compose_cell,
    manifest,
    plan,
    with_recorded_submissions,
    with_submissions,
)
from vdtn_marl.leaderboard.report import (
    MARL_EVAL_JSON,
    REPORT_FILE,
    RUNS_CSV,
    STATS_CSV,
    STATS_JSON,
    print_leaderboard,
    write_report,
)
from vdtn_marl.leaderboard.runner import BenchmarkResult, run_benchmark
from vdtn_marl.leaderboard.stats import (
    INTERVALS,
    MIN_RUNS_FOR_IQM,
    STAT_KEYS,
    aggregate,
    best_methods,
    bootstrap_ci,
    describe_interval,
    marl_eval_data,
    mean_ci,
    paired_differences,
    statistics,
    t_ci,
)
from vdtn_marl.leaderboard.target import check_target, fieller_ratio_ci

__all__ = [
    "AOI_KEYS",
    "CAM_LATENCY_KEYS",
    "INTERVALS",
    "MANIFEST_FILE",
    "MARL_EVAL_JSON",
    "METRICS",
    "METRIC_KEYS",
    "MIN_RUNS_FOR_IQM",
    "NO_DELIVERY_KEYS",
    "REPORT_FILE",
    "RUNS_CSV",
    "STATS_CSV",
    "STATS_JSON",
    "STAT_KEYS",
    "BenchmarkResult",
    "Cell",
    "LeaderboardError",
    "Metric",
    "aggregate",
    "bench_config",
    "best_methods",
    "bootstrap_ci",
    "cell_overrides",
    "check_target",
    "check_eval_pairing",
    "check_out_dir",
    "complete_summary",
    "compose_cell",
    "describe_interval",
    "fieller_ratio_ci",
    "manifest",
    "marl_eval_data",
    "mean_ci",
    "paired_differences",
    "plan",
    "print_leaderboard",
    "run_benchmark",
    "statistics",
    "t_ci",
    "with_recorded_submissions",
    "with_submissions",
    "write_report",
]
