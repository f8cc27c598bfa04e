"""The digital twin's physics: batched torch tensors, no RL API (docs/model.md)."""

from vdtn_marl.errors import ConfigError
from vdtn_marl.sim.cacc import CACCController
from vdtn_marl.sim.params import PlatoonParams, RadioParams, TwinParams
from vdtn_marl.sim.platoon import VEHICLE_OBS_FEATURES, PlatoonState
from vdtn_marl.sim.topology import Topology, platoon_topology
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord

__all__ = [
    "CACCController",
    "ConfigError",
    "DigitalTwin",
    "IntervalRecord",
    "PlatoonParams",
    "PlatoonState",
    "RadioParams",
    "Topology",
    "TwinParams",
    "VEHICLE_OBS_FEATURES",
    "platoon_topology",
]
