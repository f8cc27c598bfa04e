"""Recorded drives of 22 private vehicles around Chicago (2007) as the trace set ``"cmap"``.

``vdtn_marl/data/drives/cmap_<sampno>_<vehno>.csv`` holds one vehicle's driving segments,
``time_s,speed_mps`` at 1 Hz, read with :func:`~vdtn_marl.data.loaders.load_time_speed_csv`
(a jump of more than 1 s in ``time_s`` separates two segments) and cleaned with
:func:`~vdtn_marl.data.preprocess.preprocess` (:data:`PREPROCESS`: split at those jumps,
acceleration clipped to ±2.6 m/s², the followers' actuator bounds, segments shorter than
:data:`MIN_SEGMENT_S` dropped; not smoothed, since the default 2 s Savitzky–Golay window spans
three 1 Hz samples, which an order-2 fit passes through unchanged). Segment ids are
``cmap_<sampno>_<vehno>#k``.

Source: the GPS speed recordings that NREL's FASTSim ships in
``fastsim/resources/cycles/cmap_subset/``, which FASTSim describes as a subset of the Chicago
Regional Household Travel Inventory (run for the Chicago Metropolitan Agency for Planning,
CMAP; recorded March to August 2007) housed in NREL's Transportation Secure Data Center.
They ship with FASTSim under the Apache License 2.0 (Copyright 2020 Alliance for Sustainable
Energy, LLC); ``drives/LICENSE`` and ``drives/NOTICE`` are the wheel's, ``drives/README.md``
says how ``scripts/extract_recorded_drives.py`` made the files from FASTSim 2.1.5 (trips of
``trips.csv``, unrecorded stops of up to 60 s filled with standstill, gaps longer than 3 s
split, segments shorter than 25 s dropped).

Runs split the set **by household**, hence by vehicle (:data:`EVAL_HOUSEHOLDS`): a household's
vehicles may drive the same roads, so no household has a vehicle in both parts.
"""

from __future__ import annotations

import re
from functools import cache
from importlib import resources

from vdtn_marl.data.loaders import SpeedProfile, load_time_speed_csv
from vdtn_marl.data.preprocess import preprocess_all
from vdtn_marl.data.profiles import ProfileTraceSource, split_key
from vdtn_marl.data.traces import TraceInfo

NAME = "cmap"
MIN_SEGMENT_S = 25.0
"""Shortest segment kept, s: a 10 s episode plus the twin's 10 s look-ahead, with margin."""
PREPROCESS = {"smoothing": "none", "min_segment_s": MIN_SEGMENT_S, "clip_accel_mps2": (-2.6, 2.6)}
"""Keywords of :func:`~vdtn_marl.data.preprocess.preprocess` for the set (its other defaults)."""
EVAL_HOUSEHOLDS = ("4105836", "4107032", "4109114", "4115985", "4116728")
"""Households (CMAP ``sampno``) whose vehicles evaluate; the other 13 train.

Fixed when the set was bundled, by this rule: the 18 households ranked by their total kept
duration, longest first, and every fourth taken from the second on (ranks 2, 6, 10, 14, 18),
so that evaluation spans long and short records alike (15.7 h of the 65.1 h) and the longest
record (one household, 23.9 h) trains. Changing the list changes every result on ``cmap``.
"""
SOURCE = (
    "GPS speed recordings (1 Hz) of 22 private vehicles, a subset of the Chicago Regional "
    "Household Travel Inventory (Chicago Metropolitan Agency for Planning, 2007) housed in "
    "NREL's Transportation Secure Data Center "
    "(https://www.nrel.gov/transportation/secure-transportation-data/tsdc-cleansed-data.html), "
    "as shipped in NREL FASTSim 2.1.5 (fastsim/resources/cycles/cmap_subset); bundled as "
    "vdtn_marl/data/drives/ by scripts/extract_recorded_drives.py"
)
LICENSE = (
    "Apache License 2.0, redistributed from NREL FASTSim (Copyright 2020 Alliance for "
    "Sustainable Energy, LLC; its LICENSE and NOTICE are in vdtn_marl/data/drives/, with the "
    "changes made in README.md there); credit FASTSim and NREL's Transportation Secure Data "
    "Center (www.nrel.gov/tsdc)"
)


def household(vehicle_id: str) -> str:
    """The CMAP household (``sampno``) of a profile id ``cmap_<sampno>_<vehno>[#k]``."""
    match = re.fullmatch(r"cmap_(\d+)_\d+", split_key(vehicle_id))
    if match is None:
        raise ValueError(f"{vehicle_id!r} is not a cmap vehicle id (cmap_<sampno>_<vehno>)")
    return match.group(1)


@cache
def _load() -> tuple[SpeedProfile, ...]:
    folder = resources.files("vdtn_marl.data") / "drives"
    files = sorted(
        (f for f in folder.iterdir() if f.name.startswith("cmap_") and f.name.endswith(".csv")),
        key=lambda f: f.name,
    )
    if not files:
        raise FileNotFoundError("vdtn_marl/data/drives/ holds no cmap_*.csv: the package is broken")
    profiles = []
    for resource in files:
        with resources.as_file(resource) as path:
            profiles += load_time_speed_csv(path)
    segments, _ = preprocess_all(profiles, **PREPROCESS)
    source = "CMAP 2007 GPS drives via NREL FASTSim (bundled vdtn_marl/data/drives/)"
    return tuple(SpeedProfile(p.time_s, p.speed_mps, p.vehicle_id, source) for p in segments)


def load_cmap_profiles() -> list[SpeedProfile]:
    """Every cleaned segment of the set (fresh copies): time in s, speed in m/s."""
    return [
        SpeedProfile(p.time_s.copy(), p.speed_mps.copy(), p.vehicle_id, p.source) for p in _load()
    ]


def eval_vehicles() -> frozenset[str]:
    """The vehicles (split keys ``cmap_<sampno>_<vehno>``) of :data:`EVAL_HOUSEHOLDS`."""
    return frozenset(
        split_key(p.vehicle_id) for p in _load() if household(p.vehicle_id) in EVAL_HOUSEHOLDS
    )


def cmap_info() -> TraceInfo:
    """Provenance of the trace set ``cmap``."""
    return TraceInfo(
        name=NAME,
        description="recorded drives of 22 private vehicles around Chicago (CMAP 2007 GPS "
        "survey, 1 Hz), random windows",
        synthetic=False,
        source=SOURCE,
        license=LICENSE,
    )


def cmap_source() -> ProfileTraceSource:
    """A trace source cutting random windows out of every segment of the set; runs split it
    by vehicle (:func:`~vdtn_marl.data.profiles.vehicle_split_sources`)."""
    return ProfileTraceSource(list(_load()), cmap_info(), eval_vehicles=eval_vehicles())
