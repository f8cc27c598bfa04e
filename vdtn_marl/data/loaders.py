"""Readers for recorded leader speed data: NGSIM, highD-style tracks and plain ``time,speed`` CSV.

Every reader returns a list of :class:`SpeedProfile` (time in s, speed in m/s, one per vehicle)
and raises :class:`TraceFormatError` for a file it cannot trust. Error messages name the file,
the 1-based *data* row (the header is not counted, so data row ``r`` is line ``r + 1`` of the
file, blank lines aside) and the problem, e.g. ``traces.csv row 17: speed -3.2 m/s is negative``.

Files may be plain or compressed (``.gz``, ``.bz2``, ``.xz``, ``.zst``, or a ``.zip`` holding
one CSV); pandas infers the compression from the file name. pandas is imported lazily.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vdtn_marl.errors import TraceFormatError

FT_TO_M = 0.3048
"""Feet to metres (exact, international foot)."""
MPH_TO_MPS = 0.44704
"""Miles per hour to m/s (exact, international mile: 1609.344 m per 3600 s)."""
KMH_TO_MPS = 1.0 / 3.6
"""km/h to m/s."""


@dataclass(frozen=True)
class SpeedColumn:
    """A speed column of a ``time,speed`` CSV: accepted headers, its unit, the factor to m/s."""

    headers: tuple[str, ...]
    unit: str
    to_mps: float


SPEED_COLUMNS = (
    SpeedColumn(("speed", "speed_mps"), "m/s", 1.0),
    SpeedColumn(("speed_kmh", "speed_kph"), "km/h", KMH_TO_MPS),
    SpeedColumn(("speed_mph",), "mph", MPH_TO_MPS),
)
"""The speed columns a ``time,speed`` CSV may have (exactly one of them)."""
MAX_SPEED_MPS = 70.0
"""Highest speed accepted from a file (252 km/h); anything faster is taken as a unit mix-up."""
PLAUSIBLE_MAX_SPEED_MPS = 45.0
"""A speed column read as m/s whose maximum is above this (162 km/h) draws a warning: road
vehicles rarely drive so fast, and km/h read as m/s look like this."""
PLAUSIBLE_MEDIAN_SPEED_MPS = 36.0
"""Likewise for a median above this (130 km/h, the highest common motorway limit)."""
DUPLICATE_TOL_S = 1e-6
"""A sample whose time is within this (s) of the previous sample's repeats its timestamp."""
DUPLICATE_SPEED_TOL_MPS = 0.5
"""How far (m/s) the speeds of rows repeating a timestamp may differ: within it they are one
sample recorded twice (rounding aside) and pre-processing keeps the first; beyond it the file
contradicts itself and is refused."""
MAX_LISTED_ROWS = 10
"""At most this many row numbers are listed in a warning (then how many more)."""
NGSIM_FRAME_PERIOD_S = 0.1
HIGHD_FRAME_RATE_HZ = 25.0

_COMPRESSION_SUFFIXES = (".gz", ".bz2", ".xz", ".zst", ".zip", ".tar")

_log = logging.getLogger(__name__)


