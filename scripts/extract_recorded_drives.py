"""Extract the recorded drives that NREL's FASTSim ships into ``vdtn_marl/data/drives/``.

A development-time tool: it is run once to (re)build the bundled trace set ``cmap``; the
package never imports it and does not depend on ``fastsim``.

    python scripts/extract_recorded_drives.py WHEEL_OR_DIR OUTPUT_DIR

``WHEEL_OR_DIR`` is the FASTSim 2.1.5 wheel (``pip download --no-deps fastsim==2.1.5``) or a
folder it was unpacked into. The wheel holds, under ``fastsim/resources/cycles/cmap_subset/``,
1 Hz GPS speed recordings of 22 vehicles (one folder ``<sampno>_<vehno>`` each: one CSV per day,
``timestamp,cycle_sec,timestep,speed_mph,accel_meters_ps``, and ``trips.csv``, the trip table
with ``start_ts``/``end_ts``), a subset of the Chicago Regional Household Travel Inventory
(CMAP, 2007) housed in NREL's Transportation Secure Data Center. FASTSim is Apache-2.0
(Copyright 2020 Alliance for Sustainable Energy, LLC); the script copies the wheel's LICENSE
and NOTICE next to the extracted files and writes a README.md saying what was changed.

Rule (constants below), per vehicle:

1. **Trips.** A trip is the samples from ``start_ts`` to ``end_ts`` of one row of
   ``trips.csv``; samples outside every trip are dropped. Speeds are converted from mph at
   exactly 0.44704 m/s per mph.
2. **Stops.** The recordings hold few samples at rest (2.6 % of them) and their time gaps lie
   almost all between two samples at rest, so the recorder did not log stops: a gap of at
   most ``MAX_STOP_S`` (60 s) between two samples at rest (below ``STILL_MPS``, 0.5 m/s) is
   taken as a stop, e.g. at a traffic light, and filled with 0 m/s, one sample a second.
3. **Gaps.** Any other gap up to ``MAX_BRIDGE_S`` (3 s) is bridged by linear interpolation;
   a longer one (lost GPS while moving, a stop longer than 60 s) splits the trip into segments.
4. **Short segments.** Segments shorter than ``MIN_SEGMENT_S`` (25 s: a 10 s episode and the
   digital twin's 10 s look-ahead, with margin) are dropped.

Steps 3 and 4 are :func:`vdtn_marl.data.preprocess.preprocess` (no smoothing, no clipping, 1 s
grid). Nothing is smoothed or clipped here: the files hold the recorded speeds (rounded to
0.01 m/s); the package pre-processes them when it loads them (:mod:`vdtn_marl.data.cmap`).

Output: ``cmap_<sampno>_<vehno>.csv`` per vehicle, ``time_s,speed_mps`` (the format
:func:`vdtn_marl.data.loaders.load_time_speed_csv` reads), ``time_s`` in whole seconds since
the vehicle's first kept sample, so consecutive rows of a segment are 1 s apart and segments
are separated by the recorded time between them (always more than 1 s).
"""

from __future__ import annotations

import argparse
import hashlib
import io
import re
import sys
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from vdtn_marl.data.loaders import MPH_TO_MPS, SpeedProfile, load_time_speed_csv
from vdtn_marl.data.preprocess import preprocess

CMAP_DIR = "fastsim/resources/cycles/cmap_subset/"
STILL_MPS = 0.5
"""Speed below which a sample is at rest, m/s."""
MAX_STOP_S = 60.0
"""Longest unrecorded stop filled with standstill, s."""
MAX_BRIDGE_S = 3.0
"""Longest other gap bridged by linear interpolation, s."""
MIN_SEGMENT_S = 25.0
"""Shortest segment kept, s."""
SPEED_DECIMALS = 2


@dataclass
class VehicleDrive:
    """One vehicle's kept segments (times in s since its first kept sample) and counts."""

    name: str
    segments: list[SpeedProfile]
    first_timestamp: str
    days: int
    trips: int
    samples_in: int
    samples_outside_trips: int
    stops_filled: int
    stop_seconds_filled: int
    gaps_bridged: int
    gaps_split: int
    segments_dropped: int

    @property
    def duration_s(self) -> float:
        return sum(s.duration_s for s in self.segments)


