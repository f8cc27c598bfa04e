"""Leader speed traces for the digital twin (docs/model.md §3)."""

from vdtn_marl.data.traces import (
    ConstantSpeedTraceSource,
    SyntheticTraceSource,
    TraceInfo,
    TraceSource,
    get_trace_source,
    register_trace_source,
    trace_source_names,
)

__all__ = [
    "ConstantSpeedTraceSource",
    "SyntheticTraceSource",
    "TraceInfo",
    "TraceSource",
    "get_trace_source",
    "register_trace_source",
    "trace_source_names",
]
