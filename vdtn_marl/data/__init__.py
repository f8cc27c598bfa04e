"""Leader speed traces for the digital twin (docs/model.md §3).

Named trace sets (:func:`get_trace_source`): ``"synthetic"``, ``"constant"``, the standard
EPA driving cycles ``"udds"`` and ``"hwfet"`` (bundled, :mod:`vdtn_marl.data.cycles`), and
``"cmap"``, recorded drives of 22 vehicles around Chicago (bundled, :mod:`vdtn_marl.data.cmap`).
Recorded data the user has (NGSIM, highD-style tracks, ``time,speed`` CSV) is read with
:func:`load_trace_source` / :class:`NGSIMTraceSource`.
"""

from vdtn_marl.data.cmap import cmap_info, cmap_source, load_cmap_profiles
from vdtn_marl.data.cycles import (
    CYCLES,
    driving_cycle_info,
    driving_cycle_source,
    load_driving_cycle,
)
from vdtn_marl.data.loaders import (
    FT_TO_M,
    MAX_SPEED_MPS,
    SpeedProfile,
    TraceFormatError,
    load_highd,
    load_ngsim,
    load_time_speed_csv,
)
from vdtn_marl.data.preprocess import (
    PreprocessReport,
    limit_acceleration,
    preprocess,
    preprocess_all,
)
from vdtn_marl.data.profiles import (
    SPLIT_VERSION,
    DisjointWindowSource,
    NGSIMTraceSource,
    ProfileTraceSource,
    TooFewWindowsError,
    load_profiles,
    load_trace_source,
    load_train_eval_sources,
    split,
)
from vdtn_marl.data.traces import (
    ConstantSpeedTraceSource,
    SyntheticTraceSource,
    TraceInfo,
    TraceSource,
    get_trace_source,
    register_trace_source,
    trace_set_provenance,
    trace_source_names,
)


def _register_cycles() -> None:
    for name in CYCLES:
        register_trace_source(
            name, lambda name=name: driving_cycle_source(name), driving_cycle_info(name)
        )


_register_cycles()
register_trace_source("cmap", cmap_source, cmap_info())

__all__ = [
    "CYCLES",
    "FT_TO_M",
    "MAX_SPEED_MPS",
    "SPLIT_VERSION",
    "ConstantSpeedTraceSource",
    "DisjointWindowSource",
    "NGSIMTraceSource",
    "PreprocessReport",
    "ProfileTraceSource",
    "SpeedProfile",
    "SyntheticTraceSource",
    "TraceFormatError",
    "TraceInfo",
    "TooFewWindowsError",
    "TraceSource",
    "cmap_info",
    "cmap_source",
    "driving_cycle_info",
    "driving_cycle_source",
    "get_trace_source",
    "limit_acceleration",
    "load_cmap_profiles",
    "load_driving_cycle",
    "load_highd",
    "load_ngsim",
    "load_profiles",
    "load_time_speed_csv",
    "load_trace_source",
    "load_train_eval_sources",
    "preprocess",
    "preprocess_all",
    "register_trace_source",
    "split",
    "trace_set_provenance",
    "trace_source_names",
]
