"""The second scenario, two platoons sharing the cell: its geometry, its errors, and that its
two platoons share the radio."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment.config import RunConfig, validate
from vdtn_marl.scenarios import get_scenario, scenario_params
from vdtn_marl.scenarios.two_platoons import LANE_WIDTH_M
from vdtn_marl.sim import channel, link
from vdtn_marl.sim.twin import DigitalTwin


def test_two_pf_platoons_in_adjacent_lanes():
    topology = scenario_params("two_platoons", num_vehicles=8).platoon.topology
    assert topology.predecessor == (-1, 0, 1, 2, -1, 4, 5, 6)
    assert topology.leaders == (0, 4) and topology.followers == (1, 2, 3, 5, 6, 7)
    assert topology.link_tx == (0, 1, 2, 4, 5, 6)
    assert topology.lateral_offset_m == (0.0,) * 4 + (LANE_WIDTH_M,) * 4
    # the uplinks are shared equally, leaders first: vehicles 0, 4, 1, 5 on M = 4
    assert topology.v2i_user(4) == (0, 4, 1, 5)
    assert link._link_layout(topology, 4, None)[2].tolist() == [0, 4, 1, 5]
    scenario = get_scenario("two_platoons")
    assert scenario.vehicle_agents(topology) == [f"vehicle_{i}" for i in (1, 2, 3, 5, 6, 7)]


@pytest.mark.parametrize("vehicles", [7, 2])
def test_a_vehicle_count_that_does_not_split_is_one_clear_error(vehicles):
    with pytest.raises(ConfigError, match=f"num_vehicles={vehicles} does not split .* even"):
        scenario_params("two_platoons", num_vehicles=vehicles)
    cfg = RunConfig()
    scenario = replace(cfg.scenario, kind="two_platoons", num_vehicles=vehicles)
    with pytest.raises(ConfigError, match=f"num_vehicles={vehicles}"):
        validate(replace(cfg, scenario=scenario))


def test_the_twin_hands_the_lanes_to_the_channel(monkeypatch):
    seen = []
    original = channel.v2v_distance_m

    def spy(x, lateral=None):
        seen.append(lateral)
        return original(x, lateral)

    monkeypatch.setattr(channel, "v2v_distance_m", spy)
    DigitalTwin(scenario_params("two_platoons", num_vehicles=8), seed=0)
    DigitalTwin(scenario_params("platoon", num_vehicles=4), seed=0)
    assert seen[0].tolist() == [0.0] * 4 + [LANE_WIDTH_M] * 4
    assert seen[1] is None  # one lane: the single-lane formula, bit for bit as before


def test_links_of_the_two_platoons_interfere_on_a_shared_subchannel():
    twin = DigitalTwin(scenario_params("two_platoons", num_vehicles=8), batch_size=64, seed=3)
    topology, radio = twin.topology, twin.params.radio
    a, b = 0, topology.link_tx.index(4)  # link 0 → 1 (first platoon), link 4 → 5 (second)
    off = radio.num_power_levels - 1
    assert bool((twin.tables.cross_gain[:, :, a, b] > 0).all())  # 4 → 1 reaches link a's rx
    bits = []
    for b_action in (off, 0):  # b silent, then b at 23 dBm on a's sub-channel 0
        actions = torch.full((64, topology.num_links), off)
        actions[:, a], actions[:, b] = 0, b_action
        state = link.new_link_state(64, topology.num_links, radio.num_subchannels, radio, 50, "cpu")
        out = link.subframe_step(twin.tables, 0, actions, state, twin._decode, twin._const)
        bits.append(out.v2v_bits[:, a])
    assert bool((bits[1] < bits[0]).all())


def test_disjoint_evaluation_needs_a_trace_window_per_leader():
    cfg = RunConfig()
    base = replace(cfg.scenario, traces="udds", eval_windows="disjoint")
    experiment = replace(cfg.experiment, eval_episodes=8)  # udds's eval part holds 13 windows
    validate(replace(cfg, scenario=base, experiment=experiment))  # one platoon: 8 windows
    two = replace(base, kind="two_platoons", num_vehicles=8)
    with pytest.raises(ConfigError, match=r"holds 13 disjoint .*eval_episodes=8 × 2 leaders"):
        validate(replace(cfg, scenario=two, experiment=experiment))
