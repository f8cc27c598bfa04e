"""Reporting of run results: tables (:mod:`.tables`), plots (:mod:`.plots`), the summary of a
sweep (:mod:`.sweep`, ``vdtn-marl bench summarize``) and the helpers the scripts in
``benchmarks/`` and ``studies/`` share (:mod:`.benchmarking`: option lists, provenance, CIs,
console).

Above the trainers and below the experiment: a run writes its plots and prints its tables
through it, and it knows nothing of how a run is trained. The names of :mod:`.tables`,
:mod:`.plots` and :mod:`.sweep` are importable from :mod:`vdtn_marl.reporting`
(:mod:`.benchmarking` needs torch and is imported on its own).
"""

from vdtn_marl.reporting.plots import (
    AXIS_LABELS,
    ERROR_TRACES_FILE,
    LATENCY_CDF_FILE,
    STAGE_LABELS,
    TRAINING_CURVES_FILE,
    pareto_mask,
    plot_error_trace_comparison,
    plot_error_traces,
    plot_kappa1_pareto,
    plot_latency_cdf,
    plot_metric_bars,
    plot_training_curves,
    pyplot_agg,
    save_figure,
)
from vdtn_marl.reporting.sweep import PARETO_FILE, TABLE_FILE, SweepSummary, summarize_sweep
from vdtn_marl.reporting.tables import (
    CONFIG_COLUMNS,
    CONTROL_COST,
    SHORT_NAMES,
    TABLE_METRICS,
    V2I_THROUGHPUT,
    find_jobs,
    flatten,
    is_finite,
    load_job,
    metric_column,
    metrics_of,
    print_summary,
    print_table,
)

__all__ = [
    "AXIS_LABELS",
    "CONFIG_COLUMNS",
    "CONTROL_COST",
    "ERROR_TRACES_FILE",
    "LATENCY_CDF_FILE",
    "PARETO_FILE",
    "SHORT_NAMES",
    "STAGE_LABELS",
    "SweepSummary",
    "TABLE_FILE",
    "TABLE_METRICS",
    "TRAINING_CURVES_FILE",
    "V2I_THROUGHPUT",
    "find_jobs",
    "flatten",
    "is_finite",
    "load_job",
    "metric_column",
    "metrics_of",
    "pareto_mask",
    "plot_error_trace_comparison",
    "plot_error_traces",
    "plot_kappa1_pareto",
    "plot_latency_cdf",
    "plot_metric_bars",
    "plot_training_curves",
    "print_summary",
    "print_table",
    "pyplot_agg",
    "save_figure",
    "summarize_sweep",
]