@dataclass(eq=False)
class SpeedProfile:
    """One vehicle's speed over time.

    Attributes:
        time_s: sample times in s, shape ``[n]``, non-decreasing (readers shift nothing: NGSIM
            and highD times count from the vehicle's first frame, ``time,speed`` files keep
            their own times).
        speed_mps: speeds in m/s, shape ``[n]``, finite and in [0, ``MAX_SPEED_MPS``].
        vehicle_id: stable identifier, used by the train/eval split
            (:func:`vdtn_marl.data.profiles.split`).
        source: human-readable provenance (file name and format).
    """

    time_s: np.ndarray
    speed_mps: np.ndarray
    vehicle_id: str
    source: str

    def __post_init__(self) -> None:
        self.time_s = np.asarray(self.time_s, dtype=np.float64)
        self.speed_mps = np.asarray(self.speed_mps, dtype=np.float64)
        if self.time_s.ndim != 1 or self.time_s.shape != self.speed_mps.shape:
            raise ValueError(
                f"profile {self.vehicle_id!r}: time_s {self.time_s.shape} and speed_mps "
                f"{self.speed_mps.shape} must be 1-D arrays of the same length"
            )

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample, in s (0 for fewer than two samples)."""
        return float(self.time_s[-1] - self.time_s[0]) if len(self.time_s) > 1 else 0.0

    def __len__(self) -> int:
        return len(self.time_s)


# --------------------------------------------------------------------------------------------
# table reading and validation


def _pandas() -> Any:
    """pandas, imported on first use (it is slow to import and only the readers need it)."""
    import pandas as pd

    return pd


def file_stem(path: str | Path) -> str:
    """File name less ``.csv`` and compression suffixes (``01_tracks.csv.gz``: ``01_tracks``)."""
    name = Path(path).name
    lowered = name.lower()
    for suffix in _COMPRESSION_SUFFIXES:
        if lowered.endswith(suffix):
            name, lowered = name[: -len(suffix)], lowered[: -len(suffix)]
            break
    if lowered.endswith(".csv"):
        name = name[:-4]
    return name


def _header(path: Path) -> list[Any]:
    """The column names of a CSV file (raises :class:`TraceFormatError` if unreadable)."""
    try:
        return list(_pandas().read_csv(path, nrows=0, compression="infer").columns)
    except FileNotFoundError:
        raise
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise TraceFormatError(path, None, f"not a readable CSV file ({exc})") from None


def _read_columns(
    path: str | Path,
    wanted: dict[str, Sequence[str]],
    optional: dict[str, Sequence[str]] | None = None,
) -> tuple[dict[str, np.ndarray], int]:
    """Read the wanted columns of a CSV as raw strings.

    ``wanted``/``optional`` map a canonical name to accepted header spellings (matched without
    case or surrounding blanks). Returns ``({canonical: array of str}, number of rows)``.
    """
    pd = _pandas()
    path = Path(path)
    header = _header(path)
    by_key = {str(c).strip().lower(): c for c in header}
    chosen: dict[str, Any] = {}
    for canonical, spellings in {**wanted, **(optional or {})}.items():
        for spelling in spellings:
            if spelling.lower() in by_key:
                chosen[canonical] = by_key[spelling.lower()]
                break
        else:
            if canonical in wanted:
                have = ", ".join(str(c).strip() for c in header) or "none"
                raise TraceFormatError(
                    path,
                    None,
                    f"missing column {spellings[0]!r} (columns found: {have})",
                )
    try:
        table = pd.read_csv(
            path,
            usecols=list(chosen.values()),
            dtype=str,
            keep_default_na=False,
            compression="infer",
        )
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        raise TraceFormatError(path, None, f"not a readable CSV file ({exc})") from None
    if len(table) == 0:
        raise TraceFormatError(path, None, "no data rows")
    columns = {name: table[col].to_numpy(dtype=object) for name, col in chosen.items()}
    return columns, len(table)


def _numeric(path: Path, name: str, raw: np.ndarray, unit: str = "") -> np.ndarray:
    """Parse a column of strings as finite floats or raise naming the first bad row."""
    pd = _pandas()
    values = pd.to_numeric(pd.Series(raw), errors="coerce").to_numpy(dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        i = int(bad[0])
        text = str(raw[i]).strip()
        problem = (
            f"missing value in column {name!r}"
            if text == ""
            else f"value {text!r} in column {name!r} is not a finite number{unit}"
        )
        raise TraceFormatError(path, i + 1, problem)
    return values


def _check_speeds(path: Path, speed_mps: np.ndarray, rows: np.ndarray, hint: str) -> None:
    """Reject negative or impossibly fast speeds (m/s), naming the first offending row."""
    negative = np.flatnonzero(speed_mps < 0.0)
    too_fast = np.flatnonzero(speed_mps > MAX_SPEED_MPS)
    first = min([int(a[0]) for a in (negative, too_fast) if a.size], default=None)
    if first is None:
        return
    v = float(speed_mps[first])
    if v < 0.0:
        problem = f"speed {v:.4g} m/s is negative (allowed: 0 to {MAX_SPEED_MPS:g} m/s)"
    else:
        problem = (
            f"speed {v:.4g} m/s is above {MAX_SPEED_MPS:g} m/s ({MAX_SPEED_MPS * 3.6:.0f} "
            f"km/h), which usually means a unit mix-up: {hint}"
        )
    raise TraceFormatError(path, int(rows[first]) + 1, problem)


def _listed(rows: Sequence[int]) -> str:
    """``rows 3, 8 and 12`` (at most :data:`MAX_LISTED_ROWS`, then how many more)."""
    shown = [str(r) for r in rows[:MAX_LISTED_ROWS]]
    more = len(rows) - len(shown)
    if more:
        return f"rows {', '.join(shown)} and {more} more"
    if len(shown) == 1:
        return f"row {shown[0]}"
    return f"rows {', '.join(shown[:-1])} and {shown[-1]}"


def _check_repeated_times(
    path: Path,
    profiles: Sequence[SpeedProfile],
    rows_of: dict[str, np.ndarray],
    unit: str,
    to_mps: float,
    vehicle_of: dict[str, str] | None = None,
) -> None:
    """Refuse rows that repeat a timestamp with a different speed; say which repeat it with
    the same speed (they are dropped by :func:`~vdtn_marl.data.preprocess.preprocess`).

    ``rows_of`` maps each profile's ``vehicle_id`` to its samples' 0-based data rows,
    ``unit``/``to_mps`` are the file's speed unit and its factor to m/s (for the message),
    ``vehicle_of`` names the vehicle of each profile in a file of several."""
    repeated: list[int] = []
    for p in profiles:
        t, v, rows = p.time_s, p.speed_mps, rows_of[p.vehicle_id]
        if len(t) < 2:
            continue
        keep = np.concatenate([[True], np.diff(t) > DUPLICATE_TOL_S])
        if keep.all():
            continue
        first = np.maximum.accumulate(np.where(keep, np.arange(len(t)), 0))
        dup = np.flatnonzero(~keep)
        apart = np.abs(v[dup] - v[first[dup]])
        bad = dup[apart > DUPLICATE_SPEED_TOL_MPS + 1e-9]
        if bad.size:
            i, j = int(bad[0]), int(first[bad[0]])
            who = f"vehicle {vehicle_of[p.vehicle_id]}, " if vehicle_of else ""
            more = f" ({bad.size - 1} more such rows)" if bad.size > 1 else ""
            raise TraceFormatError(
                path,
                None,
                f"{who}rows {int(rows[j]) + 1} and {int(rows[i]) + 1} share the time "
                f"{t[i]:g} s but not the speed: {v[j] / to_mps:.4g} and {v[i] / to_mps:.4g} "
                f"{unit}, {abs(v[i] - v[j]):.3g} m/s apart (allowed: rows repeating a time "
                f"may differ by at most {DUPLICATE_SPEED_TOL_MPS:g} m/s; the first is kept)"
                f"{more}; remove the wrong row",
            )
        repeated.extend(int(r) + 1 for r in rows[dup])
    if repeated:
        _log.warning(
            "%s: %s repeat the time of the row before (speeds within %g m/s); pre-processing "
            "keeps the first row of each time and drops %s",
            path.name,
            _listed(sorted(repeated)),
            DUPLICATE_SPEED_TOL_MPS,
            "it" if len(repeated) == 1 else "them",
        )


def _check_plausible_mps(path: Path, speed_mps: np.ndarray, column: str) -> None:
    """Warn when a column read as m/s looks like km/h: a maximum above
    :data:`PLAUSIBLE_MAX_SPEED_MPS` or a median above :data:`PLAUSIBLE_MEDIAN_SPEED_MPS`."""
    if not speed_mps.size:
        return
    top, median = float(speed_mps.max()), float(np.median(speed_mps))
    if top <= PLAUSIBLE_MAX_SPEED_MPS and median <= PLAUSIBLE_MEDIAN_SPEED_MPS:
        return
    _log.warning(
        "%s: column %r is read as m/s, but its speeds reach %.4g m/s (%.0f km/h) with a "
        "median of %.3g m/s (%.0f km/h), faster than road vehicles drive (plausible: a maximum "
        "up to %g m/s, a median up to %g m/s); they look like km/h (%.4g km/h = %.3g m/s): if "
        "so, name the column speed_kmh",
        path.name,
        column,
        top,
        top * 3.6,
        median,
        median * 3.6,
        PLAUSIBLE_MAX_SPEED_MPS,
        PLAUSIBLE_MEDIAN_SPEED_MPS,
        top,
        top / 3.6,
    )


def _group_by_vehicle(keys: np.ndarray, frame: np.ndarray) -> Iterable[tuple[Any, np.ndarray]]:
    """Yield ``(key, row indices sorted by frame)`` per vehicle, in order of first appearance."""
    codes, uniques = _pandas().factorize(keys)  # codes number keys by first appearance
    order = np.lexsort((frame, codes))  # by vehicle, then frame; stable for equal frames
    bounds = np.flatnonzero(np.diff(codes[order])) + 1
    for idx in np.split(order, bounds):
        yield uniques[codes[idx[0]]], idx


def _raw_id(value: Any) -> str:
    """Normalise an id cell: ``'12'``, ``'12.0'`` and ``' 12 '`` all become ``'12'``."""
    text = str(value).strip()
    if re.fullmatch(r"[+-]?\d+\.0*", text):
        text = text.split(".")[0]
    return text


def _select(
    profiles: list[tuple[str, SpeedProfile]],
    vehicle_ids: Iterable[str | int] | None,
    min_duration_s: float,
    speed_range_mps: tuple[float, float] | None,
) -> list[SpeedProfile]:
    """Keep the requested vehicles (raw id or full ``vehicle_id``) that pass the criteria."""
    wanted = None if vehicle_ids is None else {_raw_id(v) for v in vehicle_ids}
    if speed_range_mps is not None:
        lo, hi = speed_range_mps
        if not 0.0 <= lo <= hi:
            raise ValueError(f"speed_range_mps={speed_range_mps} must satisfy 0 <= low <= high")
    if min_duration_s < 0:
        raise ValueError(f"min_duration_s={min_duration_s} must be >= 0")
    kept = []
    for raw, p in profiles:
        if wanted is not None and raw not in wanted and p.vehicle_id not in wanted:
            continue
        if p.duration_s < min_duration_s:
            continue
        if speed_range_mps is not None and not lo <= float(np.mean(p.speed_mps)) <= hi:
            continue
        kept.append(p)
    return kept


# --------------------------------------------------------------------------------------------
# formats


def load_ngsim(
    path: str | Path,
    *,
    vehicle_ids: Iterable[str | int] | None = None,
    min_duration_s: float = 0.0,
    speed_range_mps: tuple[float, float] | None = None,
    frame_period_s: float = NGSIM_FRAME_PERIOD_S,
    id_prefix: str | None = None,
) -> list[SpeedProfile]:
    """Read an NGSIM vehicle-trajectory CSV (US-101, I-80, Lankershim, Peachtree releases).

    Uses ``Vehicle_ID``, ``Frame_ID`` and ``v_Vel`` (ft/s, converted to m/s with 0.3048); an
    optional ``Location`` column (the combined release) becomes part of the id. Column names
    are matched without case. Rows are grouped per vehicle and ordered by ``Frame_ID`` (the
    releases are not always sorted); time is ``(Frame_ID - first Frame_ID) · frame_period_s``.
    Duplicate frames are kept for :func:`~vdtn_marl.data.preprocess.preprocess` to drop, and
    named in a warning; a vehicle's frame repeated with a speed more than
    :data:`DUPLICATE_SPEED_TOL_MPS` apart is refused (:class:`TraceFormatError`).

    Args:
        vehicle_ids: keep only these vehicles (raw ``Vehicle_ID`` values or full ids).
        min_duration_s: keep vehicles observed for at least this long, in s.
        speed_range_mps: keep vehicles whose *mean* speed (m/s) lies in ``[low, high]``.
        frame_period_s: time between frames in s (0.1 s in every NGSIM release).
        id_prefix: prefix of ``vehicle_id`` (default: the file name without extensions, since
            vehicle numbers repeat across NGSIM files); ids are ``prefix/[location/]Vehicle_ID``.
    """
    if not frame_period_s > 0:
        raise ValueError(f"frame_period_s={frame_period_s} must be > 0")
    path = Path(path)
    cols, _ = _read_columns(
        path,
        {"vehicle": ["Vehicle_ID"], "frame": ["Frame_ID"], "vel": ["v_Vel"]},
        {"location": ["Location"]},
    )
    frame = _numeric(path, "Frame_ID", cols["frame"])
    vel_fps = _numeric(path, "v_Vel", cols["vel"], " (ft/s)")
    speed = vel_fps * FT_TO_M
    rows = np.arange(len(speed))
    _check_speeds(path, speed, rows, "NGSIM v_Vel must be in ft/s")
    prefix = file_stem(path) if id_prefix is None else id_prefix
    raw_ids = np.array([_raw_id(v) for v in cols["vehicle"]], dtype=object)
    if "location" in cols:
        locations = np.array([str(v).strip() for v in cols["location"]], dtype=object)
        pairs = zip(locations, raw_ids, strict=True)
        keys = np.array([f"{loc}/{v}" for loc, v in pairs], dtype=object)
    else:
        keys = raw_ids
    out, rows_of, vehicle_of = [], {}, {}
    for key, idx in _group_by_vehicle(keys, frame):
        t = (frame[idx] - frame[idx[0]]) * frame_period_s
        vid = f"{prefix}/{key}" if prefix else str(key)
        source = f"NGSIM trajectories ({path.name})"
        out.append((raw_ids[idx[0]], SpeedProfile(t, speed[idx], vid, source)))
        rows_of[vid], vehicle_of[vid] = idx, str(key)
    kept = _select(out, vehicle_ids, min_duration_s, speed_range_mps)
    _check_repeated_times(path, kept, rows_of, "ft/s", FT_TO_M, vehicle_of)
    return kept


def load_highd(
    path: str | Path,
    *,
    vehicle_ids: Iterable[str | int] | None = None,
    min_duration_s: float = 0.0,
    speed_range_mps: tuple[float, float] | None = None,
    frame_rate_hz: float = HIGHD_FRAME_RATE_HZ,
    id_prefix: str | None = None,
) -> list[SpeedProfile]:
    """Read a highD-style ``NN_tracks.csv`` (columns ``frame``, ``id``, ``xVelocity`` in m/s).

    Speed is ``|xVelocity|`` (vehicles on the upper carriageway drive towards −x). Time is
    ``(frame - first frame) / frame_rate_hz``; rows are grouped per ``id`` and ordered by
    ``frame``. The same datasets family (inD, exiD, rounD) uses these columns too. Selection
    arguments are as in :func:`load_ngsim`; ids are ``prefix/id`` with the file name
    (``01_tracks``) as default prefix, since ids restart in every recording.
    """
    if not frame_rate_hz > 0:
        raise ValueError(f"frame_rate_hz={frame_rate_hz} must be > 0")
    path = Path(path)
    cols, _ = _read_columns(
        path, {"frame": ["frame"], "id": ["id", "trackId"], "vx": ["xVelocity"]}
    )
    frame = _numeric(path, "frame", cols["frame"])
    speed = np.abs(_numeric(path, "xVelocity", cols["vx"], " (m/s)"))
    _check_speeds(path, speed, np.arange(len(speed)), "highD xVelocity must be in m/s")
    prefix = file_stem(path) if id_prefix is None else id_prefix
    raw_ids = np.array([_raw_id(v) for v in cols["id"]], dtype=object)
    out, rows_of, vehicle_of = [], {}, {}
    for key, idx in _group_by_vehicle(raw_ids, frame):
        t = (frame[idx] - frame[idx[0]]) / frame_rate_hz
        vid = f"{prefix}/{key}" if prefix else str(key)
        out.append((key, SpeedProfile(t, speed[idx], vid, f"highD-style tracks ({path.name})")))
        rows_of[vid], vehicle_of[vid] = idx, str(key)
    kept = _select(out, vehicle_ids, min_duration_s, speed_range_mps)
    _check_repeated_times(path, kept, rows_of, "m/s", 1.0, vehicle_of)
    return kept


def load_time_speed_csv(
    path: str | Path,
    *,
    vehicle_id: str | None = None,
    min_duration_s: float = 0.0,
    speed_range_mps: tuple[float, float] | None = None,
) -> list[SpeedProfile]:
    """Read a ``time,speed`` CSV (header required) as one profile, speeds converted to m/s.

    Headers: ``time``/``time_s`` (s), and exactly one speed column whose header gives its
    unit: ``speed``/``speed_mps`` (m/s), ``speed_kmh``/``speed_kph`` (km/h) or ``speed_mph``
    (mph; the bundled EPA cycles are stored so). Other columns are ignored. Time must be
    non-decreasing (a repeated time is allowed when its speed is within
    :data:`DUPLICATE_SPEED_TOL_MPS` of the row before: a warning names the rows, which
    :func:`~vdtn_marl.data.preprocess.preprocess` drops; further apart it is refused); a speed
    above 70 m/s or below 0 is rejected as a likely unit mix-up, and an m/s column whose
    maximum exceeds :data:`PLAUSIBLE_MAX_SPEED_MPS` or whose median exceeds
    :data:`PLAUSIBLE_MEDIAN_SPEED_MPS` draws a warning that it may hold km/h. ``vehicle_id``
    defaults to the file name without extensions.
    ``min_duration_s`` and ``speed_range_mps`` select as in :func:`load_ngsim` (the list is
    empty when the drive does not pass them).
    """
    path = Path(path)
    optional = {c.unit: c.headers for c in SPEED_COLUMNS}
    cols, _ = _read_columns(path, {"time": ["time", "time_s"]}, optional)
    found = [c for c in SPEED_COLUMNS if c.unit in cols]
    allowed = ", ".join(h for c in SPEED_COLUMNS for h in c.headers)
    if len(found) != 1:
        problem = "missing column 'speed'" if not found else "more than one speed column"
        have = ", ".join(str(c).strip() for c in _header(path)) or "none"
        raise TraceFormatError(
            path, None, f"{problem}; allowed: exactly one of {allowed} (columns found: {have})"
        )
    (column,) = found
    t = _numeric(path, "time", cols["time"], " (s)")
    v = _numeric(path, "speed", cols[column.unit], f" ({column.unit})") * column.to_mps
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise TraceFormatError(
            path,
            i + 1,
            f"time {t[i]:g} s is earlier than the previous row's {t[i - 1]:g} s "
            "(time must not decrease)",
        )
    hint = (
        "name the speed column by its unit: speed_mps (m/s), speed_kmh (km/h) or speed_mph"
        if column.to_mps == 1.0
        else f"check that column {column.headers[0]!r} really holds {column.unit}"
    )
    _check_speeds(path, v, np.arange(len(v)), hint)
    if column.to_mps == 1.0:
        header = [str(c).strip() for c in _header(path)]
        named = next((h for h in header if h.lower() in column.headers), column.headers[0])
        _check_plausible_mps(path, v, named)
    vid = file_stem(path) if vehicle_id is None else vehicle_id
    profile = SpeedProfile(t, v, vid, f"time,speed CSV ({path.name}, {column.unit})")
    kept = _select([(vid, profile)], None, min_duration_s, speed_range_mps)
    _check_repeated_times(path, kept, {vid: np.arange(len(t))}, column.unit, column.to_mps)
    return kept


LOADERS = {"ngsim": load_ngsim, "highd": load_highd, "csv": load_time_speed_csv}
"""Reader by format name, as used by :func:`vdtn_marl.data.profiles.load_trace_source`."""
