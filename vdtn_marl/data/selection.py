"""Which leader traces a run uses: ``scenario.traces`` and ``scenario.trace_path`` checked up
front, and the training and evaluation sources they select.

A generated trace set (``synthetic``, ``constant``) serves training and evaluation alike
(their scenarios are seeded apart, so evaluation draws traces training never saw); a recorded
one is split: ``udds`` and ``hwfet`` (one drive each) in time, their first 80 % for training
and their last 20 % for evaluation, ``cmap`` (22 vehicles) by vehicle, a fixed list of
households evaluating (:func:`named_sources`); a user's file (``scenario.traces=csv|highd|ngsim``
with ``scenario.trace_path``) is read once and divided into a train and an eval part
(:func:`~vdtn_marl.data.profiles.load_train_eval_sources`).

``scenario.eval_windows`` chooses how evaluation cuts windows out of a recorded eval part:
``random`` (default) draws each scenario's window independently, so windows may overlap;
``disjoint`` hands out non-overlapping windows in an order set by the seed
(:class:`~vdtn_marl.data.profiles.DisjointWindowSource`), and :func:`check_eval_windows`
refuses the setting up front when the eval part holds too few. Generated sets draw independent
traces either way.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from functools import lru_cache
from pathlib import Path

from vdtn_marl.data.loaders import LOADERS
from vdtn_marl.data.preprocess import DEFAULT_CLIP_ACCEL_MPS2
from vdtn_marl.data.profiles import (
    TIME_SPLIT_HOW,
    TIME_SPLIT_TRAIN_FRACTION,
    DisjointWindowSource,
    ProfileTraceSource,
    clipping_note,
    load_train_eval_sources,
    time_split_sources,
    vehicle_split_sources,
)
from vdtn_marl.data.traces import TraceSource, get_trace_source, trace_source_names
from vdtn_marl.errors import ConfigError

FILE_FORMATS = tuple(sorted(LOADERS))
"""Values of ``scenario.traces`` that read ``scenario.trace_path``."""
EVAL_WINDOWS = ("random", "disjoint")
"""Values of ``scenario.eval_windows`` (:func:`eval_source`)."""
TRACE_ACCEL_CLIPS = ("actuator", "none")
"""Values of ``scenario.trace_accel_clip`` (:func:`accel_band`)."""
EVAL_LOOKAHEAD_INTERVALS = 200
"""Look-ahead of the evaluation twin beyond the episode, in control intervals (the default of
:class:`~vdtn_marl.sim.twin.DigitalTwin`, which evaluation uses)."""


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
    for a recorded set of one drive (``udds``, ``hwfet``), false for one split by vehicle
    (``cmap``) and for a generated one."""
    source = get_trace_source(name)
    return isinstance(source, ProfileTraceSource) and not source.eval_vehicles


def named_sources(
    name: str, eval_windows: str = "random"
) -> tuple[str | TraceSource, str | TraceSource]:
    """Training and evaluation sources of the named trace set ``name``: the name itself for
    both when its traces are generated; for a recorded set, its two parts, by vehicle when it
    names evaluation vehicles (``cmap``:
    :func:`~vdtn_marl.data.profiles.vehicle_split_sources`) and otherwise in time
    (:func:`~vdtn_marl.data.profiles.time_split_sources`), since evaluating on windows of the
    drive it trained on would flatter the policy. ``eval_windows`` as in :func:`eval_source`."""
    check_eval_windows_value(eval_windows)
    source = get_trace_source(name)
    if not isinstance(source, ProfileTraceSource):
        return name, name
    if source.eval_vehicles:
        train, evaluation = vehicle_split_sources(source)
    else:
        train, evaluation = time_split_sources(source)
    return train, eval_source(evaluation, eval_windows)


def check_eval_windows_value(eval_windows: str) -> None:
    if eval_windows not in EVAL_WINDOWS:
        raise ConfigError(
            f"scenario.eval_windows={eval_windows!r} is not allowed; choose one of "
            f"{', '.join(EVAL_WINDOWS)}"
        )


