"""Model parameters of the digital twin (see docs/model.md for every equation and source).

Every default below is a spec value; nothing in the core hard-codes a number that a user may want
to change. Units are in the field names (``_m``, ``_s``, ``_mps``, ``_mps2``, ``_dbm``, ``_db``,
``_hz``, ``_bits``).
"""

from __future__ import annotations

import difflib
import math
import numbers
from dataclasses import asdict, dataclass, field, fields
from functools import cached_property
from types import SimpleNamespace
from typing import Any

from vdtn_marl.errors import ConfigError
from vdtn_marl.sim.topology import Topology, platoon_topology


def _check_types(params: Any) -> None:
    """Every ``int`` field holds an integer and every ``float`` field a real number (bools,
    strings and None are refused, naming the key)."""
    for f in fields(params):
        value = getattr(params, f.name)
        if f.type == "int":
            ok, kind = isinstance(value, numbers.Integral), "an integer"
        elif f.type == "float":
            ok, kind = isinstance(value, numbers.Real), "a number"
        elif f.type.startswith("tuple[float"):
            ok = isinstance(value, tuple) and all(
                isinstance(v, numbers.Real) and not isinstance(v, bool) for v in value
            )
            kind = "a list of numbers"
        else:
            continue
        if not ok or isinstance(value, bool):
            raise ConfigError(f"{f.name}={value!r} must be {kind}")


def _check_range(name: str, value: float, low: float, high: float, *, low_open=False) -> None:
    bad = value != value or value > high or (value <= low if low_open else value < low)
    if bad:
        bracket = "(" if low_open else "["
        raise ConfigError(f"{name}={value!r} is outside the allowed range {bracket}{low}, {high}]")


@dataclass(frozen=True)
class PlatoonParams:
    """Platoon dynamics, spacing policy and control reward (docs/model.md §2)."""

    num_vehicles: int = 4  # leader + followers
    control_interval_s: float = 0.05  # Δt
    subframes_per_interval: int = 50  # T
    driveline_lag_s: float = 0.1  # τ
    accel_min_mps2: float = -2.6
    accel_max_mps2: float = 2.6
    vehicle_length_m: float = 4.0  # L
    standstill_gap_m: float = 2.0  # r
    time_headway_s: float = 0.1  # h
    gap_error_scale_m: float = 15.0  # ê_p
    speed_error_scale_mps: float = 10.0  # ê_v
    weight_speed: float = 0.1  # α
    weight_accel: float = 0.2  # β
    weight_jerk: float = 0.5  # γ_j
    collision_penalty: float = -100.0
    initial_gap_noise_m: float = 0.0  # std of the initial gap perturbation
    initial_speed_noise_mps: float = 0.0  # std of the initial speed perturbation
    # who leads, who follows whom, lanes and V2I users, built by a scenario
    # (vdtn_marl.scenarios); None: one platoon with predecessor following (docs/model.md §6)
    scenario_topology: Topology | None = None

    @property
    def topology(self) -> Topology:
        """The scenario's topology, or one PF platoon of ``num_vehicles``."""
        if self.scenario_topology is None:
            return platoon_topology(self.num_vehicles)
        return self.scenario_topology

    @property
    def num_followers(self) -> int:
        return self.topology.num_followers

    @property
    def subframe_s(self) -> float:
        return self.control_interval_s / self.subframes_per_interval

    @property
    def jerk_max_mps3(self) -> float:
        """j_max = 2·u_max/Δt (docs/model.md §2)."""
        return 2.0 * self.accel_max_mps2 / self.control_interval_s

    @cached_property
    def numbers(self) -> SimpleNamespace:
        """The numbers of the platoon's equations (:mod:`vdtn_marl.sim.platoon`) by short
        name, as Python numbers."""
        return SimpleNamespace(
            accel_min=self.accel_min_mps2,
            accel_max=self.accel_max_mps2,
            length=self.vehicle_length_m,
            standstill=self.standstill_gap_m,
            headway=self.time_headway_s,
            interval_s=self.control_interval_s,
            gap_scale=self.gap_error_scale_m,
            weight_speed=self.weight_speed,
            speed_scale=self.speed_error_scale_mps,
            weight_accel=self.weight_accel,
            weight_jerk=self.weight_jerk,
            jerk_max=self.jerk_max_mps3,
            collision_penalty=self.collision_penalty,
            zero=0.0,
        )

    @cached_property
    def numbers_float32(self) -> SimpleNamespace | None:
        """:attr:`numbers` as read-only float32 0-d NumPy arrays, for float32 NumPy arrays:
        the same operations as with the Python numbers (NumPy casts a Python scalar to the
        array's dtype first) at about half the cost per call on arrays of a few entries. None
        unless every number is a Python ``int`` or ``float``."""
        from vdtn_marl.sim.backend import float32_scalars

        return float32_scalars(**vars(self.numbers))

    def validate(self) -> None:
        _check_types(self)
        if not 2 <= self.num_vehicles <= 64:
            raise ConfigError(f"num_vehicles={self.num_vehicles!r} is outside [2, 64]")
        topology = self.scenario_topology
        if topology is not None and topology.num_vehicles != self.num_vehicles:
            raise ConfigError(
                f"num_vehicles={self.num_vehicles!r} differs from the {topology.num_vehicles} "
                f"vehicles of the scenario topology {topology.name!r}; allowed: "
                f"{topology.num_vehicles}"
            )
        if not 1 <= self.subframes_per_interval <= 1000:
            raise ConfigError(
                f"subframes_per_interval={self.subframes_per_interval!r} is outside [1, 1000]"
            )
        _check_range("control_interval_s", self.control_interval_s, 0.0, 10.0, low_open=True)
        _check_range("driveline_lag_s", self.driveline_lag_s, 0.0, 10.0, low_open=True)
        _check_range("accel_min_mps2", self.accel_min_mps2, -20.0, 0.0)
        _check_range("accel_max_mps2", self.accel_max_mps2, 0.0, 20.0, low_open=True)
        _check_range("vehicle_length_m", self.vehicle_length_m, 0.0, 30.0)
        _check_range("standstill_gap_m", self.standstill_gap_m, 0.0, 100.0, low_open=True)
        _check_range("time_headway_s", self.time_headway_s, 0.0, 10.0)
        for name in ("gap_error_scale_m", "speed_error_scale_mps"):
            _check_range(name, getattr(self, name), 0.0, 1e6, low_open=True)
        for name in ("weight_speed", "weight_accel", "weight_jerk"):
            _check_range(name, getattr(self, name), 0.0, 1e6)
        _check_range("collision_penalty", self.collision_penalty, -1e9, 0.0)
        _check_range("initial_gap_noise_m", self.initial_gap_noise_m, 0.0, 10.0)
        _check_range("initial_speed_noise_mps", self.initial_speed_noise_mps, 0.0, 10.0)


