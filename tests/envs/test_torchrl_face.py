"""The batched TorchRL face: specs, equivalence with the PettingZoo faces, partial resets."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from tensordict import TensorDict
from torchrl.envs.utils import check_env_specs

from vdtn_marl.core.reward import REWARD_KINDS
from vdtn_marl.envs.control import PlatoonControlEnv
from vdtn_marl.envs.radio import V2XRRAEnv
from vdtn_marl.envs.torchrl import MODES, VDTNTorchRLEnv
from vdtn_marl.envs.two_timescale import TwoTimescaleEnv
from vdtn_marl.sim.params import ConfigError
from vdtn_marl.sim.platoon import spacing_errors
from vdtn_marl.voi import RolloutIVoIEstimator

ATOL = 1e-5
RTOL = 1e-5


class FixedRRAPolicy:
    """Deterministic RRA actions that cycle with the call count (NumPy or torch)."""

    def __init__(self, num_actions: int):
        self.num_actions = num_actions
        self.calls = 0

    def __call__(self, observation):
        shape = observation.shape[:-1]
        base = (np.arange(int(np.prod(shape))).reshape(shape) * 3 + self.calls) % self.num_actions
        self.calls += 1
        if isinstance(observation, np.ndarray):
            return base.astype(np.int64)
        return torch.as_tensor(base, dtype=torch.long, device=observation.device)


class OwnSubchannelRRAPolicy:
    """Link l on sub-channel l at full power (action l·P): CAMs that are mostly delivered."""

    def __init__(self, num_power_levels: int = 4):
        self.num_power_levels = num_power_levels

    def __call__(self, observation):
        shape = observation.shape[:-1]
        actions = np.broadcast_to(np.arange(shape[-1]) * self.num_power_levels, shape).copy()
        if isinstance(observation, np.ndarray):
            return actions.astype(np.int64)
        return torch.as_tensor(actions, dtype=torch.long, device=observation.device)


def _close(a, b, what):
    np.testing.assert_allclose(
        np.asarray(a, np.float64), np.asarray(b, np.float64), atol=ATOL, rtol=RTOL, err_msg=what
    )


# ---------------------------------------------------------------------- specs
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("batch", [1, 64])
def test_check_env_specs(mode, batch):
    env = VDTNTorchRLEnv(mode=mode, batch_size=batch, seed=3, episode_intervals=3)
    check_env_specs(env)
    keys = set(env.full_action_spec.keys(True, True))
    assert (("vehicle", "action") in keys) == (mode != "rra")
    assert (("rra", "action") in keys) == (mode in ("rra", "joint"))
    assert env.full_done_spec["done"].shape == (batch, 1)


@pytest.mark.parametrize("mode", ["rra", "joint"])
def test_specs_across_interval_ends_and_auto_reset(mode):
    """Short intervals and episodes: closing steps, episode ends and automatic resets happen."""
    env = VDTNTorchRLEnv(
        mode=mode, batch_size=8, seed=1, episode_intervals=2, subframes_per_interval=2
    )
    check_env_specs(env)
    rollout = env.rollout(9, break_when_any_done=False)
    done = rollout["next", "done"][..., 0]
    assert done[:, 3].all() and done[:, 7].all() and not done[:, [0, 1, 2, 4, 5, 6, 8]].any()
    if mode == "joint":
        acts = rollout["vehicle", "acts"][..., 0, 0]
        assert acts[:, 1::2].all() and not acts[:, 0::2].any()
    assert torch.isfinite(rollout["next", "rra", "reward"]).all()


@pytest.mark.parametrize("mode", ["control_impaired", "joint"])
def test_observations_stay_in_their_specs(mode):
    env = VDTNTorchRLEnv(mode=mode, batch_size=8, seed=0, episode_intervals=4)
    with torch.random.fork_rng():
        torch.manual_seed(0)
        rollout = env.rollout(10 if mode == "control_impaired" else 120, break_when_any_done=False)
    for key, spec in env.full_observation_spec.items(True, True):
        values = rollout["next", key]
        assert all(spec.is_in(values[:, i]) for i in range(values.shape[1])), key


# ---------------------------------------------------------------------- equivalence
def _vehicle_stack(obs: dict, names: list[str]) -> np.ndarray:
    return np.stack([obs[n] for n in names])


@pytest.mark.parametrize("impaired", [False, True])
def test_control_matches_pettingzoo(impaired):
    seed, kwargs = 11, {"episode_intervals": 40}

    def policy():  # one per env: the policy counts its calls
        return {"rra_policy": FixedRRAPolicy(16)} if impaired else {}

    pz = PlatoonControlEnv(impaired=impaired, seed=seed, **policy(), **kwargs)
    assert pz.twin.params.radio.num_actions == 16
    mode = "control_impaired" if impaired else "control"
    env = VDTNTorchRLEnv(mode=mode, seed=seed, **policy(), **kwargs)
    obs, _ = pz.reset()
    names = pz.possible_agents
    td = env.reset()
    _close(td["vehicle", "observation"][0], _vehicle_stack(obs, names), "reset observation")
    rng = np.random.default_rng(0)
    steps = 0
    while True:
        u = rng.uniform(-2.0, 2.0, size=len(names)).astype(np.float32)
        obs, rew, term, trunc, _ = pz.step({n: u[i : i + 1] for i, n in enumerate(names)})
        td["vehicle", "action"] = torch.as_tensor(u)[None, :, None]
        nxt = env.step(td)["next"]
        steps += 1
        _close(
            nxt["vehicle", "observation"][0],
            _vehicle_stack(obs, names),
            f"observation at step {steps}",
        )
        _close(
            nxt["vehicle", "reward"][0, :, 0], [rew[n] for n in names], f"reward at step {steps}"
        )
        assert nxt["vehicle", "terminated"][0, :, 0].tolist() == [term[n] for n in names]
        assert nxt["vehicle", "truncated"][0, :, 0].tolist() == [trunc[n] for n in names]
        assert bool(nxt["done"]) == (any(term.values()) or any(trunc.values()))
        if bool(nxt["done"]):
            break
        td = nxt
    assert steps == 40 or bool(nxt["terminated"])


def _run_two_timescale(pz, env, vehicles: bool, intervals: int, seed: int = 0):
    obs, infos = pz.reset()
    rra_names = pz.rra_agents
    veh_names = pz.vehicle_agents
    td = env.reset()
    _close(
        td["rra", "observation"][0], np.stack([obs[n] for n in rra_names]), "reset rra observation"
    )
    if vehicles:
        _close(
            td["vehicle", "observation"][0],
            _vehicle_stack(obs, veh_names),
            "reset vehicle observation",
        )
    rng = np.random.default_rng(seed)
    n_act = pz.twin.params.radio.num_actions
    t_steps = pz.twin.subframes_per_interval
    steps = closing_steps = 0
    while True:
        a = rng.integers(0, n_act, size=len(rra_names))
        actions = {n: np.int64(a[i]) for i, n in enumerate(rra_names)}
        td["rra", "action"] = torch.as_tensor(a, dtype=torch.long)[None]
        if vehicles:
            u = rng.uniform(-2.0, 2.0, size=len(veh_names)).astype(np.float32)
            assert bool(td["vehicle", "acts"].all()) == infos[veh_names[0]]["acts"]
            assert bool(td["vehicle", "acts"].any()) == infos[veh_names[0]]["acts"]
            if infos[veh_names[0]]["acts"]:
                actions.update({n: u[i : i + 1] for i, n in enumerate(veh_names)})
                closing_steps += 1
            td["vehicle", "action"] = torch.as_tensor(u)[None, :, None]
        obs, rew, term, trunc, infos = pz.step(actions)
        nxt = env.step(td)["next"]
        steps += 1
        what = f"step {steps}"
        _close(
            nxt["rra", "observation"][0],
            np.stack([obs[n] for n in rra_names]),
            f"rra observation, {what}",
        )
        _close(nxt["rra", "reward"][0, :, 0], [rew[n] for n in rra_names], f"rra reward, {what}")
        if vehicles:
            _close(
                nxt["vehicle", "observation"][0],
                _vehicle_stack(obs, veh_names),
                f"vehicle observation, {what}",
            )
            _close(
                nxt["vehicle", "reward"][0, :, 0],
                [rew[n] for n in veh_names],
                f"vehicle reward, {what}",
            )
        assert nxt["rra", "terminated"][0, :, 0].tolist() == [term[n] for n in rra_names]
        assert nxt["rra", "truncated"][0, :, 0].tolist() == [trunc[n] for n in rra_names]
        if bool(nxt["done"]):
            assert any(term.values()) or any(trunc.values())
            break
        assert not (any(term.values()) or any(trunc.values()))
        td = nxt
    assert steps == intervals * t_steps
    return closing_steps


def test_joint_matches_pettingzoo():
    seed, kwargs = 5, {"episode_intervals": 3}
    pz = TwoTimescaleEnv(seed=seed, ivoi_estimator="rollout", **kwargs)
    env = VDTNTorchRLEnv(mode="joint", seed=seed, ivoi_estimator="rollout", **kwargs)
    assert _run_two_timescale(pz, env, vehicles=True, intervals=3) == 3


@pytest.mark.parametrize("reward", REWARD_KINDS)
def test_rra_matches_pettingzoo(reward):
    seed, kwargs = 9, {"episode_intervals": 2, "reward": reward, "kappa1": 0.3}
    pz = V2XRRAEnv(seed=seed, **kwargs)
    env = VDTNTorchRLEnv(mode="rra", seed=seed, **kwargs)
    _run_two_timescale(pz, env, vehicles=False, intervals=2)


def test_rra_with_the_cam_lost_ivoi_baseline_matches_pettingzoo():
    """Both faces ask their control module what a follower would have done had its CAM been
    lost, and pay the same difference reward; the joint mode, without a control module,
    refuses that estimator."""
    seed, kwargs = 4, {"episode_intervals": 3, "kappa1": 0.3}

    def estimator():
        return RolloutIVoIEstimator(horizon_intervals=2, baseline="cam_lost")

    pz = V2XRRAEnv(seed=seed, ivoi_estimator=estimator(), **kwargs)
    env = VDTNTorchRLEnv(mode="rra", seed=seed, ivoi_estimator=estimator(), **kwargs)
    _run_two_timescale(pz, env, vehicles=False, intervals=3)
    with pytest.raises(ConfigError, match="cam_lost baseline.*mode='rra'"):
        VDTNTorchRLEnv(mode="joint", seed=seed, ivoi_estimator=estimator(), **kwargs)


# ---------------------------------------------------------------------- partial reset
def _reset_first(env, td):
    td = td.clone()
    mask = torch.zeros(env.batch_size[0], 1, dtype=torch.bool)
    mask[0] = True
    td["_reset"] = mask
    return env.reset(td)


def test_partial_reset_control_keeps_other_scenarios():
    kwargs = {"mode": "control", "batch_size": 4, "seed": 2, "episode_intervals": 50}
    env, ref = VDTNTorchRLEnv(**kwargs), VDTNTorchRLEnv(**kwargs)
    td, td_ref = env.reset(), ref.reset()
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        u = torch.rand(4, 3, 1, generator=gen) * 2 - 1
        td["vehicle", "action"] = u
        td_ref["vehicle", "action"] = u
        td, td_ref = env.step(td)["next"], ref.step(td_ref)["next"]
    before = td["vehicle", "observation"].clone()
    td = _reset_first(env, td)
    after = td["vehicle", "observation"]
    torch.testing.assert_close(after[1:], before[1:], rtol=0, atol=0)
    assert not torch.equal(after[0], before[0])
    assert not td["done"].any()
    assert int(env.twin.interval[0]) == 0 and env.twin.interval[1:].eq(5).all()
    for _ in range(5):  # no randomness after the start: the other scenarios go on unchanged
        u = torch.rand(4, 3, 1, generator=gen) * 2 - 1
        td["vehicle", "action"] = u
        td_ref["vehicle", "action"] = u
        td, td_ref = env.step(td)["next"], ref.step(td_ref)["next"]
        torch.testing.assert_close(
            td["vehicle", "observation"][1:], td_ref["vehicle", "observation"][1:]
        )
        torch.testing.assert_close(td["vehicle", "reward"][1:], td_ref["vehicle", "reward"][1:])


def test_partial_reset_control_impaired_keeps_other_scenarios():
    env = VDTNTorchRLEnv(mode="control_impaired", batch_size=4, seed=4, episode_intervals=50)
    td = env.reset()
    for _ in range(3):
        td["vehicle", "action"] = torch.full((4, 3, 1), 0.5)
        td = env.step(td)["next"]
    before = td["vehicle", "observation"].clone()
    delay_before = env.twin.link_state.delay_subframes.clone()
    td = _reset_first(env, td)
    torch.testing.assert_close(td["vehicle", "observation"][1:], before[1:], rtol=0, atol=0)
    torch.testing.assert_close(
        env.twin.link_state.delay_subframes[1:], delay_before[1:], rtol=0, atol=0
    )
    assert not torch.equal(td["vehicle", "observation"][0], before[0])
    assert env.twin.subframe == env.twin.subframes_per_interval
    td["vehicle", "action"] = torch.zeros(4, 3, 1)
    assert torch.isfinite(env.step(td)["next", "vehicle", "reward"]).all()


def _counting_radio(env):
    """Count the engine's radio runs (an instance attribute shadows the method)."""
    runs = []
    radio = env.engine.run_radio

    def counted(*args, **kwargs):
        runs.append(1)
        return radio(*args, **kwargs)

    env.engine.run_radio = counted
    return runs