def eval_source(source: str | TraceSource, eval_windows: str) -> str | TraceSource:
    """The evaluation source for ``scenario.eval_windows``: ``source`` itself for ``random``
    (or a generated set), its :class:`~vdtn_marl.data.profiles.DisjointWindowSource` for
    ``disjoint``."""
    check_eval_windows_value(eval_windows)
    if eval_windows == "disjoint" and isinstance(source, ProfileTraceSource):
        return DisjointWindowSource(source)
    return source


def check_eval_windows(
    traces: str,
    trace_path: str | None,
    eval_windows: str,
    *,
    episodes: int,
    episode_intervals: int,
    control_interval_s: float,
    leaders: int = 1,
) -> None:
    """Raise :class:`ConfigError` naming ``scenario.eval_windows`` when ``disjoint`` is asked
    for and the eval part holds fewer disjoint windows of an episode and the look-ahead
    (``episode_intervals + 1 + EVAL_LOOKAHEAD_INTERVALS`` points) than evaluation draws: one per
    leader of each of the ``episodes`` scenarios; the message names both numbers. The trace
    settings must be valid (:func:`check_trace_settings`)."""
    check_eval_windows_value(eval_windows)
    if eval_windows == "random":
        return
    if trace_path is None:
        _, evaluation = named_sources(traces, eval_windows)
    else:
        _, evaluation = file_sources(traces, trace_path, eval_windows)
    if not isinstance(evaluation, DisjointWindowSource):
        return
    num_points = episode_intervals + 1 + EVAL_LOOKAHEAD_INTERVALS
    available = evaluation.count(num_points, control_interval_s)
    if available < episodes * leaders:
        span = (num_points - 1) * control_interval_s
        needed = f"{episodes}" if leaders == 1 else f"{episodes} × {leaders} leaders"
        raise ConfigError(
            f"scenario.eval_windows=disjoint: the eval part of scenario.traces={traces!r} holds "
            f"{available} disjoint windows of {span:g} s (episode and look-ahead), "
            f"experiment.eval_episodes={needed} needed; use scenario.eval_windows=random, "
            "fewer episodes or a larger trace set"
        )


def check_trace_lengths(
    traces: str,
    trace_path: str | None,
    *,
    episode_intervals: int,
    control_interval_s: float,
) -> None:
    """Raise :class:`ConfigError` naming the trace setting when a part of the selected traces
    (training or evaluation) holds no profile long enough for one scenario: the episode plus
    the twin's look-ahead for VoI rollouts (``episode_intervals + EVAL_LOOKAHEAD_INTERVALS``
    control intervals). The message gives the length needed, why, and, for a file split in
    time, how long the file must be. Generated sets always fit. The trace settings must be
    valid (:func:`check_trace_settings`)."""
    if trace_path is None:
        parts = named_sources(traces)
        key = f"scenario.traces={traces!r}"
    else:
        parts = file_sources(traces, trace_path)
        key = f"scenario.trace_path={trace_path!r} ({traces})"
    span = (episode_intervals + EVAL_LOOKAHEAD_INTERVALS) * control_interval_s
    episode_s = episode_intervals * control_interval_s
    why = (
        f"{span:g} s (the episode, scenario.episode_intervals={episode_intervals} = "
        f"{episode_s:g} s, and {span - episode_s:g} s of look-ahead for VoI rollouts)"
    )
    for part, source in zip(("train", "eval"), parts, strict=True):
        if not isinstance(source, ProfileTraceSource) or source.too_short == "reflect":
            continue
        longest = max(p.duration_s for p in source.profiles)
        if longest >= span - 1e-9:
            continue
        if TIME_SPLIT_HOW in source.info.description:
            share = TIME_SPLIT_TRAIN_FRACTION if part == "train" else 1 - TIME_SPLIT_TRAIN_FRACTION
            need = span / min(TIME_SPLIT_TRAIN_FRACTION, 1 - TIME_SPLIT_TRAIN_FRACTION)
            raise ConfigError(
                f"{key} is too short: its {part} part (the {'first' if part == 'train' else 'last'}"
                f" {share:.0%} of each drive) lasts at most {longest:g} s, and a scenario needs "
                f"{why}; a run trains on the first {TIME_SPLIT_TRAIN_FRACTION:.0%} and evaluates "
                f"on the last {1 - TIME_SPLIT_TRAIN_FRACTION:.0%} of a drive, so a drive must "
                f"last at least {need:g} s; use a longer recording or fewer "
                "scenario.episode_intervals"
            )
        raise ConfigError(
            f"{key} is too short: no profile of its {part} part ({source.info.description}) "
            f"lasts {span:g} s (the longest {longest:g} s), and a scenario needs {why}; use "
            "longer recordings or fewer scenario.episode_intervals"
        )


