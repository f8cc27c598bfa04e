"""Two platoons sharing the cell: ``two_platoons`` (docs/model.md §6.2).

N vehicles form two platoons of n = N/2, each with predecessor following: vehicles 0..n−1
(leader 0) drive in the lane at y = 0, vehicles n..N−1 (leader n) in the adjacent lane at
y = ``LANE_WIDTH_M``, towards the base stations. Each leader drives its own window of the
trace set; both start abreast at x = 0 m (``SECOND_LEADER_OFFSET_M``), each follower at its
desired gap behind its predecessor. A collision in either platoon ends the scenario.

Radio: the 2(n − 1) V2V links of both platoons share the cell's M sub-channels, so a link
interferes with links of either platoon and with the V2I uplink on the sub-channel it picks.
The uplinks are shared equally and leaders first: sub-channel m carries the V2I uplink of
vehicle ``order[m mod N]`` with order = (0, n, 1, n+1, …, n−1, N−1), i.e. the two leaders on
sub-channels 0 and 1, then the first followers of each platoon, and so on. With the case
study's M = 4 and N = 8 the uplinks are those of vehicles 0, 4, 1 and 5.

Agents are named by vehicle id across both platoons (``vehicle_1..3`` and ``vehicle_5..7`` for
N = 8), so every name is unique.
"""

from __future__ import annotations

from vdtn_marl.errors import ConfigError
from vdtn_marl.scenarios.base import Scenario
from vdtn_marl.sim.params import PlatoonParams
from vdtn_marl.sim.topology import LEADER, Topology

LANE_WIDTH_M = 4.0
"""Lateral distance between the two platoons' lanes (m): the lane width of 3GPP TR 36.885's
highway layout (Annex A.1.2)."""
SECOND_LEADER_OFFSET_M = 0.0
"""Where the second platoon's leader starts along the road relative to the first's (m)."""


class TwoPlatoonsScenario(Scenario):
    name = "two_platoons"
    description = "two PF platoons of N/2 in adjacent lanes sharing the cell's sub-channels"

    def topology(self, platoon: PlatoonParams) -> Topology:
        n = platoon.num_vehicles
        if n % 2 or n < 4:
            raise ConfigError(
                f"num_vehicles={n!r} does not split into two platoons; allowed for scenario "
                "'two_platoons': an even number in [4, 64] (a leader and at least one "
                "follower each)"
            )
        half = n // 2
        predecessor = tuple(LEADER if i % half == 0 else i - 1 for i in range(n))
        return Topology(
            predecessor=predecessor,
            lateral_offset_m=(0.0,) * half + (LANE_WIDTH_M,) * half,
            leader_position_m=(0.0, SECOND_LEADER_OFFSET_M),
            v2i_order=tuple(v for i in range(half) for v in (i, half + i)),
            name=self.name,
        )