class WheelFiles:
    """The files of a wheel or of a folder it was unpacked into, by path inside the wheel."""

    def __init__(self, path: Path) -> None:
        self.path = path
        if path.is_file():
            self._zip: zipfile.ZipFile | None = zipfile.ZipFile(path)
            self.names = [n for n in self._zip.namelist() if not n.endswith("/")]
            self.sha256 = hashlib.sha256(path.read_bytes()).hexdigest()
        elif path.is_dir():
            self._zip = None
            self.names = [p.relative_to(path).as_posix() for p in path.rglob("*") if p.is_file()]
            self.sha256 = None
        else:
            raise SystemExit(f"{path}: no such wheel file or folder")
        if not any(n.startswith(CMAP_DIR) for n in self.names):
            raise SystemExit(f"{path}: holds no {CMAP_DIR} (is it the FASTSim 2.x wheel?)")

    def read(self, name: str) -> bytes:
        if self._zip is not None:
            return self._zip.read(name)
        return (self.path / name).read_bytes()

    def find(self, pattern: str) -> str:
        """The one file whose path matches the regular expression ``pattern``."""
        hits = [n for n in self.names if re.fullmatch(pattern, n)]
        if len(hits) != 1:
            raise SystemExit(f"{self.path}: expected one file matching {pattern!r}, got {hits}")
        return hits[0]

    def vehicles(self) -> dict[str, list[str]]:
        """Vehicle folder name -> its files (paths inside the wheel), sorted."""
        out: dict[str, list[str]] = {}
        for n in sorted(self.names):
            if n.startswith(CMAP_DIR):
                parts = n[len(CMAP_DIR) :].split("/")
                if len(parts) == 2 and n.endswith(".csv"):
                    out.setdefault(parts[0], []).append(n)
        return out


def _seconds(timestamps: pd.Series) -> np.ndarray:
    """Local timestamps (``YYYY-MM-DD hh:mm:ss``) as whole seconds since 1970 (naive)."""
    parsed = pd.to_datetime(timestamps, format="%Y-%m-%d %H:%M:%S")
    return parsed.to_numpy().astype("datetime64[s]").astype(np.int64)


