"""One platoon with predecessor following: ``platoon``, the default scenario (docs/model.md §6).

Vehicle 0 leads and drives the speed trace; vehicle i follows vehicle i−1 and receives its CAM
over V2V link i (i−1 → i); sub-channel m is the V2I uplink of vehicle m mod N (Seed); one lane,
the leader starting at 0 m. The case study (``conf/scenario/platoon4.yaml``) has N = 4.
"""

from __future__ import annotations

from vdtn_marl.scenarios.base import Scenario
from vdtn_marl.sim.params import PlatoonParams
from vdtn_marl.sim.topology import Topology, platoon_topology


class PlatoonScenario(Scenario):
    name = "platoon"
    description = "one platoon, predecessor following: leader 0, vehicle i follows i-1"

    def topology(self, platoon: PlatoonParams) -> Topology:
        return platoon_topology(platoon.num_vehicles)