def test_scenarios_ending_apart_restart_in_the_step_with_one_radio_run():
    """Scenarios whose episodes end at different intervals (persisting scenarios): the step
    that ends some starts their new episodes together with the others' next interval, one radio
    run per interval, and TorchRL's reset that follows hands out their first observation."""
    env = VDTNTorchRLEnv(mode="control_impaired", batch_size=4, seed=4, episode_intervals=6)
    td = env.reset()
    for _ in range(2):
        td["vehicle", "action"] = torch.zeros(4, 3, 1)
        td = env.step(td)["next"]
    td = _reset_first(env, td)  # scenario 0 now ends 2 intervals after the others
    runs = _counting_radio(env)
    ended = []
    for _ in range(6):
        td["vehicle", "action"] = torch.zeros(4, 3, 1)
        step, td = env.step_and_maybe_reset(td)
        done = step["next", "done"].squeeze(-1)
        ended.append(done.clone())
        if bool(done.any()):
            assert not bool(done.all())
            assert env.twin.interval[done].eq(0).all()  # started anew, by the step
            # the carried observation of a restarted scenario is its new episode's first
            torch.testing.assert_close(
                td["vehicle", "observation"][done], env.engine.observe()[done], rtol=0, atol=0
            )
            assert not torch.equal(
                td["vehicle", "observation"][done], step["next", "vehicle", "observation"][done]
            )
    assert len(runs) == 6  # one radio run per interval, endings included
    assert ended[3].tolist() == [False, True, True, True]  # the others' 6th interval
    assert ended[5].tolist() == [True, False, False, False]


