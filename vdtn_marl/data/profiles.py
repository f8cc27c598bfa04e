"""Recorded speed profiles as a :class:`~vdtn_marl.data.traces.TraceSource`, and the split rule.

:class:`ProfileTraceSource` cuts random windows out of a fixed list of
:class:`~vdtn_marl.data.loaders.SpeedProfile`; :class:`DisjointWindowSource` hands out
non-overlapping windows of one instead; :func:`split` divides profiles into a train and an eval
part by a fixed, versioned rule; :func:`load_trace_source` builds a source from a file.
"""

from __future__ import annotations

import hashlib
import inspect
import logging
import re
from collections.abc import Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import torch

from vdtn_marl.data.loaders import LOADERS, SpeedProfile
from vdtn_marl.data.preprocess import (
    DEFAULT_CLIP_ACCEL_MPS2,
    DEFAULT_MIN_SEGMENT_S,
    preprocess_all,
    summarize_reports,
)
from vdtn_marl.data.traces import TraceInfo

NGSIM_LICENSE = (
    "U.S. DOT open data, terms as published on data.transportation.gov; cite: U.S. "
    "Department of Transportation Federal Highway Administration, Next Generation Simulation "
    "(NGSIM) Vehicle Trajectories and Supporting Data"
)
FILE_LICENSES = {
    "ngsim": NGSIM_LICENSE,
    "highd": "the licence the highD files were obtained under (ika, RWTH Aachen University); "
    "cite Krajewski et al., The highD Dataset, IEEE ITSC 2018",
    "csv": "the terms of the user's own file",
}
SPLIT_VERSION = "1"
"""Version of the train/eval rule in :func:`split`; changing the rule means bumping this."""
EVAL_MODULUS = 5
"""One profile in ``EVAL_MODULUS`` (by hash) goes to the eval part: a 80/20 split."""

Part = Literal["train", "eval", "all"]
TooShort = Literal["raise", "reflect"]
ACTUATOR_LIMITS = "the followers' actuator limits"

_log = logging.getLogger(__name__)


def split_key(vehicle_id: str) -> str:
    """The id the split hashes: ``vehicle_id`` less a ``#k`` segment suffix from preprocessing.

    So all segments of one vehicle land in the same part.
    """
    return re.sub(r"#\d+$", "", vehicle_id)


def is_eval(vehicle_id: str) -> bool:
    """Split rule v1: eval iff ``sha256("1:" + split_key(id))`` as an integer is ≡ 0 mod 5."""
    digest = hashlib.sha256(f"{SPLIT_VERSION}:{split_key(vehicle_id)}".encode()).hexdigest()
    return int(digest, 16) % EVAL_MODULUS == 0


def split(profiles: Sequence[SpeedProfile], part: Part = "train") -> list[SpeedProfile]:
    """Profiles of one part of the deterministic train/eval split (order kept).

    The rule depends only on each ``vehicle_id`` and :data:`SPLIT_VERSION` (see
    :func:`is_eval`), so the parts are disjoint, stable across runs and machines, and a
    profile's part does not change when other profiles are added. ``part="all"`` returns all.
    """
    if part == "all":
        return list(profiles)
    if part not in ("train", "eval"):
        raise ValueError(f"part={part!r} must be 'train', 'eval' or 'all'")
    want_eval = part == "eval"
    return [p for p in profiles if is_eval(p.vehicle_id) == want_eval]


def check_sample_request(num_traces: int, num_points: int, dt_s: float) -> None:
    """A trace source's ``sample`` arguments: ≥ 1 trace of ≥ 2 points at a step > 0 s."""
    if num_traces < 1 or num_points < 2 or not dt_s > 0:
        raise ValueError(
            f"num_traces={num_traces}, num_points={num_points}, dt_s={dt_s} must be "
            ">= 1, >= 2 and > 0"
        )


