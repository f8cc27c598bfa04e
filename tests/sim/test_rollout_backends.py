"""The rollout on NumPy arrays (what the rollout IVoI runs at B = 1 on a NumPy twin: the
written-out CACC loop) gives the rollout loop's numbers on torch tensors bit for bit, on every
registered scenario, with and without a first command and switch, at the episode's end and
through collisions."""

from dataclasses import fields

import numpy as np
import pytest
import torch

from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.scenarios import SCENARIOS, scenario_params
from vdtn_marl.sim.backend import repeat_rows, to_numpy, to_torch
from vdtn_marl.sim.platoon import PlatoonState
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi import rollout as rollout_module


def _record(twin: DigitalTwin, cacc: CACCController, intervals: int):
    num_actions = twin.params.radio.num_actions
    actions = np.random.default_rng(3)
    record = None
    for k in range(intervals):
        if k:
            twin.begin_interval()
        for _ in range(twin.subframes_per_interval):
            twin.step_subframe(actions.integers(0, num_actions, (twin.batch_size, twin.num_links)))
        obs = twin.vehicle_observation(perfect=False)
        record = twin.finish_interval(cacc(torch.as_tensor(obs)), perfect=False)
    return record


def _assert_same(numpy_run, torch_run):
    (r_n, s_n, a_n), (r_t, s_t, a_t) = numpy_run, torch_run
    np.testing.assert_array_equal(r_n, to_numpy(r_t))
    np.testing.assert_array_equal(a_n, to_numpy(a_t))
    for field in fields(PlatoonState):
        np.testing.assert_array_equal(getattr(s_n, field.name), to_numpy(getattr(s_t, field.name)))


def _torch(x):
    return None if x is None else to_torch(x)


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
@pytest.mark.parametrize("batch", [1, 2])
def test_the_numpy_rollout_equals_the_torch_rollout(scenario, batch):
    params = scenario_params(scenario, num_vehicles=6, episode_intervals=12)
    twin = DigitalTwin(params, batch_size=batch, seed=5, backend="numpy")
    twin.reset(seed=5)
    cacc = CACCController(params.platoon)
    record = _record(twin, cacc, 3)
    state = record.state_before.numpy()
    f, t = twin.num_followers, twin.subframes_per_interval
    branches = 1 + f
    rows = branches * batch
    rng = np.random.default_rng(11)
    first = rng.uniform(-6.0, 4.0, (rows, f)).astype(np.float32)  # beyond the bounds too
    switch = rng.integers(0, t + 1, (rows, f))
    # a crowded copy: followers pushed into their predecessors, so rows collide mid-rollout
    crowded = state.repeat(branches)
    position = crowded.position_m.copy()
    position[: batch * 2] += rng.uniform(0.0, 12.0, position[: batch * 2].shape).astype(np.float32)
    crowded = PlatoonState(position, crowded.speed_mps, crowded.accel_mps2, crowded.command_mps2)
    near_end = np.full(rows, params.episode_intervals - 4, np.int64)
    cases = [
        (state.repeat(branches), repeat_rows(to_numpy(record.interval), branches), None, None),
        (state.repeat(branches), near_end, first, switch),
        (crowded, near_end, first, None),
    ]
    collided = False
    for case_state, interval, command, first_switch in cases:
        for stop in (False, True):
            runs = [
                rollout_module._rollout(
                    twin, case_state, interval, cacc, 6, 0.97, command, first_switch, stop
                ),
                rollout_module._rollout(
                    twin, case_state.torch(), _torch(interval), cacc, 6, 0.97,
                    _torch(command), _torch(first_switch), stop,
                ),
            ]  # fmt: skip
            _assert_same(*runs)
            collided |= bool((runs[0][2] == 0).any())
    assert collided, "no row collided: the collision branch went untested"