def test_a_reset_of_more_scenarios_than_the_step_ended_resets_the_others_only():
    """A collector may reset scenarios the step did not end (its own truncation): those start
    anew there; the ones the step already started are not started twice."""
    env = VDTNTorchRLEnv(mode="control_impaired", batch_size=4, seed=5, episode_intervals=4)
    td = env.reset()
    td["vehicle", "action"] = torch.zeros(4, 3, 1)
    td = env.step(td)["next"]
    td = _reset_first(env, td)
    for _ in range(3):  # scenarios 1-3 end at the third step, scenario 0 goes on
        td["vehicle", "action"] = torch.zeros(4, 3, 1)
        td = env.step(td)["next"]
    restarted = env.twin.interval.eq(0)
    assert restarted.tolist() == [False, True, True, True]
    state = {f: getattr(env.twin._platoon, f).clone() for f in ("position_m", "speed_mps")}
    td = td.clone()
    td["_reset"] = torch.tensor([[True], [True], [False], [False]])  # 1 ended, 0 cut short
    env.reset(td)
    assert env.twin.interval.eq(0).all()  # scenario 0 started anew here
    for name, before in state.items():  # scenario 1 kept the episode the step started
        assert torch.equal(getattr(env.twin._platoon, name)[1], before[1]), name
    assert not torch.equal(env.twin._platoon.position_m[0], state["position_m"][0])