class ProfileTraceSource:
    """Hands out random windows of recorded speed profiles, resampled to the caller's grid.

    For each trace, a profile is picked uniformly (every profile equally likely, whatever its
    length) among those long enough for ``(num_points − 1)·dt_s`` seconds, then a start offset
    is drawn uniformly so the window fits, and the speed is linearly interpolated at
    ``offset + j·dt_s``. All draws come from the caller's generator.

    If no profile is long enough, ``too_short="raise"`` (default) raises a ``ValueError``
    naming the longest profile; ``too_short="reflect"`` instead makes every profile usable by
    playing it forward, then backward, then forward again… (speed stays continuous; the
    acceleration changes sign at each turn), with the offset drawn over one period.

    ``eval_vehicles`` (split keys, :func:`split_key`) marks a recorded set whose runs split it
    by vehicle, these vehicles evaluating and the others training
    (:func:`vehicle_split_sources`); ``None`` (default): runs split it in time
    (:func:`time_split_sources`).
    """

    def __init__(
        self,
        profiles: Sequence[SpeedProfile],
        info: TraceInfo | None = None,
        *,
        too_short: TooShort = "raise",
        eval_vehicles: Iterable[str] | None = None,
    ) -> None:
        if too_short not in ("raise", "reflect"):
            raise ValueError(f"too_short={too_short!r} must be 'raise' or 'reflect'")
        usable = [p for p in profiles if len(p) >= 2 and p.duration_s > 0]
        if not usable:
            raise ValueError("ProfileTraceSource needs at least one profile with >= 2 samples")
        for p in usable:
            if np.any(np.diff(p.time_s) <= 0) or not np.all(np.isfinite(p.speed_mps)):
                raise ValueError(
                    f"profile {p.vehicle_id!r} needs strictly increasing times and finite "
                    "speeds: run vdtn_marl.data.preprocess.preprocess on it first"
                )
            if np.any(p.speed_mps < 0):
                raise ValueError(f"profile {p.vehicle_id!r} has negative speeds")
        self.profiles = usable
        self.too_short = too_short
        #: what pre-processing changed in the file these profiles were read from (plain data,
        #: :func:`~vdtn_marl.data.preprocess.summarize_reports`), or None
        self.preprocessing: dict[str, Any] | None = None
        self.eval_vehicles = None if eval_vehicles is None else frozenset(eval_vehicles)
        self._times = [p.time_s - p.time_s[0] for p in usable]
        self._durations = np.array([p.duration_s for p in usable])
        self.info = info or TraceInfo(
            name="profiles",
            description=f"{len(usable)} recorded speed profiles",
            synthetic=False,
            source="; ".join(sorted({p.source for p in usable})),
        )

    def __len__(self) -> int:
        return len(self.profiles)

    def sample(
        self, num_traces: int, num_points: int, dt_s: float, generator: torch.Generator
    ) -> torch.Tensor:
        check_sample_request(num_traces, num_points, dt_s)
        span = (num_points - 1) * dt_s
        if self.too_short == "reflect":
            eligible = np.arange(len(self.profiles))
        else:
            eligible = np.flatnonzero(self._durations >= span - 1e-9)
            if eligible.size == 0:
                longest = int(np.argmax(self._durations))
                raise ValueError(
                    f"trace set {self.info.name!r}: no profile covers {span:g} s "
                    f"({num_points} points at dt {dt_s:g} s); the longest, "
                    f"{self.profiles[longest].vehicle_id!r}, lasts "
                    f"{self._durations[longest]:g} s. Use shorter episodes, more data, or "
                    "too_short='reflect'"
                )
        dev = generator.device
        pick = torch.randint(len(eligible), (num_traces,), generator=generator, device=dev)
        frac = torch.rand(num_traces, generator=generator, device=dev, dtype=torch.float64)
        pick_np, frac_np = pick.cpu().numpy(), frac.cpu().numpy()
        grid = dt_s * np.arange(num_points)
        out = np.empty((num_traces, num_points))
        for n in range(num_traces):
            i = int(eligible[pick_np[n]])
            dur = self._durations[i]
            if dur >= span - 1e-9:
                t = frac_np[n] * max(dur - span, 0.0) + grid
                t = np.minimum(t, dur)
            else:  # reflect: period 2·dur, offset anywhere in one period
                phase = np.mod(frac_np[n] * 2.0 * dur + grid, 2.0 * dur)
                t = np.where(phase > dur, 2.0 * dur - phase, phase)
            out[n] = np.interp(t, self._times[i], self.profiles[i].speed_mps)
        return torch.as_tensor(out, dtype=torch.get_default_dtype()).to(dev)


def load_profiles(
    kind: str,
    path: str | Path,
    *,
    part: Part = "all",
    clean: bool = True,
    preprocess_kw: dict[str, Any] | None = None,
    **loader_kw: Any,
) -> list[SpeedProfile]:
    """Read a file (``kind`` ``"ngsim"``, ``"highd"`` or ``"csv"``), clean it, keep one part.

    ``loader_kw`` go to the reader (e.g. ``vehicle_ids``, ``min_duration_s``,
    ``speed_range_mps``), ``preprocess_kw`` to :func:`~vdtn_marl.data.preprocess.preprocess`.
    """
    profiles, _ = _read_clean(kind, path, clean, preprocess_kw, loader_kw)
    return split(profiles, part)


