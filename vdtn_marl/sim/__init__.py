"""The digital twin's physics: batched torch tensors, no RL API (docs/model.md).

Every name is imported on first use, so that reading the parameters (:mod:`.params`, which the
config schema does) imports neither the twin nor torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vdtn_marl._lazy import lazy_exports
from vdtn_marl.errors import ConfigError

if TYPE_CHECKING:
    from vdtn_marl.sim.layout import VEHICLE_OBS_FEATURES
    from vdtn_marl.sim.params import PlatoonParams, RadioParams, TwinParams
    from vdtn_marl.sim.platoon import PlatoonState
    from vdtn_marl.sim.topology import Topology, platoon_topology
    from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord

#: name → the module of this package that defines it
_HOMES = {
    "PlatoonParams": "params",
    "RadioParams": "params",
    "TwinParams": "params",
    "VEHICLE_OBS_FEATURES": "layout",
    "PlatoonState": "platoon",
    "Topology": "topology",
    "platoon_topology": "topology",
    "DigitalTwin": "twin",
    "IntervalRecord": "twin",
}

__all__ = [
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


__getattr__, __dir__ = lazy_exports(__name__, _HOMES)