def test_partial_reset_joint_mid_interval():
    kwargs = {"mode": "joint", "batch_size": 4, "seed": 6, "episode_intervals": 5}
    env, ref = VDTNTorchRLEnv(**kwargs), VDTNTorchRLEnv(**kwargs)
    td, td_ref = env.reset(), ref.reset()
    t_steps = env.twin.subframes_per_interval
    gen = torch.Generator().manual_seed(1)

    def step_both(td, td_ref):
        a = torch.randint(0, env.num_actions, (4, 3), generator=gen)
        u = torch.rand(4, 3, 1, generator=gen) * 2 - 1
        for t in (td, td_ref):
            t["rra", "action"] = a
            t["vehicle", "action"] = u
        return env.step(td)["next"], ref.step(td_ref)["next"]

    for _ in range(t_steps + 10):
        td, td_ref = step_both(td, td_ref)
    rra_before = td["rra", "observation"].clone()
    veh_before = td["vehicle", "observation"].clone()
    td = _reset_first(env, td)
    torch.testing.assert_close(td["rra", "observation"][1:], rra_before[1:], rtol=0, atol=0)
    torch.testing.assert_close(td["vehicle", "observation"][1:], veh_before[1:], rtol=0, atol=0)
    assert not torch.equal(td["vehicle", "observation"][0], veh_before[0])
    assert env.twin.subframe == ref.twin.subframe == 10
    for k in range(10, t_steps):  # rest of the interval, closing step included
        td, td_ref = step_both(td, td_ref)
        keys = [("rra", "reward"), ("vehicle", "observation")]
        if k < t_steps - 1:  # the next interval's fading comes from the (diverged) generator
            keys.append(("rra", "observation"))
        for key in keys:
            torch.testing.assert_close(td[key][1:], td_ref[key][1:])
    torch.testing.assert_close(td["vehicle", "reward"][1:], td_ref["vehicle", "reward"][1:])
    assert td["vehicle", "acts"].sum() == 0 and ref.twin.interval.eq(2).all()


