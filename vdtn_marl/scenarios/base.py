"""The base of every scenario: what a world of the benchmark owns (docs/model.md §6).

A scenario is one file with a subclass of :class:`Scenario` (as in VMAS, one file over a small
base class), one line in :data:`vdtn_marl.scenarios.SCENARIOS` and one YAML in
``conf/scenario/``. It owns:

- the topology and geometry (:meth:`Scenario.topology`): who leads and drives a speed trace,
  whom each follower follows and receives its CAM from over its V2V link, which vehicle uses
  which V2I sub-channel, the lanes and where the vehicles start; the physics
  (:mod:`vdtn_marl.sim`) reads it as index arrays (:class:`~vdtn_marl.sim.topology.Topology`);
- its agents (:meth:`Scenario.vehicle_agents`, :meth:`Scenario.rra_agents`): one vehicle agent
  per follower and one RRA agent per V2V link, named by vehicle id, so names stay unique in any
  topology;
- their observation layouts: every agent observes the features of
  :data:`~vdtn_marl.sim.layout.VEHICLE_OBS_FEATURES` or
  :data:`~vdtn_marl.sim.layout.RRA_OBS_FEATURES` relative to its own predecessor and link
  (one definition each, in ``sim/``), so a new topology needs no new layout.

Everything else (platoon dynamics, radio, episode, traces) is a parameter of
:class:`~vdtn_marl.sim.params.TwinParams`, set in the scenario's YAML.
"""

from __future__ import annotations

from dataclasses import replace
from typing import ClassVar

from vdtn_marl.sim.layout import RRA_OBS_FEATURES, VEHICLE_OBS_FEATURES, Feature
from vdtn_marl.sim.params import PlatoonParams, TwinParams
from vdtn_marl.sim.topology import Topology


def vehicle_name(vehicle: int) -> str:
    """Agent name of the follower that is vehicle ``vehicle`` (its index among all vehicles;
    in one platoon, follower i is vehicle i)."""
    return f"vehicle_{vehicle}"


def rra_name(recipient: int) -> str:
    """Agent name of the RRA agent of the V2V link whose CAMs go to vehicle ``recipient``."""
    return f"rra_{recipient}"


class Scenario:
    """A world of the benchmark (see the module doc). Subclasses set :attr:`name`,
    :attr:`description` and define :meth:`topology`."""

    #: the key in :data:`~vdtn_marl.scenarios.SCENARIOS` (``scenario.kind`` in the config,
    #: ``scenario=`` of ``vdtn_marl.make``)
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    #: observation layouts of the vehicle and RRA agents (one definition each, in sim/)
    vehicle_observation_features: ClassVar[tuple[str, ...]] = VEHICLE_OBS_FEATURES
    rra_observation_features: ClassVar[tuple[Feature, ...]] = RRA_OBS_FEATURES

    def topology(self, platoon: PlatoonParams) -> Topology:
        """Who leads, who follows whom, V2I users, lanes and start positions for the
        ``platoon.num_vehicles`` vehicles; a :class:`~vdtn_marl.errors.ConfigError` for a
        vehicle count the scenario cannot arrange."""
        raise NotImplementedError

    def twin_params(self, **overrides) -> TwinParams:
        """The model with this scenario's topology: ``overrides`` as
        :meth:`TwinParams.from_overrides` takes them (``num_vehicles=8``, ...)."""
        params = TwinParams.from_overrides(**overrides)
        topology = self.topology(params.platoon)
        platoon = replace(params.platoon, scenario_topology=topology)
        return replace(params, platoon=platoon).validate()

    def vehicle_agents(self, topology: Topology) -> list[str]:
        """Vehicle agent names, one per follower in follower-row order."""
        return [vehicle_name(v) for v in topology.followers]

    def rra_agents(self, topology: Topology) -> list[str]:
        """RRA agent names, one per V2V link in link-row order (named by the recipient, so
        ``rra_i`` serves ``vehicle_i`` and is paid its IVoI)."""
        return [rra_name(v) for v in topology.link_rx]