def clipping_note(
    cleaning: dict[str, Any] | None, where: str, keep: str, why: str = ACTUATOR_LIMITS
) -> str | None:
    """One line when pre-processing clipped a file's acceleration (``cleaning``: what
    :func:`load_trace_source` and the like record as ``source.preprocessing``), else None:
    ``where`` names the file, ``why`` says what the band is, ``keep`` how to keep the
    recorded acceleration."""
    if not cleaning or not cleaning.get("accel_points_clipped"):
        return None
    lo, hi = cleaning["clip_accel_mps2"]
    return (
        f"{where}: pre-processing clipped the acceleration of "
        f"{cleaning['accel_points_clipped']} of {cleaning['output_points']} samples to "
        f"[{lo:g}, {hi:g}] m/s² ({why}): the largest deceleration "
        f"{-cleaning['accel_min_before_mps2']:.2f} m/s² became "
        f"{-cleaning['accel_min_after_mps2']:.2f} m/s², the largest acceleration "
        f"{cleaning['accel_max_before_mps2']:.2f} became "
        f"{cleaning['accel_max_after_mps2']:.2f}; {keep}"
    )


def _read_clean(
    kind: str,
    path: str | Path,
    clean: bool,
    preprocess_kw: dict[str, Any] | None,
    loader_kw: dict[str, Any],
    warn_clipping: bool = True,
) -> tuple[list[SpeedProfile], dict[str, Any] | None]:
    """The file's profiles, cleaned if ``clean``, and what cleaning changed
    (:func:`~vdtn_marl.data.preprocess.summarize_reports`; ``None`` when not cleaned). A
    warning (:func:`clipping_note`) says when the acceleration was clipped, unless
    ``warn_clipping`` is false (the CLI gives its own, naming its setting)."""
    try:
        loader = LOADERS[kind]
    except KeyError:
        raise ValueError(f"kind={kind!r} must be one of {', '.join(sorted(LOADERS))}") from None
    allowed = [k for k in inspect.signature(loader).parameters if k != "path"]
    unknown = sorted(set(loader_kw) - set(allowed))
    if unknown:
        raise ValueError(
            f"{unknown[0]}={loader_kw[unknown[0]]!r} is not a keyword of the {kind!r} reader; "
            f"allowed: {', '.join(allowed)}"
        )
    profiles = loader(path, **loader_kw)
    if not clean:
        return profiles, None
    kw = dict(preprocess_kw or {})
    raw_longest = max((p.duration_s for p in profiles), default=0.0)
    profiles, reports = preprocess_all(profiles, **kw)
    summary = summarize_reports(reports)
    summary["longest_input_s"] = float(raw_longest)
    summary["min_segment_s"] = float(kw.get("min_segment_s", DEFAULT_MIN_SEGMENT_S))
    band = kw.get("clip_accel_mps2", DEFAULT_CLIP_ACCEL_MPS2)
    summary["clip_accel_mps2"] = None if band is None else [float(b) for b in band]
    if warn_clipping:
        default = band is not None and tuple(band) == tuple(DEFAULT_CLIP_ACCEL_MPS2)
        note = clipping_note(
            summary,
            str(path),
            "preprocess_kw={'clip_accel_mps2': None} keeps the recorded ones",
            ACTUATOR_LIMITS if default else "preprocess_kw's clip_accel_mps2",
        )
        if note:
            _log.warning(note)
    return profiles, summary


def load_trace_source(
    kind: str,
    path: str | Path,
    *,
    part: Part = "all",
    too_short: TooShort = "raise",
    clean: bool = True,
    preprocess_kw: dict[str, Any] | None = None,
    **loader_kw: Any,
) -> ProfileTraceSource:
    """A :class:`ProfileTraceSource` over one part of a user's file (arguments as in
    :func:`load_profiles`); the parts are those of :func:`load_train_eval_sources`, so a file
    whose profiles all land in one part of the split (one drive) is split in time.

    Example: ``load_trace_source("ngsim", "trajectories-0750am-0805am.csv", part="train",
    min_duration_s=60, speed_range_mps=(5, 30))``. When pre-processing clips the
    acceleration, one warning names the file and how many samples changed
    (:func:`clipping_note`); ``source.preprocessing`` holds the figures.
    """
    if part not in ("train", "eval", "all"):
        raise ValueError(f"part={part!r} must be 'train', 'eval' or 'all'")
    profiles, cleaning = _selected_profiles(kind, path, clean, preprocess_kw, loader_kw)
    if part == "all":
        return _file_source(kind, path, profiles, "part=all", too_short, cleaning)
    parts, how = train_eval_parts(profiles)
    return _file_source(kind, path, parts[part], f"part={part}, {how}", too_short, cleaning)