# ---------------------------------------------------------------------- bad actions
@pytest.mark.parametrize(
    "value, match",
    [
        (float("nan"), r"nan m/s² .* outside \[-2\.6, 2\.6\]"),
        (3.0, r"3\.0 m/s² .* outside \[-2\.6, 2\.6\]"),
        (-2.7, r"outside \[-2\.6, 2\.6\]"),
    ],
)
def test_bad_vehicle_action_raises(value, match):
    env = VDTNTorchRLEnv(mode="control", batch_size=2, seed=0)
    td = env.reset()
    u = torch.zeros(2, 3, 1)
    u[1, 2, 0] = value
    td["vehicle", "action"] = u
    with pytest.raises(ValueError, match=match):
        env.step(td)
    assert env.twin.interval.eq(0).all()
    td["vehicle", "action"] = torch.zeros(2, 3)
    with pytest.raises(ValueError, match=r"shape \(2, 3\), expected \(2, 3, 1\)"):
        env.step(td)


def test_bad_rra_action_raises():
    env = VDTNTorchRLEnv(mode="joint", batch_size=2, seed=0, episode_intervals=3)
    td = env.reset()
    td["vehicle", "action"] = torch.zeros(2, 3, 1)
    for bad, match in [
        (torch.tensor([[0, 1, 16], [0, 0, 0]]), r"RRA action 16 .* outside \[0, 15\]"),
        (torch.tensor([[0, -1, 0], [0, 0, 0]]), r"RRA action -1 .* outside \[0, 15\]"),
        (torch.zeros(2, 3), r"float32; expected integers in \[0, 15\]"),
        (torch.zeros(2, 3, 1, dtype=torch.long), r"shape \(2, 3, 1\), expected \(2, 3\)"),
    ]:
        td["rra", "action"] = bad
        with pytest.raises(ValueError, match=match):
            env.step(td)
    assert env.twin.subframe == 0
    # off-tick vehicle actions are not read; at the closing step they are
    td["rra", "action"] = torch.zeros(2, 3, dtype=torch.long)
    td["vehicle", "action"] = torch.full((2, 3, 1), float("nan"))
    for _ in range(env.twin.subframes_per_interval - 1):
        td = env.step(td)["next"]
        td["rra", "action"] = torch.zeros(2, 3, dtype=torch.long)
        td["vehicle", "action"] = torch.full((2, 3, 1), float("nan"))
    assert td["vehicle", "acts"].all()
    with pytest.raises(ValueError, match=r"nan m/s² .* outside \[-2\.6, 2\.6\]"):
        env.step(td)


