"""Standard driving cycles (US EPA UDDS and HWFET) as leader traces, bundled with the package.

``vdtn_marl/data/cycles/<name>.csv`` holds the US EPA's dynamometer driving schedule as the
EPA publishes it: one row per second, ``time_s,speed_mph`` with speeds to 0.1 mph (read with
:func:`~vdtn_marl.data.loaders.load_time_speed_csv`, which converts to m/s at exactly
0.44704 m/s per mph):

- ``"udds"``: EPA Urban Dynamometer Driving Schedule (UDDS, FTP-72; 40 CFR 86 Appendix I),
  1369 s, 7.45 mi (11.99 km), average 19.59 mph, stop-and-go city driving up to 56.7 mph
  (25.35 m/s), accelerations within ±1.5 m/s².
- ``"hwfet"``: EPA Highway Fuel Economy Test (HWFET; 40 CFR 600 Appendix I), 765 s, 10.26 mi
  (16.51 km), average 48.3 mph, free-flowing highway driving up to 59.9 mph (26.78 m/s).

Both start and end at rest. The schedules are US government works in the public domain
(https://www.epa.gov/vehicle-and-fuel-emissions-testing/dynamometer-drive-schedules). The
figures above are the EPA's and ``tests/data/test_data_cycles.py`` checks the files against
them. Before vdtn-marl bundled them, the cycles came from the optional package ``fastsim``,
whose copies convert mph at 1/2.2369 m/s (at most 0.0005 m/s, 0.0016 %, faster than these);
the recorded-cycle results in ``benchmarks/results/`` written before then used those copies.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from importlib import resources

from vdtn_marl.data.loaders import SpeedProfile, load_time_speed_csv
from vdtn_marl.data.profiles import ProfileTraceSource
from vdtn_marl.data.traces import TraceInfo


@dataclass(frozen=True)
class DrivingCycle:
    """A bundled driving cycle: its description and the EPA's published figures."""

    description: str
    regulation: str
    duration_s: float
    distance_mi: float
    average_speed_mph: float
    max_speed_mph: float


CYCLES = {
    "udds": DrivingCycle(
        "EPA Urban Dynamometer Driving Schedule (UDDS / FTP-72), urban",
        "40 CFR 86 Appendix I",
        duration_s=1369.0,
        distance_mi=7.45,
        average_speed_mph=19.59,
        max_speed_mph=56.7,
    ),
    "hwfet": DrivingCycle(
        "EPA Highway Fuel Economy Test cycle (HWFET), highway",
        "40 CFR 600 Appendix I",
        duration_s=765.0,
        distance_mi=10.26,
        average_speed_mph=48.3,
        max_speed_mph=59.9,
    ),
}
"""Cycle name -> :class:`DrivingCycle` (file ``cycles/<name>.csv`` of this package)."""

SOURCE_URL = "https://www.epa.gov/vehicle-and-fuel-emissions-testing/dynamometer-drive-schedules"
LICENSE = "US EPA dynamometer driving schedule, US government work in the public domain"


def _check_name(name: str) -> DrivingCycle:
    if name not in CYCLES:
        raise ValueError(f"driving cycle {name!r} is not known; known: {', '.join(CYCLES)}")
    return CYCLES[name]


@cache
def _load(name: str) -> SpeedProfile:
    resource = resources.files("vdtn_marl.data") / "cycles" / f"{name}.csv"
    with resources.as_file(resource) as path:
        (profile,) = load_time_speed_csv(path, vehicle_id=name)
    return profile


def load_driving_cycle(name: str) -> SpeedProfile:
    """The cycle ``name`` (``"udds"`` or ``"hwfet"``) as a profile: time in s, speed in m/s."""
    cycle = _check_name(name)
    profile = _load(name)
    source = f"{cycle.description.split(',')[0]} ({cycle.regulation}), bundled {name}.csv"
    return SpeedProfile(profile.time_s.copy(), profile.speed_mps.copy(), name, source)


def driving_cycle_info(name: str) -> TraceInfo:
    """Provenance of the cycle ``name``."""
    cycle = _check_name(name)
    return TraceInfo(
        name=name,
        description=f"{cycle.description} driving cycle, random windows",
        synthetic=False,
        source=f"{cycle.description.split(',')[0]} ({cycle.regulation}); {SOURCE_URL}",
        license=LICENSE,
    )


def driving_cycle_source(name: str) -> ProfileTraceSource:
    """A trace source cutting random windows out of one standard driving cycle."""
    return ProfileTraceSource([load_driving_cycle(name)], driving_cycle_info(name))