def _selected_profiles(
    kind: str,
    path: str | Path,
    clean: bool,
    preprocess_kw: dict[str, Any] | None,
    loader_kw: dict[str, Any],
    warn_clipping: bool = True,
) -> tuple[list[SpeedProfile], dict[str, Any] | None]:
    """Every profile of the file that passes selection and cleaning (raises if none does),
    and what cleaning changed (as :func:`_read_clean`)."""
    profiles, cleaning = _read_clean(kind, path, clean, preprocess_kw, loader_kw, warn_clipping)
    if profiles:
        return profiles, cleaning
    name = Path(path).name
    if cleaning and cleaning["profiles"]:  # read, then every stretch was too short to keep
        raise ValueError(
            f"{name} is too short: its longest drive lasts {cleaning['longest_input_s']:g} s, "
            f"and pre-processing keeps stretches of at least {cleaning['min_segment_s']:g} s "
            "(a scenario needs far more: an episode and its look-ahead)"
        )
    if loader_kw:
        chosen = ", ".join(f"{k}={v!r}" for k, v in sorted(loader_kw.items()))
        raise ValueError(f"{name}: no {kind} profile passes the selection ({chosen}); loosen it")
    raise ValueError(f"{name} holds no {kind} profile")


def _file_source(
    kind: str,
    path: str | Path,
    profiles: list[SpeedProfile],
    how: str,
    too_short: TooShort,
    cleaning: dict[str, Any] | None = None,
) -> ProfileTraceSource:
    """A source over ``profiles`` read from ``path``; ``how`` says which part of the file."""
    info = TraceInfo(
        name=f"{kind}:{Path(path).name}",
        description=f"{len(profiles)} {kind} speed profiles from {Path(path).name} ({how})",
        synthetic=False,
        source=profiles[0].source,
        license=FILE_LICENSES.get(kind, ""),
    )
    source = ProfileTraceSource(profiles, info, too_short=too_short)
    source.preprocessing = cleaning
    return source


TIME_SPLIT_TRAIN_FRACTION = 1.0 - 1.0 / EVAL_MODULUS
"""The share of each profile's duration that trains when a file is split in time (0.8)."""
TIME_SPLIT_HOW = (
    f"first {TIME_SPLIT_TRAIN_FRACTION:.0%} / last {1 - TIME_SPLIT_TRAIN_FRACTION:.0%}"
    " of each profile's duration"
)


def time_split(profile: SpeedProfile, part: Literal["train", "eval"]) -> SpeedProfile:
    """The first 80 % of ``profile``'s duration (``"train"``) or its last 20 % (``"eval"``).

    The two parts share only the sample nearest the cut; ids get a ``@train``/``@eval`` suffix.
    """
    if part not in ("train", "eval"):
        raise ValueError(f"part={part!r} must be 'train' or 'eval'")
    t = profile.time_s
    cut_s = t[0] + TIME_SPLIT_TRAIN_FRACTION * profile.duration_s
    at = int(np.argmin(np.abs(t - cut_s)))
    keep = slice(0, at + 1) if part == "train" else slice(at, None)
    return SpeedProfile(
        t[keep], profile.speed_mps[keep], f"{profile.vehicle_id}@{part}", profile.source
    )


def time_split_sources(
    source: ProfileTraceSource,
) -> tuple[ProfileTraceSource, ProfileTraceSource]:
    """Training and evaluation sources of a recorded trace set: the first 80 % and the last
    20 % of each of its profiles' duration (:func:`time_split`), so that evaluation windows
    never replay a stretch that training drew from."""
    parts = []
    for part in ("train", "eval"):
        info = replace(
            source.info, description=f"{source.info.description} (part={part}, {TIME_SPLIT_HOW})"
        )
        profiles = [time_split(p, part) for p in source.profiles]
        parts.append(ProfileTraceSource(profiles, info, too_short=source.too_short))
    return parts[0], parts[1]