V2V_PATHLOSS_FORMS = ("liang", "winner_b1")
"""Values of :attr:`RadioParams.v2v_pathloss_form`."""


@dataclass(frozen=True)
class RadioParams:
    """C-V2X sidelink / uplink radio model (docs/model.md §4)."""

    num_subchannels: int = 4  # M
    subchannel_bandwidth_hz: float = 180e3
    carrier_ghz: float = 2.0
    v2i_power_dbm: float = 23.0
    v2v_power_levels_dbm: tuple[float, ...] = (23.0, 15.0, 5.0)  # plus "off" as the last level
    cam_size_bits: int = 14_400  # 1800 bytes
    inter_site_distance_m: float = 1732.0
    bs_road_offset_m: float = 35.0
    bs_height_m: float = 25.0
    vehicle_height_m: float = 1.5
    vehicle_antenna_gain_db: float = 3.0
    bs_antenna_gain_db: float = 8.0
    vehicle_noise_figure_db: float = 9.0
    bs_noise_figure_db: float = 5.0
    noise_density_dbm_hz: float = -174.0
    v2i_shadow_std_db: float = 8.0
    v2i_decorrelation_m: float = 50.0
    v2v_shadow_std_db: float = 3.0
    v2v_decorrelation_m: float = 10.0
    # V2V path loss (docs/model.md §4.2): "winner_b1" (WINNER+ B1 LOS with the effective
    # antenna heights h − 1 and a free-space floor, as TR 36.885's highway V2V model;
    # continuous at the breakpoint) or "liang" (Liang et al.'s simulator, the v0 default: real
    # heights h beyond the breakpoint and no floor, 16.5 dB lower just beyond the breakpoint
    # than just below and 10–20 dB below free space at 7–20 m)
    v2v_pathloss_form: str = "winner_b1"
    # Sub-channel noise power in dBm that replaces −174 dBm/Hz + 10·log10(B) when set (a
    # sensitivity knob, e.g. the −90 dBm row of the Seed's source; docs/model.md §4.4)
    noise_power_override_dbm: float | None = None
    # The RRA observation also carries the CAM content's innovation (``cam_innovation`` of
    # vdtn_marl.sim.layout: the predecessor's acceleration and command now minus what the
    # recipient holds; docs/model.md §4.6)
    rra_cam_innovation: bool = False

    @property
    def num_power_levels(self) -> int:
        """Power levels including "off" (the last action of each sub-channel)."""
        return len(self.v2v_power_levels_dbm) + 1

    @property
    def num_actions(self) -> int:
        """Size of an RRA agent's Discrete action space: M·P (sub-channel × power level)."""
        return self.num_subchannels * self.num_power_levels

    @property
    def noise_power_dbm(self) -> float:
        """Noise power in one sub-channel: ``noise_power_override_dbm`` when set, else the
        thermal noise −174 dBm/Hz + 10·log10(B) (docs/model.md §4.4)."""
        if self.noise_power_override_dbm is not None:
            return float(self.noise_power_override_dbm)
        return self.noise_density_dbm_hz + 10.0 * math.log10(self.subchannel_bandwidth_hz)

    def validate(self) -> None:
        _check_types(self)
        if not isinstance(self.rra_cam_innovation, bool):
            raise ConfigError(
                f"rra_cam_innovation={self.rra_cam_innovation!r} must be true or false"
            )
        if not 1 <= self.num_subchannels <= 64:
            raise ConfigError(f"num_subchannels={self.num_subchannels!r} is outside [1, 64]")
        _check_range(
            "subchannel_bandwidth_hz", self.subchannel_bandwidth_hz, 0.0, 1e9, low_open=True
        )
        _check_range("carrier_ghz", self.carrier_ghz, 0.0, 100.0, low_open=True)
        _check_range("v2i_power_dbm", self.v2i_power_dbm, -50.0, 46.0)
        if len(self.v2v_power_levels_dbm) == 0:
            raise ConfigError("v2v_power_levels_dbm=() must hold at least one level in [-50, 46]")
        for level in self.v2v_power_levels_dbm:
            _check_range("v2v_power_levels_dbm", level, -50.0, 46.0)
        if not 1 <= self.cam_size_bits <= 10_000_000:
            raise ConfigError(f"cam_size_bits={self.cam_size_bits!r} is outside [1, 10000000]")
        _check_range("inter_site_distance_m", self.inter_site_distance_m, 1.0, 1e6)
        _check_range("bs_road_offset_m", self.bs_road_offset_m, 0.0, 1e4)
        _check_range("bs_height_m", self.bs_height_m, 1.0, 500.0)
        _check_range("vehicle_height_m", self.vehicle_height_m, 1.0, 10.0, low_open=True)
        for name in ("v2i_shadow_std_db", "v2v_shadow_std_db"):
            _check_range(name, getattr(self, name), 0.0, 30.0)
        for name in ("v2i_decorrelation_m", "v2v_decorrelation_m"):
            _check_range(name, getattr(self, name), 0.0, 1e5, low_open=True)
        override = self.noise_power_override_dbm
        if override is not None:
            if not isinstance(override, numbers.Real) or isinstance(override, bool):
                raise ConfigError(
                    f"noise_power_override_dbm={override!r} must be a number in [-200, 0] "
                    "(dBm per sub-channel) or null"
                )
            _check_range("noise_power_override_dbm", override, -200.0, 0.0)
        if self.v2v_pathloss_form not in V2V_PATHLOSS_FORMS:
            raise ConfigError(
                f"v2v_pathloss_form={self.v2v_pathloss_form!r} must be one of "
                f"{', '.join(repr(form) for form in V2V_PATHLOSS_FORMS)}"
            )


