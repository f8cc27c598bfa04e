"""The written-out CACC rollout on NumPy arrays (what the rollout IVoI runs at B = 1) gives the
general rollout loop's numbers bit for bit, on NumPy arrays and on torch tensors, on every
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


def _assert_same(fused, general):
    (r_f, s_f, a_f), (r_g, s_g, a_g) = fused, general
    np.testing.assert_array_equal(r_f, to_numpy(r_g))
    np.testing.assert_array_equal(a_f, to_numpy(a_g))
    for field in fields(PlatoonState):
        np.testing.assert_array_equal(getattr(s_f, field.name), to_numpy(getattr(s_g, field.name)))


def _torch(x):
    return None if x is None else to_torch(x)


@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
@pytest.mark.parametrize("batch", [1, 2])
def test_fused_cacc_rollout_equals_the_general_loop_on_numpy_and_torch(scenario, batch):
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
                    twin,
                    case_state,
                    interval,
                    cacc,
                    6,
                    0.97,
                    command,
                    first_switch,
                    stop,
                    fused=fused,
                )  # fmt: skip
                for fused in (True, False)
            ]
            runs.append(
                rollout_module._rollout(
                    twin,
                    case_state.torch(),
                    _torch(interval),
                    cacc,
                    6,
                    0.97,
                    _torch(command),
                    _torch(first_switch),
                    stop,
                )  # fmt: skip
            )
            _assert_same(runs[0], runs[1])
            _assert_same(runs[0], runs[2])
            collided |= bool((runs[0][2] == 0).any())
    assert collided, "no row collided: the collision branch went untested"


def test_only_numpy_arrays_and_the_linear_cacc_take_the_fused_loop(monkeypatch):
    params = scenario_params("platoon", episode_intervals=12)
    twin = DigitalTwin(params, batch_size=1, seed=5, backend="numpy")
    twin.reset(seed=5)
    cacc = CACCController(params.platoon)
    record = _record(twin, cacc, 2)
    calls = []
    fused = rollout_module._cacc_rollout_numpy
    monkeypatch.setattr(
        rollout_module, "_cacc_rollout_numpy", lambda *a, **k: calls.append(1) or fused(*a, **k)
    )
    state, interval = record.state_before, record.interval
    rollout_module._rollout(twin, state, interval, cacc, 3, 0.9)  # torch tensors
    rollout_module._rollout(twin, state.numpy(), to_numpy(interval), lambda o: o[..., 0], 3, 0.9)
    assert calls == []
    rollout_module._rollout(twin, state.numpy(), to_numpy(interval), cacc, 3, 0.9)
    assert calls == [1]


def test_a_numpy_scalar_gain_takes_the_general_loop_and_its_numbers():
    """A NumPy float64 gain keeps its dtype in NumPy's arithmetic (a Python number takes the
    array's float32): the written-out copy, whose constants are float32 0-d arrays, hands such
    a rollout to the general loop, so both give its numbers."""
    params = scenario_params("platoon", episode_intervals=12)
    twin = DigitalTwin(params, batch_size=1, seed=5, backend="numpy")
    twin.reset(seed=5)
    record = _record(twin, CACCController(params.platoon), 2)
    strong = CACCController(params.platoon, gap_gain=np.float64(0.45))
    state, interval = record.state_before.numpy(), to_numpy(record.interval)
    # spacing errors to act on: followers 0.3–3 m off their gaps
    offset = np.random.default_rng(2).uniform(0.3, 3.0, state.position_m.shape)
    state = PlatoonState(
        (state.position_m + offset).astype(np.float32),
        state.speed_mps,
        state.accel_mps2,
        state.command_mps2,
    )
    runs = [
        rollout_module._rollout(twin, state, interval, strong, 4, 0.9, fused=fused)
        for fused in (True, False)
    ]
    _assert_same(*runs)
    assert runs[1][0].dtype == np.float64  # the general loop computed in float64