def vehicle_split_sources(
    source: ProfileTraceSource,
) -> tuple[ProfileTraceSource, ProfileTraceSource]:
    """Training and evaluation sources of a recorded trace set split by vehicle: the profiles
    of ``source.eval_vehicles`` (matched by :func:`split_key`, so every segment of a vehicle
    lands in the same part) evaluate, the others train. No stretch of road driven by an
    evaluation vehicle is ever drawn in training."""
    chosen = source.eval_vehicles
    if not chosen:
        raise ValueError(f"trace set {source.info.name!r} has no evaluation vehicles")
    keys = {split_key(p.vehicle_id) for p in source.profiles}
    if not chosen <= keys or chosen == keys:
        raise ValueError(
            f"trace set {source.info.name!r}: the evaluation vehicles must be some, not all, of "
            f"its vehicles; unknown: {', '.join(sorted(chosen - keys)) or 'none'}"
        )
    parts = []
    for part in ("train", "eval"):
        profiles = [
            p for p in source.profiles if (split_key(p.vehicle_id) in chosen) == (part == "eval")
        ]
        vehicles = len({split_key(p.vehicle_id) for p in profiles})
        how = f"split by vehicle: {vehicles} of {len(keys)} vehicles, {len(profiles)} segments"
        info = replace(source.info, description=f"{source.info.description} (part={part}, {how})")
        parts.append(ProfileTraceSource(profiles, info, too_short=source.too_short))
    return parts[0], parts[1]


class TooFewWindowsError(ValueError):
    """A :class:`DisjointWindowSource` asked for more windows than its profiles hold."""

    def __init__(self, message: str, available: int, needed: int) -> None:
        super().__init__(message)
        self.available = available
        self.needed = needed


class DisjointWindowSource:
    """Non-overlapping windows of a :class:`ProfileTraceSource`, in an order set by the seed.

    Each profile of duration ``d`` is tiled with ``n = ⌊(d − span) / stride⌋ + 1`` windows of
    ``span = (num_points − 1)·dt_s`` seconds, one ``stride = num_points·dt_s`` apart (so no
    two share a sample), shifted together by a drawn fraction of what the tiling leaves over
    at the profile's end; the windows of all profiles are then put in a drawn order
    (``torch.randperm``) and a call returns the first ``num_traces``. All draws come from the
    caller's generator, so a seed fixes the windows and their order. The windows of one call
    never overlap (an evaluation draws all its scenarios in one call); separate calls may
    hand out the same stretch again. Asking for more windows than there are raises
    :class:`TooFewWindowsError`, naming how many are available and how many are needed.
    """

    def __init__(self, source: ProfileTraceSource) -> None:
        if not isinstance(source, ProfileTraceSource):
            raise TypeError(f"DisjointWindowSource needs a ProfileTraceSource, got {source!r}")
        self.source = source
        self.profiles = source.profiles
        desc = source.info.description
        if "random windows" in desc:
            desc = desc.replace("random windows", "disjoint windows")
        else:
            desc = f"{desc}, disjoint windows"
        self.info = replace(source.info, description=desc)

    def __len__(self) -> int:
        return len(self.source)

    def windows_per_profile(self, num_points: int, dt_s: float) -> np.ndarray:
        """How many disjoint windows of ``num_points`` points at step ``dt_s`` each profile
        holds (see the class doc)."""
        if num_points < 2 or not dt_s > 0:
            raise ValueError(f"num_points={num_points} and dt_s={dt_s} must be >= 2 and > 0")
        span, stride = (num_points - 1) * dt_s, num_points * dt_s
        durations = self.source._durations
        fits = durations >= span - 1e-9
        counts = np.floor((durations - span) / stride + 1e-9).astype(np.int64) + 1
        return np.where(fits, counts, 0)

    def count(self, num_points: int, dt_s: float) -> int:
        """How many disjoint windows of ``num_points`` points at step ``dt_s`` there are."""
        return int(self.windows_per_profile(num_points, dt_s).sum())

    def sample(
        self, num_traces: int, num_points: int, dt_s: float, generator: torch.Generator
    ) -> torch.Tensor:
        check_sample_request(num_traces, num_points, dt_s)
        counts = self.windows_per_profile(num_points, dt_s)
        total = int(counts.sum())
        span, stride = (num_points - 1) * dt_s, num_points * dt_s
        if total < num_traces:
            durations = self.source._durations
            raise TooFewWindowsError(
                f"trace set {self.info.name!r}: {total} disjoint windows of {span:g} s "
                f"({num_points} points at dt {dt_s:g} s) available in its {len(durations)} "
                f"profiles ({durations.sum():.0f} s), {num_traces} needed; use fewer or shorter "
                "episodes, more data, or random (overlapping) windows",
                available=total,
                needed=num_traces,
            )
        dev = generator.device
        shift = torch.rand(len(counts), generator=generator, device=dev, dtype=torch.float64)
        order = torch.randperm(total, generator=generator, device=dev)[:num_traces]
        profile_of = np.repeat(np.arange(len(counts)), counts)
        index_in = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
        leftover = np.maximum(self.source._durations - span - (counts - 1) * stride, 0.0)
        offsets = shift.cpu().numpy() * leftover
        grid = dt_s * np.arange(num_points)
        out = np.empty((num_traces, num_points))
        for n, w in enumerate(order.cpu().numpy()):
            i = int(profile_of[w])
            t = offsets[i] + index_in[w] * stride + grid
            t = np.minimum(t, self.source._durations[i])
            out[n] = np.interp(t, self.source._times[i], self.profiles[i].speed_mps)
        return torch.as_tensor(out, dtype=torch.get_default_dtype()).to(dev)


