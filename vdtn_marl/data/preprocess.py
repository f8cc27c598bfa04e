"""Clean a recorded speed profile into something a leader can physically drive.

:func:`preprocess` runs these steps, in order, and reports each in a :class:`PreprocessReport`:

1. **Duplicates.** Samples whose time equals the previous sample's (within 1 µs) are dropped;
   the first is kept. (The file readers of :mod:`~vdtn_marl.data.loaders` name such rows in
   a warning, and refuse a file whose rows repeat a time with speeds more than 0.5 m/s apart.)
2. **Gaps.** The nominal step is the median time step. A step longer than 1.5 × nominal is a
   gap (a lost frame or more). Gaps up to ``max_gap_s`` are bridged by the linear
   interpolation of step 3; longer gaps split the profile into segments, which get ids
   ``vehicle_id#0``, ``vehicle_id#1``, … Segments shorter than ``min_segment_s`` are dropped.
3. **Resampling** to a uniform grid of step ``dt_s`` (default: the nominal step) starting at the
   segment's first time, by linear interpolation.
4. **Smoothing** of speed (m/s):

   - ``"savgol"``: :func:`scipy.signal.savgol_filter`, polynomial order ``polyorder`` (2) over
     a window of ``window_s`` seconds (rounded to an odd sample count ≥ ``polyorder + 2``;
     shrunk to the segment if the segment is shorter), ``mode="interp"`` at the ends.
   - ``"ema"``: a zero-phase exponential moving average — :func:`scipy.signal.filtfilt` of the
     first-order filter ``y[k] = y[k−1] + α (x[k] − y[k−1])`` with ``α = 1 − exp(−dt/τ)`` and
     time constant ``τ = window_s / 4``, run forward then backward (so no lag; the ends are
     padded by odd reflection over ``3·window_s``). The factor 4 makes both smoothers remove
     about the same acceleration noise for the same ``window_s``.
   - ``"none"``: no smoothing.

5. **Speed clipping** to [0, ``max_speed_mps``] (smoothing can overshoot below 0 at stops).
6. **Acceleration clipping** (unless ``clip_accel_mps2=None``, which keeps the recorded
   acceleration): the profile is re-integrated forward so every step's
   acceleration lies in ``clip_accel_mps2`` (m/s²), i.e. ``v[k+1] = v[k] + dt · clip((x[k+1] −
   v[k]) / dt, a_min, a_max)`` (and kept inside the speed band), which follows the input
   wherever it is physically reachable.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from vdtn_marl.data.loaders import DUPLICATE_TOL_S, MAX_SPEED_MPS, SpeedProfile

Smoothing = Literal["savgol", "ema", "none"]
GAP_FACTOR = 1.5
"""A time step longer than this multiple of the nominal step counts as a gap."""
DEFAULT_MIN_SEGMENT_S = 5.0
"""The shortest stretch (s) :func:`preprocess` keeps by default."""
DEFAULT_CLIP_ACCEL_MPS2 = (-2.6, 2.6)
"""The acceleration band (m/s²) :func:`preprocess` clips to by default: the followers' actuator
limits (:class:`~vdtn_marl.sim.params.PlatoonParams`)."""


@dataclass
class PreprocessReport:
    """What :func:`preprocess` changed, for one input profile.

    Attributes:
        vehicle_id: the input profile's id.
        input_points / output_points: samples in, and samples out over all segments.
        duplicates_dropped: samples dropped because their time repeated the previous one.
        gaps_interpolated: gaps no longer than ``max_gap_s`` bridged by interpolation.
        gaps_split: gaps longer than ``max_gap_s`` where the profile was split.
        segments_dropped: segments discarded for being shorter than ``min_segment_s``.
        speed_points_clipped: grid points whose smoothed speed left [0, max_speed_mps].
        accel_points_clipped: grid steps whose acceleration was clipped.
        accel_min_before_mps2 / accel_max_before_mps2: the extreme accelerations (m/s²) of the
            resampled input, before smoothing and clipping (0 with no segment).
        accel_min_after_mps2 / accel_max_after_mps2: the same of the output.
        smoothing_rms_change_mps: RMS of (smoothed − resampled) speed in m/s, over all segments.
        nominal_dt_s / dt_s: the input's median step and the output grid step, in s.
        segments: the output segments' ids.
    """

    vehicle_id: str
    input_points: int
    output_points: int = 0
    duplicates_dropped: int = 0
    gaps_interpolated: int = 0
    gaps_split: int = 0
    segments_dropped: int = 0
    speed_points_clipped: int = 0
    accel_points_clipped: int = 0
    accel_min_before_mps2: float = 0.0
    accel_max_before_mps2: float = 0.0
    accel_min_after_mps2: float = 0.0
    accel_max_after_mps2: float = 0.0
    smoothing: str = "none"
    smoothing_rms_change_mps: float = 0.0
    nominal_dt_s: float = float("nan")
    dt_s: float = float("nan")
    segments: list[str] = field(default_factory=list)


def preprocess(
    profile: SpeedProfile,
    *,
    smoothing: Smoothing = "savgol",
    window_s: float = 2.0,
    polyorder: int = 2,
    dt_s: float | None = None,
    max_gap_s: float = 1.0,
    min_segment_s: float = DEFAULT_MIN_SEGMENT_S,
    max_speed_mps: float = MAX_SPEED_MPS,
    clip_accel_mps2: tuple[float, float] | None = DEFAULT_CLIP_ACCEL_MPS2,
) -> tuple[list[SpeedProfile], PreprocessReport]:
    """Clean one profile; returns the cleaned segments (on uniform grids) and a report.

    Usually one segment comes back; a gap longer than ``max_gap_s`` splits the profile and a
    profile shorter than ``min_segment_s`` yields none. See the module docstring for the rules.

    Args:
        smoothing: ``"savgol"``, ``"ema"`` or ``"none"``.
        window_s: smoothing window in s (Savitzky–Golay window; 4 × the EMA time constant).
        polyorder: Savitzky–Golay polynomial order.
        dt_s: output grid step in s (default: the input's median step).
        max_gap_s: longest gap in s that is interpolated rather than split.
        min_segment_s: shortest segment in s that is kept.
        max_speed_mps: upper speed clip in m/s.
        clip_accel_mps2: ``(a_min, a_max)`` in m/s², with ``a_min < 0 < a_max``; ``None``
            keeps the recorded acceleration (step 6 is skipped).
    """
    _check_args(smoothing, window_s, polyorder, dt_s, max_gap_s, min_segment_s, clip_accel_mps2)
    t = np.asarray(profile.time_s, dtype=np.float64)
    v = np.asarray(profile.speed_mps, dtype=np.float64)
    report = PreprocessReport(profile.vehicle_id, input_points=len(t), smoothing=smoothing)
    if len(t) and not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
        raise ValueError(f"profile {profile.vehicle_id!r} has non-finite times or speeds")
    if np.any(np.diff(t) < 0):
        raise ValueError(f"profile {profile.vehicle_id!r}: time_s must be non-decreasing")

    keep = np.concatenate([[True], np.diff(t) > DUPLICATE_TOL_S]) if len(t) else np.ones(0, bool)
    report.duplicates_dropped = int(np.count_nonzero(~keep))
    t, v = t[keep], v[keep]
    if len(t) < 2:
        return [], report

    steps = np.diff(t)
    nominal = float(np.median(steps))
    report.nominal_dt_s = nominal
    grid_dt = nominal if dt_s is None else float(dt_s)
    report.dt_s = grid_dt
    is_gap = steps > GAP_FACTOR * nominal
    splits = is_gap & (steps > max_gap_s)
    report.gaps_interpolated = int(np.count_nonzero(is_gap & ~splits))
    report.gaps_split = int(np.count_nonzero(splits))

    out: list[SpeedProfile] = []
    sq_change, n_change = 0.0, 0
    bounds = np.flatnonzero(splits) + 1
    for seg_t, seg_v in zip(np.split(t, bounds), np.split(v, bounds), strict=True):
        if seg_t[-1] - seg_t[0] < min_segment_s or len(seg_t) < 2:
            report.segments_dropped += 1
            continue
        count = int(np.floor((seg_t[-1] - seg_t[0]) / grid_dt + 1e-9)) + 1
        grid = seg_t[0] + grid_dt * np.arange(count)
        raw = np.interp(grid, seg_t, seg_v)
        smooth = _smooth(raw, grid_dt, smoothing, window_s, polyorder)
        sq_change += float(np.sum((smooth - raw) ** 2))
        n_change += len(raw)
        outside = (smooth < 0.0) | (smooth > max_speed_mps)
        report.speed_points_clipped += int(np.count_nonzero(outside))
        smooth = np.clip(smooth, 0.0, max_speed_mps)
        if clip_accel_mps2 is None:
            limited, n_clipped = smooth, 0
        else:
            limited, n_clipped = limit_acceleration(smooth, grid_dt, clip_accel_mps2, max_speed_mps)
        report.accel_points_clipped += n_clipped
        for when, speed in (("before", raw), ("after", limited)):
            accel = np.diff(speed) / grid_dt
            if accel.size:
                lo, hi = f"accel_min_{when}_mps2", f"accel_max_{when}_mps2"
                setattr(report, lo, min(getattr(report, lo), float(accel.min())))
                setattr(report, hi, max(getattr(report, hi), float(accel.max())))
        seg_id = f"{profile.vehicle_id}#{len(out)}" if len(bounds) else profile.vehicle_id
        out.append(SpeedProfile(grid, limited, seg_id, profile.source))
    report.smoothing_rms_change_mps = float(np.sqrt(sq_change / n_change)) if n_change else 0.0
    report.output_points = sum(len(p) for p in out)
    report.segments = [p.vehicle_id for p in out]
    return out, report


def preprocess_all(
    profiles: list[SpeedProfile], **kwargs: object
) -> tuple[list[SpeedProfile], list[PreprocessReport]]:
    """:func:`preprocess` every profile; returns all kept segments and one report per input."""
    segments: list[SpeedProfile] = []
    reports: list[PreprocessReport] = []
    for p in profiles:
        segs, rep = preprocess(p, **kwargs)  # type: ignore[arg-type]
        segments.extend(segs)
        reports.append(rep)
    return segments, reports


def summarize_reports(reports: list[PreprocessReport]) -> dict[str, object]:
    """What pre-processing changed over a file, as plain data (for a run's summary): profiles
    and samples in and out, samples whose speed or acceleration was clipped, and the extreme
    accelerations (m/s²) before and after."""

    def extreme(key: str, pick) -> float:
        values = [getattr(r, key) for r in reports]
        return float(pick(values)) if values else 0.0

    return {
        "profiles": len(reports),
        "segments": sum(len(r.segments) for r in reports),
        "input_points": sum(r.input_points for r in reports),
        "output_points": sum(r.output_points for r in reports),
        "speed_points_clipped": sum(r.speed_points_clipped for r in reports),
        "accel_points_clipped": sum(r.accel_points_clipped for r in reports),
        "accel_min_before_mps2": extreme("accel_min_before_mps2", min),
        "accel_min_after_mps2": extreme("accel_min_after_mps2", min),
        "accel_max_before_mps2": extreme("accel_max_before_mps2", max),
        "accel_max_after_mps2": extreme("accel_max_after_mps2", max),
        "smoothing": reports[0].smoothing if reports else "none",
    }


def limit_acceleration(
    speed_mps: np.ndarray,
    dt_s: float,
    accel_bounds_mps2: tuple[float, float],
    max_speed_mps: float = MAX_SPEED_MPS,
) -> tuple[np.ndarray, int]:
    """Re-integrate ``speed_mps`` (uniform step ``dt_s``) with per-step acceleration clipped.

    Returns the new speeds (m/s, in [0, ``max_speed_mps``]) and the number of steps clipped.
    """
    lo, hi = accel_bounds_mps2[0] * dt_s, accel_bounds_mps2[1] * dt_s
    steps = np.diff(speed_mps)
    if len(speed_mps) < 2 or (np.all(steps >= lo) and np.all(steps <= hi)):
        return speed_mps.copy(), 0
    out = np.empty_like(speed_mps)
    out[0] = speed_mps[0]
    clipped = 0
    for k in range(1, len(speed_mps)):
        step = speed_mps[k] - out[k - 1]
        if step < lo or step > hi:
            clipped += 1
            step = min(max(step, lo), hi)
        out[k] = min(max(out[k - 1] + step, 0.0), max_speed_mps)
    return out, clipped


def _smooth(
    speed: np.ndarray, dt_s: float, smoothing: Smoothing, window_s: float, polyorder: int
) -> np.ndarray:
    if smoothing == "none":
        return speed.copy()
    from scipy import signal

    if smoothing == "savgol":
        window = int(round(window_s / dt_s)) | 1  # odd
        smallest = polyorder + 1 if polyorder % 2 == 0 else polyorder + 2  # odd, > polyorder
        window = max(window, smallest)
        if window > len(speed):
            window = len(speed) if len(speed) % 2 == 1 else len(speed) - 1
        if window <= polyorder:
            return speed.copy()
        return signal.savgol_filter(speed, window, polyorder, mode="interp")
    alpha = 1.0 - float(np.exp(-dt_s / (window_s / 4.0)))
    b, a = [alpha], [1.0, alpha - 1.0]
    padlen = min(len(speed) - 1, int(round(3 * window_s / dt_s)))
    if padlen < 1:
        return speed.copy()
    return signal.filtfilt(b, a, speed, padlen=padlen, padtype="odd")


def _check_args(
    smoothing: str,
    window_s: float,
    polyorder: int,
    dt_s: float | None,
    max_gap_s: float,
    min_segment_s: float,
    clip_accel_mps2: tuple[float, float] | None,
) -> None:
    if smoothing not in ("savgol", "ema", "none"):
        raise ValueError(f"smoothing={smoothing!r} must be one of 'savgol', 'ema', 'none'")
    if not window_s > 0:
        raise ValueError(f"window_s={window_s} must be > 0 s")
    if not 0 <= polyorder <= 5:
        raise ValueError(f"polyorder={polyorder} must be in [0, 5]")
    if dt_s is not None and not dt_s > 0:
        raise ValueError(f"dt_s={dt_s} must be > 0 s")
    if not max_gap_s >= 0 or not min_segment_s >= 0:
        raise ValueError(f"max_gap_s={max_gap_s} and min_segment_s={min_segment_s} must be >= 0")
    if clip_accel_mps2 is None:
        return
    lo, hi = clip_accel_mps2
    if not lo < 0 < hi:
        raise ValueError(f"clip_accel_mps2={clip_accel_mps2} must satisfy a_min < 0 < a_max")