def test_bad_configuration_raises():
    with pytest.raises(ValueError, match="mode="):
        VDTNTorchRLEnv(mode="nope")
    with pytest.raises(ValueError, match="batch_size"):
        VDTNTorchRLEnv(batch_size=0)
    with pytest.raises(ValueError, match="kappa1"):
        VDTNTorchRLEnv(mode="joint", kappa1=1.5)
    with pytest.raises(ConfigError, match="both choose the leader traces"):
        VDTNTorchRLEnv(traces="hwfet", trace_source="udds")


def test_seed_reproducible_and_model_kwargs():
    a = VDTNTorchRLEnv(mode="joint", batch_size=3, num_vehicles=6, episode_intervals=3)
    b = VDTNTorchRLEnv(mode="joint", batch_size=3, num_vehicles=6, episode_intervals=3)
    assert a.full_action_spec["vehicle", "action"].shape == (3, 5, 1)
    a.set_seed(123)
    b.set_seed(123)
    with torch.random.fork_rng():  # the rollout's random actions come from torch's global RNG
        torch.manual_seed(0)
        ra = a.rollout(5)
        torch.manual_seed(0)
        rb = b.rollout(5)
    torch.testing.assert_close(ra["next", "rra", "observation"], rb["next", "rra", "observation"])
    torch.testing.assert_close(ra["vehicle", "observation"], rb["vehicle", "observation"])


# ---------------------------------------------------------------------- device
@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA is not available")
@pytest.mark.parametrize("mode", MODES)
def test_cuda(mode):
    env = VDTNTorchRLEnv(mode=mode, batch_size=16, device="cuda", seed=0, episode_intervals=3)
    check_env_specs(env)
    rollout = env.rollout(5)
    assert rollout.device.type == "cuda"
    for key in rollout.keys(True, True):
        assert rollout[key].device.type == "cuda", key
    assert env.twin.device.type == "cuda"


def test_reset_without_reset_key_is_full():
    env = VDTNTorchRLEnv(mode="control", batch_size=2, seed=0)
    td = env.reset()
    td["vehicle", "action"] = torch.ones(2, 3, 1)
    env.step(td)
    assert env.twin.interval.eq(1).all()
    env.reset(TensorDict({}, batch_size=[2]))
    assert env.twin.interval.eq(0).all()


# ---------------------------------------------------------------------- RRA burn-in
def _reset_interval(burn_in: int, seed: int) -> torch.Tensor:
    env = VDTNTorchRLEnv(
        mode="rra", batch_size=4, seed=seed, episode_intervals=20, burn_in_intervals=burn_in
    )
    env.set_seed(seed)
    env.reset()
    return env.twin.interval.clone()