def accel_band(
    trace_accel_clip: str, accel_min_mps2: float, accel_max_mps2: float
) -> tuple[float, float] | None:
    """The acceleration band (m/s²) pre-processing clips a trace file to for
    ``scenario.trace_accel_clip``: the followers' actuator limits (``actuator``) or none."""
    if trace_accel_clip not in TRACE_ACCEL_CLIPS:
        raise ConfigError(
            f"scenario.trace_accel_clip={trace_accel_clip!r} is not allowed; choose one of "
            f"{', '.join(TRACE_ACCEL_CLIPS)}"
        )
    return None if trace_accel_clip == "none" else (accel_min_mps2, accel_max_mps2)


def preprocessing_note(source: object, trace_path: str | None) -> str | None:
    """One line when pre-processing clipped the acceleration of the trace file ``source`` was
    read from (what changed, and the setting that keeps the recorded one), else None."""
    return clipping_note(
        getattr(source, "preprocessing", None),
        f"scenario.trace_path={trace_path!r}",
        "scenario.trace_accel_clip=none keeps the recorded ones",
    )


def file_sources(
    kind: str,
    trace_path: str,
    eval_windows: str = "random",
    clip_accel_mps2: tuple[float, float] | None = DEFAULT_CLIP_ACCEL_MPS2,
) -> tuple[ProfileTraceSource, ProfileTraceSource | DisjointWindowSource]:
    """Training and evaluation sources of a user's trace file; :class:`ConfigError` naming
    ``scenario.trace_path`` if it is missing or cannot be read as ``kind``. ``eval_windows``
    as in :func:`eval_source`; ``clip_accel_mps2`` is pre-processing's acceleration band
    (:func:`accel_band`; ``None`` keeps the recorded acceleration). Both sources carry what
    pre-processing changed (``source.preprocessing``)."""
    check_eval_windows_value(eval_windows)
    path = Path(trace_path).expanduser()
    if not path.is_file():
        raise ConfigError(f"scenario.trace_path={trace_path!r} is not a file")
    stat = path.stat()
    try:
        band = None if clip_accel_mps2 is None else tuple(float(b) for b in clip_accel_mps2)
        train, evaluation = _read(kind, str(path.resolve()), stat.st_mtime_ns, stat.st_size, band)
    except (ValueError, OSError) as exc:  # TraceFormatError is a ValueError
        raise ConfigError(f"scenario.trace_path={trace_path!r} ({kind}): {exc}") from None
    return train, eval_source(evaluation, eval_windows)


@lru_cache(maxsize=4)
def _read(
    kind: str, path: str, mtime_ns: int, size: int, band: tuple[float, ...] | None
) -> tuple[ProfileTraceSource, ProfileTraceSource]:
    """Cached per file version and band (the sources are stateless: draws come from the
    caller); what the reader warns of is said once per file version, whatever the band."""
    # the run warns of clipping itself (preprocessing_note), naming its setting
    with _said_once((path, mtime_ns, size)):
        return load_train_eval_sources(
            kind, path, preprocess_kw={"clip_accel_mps2": band}, warn_clipping=False
        )


_SAID: set[tuple[object, ...]] = set()


@contextlib.contextmanager
def _said_once(version: tuple[object, ...]) -> Iterator[None]:
    """Drop the readers' warnings already given for this file version in this process (a
    run reads a file for its checks with one band and may train with another)."""

    def first_time(record: logging.LogRecord) -> bool:
        key = (*version, record.getMessage())
        if key in _SAID:
            return False
        _SAID.add(key)
        return True

    reader = logging.getLogger("vdtn_marl.data.loaders")
    reader.addFilter(first_time)
    try:
        yield
    finally:
        reader.removeFilter(first_time)