def train_eval_parts(
    profiles: Sequence[SpeedProfile],
) -> tuple[dict[str, list[SpeedProfile]], str]:
    """``({"train": [...], "eval": [...]}, how)``: the profiles divided by the split rule
    (:func:`split`), or, when every profile lands in the same part (a file with one vehicle,
    say), each profile split in time (:func:`time_split`: its first 80 % trains, its last 20 %
    evaluates), so that evaluation never sees the stretch of road it was trained on."""
    parts = {part: split(profiles, part) for part in ("train", "eval")}
    if parts["train"] and parts["eval"]:
        return parts, f"split v{SPLIT_VERSION}"
    in_time = {part: [time_split(p, part) for p in profiles] for part in ("train", "eval")}
    return in_time, TIME_SPLIT_HOW


def load_train_eval_sources(
    kind: str,
    path: str | Path,
    *,
    too_short: TooShort = "raise",
    clean: bool = True,
    preprocess_kw: dict[str, Any] | None = None,
    warn_clipping: bool = True,
    **loader_kw: Any,
) -> tuple[ProfileTraceSource, ProfileTraceSource]:
    """Training and evaluation sources from one file, read once (arguments as in
    :func:`load_trace_source`).

    The parts are those of :func:`train_eval_parts`. When pre-processing clips the
    acceleration, one warning says so (:func:`clipping_note`), unless ``warn_clipping`` is
    false (the CLI gives its own, which names its setting).
    """
    profiles, cleaning = _selected_profiles(
        kind, path, clean, preprocess_kw, loader_kw, warn_clipping
    )
    parts, how = train_eval_parts(profiles)
    train, evaluation = (
        _file_source(kind, path, parts[part], f"part={part}, {how}", too_short, cleaning)
        for part in ("train", "eval")
    )
    return train, evaluation


class NGSIMTraceSource(ProfileTraceSource):
    """Leader traces from an NGSIM trajectory file the user has (never downloaded here).

    ``NGSIMTraceSource(path, vehicle_ids=None, part="train", min_duration_s=30.0, ...)``:
    selection keywords go to :func:`~vdtn_marl.data.loaders.load_ngsim`, cleaning is
    :func:`~vdtn_marl.data.preprocess.preprocess` with ``preprocess_kw``.
    """

    def __init__(
        self,
        path: str | Path,
        vehicle_ids: Sequence[str | int] | None = None,
        *,
        part: Part = "all",
        too_short: TooShort = "raise",
        preprocess_kw: dict[str, Any] | None = None,
        **loader_kw: Any,
    ) -> None:
        src = load_trace_source(
            "ngsim",
            path,
            part=part,
            too_short=too_short,
            preprocess_kw=preprocess_kw,
            vehicle_ids=vehicle_ids,
            **loader_kw,
        )
        info = TraceInfo(
            name="ngsim",
            description=src.info.description,
            synthetic=False,
            source="NGSIM vehicle trajectories (U.S. DOT FHWA, Next Generation Simulation), "
            f"file {Path(path).name}",
            license=NGSIM_LICENSE,
        )
        super().__init__(src.profiles, info, too_short=too_short)
