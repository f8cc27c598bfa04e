"""Scenarios: a world's topology, geometry, agents and observation layouts (docs/model.md §6).

:data:`SCENARIOS` maps a name to its class, one file each over :class:`Scenario`
(``base.py``). The config selects one with ``scenario.kind`` (``conf/scenario/*.yaml``), the
environments with ``scenario=`` (``vdtn_marl.make("vdtn/vdtn-joint-v1",
scenario="two_platoons", num_vehicles=8)``). A new scenario is one file, one line here and one
YAML (docs/registry.md).
"""

from __future__ import annotations

from vdtn_marl.errors import ConfigError
from vdtn_marl.scenarios.base import Scenario, rra_name, vehicle_name
from vdtn_marl.scenarios.platoon import PlatoonScenario
from vdtn_marl.scenarios.two_platoons import TwoPlatoonsScenario
from vdtn_marl.sim.params import TwinParams

SCENARIOS: dict[str, type[Scenario]] = {
    "platoon": PlatoonScenario,
    "two_platoons": TwoPlatoonsScenario,
}
"""Scenario name → class; the only list of scenarios (config validation and tests read it)."""

DEFAULT_SCENARIO = "platoon"

__all__ = [
    "DEFAULT_SCENARIO",
    "SCENARIOS",
    "Scenario",
    "get_scenario",
    "rra_name",
    "scenario_params",
    "vehicle_name",
]


def get_scenario(name: str | Scenario = DEFAULT_SCENARIO, key: str = "scenario") -> Scenario:
    """The scenario registered as ``name`` (a :class:`Scenario` passes through); an unknown
    name is a :class:`ConfigError` naming ``key``, the value and the registered names."""
    if isinstance(name, Scenario):
        return name
    cls = SCENARIOS.get(name) if isinstance(name, str) else None
    if cls is None:
        raise ConfigError(
            f"{key}={name!r} is not a registered scenario; allowed: {', '.join(SCENARIOS)}"
        )
    return cls()


def scenario_params(scenario: str | Scenario = DEFAULT_SCENARIO, **overrides) -> TwinParams:
    """:class:`TwinParams` of ``scenario`` with flat model ``overrides``
    (``scenario_params("two_platoons", num_vehicles=8)``)."""
    return get_scenario(scenario).twin_params(**overrides)
