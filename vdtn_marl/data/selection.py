"""Which leader traces a run uses: ``scenario.traces`` and ``scenario.trace_path`` checked up
front, and the training and evaluation sources they select.

A generated trace set (``synthetic``, ``constant``) serves training and evaluation alike
(their scenarios are seeded apart, so evaluation draws traces training never saw); a recorded
one (``udds``, ``hwfet``: one drive each) is split in time, its first 80 % for training and
its last 20 % for evaluation (:func:`named_sources`); a user's file
(``scenario.traces=csv|highd|ngsim`` with ``scenario.trace_path``) is read once and divided
into a train and an eval part (:func:`~vdtn_marl.data.profiles.load_train_eval_sources`).
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

from vdtn_marl.data.loaders import LOADERS
from vdtn_marl.data.profiles import (
    ProfileTraceSource,
    load_train_eval_sources,
    time_split_sources,
)
from vdtn_marl.data.traces import TraceSource, get_trace_source, trace_source_names
from vdtn_marl.sim.params import ConfigError

FILE_FORMATS = tuple(sorted(LOADERS))
"""Values of ``scenario.traces`` that read ``scenario.trace_path``."""


def check_trace_settings(traces: str, trace_path: str | None) -> None:
    """Raise :class:`ConfigError` naming the key unless the settings select usable traces.

    A trace file is read (once per process and file version, see :func:`file_sources`), so a
    malformed or empty file is reported here, before a run starts.
    """
    if trace_path is None:
        if traces in trace_source_names():
            return
        if traces in FILE_FORMATS:
            raise ConfigError(
                f"scenario.traces={traces!r} reads a file: set scenario.trace_path=FILE"
            )
        raise ConfigError(
            f"scenario.traces={traces!r} is not a known trace set; choose one of "
            f"{', '.join(trace_source_names())}, or set scenario.traces to a file format "
            f"({', '.join(FILE_FORMATS)}) and scenario.trace_path to the file"
        )
    if traces not in FILE_FORMATS:
        raise ConfigError(
            f"scenario.traces={traces!r} cannot read scenario.trace_path={trace_path!r}; "
            f"with a trace file set scenario.traces to its format: {', '.join(FILE_FORMATS)}"
        )
    file_sources(traces, trace_path)


def split_in_time(name: str) -> bool:
    """Whether runs split the named trace set ``name`` in time (:func:`named_sources`): true
    for a recorded set, false for a generated one."""
    return isinstance(get_trace_source(name), ProfileTraceSource)


def named_sources(name: str) -> tuple[str | TraceSource, str | TraceSource]:
    """Training and evaluation sources of the named trace set ``name``: the name itself for
    both when its traces are generated, the two time parts of a recorded set
    (:func:`~vdtn_marl.data.profiles.time_split_sources`), which would otherwise evaluate on
    windows of the drive it trained on."""
    source = get_trace_source(name)
    if isinstance(source, ProfileTraceSource):
        return time_split_sources(source)
    return name, name


def file_sources(kind: str, trace_path: str) -> tuple[ProfileTraceSource, ProfileTraceSource]:
    """Training and evaluation sources of a user's trace file; :class:`ConfigError` naming
    ``scenario.trace_path`` if it is missing or cannot be read as ``kind``."""
    path = Path(trace_path).expanduser()
    if not path.is_file():
        raise ConfigError(f"scenario.trace_path={trace_path!r} is not a file")
    stat = path.stat()
    try:
        return _read(kind, str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    except (ValueError, OSError) as exc:  # TraceFormatError is a ValueError
        raise ConfigError(f"scenario.trace_path={trace_path!r} ({kind}): {exc}") from None


@lru_cache(maxsize=4)
def _read(
    kind: str, path: str, mtime_ns: int, size: int
) -> tuple[ProfileTraceSource, ProfileTraceSource]:
    """Cached per file version (the sources are stateless: draws come from the caller)."""
    return load_train_eval_sources(kind, path)
