"""The metrics a run reports in ``summary.json`` that the leaderboard aggregates, compares and
plots, with their labels and which way is better (one table, read by the config validation of
a benchmark's target and by the leaderboard)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Metric:
    key: str  # summary.json key
    label: str  # column header, with the unit
    better: str | None  # "min", "max" or None (no "best" is marked)
    table: bool = True  # shown in LEADERBOARD.md (every metric is in the JSON and CSV)
    # False for a metric that summaries written before it was reported lack: a leaderboard
    # cell without it still counts as finished, and its runs are left out of that column
    required: bool = True


METRICS = (
    Metric("control_cost", "control cost", "min"),
    Metric("gap_error_abs_m", "\\|gap error\\| (m)", "min"),
    Metric("speed_error_abs_mps", "\\|speed error\\| (m/s)", "min"),
    Metric("collision_rate", "collisions (fraction of scenarios)", "min"),
    Metric("cam_delivery_rate", "CAM delivery rate", "max"),
    Metric("cam_latency_ms_mean", "CAM latency mean (ms)", "min", table=False),
    Metric("cam_latency_ms_p50", "CAM latency p50 (ms)", "min"),
    Metric("cam_latency_ms_p95", "CAM latency p95 (ms)", "min"),
    Metric("aoi_ms_mean", "AoI mean (ms)", "min", required=False),
    Metric("peak_aoi_ms_mean", "peak AoI (ms)", "min", required=False),
    Metric("v2i_throughput_mbps_per_link", "V2I throughput per link (Mbps)", "max"),
    Metric("evoi", "EVoI", None),
    Metric("evoi_ci_low", "EVoI CI low (within run)", None, table=False),
    Metric("evoi_ci_high", "EVoI CI high (within run)", None, table=False),
    Metric("optimal_control_cost", "control cost of π*", None, table=False),
)
METRIC_KEYS = tuple(m.key for m in METRICS)
#: The metrics every finished run's summary holds (the others came later).
REQUIRED_METRIC_KEYS = tuple(m.key for m in METRICS if m.required)
#: Metrics that are undefined (null) when a run delivered no CAM at all.
CAM_LATENCY_KEYS = ("cam_latency_ms_mean", "cam_latency_ms_p50", "cam_latency_ms_p95")
#: Age of Information (docs/model.md §4.8), missing from summaries written before vdtn-marl
#: reported it.
AOI_KEYS = ("aoi_ms_mean", "peak_aoi_ms_mean")
#: Metrics that are undefined (null) when a run delivered no CAM: the latencies and the peak
#: AoI (the age just before a refresh: there was none).
NO_DELIVERY_KEYS = (*CAM_LATENCY_KEYS, "peak_aoi_ms_mean")