def test_rra_burn_in_starts_batches_mid_episode_reproducibly():
    starts = [_reset_interval(15, seed) for seed in range(8)]
    for start in starts:  # one K per reset, in 0..15
        assert (start == start[0]).all() and 0 <= int(start[0]) <= 15
    assert len({int(s[0]) for s in starts}) > 2  # K is drawn, not fixed
    torch.testing.assert_close(_reset_interval(15, 3), starts[3])  # and seeded
    assert (_reset_interval(0, 3) == 0).all()  # the default starts at the episode's start


def test_rra_burn_in_leaves_a_platoon_that_has_been_driving():
    env = VDTNTorchRLEnv(
        mode="rra", batch_size=4, seed=1, episode_intervals=60, burn_in_intervals=59
    )
    for seed in range(10):
        env.set_seed(seed)
        env.reset()
        if int(env.twin.interval[0]) >= 20:
            break
    else:
        pytest.fail("no reset drew K >= 20 of 0..59 in 10 tries")
    gap_error, speed_error = spacing_errors(env.twin.platoon, env.twin.params.platoon)
    # at reset the followers sit at the desired gap and the leader's speed; after ≥ 1 s of
    # the leader's trace they do not
    assert gap_error.abs().max() > 1e-2 or speed_error.abs().max() > 1e-2
    check_env_specs(env)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        ({"mode": "control", "burn_in_intervals": 5}, "only used with mode='rra'"),
        ({"mode": "rra", "burn_in_intervals": 20}, r"burn_in_intervals=20 must be in \[0, 19\]"),
        ({"mode": "rra", "burn_in_intervals": -1}, r"burn_in_intervals=-1 must be in"),
        ({"mode": "rra", "burn_in_intervals": 2.5}, "must be an integer"),
    ],
)
def test_bad_burn_in_raises(kwargs, match):
    with pytest.raises(ValueError, match=match):
        VDTNTorchRLEnv(episode_intervals=20, **kwargs)


# ---------------------------------------------------------------------- state, infos, frames
@pytest.mark.parametrize("mode", MODES)
def test_state_and_infos_are_in_the_specs(mode):
    env = VDTNTorchRLEnv(
        mode=mode, batch_size=3, seed=0, episode_intervals=2, return_state=True, return_info=True
    )
    check_env_specs(env, seed=0)
    n = env.twin.params.platoon.num_vehicles
    assert env.full_observation_spec["state"].shape == (3, 3 * n)
    for group, agents in env.group_map.items():
        info = env.full_observation_spec[group, "info"]
        assert set(info.keys()) == set(env.info_keys) and info.shape == (3, len(agents))
    radio = {"cam_delivered", "aoi_ms", "v2i_throughput_mbps"}
    assert radio.issubset(env.info_keys) == (mode != "control")
    assert ("closes_interval" in env.info_keys) == (mode in ("rra", "joint"))
    plain = VDTNTorchRLEnv(mode=mode, batch_size=3, seed=0, episode_intervals=2)
    keys = set(plain.full_observation_spec.keys(True, True))
    assert "state" not in keys and not any("info" in key for key in keys)