def _fill_stops(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Rule 2: fill each gap of at most MAX_STOP_S between two samples at rest with 0 m/s."""
    dt = np.diff(t)
    still = v < STILL_MPS
    stops = np.flatnonzero((dt > 1) & (dt <= MAX_STOP_S) & still[:-1] & still[1:])
    if stops.size == 0:
        return t, v, 0, 0
    fill_t = np.concatenate([np.arange(t[i] + 1, t[i + 1]) for i in stops])
    t_all = np.concatenate([t, fill_t])
    v_all = np.concatenate([v, np.zeros(len(fill_t))])
    order = np.argsort(t_all, kind="stable")
    return t_all[order], v_all[order], int(stops.size), int(len(fill_t))


def extract_vehicle(files: WheelFiles, name: str, paths: list[str]) -> VehicleDrive:
    """Rules 1-4 for one vehicle folder."""
    trips_path = next(p for p in paths if p.endswith("/trips.csv"))
    day_paths = [p for p in paths if p != trips_path]
    days = [
        pd.read_csv(io.BytesIO(files.read(p)), usecols=["timestamp", "speed_mph"])
        for p in day_paths
    ]
    points = pd.concat(days, ignore_index=True)
    t = _seconds(points["timestamp"])
    v = points["speed_mph"].to_numpy(dtype=np.float64) * MPH_TO_MPS
    if not (np.all(np.isfinite(v)) and np.all(v >= 0)):
        raise SystemExit(f"{name}: non-finite or negative speeds")
    order = np.argsort(t, kind="stable")
    t, v = t[order], v[order]
    trips = pd.read_csv(
        io.BytesIO(files.read(trips_path)), usecols=["trip_id", "start_ts", "end_ts"]
    )
    starts, ends = _seconds(trips["start_ts"]), _seconds(trips["end_ts"])
    inside = np.zeros(len(t), dtype=bool)
    raw_segments: list[tuple[np.ndarray, np.ndarray]] = []
    filled = seconds = bridged = split = dropped = 0
    for trip_id, start, end in sorted(
        zip(trips["trip_id"], starts, ends, strict=True), key=lambda r: r[1]
    ):
        rows = (t >= start) & (t <= end)
        inside |= rows
        if np.count_nonzero(rows) < 2:
            continue
        tt, vv, n_stops, n_seconds = _fill_stops(t[rows], v[rows])
        filled, seconds = filled + n_stops, seconds + n_seconds
        segs, report = preprocess(
            SpeedProfile(tt.astype(np.float64), vv, f"{name}/trip{trip_id}", "cmap_subset"),
            smoothing="none",
            dt_s=1.0,
            max_gap_s=MAX_BRIDGE_S,
            min_segment_s=MIN_SEGMENT_S,
            clip_accel_mps2=(-1e6, 1e6),
        )
        if report.speed_points_clipped or report.accel_points_clipped:
            raise SystemExit(f"{name} trip {trip_id}: unexpected clipping")
        bridged += report.gaps_interpolated
        split += report.gaps_split
        dropped += report.segments_dropped
        raw_segments += [(s.time_s, s.speed_mps) for s in segs]
    raw_segments.sort(key=lambda s: s[0][0])
    for (a, _), (b, _) in zip(raw_segments, raw_segments[1:], strict=False):
        if b[0] <= a[-1]:
            raise SystemExit(f"{name}: trips overlap in time")
    t0 = raw_segments[0][0][0] if raw_segments else 0.0
    segments = [
        SpeedProfile(st - t0, np.round(sv, SPEED_DECIMALS), f"cmap_{name}#{k}", "cmap_subset")
        for k, (st, sv) in enumerate(raw_segments)
    ]
    first = pd.Timestamp(int(t0), unit="s").strftime("%Y-%m-%d %H:%M:%S") if segments else ""
    return VehicleDrive(
        name=name,
        segments=segments,
        first_timestamp=first,
        days=len(day_paths),
        trips=len(trips),
        samples_in=len(t),
        samples_outside_trips=int(np.count_nonzero(~inside)),
        stops_filled=filled,
        stop_seconds_filled=seconds,
        gaps_bridged=bridged,
        gaps_split=split,
        segments_dropped=dropped,
    )


def write_vehicle(drive: VehicleDrive, out_dir: Path) -> Path:
    """``cmap_<name>.csv``; read back with the package's reader to check it."""
    path = out_dir / f"cmap_{drive.name}.csv"
    t = np.concatenate([s.time_s for s in drive.segments])
    v = np.concatenate([s.speed_mps for s in drive.segments])
    lines = ["time_s,speed_mps"]
    lines += [f"{int(round(a))},{b:.{SPEED_DECIMALS}f}" for a, b in zip(t, v, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    (back,) = load_time_speed_csv(path)
    if len(back) != len(t) or np.abs(back.speed_mps - v).max() > 0.5 * 10**-SPEED_DECIMALS:
        raise SystemExit(f"{path}: does not read back")
    return path


COLUMNS = (
    "vehicle", "first sample", "days", "trips", "segments", "duration (s)", "samples in",
    "outside trips", "stops filled (s)", "gaps bridged", "gaps split", "segments dropped",
)  # fmt: skip
README = """\
# Recorded drives: trace set `cmap`

One file per vehicle, `cmap_<sampno>_<vehno>.csv`: `time_s,speed_mps`, 1 Hz, `time_s` in whole
seconds since the vehicle's first kept sample (`first sample` below, local time); a jump of more
than 1 s separates two segments. Read by `vdtn_marl.data.cmap`.

## Provenance and licence

Extracted from the Python wheel of NREL's FASTSim {version} (`{wheel}`{sha}), folder
`fastsim/resources/cycles/cmap_subset/`: 1 Hz GPS speed recordings of 22 private vehicles
(recorded {first_day} to {last_day}), which FASTSim describes as "a subset of [the] Chicago
Regional Household Travel Inventory housed in the Transportation Secure Data Center" (TSDC) of
the National Renewable Energy Laboratory (NREL),
https://www.nrel.gov/transportation/secure-transportation-data/tsdc-cleansed-data.html ; the
survey was run for the Chicago Metropolitan Agency for Planning (CMAP), hence the folder name.
FASTSim, these files included, is distributed under the Apache License 2.0, Copyright 2020
Alliance for Sustainable Energy, LLC (the operator of NREL): see `LICENSE` and `NOTICE` in
this folder, copied unchanged from the wheel. That is the licence this package redistributes
them under; the wheel states no other terms for them. When you use them, credit FASTSim and,
as the origin of the data, NREL's TSDC (www.nrel.gov/tsdc).

## Changes made to the FASTSim files

Written by `scripts/extract_recorded_drives.py` (its docstring states the rule): samples
outside the trips of each vehicle's `trips.csv` dropped; mph converted to m/s (0.44704) and
rounded to 0.01 m/s; days of one vehicle joined into one file; unrecorded stops of at most
{max_stop:g} s between two samples at rest (< {still:g} m/s) filled with 0 m/s; other gaps of
at most {bridge:g} s linearly interpolated; longer gaps split a trip; segments shorter than
{min_seg:g} s dropped; other columns (`cycle_sec`, `timestep`, `accel_meters_ps`, the trip
statistics) not kept.

## Vehicles

{rows}
"""


def write_readme(files: WheelFiles, drives: list[VehicleDrive], out_dir: Path) -> None:
    meta = files.read(files.find(r"fastsim-[^/]+\.dist-info/METADATA")).decode()
    version = re.search(r"^Version: (.+)$", meta, re.M)
    rows = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    rows += [
        f"| {d.name} | {d.first_timestamp} | {d.days} | {d.trips} | {len(d.segments)} | "
        f"{d.duration_s:.0f} | {d.samples_in} | {d.samples_outside_trips} | "
        f"{d.stops_filled} ({d.stop_seconds_filled}) | {d.gaps_bridged} | {d.gaps_split} | "
        f"{d.segments_dropped} |"
        for d in drives
    ]
    total = sum(d.duration_s for d in drives)
    days = [
        Path(n).stem
        for n in files.names
        if n.startswith(CMAP_DIR) and re.search(r"/\d{4}-\d\d-\d\d\.csv$", n)
    ]
    rows.append(
        f"| all | | {sum(d.days for d in drives)} | {sum(d.trips for d in drives)} | "
        f"{sum(len(d.segments) for d in drives)} | {total:.0f} | "
        f"{sum(d.samples_in for d in drives)} | "
        f"{sum(d.samples_outside_trips for d in drives)} | "
        f"{sum(d.stops_filled for d in drives)} ({sum(d.stop_seconds_filled for d in drives)}) | "
        f"{sum(d.gaps_bridged for d in drives)} | {sum(d.gaps_split for d in drives)} | "
        f"{sum(d.segments_dropped for d in drives)} |"
    )
    text = README.format(
        version=version.group(1).strip() if version else "(unknown version)",
        wheel=files.path.name,
        sha=f", sha256 `{files.sha256}`" if files.sha256 else "",
        max_stop=MAX_STOP_S,
        still=STILL_MPS,
        bridge=MAX_BRIDGE_S,
        min_seg=MIN_SEGMENT_S,
        first_day=min(days),
        last_day=max(days),
        rows="\n".join(rows),
    )
    (out_dir / "README.md").write_text(text)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "source", type=Path, help="the FASTSim 2.x wheel, or a folder it was unpacked into"
    )
    parser.add_argument(
        "out_dir", type=Path, help="where to write the files (vdtn_marl/data/drives)"
    )
    args = parser.parse_args(argv)
    files = WheelFiles(args.source)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    for old in args.out_dir.glob("cmap_*.csv"):
        old.unlink()
    drives = []
    for name, paths in files.vehicles().items():
        drive = extract_vehicle(files, name, paths)
        if not drive.segments:
            print(f"{name}: no segment of {MIN_SEGMENT_S:g} s or more, skipped")
            continue
        path = write_vehicle(drive, args.out_dir)
        drives.append(drive)
        print(
            f"{path.name}: {len(drive.segments)} segments, {drive.duration_s:.0f} s, "
            f"{path.stat().st_size / 1e3:.0f} kB"
        )
    for license_file in ("LICENSE", "NOTICE"):
        name = files.find(rf"fastsim-[^/]+\.dist-info/(?:license_files/|licenses/)?{license_file}")
        (args.out_dir / license_file).write_bytes(files.read(name))
    write_readme(files, drives, args.out_dir)
    total = sum(p.stat().st_size for p in args.out_dir.iterdir())
    print(
        f"{len(drives)} vehicles, {sum(len(d.segments) for d in drives)} segments, "
        f"{sum(d.duration_s for d in drives) / 3600:.2f} h; {total / 1e6:.2f} MB in {args.out_dir}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
