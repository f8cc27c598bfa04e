"""Standard driving cycles (US EPA UDDS and HWFET) as leader traces, via the optional ``fastsim``.

NREL's FASTSim package (``pip install fastsim``, Apache-2.0) ships the cycles as built-in
resources at 1 s resolution, in m/s:

- ``"udds"``: EPA Urban Dynamometer Driving Schedule (FTP-72), 1369 s, stop-and-go city
  driving, up to 25.3 m/s (91.2 km/h), accelerations within ±1.5 m/s².
- ``"hwfet"``: EPA Highway Fuel Economy Test, 765 s, free-flowing highway driving, up to
  26.8 m/s (96.4 km/h), accelerations within ±1.5 m/s².

Both start and end at rest. ``fastsim`` is imported only when a cycle is first loaded, and the
trace names are registered (in :mod:`vdtn_marl.data`) only where it is installed.
"""

from __future__ import annotations

import importlib.util
from functools import cache

import numpy as np

from vdtn_marl.data.loaders import SpeedProfile
from vdtn_marl.data.profiles import ProfileTraceSource
from vdtn_marl.data.traces import TraceInfo

CYCLES = {
    "udds": ("udds.csv", "EPA Urban Dynamometer Driving Schedule (UDDS / FTP-72), urban"),
    "hwfet": ("hwfet.csv", "EPA Highway Fuel Economy Test cycle (HWFET), highway"),
}
"""Cycle name -> (FASTSim resource, description)."""
PACKAGE = "fastsim"


def cycles_available() -> bool:
    """Whether the optional package that ships the cycles is importable (without importing)."""
    return importlib.util.find_spec(PACKAGE) is not None


@cache
def _load_arrays(name: str) -> tuple[np.ndarray, np.ndarray, str]:
    try:
        import fastsim
    except ImportError as exc:
        raise ImportError(
            f"driving cycle {name!r} needs the optional package {PACKAGE!r}: "
            "pip install 'vdtn-marl[data]' (or pip install fastsim)"
        ) from exc
    resource, _ = CYCLES[name]
    cycle = fastsim.Cycle.from_resource(resource).to_dict()
    t = np.asarray(cycle["time_seconds"], dtype=np.float64)
    v = np.asarray(cycle["speed_meters_per_second"], dtype=np.float64)
    version = getattr(fastsim, "__version__", "unknown version")
    return t, v, f"fastsim {version} resource {resource}"


def load_driving_cycle(name: str) -> SpeedProfile:
    """The cycle ``name`` (``"udds"`` or ``"hwfet"``) as a profile: time in s, speed in m/s."""
    if name not in CYCLES:
        raise ValueError(f"driving cycle {name!r} is not known; known: {', '.join(CYCLES)}")
    t, v, source = _load_arrays(name)
    return SpeedProfile(t.copy(), v.copy(), vehicle_id=name, source=source)


LICENSE = (
    "US EPA dynamometer driving schedules (UDDS: 40 CFR 86 App. I; HWFET: 40 CFR 600 App. I), "
    "US government work in the public domain; shipped by NREL's fastsim (Apache-2.0)"
)


def driving_cycle_info(name: str, data_source: str | None = None) -> TraceInfo:
    """Provenance of the cycle ``name`` (no import of the optional package)."""
    resource, description = CYCLES[name]
    return TraceInfo(
        name=name,
        description=f"{description} driving cycle, random windows",
        synthetic=False,
        source=f"{description.split(',')[0]}; data from "
        f"{data_source or f'{PACKAGE} resource {resource}'}",
        license=LICENSE,
    )


def driving_cycle_source(name: str) -> ProfileTraceSource:
    """A trace source cutting random windows out of one standard driving cycle."""
    profile = load_driving_cycle(name)
    return ProfileTraceSource([profile], driving_cycle_info(name, profile.source))