@pytest.mark.parametrize("impaired", [False, True])
def test_control_state_and_infos_are_the_pettingzoo_faces(impaired):
    seed, kwargs = 11, {"episode_intervals": 6}
    policy = {"rra_policy": OwnSubchannelRRAPolicy()} if impaired else {}
    pz = PlatoonControlEnv(impaired=impaired, seed=seed, **policy, **kwargs)
    mode = "control_impaired" if impaired else "control"
    env = VDTNTorchRLEnv(
        mode=mode, seed=seed, return_state=True, return_info=True, **policy, **kwargs
    )
    pz.reset()
    names = pz.possible_agents
    td = env.reset()
    _close(td["state"][0], pz.state(), "state at reset")
    rng = np.random.default_rng(0)
    delivered = 0
    for step in range(6):
        u = rng.uniform(-2.0, 2.0, size=len(names)).astype(np.float32)
        _, _, _, _, infos = pz.step({n: u[i : i + 1] for i, n in enumerate(names)})
        td["vehicle", "action"] = torch.as_tensor(u)[None, :, None]
        nxt = env.step(td)["next"]
        _close(nxt["state"][0], pz.state(), f"state at step {step}")
        info = nxt["vehicle", "info"][0]
        for key, pz_key in [
            ("gap_error_abs_m", "gap_error_m"),
            ("speed_error_abs_mps", "speed_error_mps"),
        ]:
            _close(info[key], [abs(infos[n][pz_key]) for n in names], f"{key}, step {step}")
        _close(info["collided"], [infos[n]["collided"] for n in names], f"collided, step {step}")
        if impaired:
            _close(info["cam_delivered"], [infos[n]["cam_delivered"] for n in names], "delivered")
            delivered += int(info["cam_delivered"].sum())
            v2i_mbps = float(pz.last_record.v2i_rate_bps.sum()) * 1e-6
            _close(info["v2i_throughput_mbps"], [v2i_mbps] * len(names), f"V2I, step {step}")
            # the content is at least the interval's own age: (T + 1) / 2 subframes on average
            assert (info["aoi_ms"] >= 25.5 - 1e-4).all()
        td = nxt
    assert not impaired or 0 < delivered < 6 * len(names)  # both outcomes were compared


def test_rra_state_and_infos_are_the_pettingzoo_faces():
    seed, kwargs = 9, {"episode_intervals": 2, "kappa1": 0.3}
    pz = V2XRRAEnv(seed=seed, **kwargs)
    env = VDTNTorchRLEnv(mode="rra", seed=seed, return_state=True, return_info=True, **kwargs)
    pz.reset()
    names = pz.rra_agents
    td = env.reset()
    rng = np.random.default_rng(0)
    n_act = pz.twin.params.radio.num_actions
    closings = 0
    for step in range(2 * pz.twin.subframes_per_interval):
        a = rng.integers(0, n_act, size=len(names))
        _, _, _, _, infos = pz.step({n: np.int64(a[i]) for i, n in enumerate(names)})
        td["rra", "action"] = torch.as_tensor(a, dtype=torch.long)[None]
        nxt = env.step(td)["next"]
        _close(nxt["state"][0], pz.state(), f"state at step {step}")
        info = nxt["rra", "info"][0]
        for key in ("v2i_throughput_mbps", "cam_delivered", "collided", "closes_interval"):
            _close(info[key], [infos[n][key] for n in names], f"{key}, step {step}")
        if infos[names[0]]["closes_interval"]:
            closings += 1
            record = pz.last_record
            _close(info["gap_error_abs_m"], record.gap_error_m[0].abs(), f"gap error, {step}")
        else:  # the AoI at the subframe's end: what the RRA reward 'aoi' reads
            _close(info["aoi_ms"], pz.twin.cam_age_ms()[0], f"AoI, step {step}")
        td = nxt
    assert closings == 2


def test_the_batched_face_draws_what_the_pettingzoo_face_draws():
    seed = 3
    pz = PlatoonControlEnv(
        impaired=True, seed=seed, rra_policy=FixedRRAPolicy(16), render_mode="rgb_array"
    )
    env = VDTNTorchRLEnv(mode="control_impaired", seed=seed, rra_policy=FixedRRAPolicy(16))
    pz.reset()
    td = env.reset()
    for _ in range(2):
        pz.step({n: np.array([0.5], np.float32) for n in pz.possible_agents})
        td["vehicle", "action"] = torch.full((1, 3, 1), 0.5)
        td = env.step(td)["next"]
    frame = env.render(mode="rgb_array")
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    np.testing.assert_array_equal(frame, pz.render())
    with pytest.raises(ConfigError, match="rgb_array"):
        env.render(mode="human")
    batched = VDTNTorchRLEnv(mode="rra", batch_size=3, seed=seed)
    batched.rollout(3)
    assert batched.render().shape == frame.shape  # scenario 0 of B