@dataclass(frozen=True)
class TwinParams:
    """Everything a digital twin needs: platoon, radio and episode settings."""

    platoon: PlatoonParams = field(default_factory=PlatoonParams)
    radio: RadioParams = field(default_factory=RadioParams)
    episode_intervals: int = 400  # 20 s at Δt = 50 ms
    traces: str = "udds"  # leader trace set by name (vdtn_marl.data): the EPA city cycle

    def validate(self) -> TwinParams:
        self.platoon.validate()
        self.radio.validate()
        _check_types(self)
        if not 1 <= self.episode_intervals <= 10_000_000:
            raise ConfigError(
                f"episode_intervals={self.episode_intervals!r} is outside [1, 10000000]"
            )
        return self

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_overrides(cls, **overrides) -> TwinParams:
        """Build params from flat keyword overrides, e.g. ``num_vehicles=6, cam_size_bits=8000``.

        Unknown keys raise a :class:`ConfigError` listing the known ones.
        """
        platoon_keys = {f.name for f in fields(PlatoonParams)} - {"scenario_topology"}
        radio_keys = {f.name for f in fields(RadioParams)}
        top_keys = {"episode_intervals", "traces"}
        platoon_kw, radio_kw, top_kw = {}, {}, {}
        for key, value in overrides.items():
            if key in platoon_keys:
                platoon_kw[key] = value
            elif key in radio_keys:
                radio_kw[key] = tuple(value) if key == "v2v_power_levels_dbm" else value
            elif key in top_keys:
                top_kw[key] = value
            else:
                known = sorted(platoon_keys | radio_keys | top_keys)
                close = difflib.get_close_matches(str(key), known, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise ConfigError(
                    f"unknown model parameter {key!r}{hint}; known: {', '.join(known)}"
                )
        return cls(PlatoonParams(**platoon_kw), RadioParams(**radio_kw), **top_kw).validate()
