"""The topology the physics reads: index arrays, their checks, and the physics that uses them."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from vdtn_marl.errors import ConfigError
from vdtn_marl.sim import channel
from vdtn_marl.sim.params import PlatoonParams, RadioParams
from vdtn_marl.sim.platoon import PlatoonState, cam_snapshot, initial_state, spacing_errors
from vdtn_marl.sim.topology import LEADER, Topology, platoon_topology

#: a hand-made topology whose rows are not contiguous: leaders 0 and 3, 1 follows 0,
#: 2 follows 1, 4 follows 3 (two platoons of 3 and 2)
TWO = Topology(
    predecessor=(LEADER, 0, 1, LEADER, 3),
    lateral_offset_m=(0.0, 0.0, 0.0, 4.0, 4.0),
    leader_position_m=(0.0, 12.0),
    v2i_order=(0, 3, 1, 4, 2),
)


def test_the_default_is_one_pf_platoon():
    t = platoon_topology(4)
    assert (t.leaders, t.followers) == ((0,), (1, 2, 3))
    assert (t.link_tx, t.link_rx) == ((0, 1, 2), (1, 2, 3))
    assert t.v2i_user(4) == (0, 1, 2, 3) and t.v2i_user(6) == (0, 1, 2, 3, 0, 1)
    assert t.follows_leader == (True, False, False)
    assert t.single_lane and PlatoonParams().topology is t


def test_links_run_from_each_predecessor_to_its_follower():
    assert TWO.followers == (1, 2, 4) and TWO.leaders == (0, 3)
    assert TWO.link_tx == (0, 1, 3) and TWO.link_rx == (1, 2, 4)
    assert TWO.leader_of == (0, 0, 0, 1, 1)
    assert TWO.follows_leader == (True, False, True)
    assert TWO.v2i_user(4) == (0, 3, 1, 4)


@pytest.mark.parametrize("lib", ["numpy", "torch"])
def test_rows_are_gathered_and_assembled_back(lib):
    x = np.arange(10.0, 60.0, 10.0, dtype=np.float32)[None]  # [1, 5]: 10, 20, ..., 50
    x = x if lib == "numpy" else torch.from_numpy(x)
    assert np.asarray(TWO.followers_of(x)).tolist() == [[20.0, 30.0, 50.0]]
    assert np.asarray(TWO.predecessors_of(x)).tolist() == [[10.0, 20.0, 40.0]]
    assert np.asarray(TWO.leaders_of(x)).tolist() == [[10.0, 40.0]]
    back = TWO.assemble(TWO.leaders_of(x), TWO.followers_of(x))
    assert np.asarray(back).tolist() == np.asarray(x).tolist()


@pytest.mark.parametrize(
    ("predecessor", "match"),
    [
        ((LEADER, 2, 1), r"topology.predecessor=\(-1, 2, 1\) has a cycle 1 → 2 → 1"),
        ((LEADER, 1), r"cycle 1 → 1"),
        ((LEADER, 0, 7), r"topology.predecessor\[2\]=7 points outside .* -1 .* 0\.\.2"),
        ((LEADER, -3), r"topology.predecessor\[1\]=-3"),
        ((1, 0), r"has no leader"),
        ((LEADER,), r"has 1 vehicles; allowed: 2 to 64"),
    ],
)
def test_a_bad_predecessor_map_is_one_clear_error(predecessor, match):
    with pytest.raises(ConfigError, match=match):
        Topology(predecessor=predecessor)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"lateral_offset_m": (0.0, 4.0)}, r"topology.lateral_offset_m=.* must hold 3 numbers"),
        ({"leader_position_m": (0.0, 5.0)}, r"topology.leader_position_m=.* must hold 1 numbers"),
        ({"v2i_order": (0, 0, 1)}, r"topology.v2i_order=\(0, 0, 1\) must order every vehicle"),
    ],
)
def test_bad_geometry_is_one_clear_error(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        Topology(predecessor=(LEADER, 0, 1), **kwargs)


def test_params_refuse_a_topology_of_another_size():
    with pytest.raises(ConfigError, match=r"num_vehicles=4 differs .* allowed: 5"):
        PlatoonParams(num_vehicles=4, scenario_topology=TWO).validate()


def test_gap_and_speed_error_are_to_each_followers_own_predecessor():
    params = PlatoonParams(num_vehicles=5, scenario_topology=TWO)
    position = torch.tensor([[0.0, -10.0, -19.0, 12.0, 3.0]])
    speed = torch.tensor([[20.0, 19.0, 18.5, 10.0, 11.0]])
    zeros = torch.zeros(1, 5)
    gap_error, speed_error = spacing_errors(PlatoonState(position, speed, zeros, zeros), params)
    length, r, h = params.vehicle_length_m, params.standstill_gap_m, params.time_headway_s
    gaps = [10.0 - length, 9.0 - length, 9.0 - length]  # 0 → 1, 1 → 2, 3 → 4
    desired = [r + h * 19.0, r + h * 18.5, r + h * 11.0]
    expected = [g - d for g, d in zip(gaps, desired, strict=True)]
    torch.testing.assert_close(gap_error[0], torch.tensor(expected))
    torch.testing.assert_close(speed_error[0], torch.tensor([1.0, 0.5, -1.0]))


def test_cams_carry_each_predecessors_acceleration_and_command():
    params = PlatoonParams(num_vehicles=5, scenario_topology=TWO)
    accel = torch.tensor([[0.1, 0.2, 0.3, 0.4, 0.5]])
    command = -accel
    state = PlatoonState(torch.zeros(1, 5), torch.zeros(1, 5), accel, command)
    snapshot = cam_snapshot(state, params)  # [1, F, 2]: from vehicles 0, 1 and 3
    torch.testing.assert_close(snapshot[0, :, 0], torch.tensor([0.1, 0.2, 0.4]))
    torch.testing.assert_close(snapshot[0, :, 1], torch.tensor([-0.1, -0.2, -0.4]))


def test_start_at_the_desired_gap_behind_each_predecessor():
    params = PlatoonParams(num_vehicles=5, scenario_topology=TWO)
    state = initial_state(torch.tensor([[20.0, 10.0]]), params, torch.Generator())
    spacing_1 = params.vehicle_length_m + params.standstill_gap_m + params.time_headway_s * 20.0
    spacing_2 = params.vehicle_length_m + params.standstill_gap_m + params.time_headway_s * 10.0
    expected = [0.0, -spacing_1, -2 * spacing_1, 12.0, 12.0 - spacing_2]
    torch.testing.assert_close(state.position_m[0], torch.tensor(expected))
    assert state.speed_mps[0].tolist() == [20.0, 20.0, 20.0, 10.0, 10.0]
    gap_error, speed_error = spacing_errors(state, params)
    assert float(gap_error.abs().max()) < 1e-5 and float(speed_error.abs().max()) == 0.0


def test_distances_across_lanes():
    x = torch.tensor([[0.0, -3.0, 0.0]])
    lateral = torch.tensor([0.0, 0.0, 4.0])
    d = channel.v2v_distance_m(x, lateral)[0]
    torch.testing.assert_close(d, torch.tensor([[0.0, 3.0, 4.0], [3.0, 0.0, 5.0], [4.0, 5.0, 0.0]]))
    radio = RadioParams()
    to_bs = channel.v2i_distance_m(x, torch.tensor([0.0]), radio, lateral)[0]
    dz = radio.bs_height_m - radio.vehicle_height_m
    far, near = radio.bs_road_offset_m, radio.bs_road_offset_m - 4.0
    expected = [math.hypot(far, dz), math.hypot(3.0, far, dz), math.hypot(near, dz)]
    torch.testing.assert_close(to_bs, torch.tensor(expected))
    # one lane: the same numbers as without offsets
    same = channel.v2v_distance_m(x, torch.zeros(3))
    torch.testing.assert_close(same, channel.v2v_distance_m(x))
