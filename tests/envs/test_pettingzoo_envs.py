"""The registered PettingZoo environments: API contract, seeding, clocks, VoI flow, bad input."""

import math
import warnings

import numpy as np
import pytest
import torch
from pettingzoo.test import parallel_api_test, parallel_seed_test

import vdtn_marl
from vdtn_marl.envs import PlatoonControlEnv, TwoTimescaleEnv
from vdtn_marl.sim.params import ConfigError
from vdtn_marl.voi import RolloutIVoIEstimator

ENV_IDS = [env_id for env_id in vdtn_marl.list_envs(api="pettingzoo") if env_id.startswith("vdtn/")]
"""Every built-in PettingZoo id, from the registry (tests/test_registry.py pins the list)."""
T = 50


def test_all_builtin_envs_registered():
    assert len(ENV_IDS) == 4, ENV_IDS


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_parallel_api(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parallel_api_test(vdtn_marl.make(env_id, seed=0), num_cycles=1000)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_parallel_seed(env_id):
    parallel_seed_test(lambda: vdtn_marl.make(env_id), num_cycles=100)


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("return_state", [False, True])
def test_pettingzoo_wrapper_check_env_specs(env_id, return_state):
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    face = vdtn_marl.make(env_id, seed=0, episode_intervals=3)
    env = PettingZooWrapper(face, use_mask=True, return_state=return_state)
    check_env_specs(env, seed=0)
    if return_state:  # read from the face's state_space; the state of all N vehicles
        n = face.twin.params.platoon.num_vehicles
        assert env.observation_spec["state"].shape == (3 * n,)
        assert env.reset(seed=0)["state"].shape == (3 * n,)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_observations_stay_inside_their_spaces(env_id):
    env = vdtn_marl.make(env_id, seed=3, episode_intervals=4)
    obs, _ = env.reset(seed=3)
    for agent in env.agents:
        env.action_space(agent).seed(1)
    while env.agents:
        for agent, o in obs.items():
            assert env.observation_space(agent).contains(o), (agent, o)
        obs, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})


def _random_actions(env, rng, include_vehicles):
    actions = {a: int(rng.integers(16)) for a in env.rra_agents}
    if include_vehicles:
        actions |= {a: rng.uniform(-2.6, 2.6, 1).astype(np.float32) for a in env.vehicle_agents}
    return actions


def test_joint_env_clocks_and_acts_flags():
    env = TwoTimescaleEnv(seed=0)
    assert [env.clock_period(a) for a in env.possible_agents] == [T] * 3 + [1] * 3
    obs, infos = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for step in range(3 * T):
        t = step % T
        assert all(infos[a]["acts"] for a in env.rra_agents)
        assert all(infos[a]["acts"] == (t == T - 1) for a in env.vehicle_agents)
        before = {a: obs[a].copy() for a in env.vehicle_agents}
        obs, rewards, *_, infos = env.step(_random_actions(env, rng, include_vehicles=t == T - 1))
        changed = any(not np.array_equal(before[a], obs[a]) for a in env.vehicle_agents)
        if t != T - 2:
            assert not changed, f"vehicle observation changed off its tick at t={t}"
        if t != T - 1:
            assert all(rewards[a] == 0.0 for a in env.vehicle_agents)
    assert env.agents == env.possible_agents  # everyone stays listed


def test_off_tick_vehicle_actions_change_nothing():
    def run(off_tick_vehicle_actions):
        env = TwoTimescaleEnv(seed=5)
        env.reset(seed=5)
        rng, garbage = np.random.default_rng(1), np.random.default_rng(2)
        out = []
        for step in range(2 * T):
            actions = _random_actions(env, rng, include_vehicles=step % T == T - 1)
            if off_tick_vehicle_actions and step % T != T - 1:
                actions |= {
                    a: garbage.uniform(-2.6, 2.6, 1).astype(np.float32) for a in env.vehicle_agents
                }
            obs, rewards, *_ = env.step(actions)
            out.append((obs, rewards))
        return out

    for (obs_a, rew_a), (obs_b, rew_b) in zip(run(False), run(True), strict=True):
        assert rew_a == rew_b
        assert all(np.array_equal(obs_a[k], obs_b[k]) for k in obs_a)


def test_kappa2_ivoi_term_only_at_last_subframe_and_equals_infos():
    kappa1, s_g, s_xi = 0.3, 0.004, 20.0
    env = TwoTimescaleEnv(seed=2, kappa1=kappa1, throughput_scale=s_g, ivoi_scale=s_xi)
    env.reset(seed=2)
    rng = np.random.default_rng(4)
    nonzero = 0
    for step in range(3 * T):
        t = step % T
        # vehicles brake hard at their tick: a deviation from CACC that has a real cost
        actions = _random_actions(env, rng, include_vehicles=False)
        if t == T - 1:
            actions |= {a: np.array([-2.6], np.float32) for a in env.vehicle_agents}
        _, rewards, *_, infos = env.step(actions)
        for agent in env.rra_agents:
            extra = rewards[agent] - kappa1 * s_g * infos[agent]["v2i_throughput_mbps"]
            xi = infos[agent]["ivoi"]
            assert infos[agent]["closes_interval"] == (t == T - 1)
            if t == T - 1:
                assert extra == pytest.approx((1 - kappa1) * s_xi * xi, abs=1e-5)
                nonzero += xi != 0.0
            else:
                assert xi == 0.0 and extra == pytest.approx(0.0, abs=1e-6)
    assert nonzero > 0


def test_cam_lost_ivoi_pays_only_for_cams_that_arrived_in_time():
    """With the cam_lost baseline the V2X RRA env's ξ_i is 0 whenever follower i's CAM did not
    arrive within its interval, and not always 0 when it did."""
    estimator = RolloutIVoIEstimator(horizon_intervals=3, baseline="cam_lost")
    env = vdtn_marl.make("vdtn/v2x-rra-v1", seed=6, ivoi_estimator=estimator, kappa1=0.0)
    env.reset(seed=6)
    # even intervals: every link at 23 dBm on a sub-channel whose V2I user is two vehicles from
    # its receiver (most CAMs arrive); odd intervals: every link silent (every CAM is lost)
    levels = env.twin.params.radio.num_power_levels
    sending = {"rra_1": 3 * levels, "rra_2": 0, "rra_3": 1 * levels}
    paid = unpaid = 0
    for step in range(8 * T):
        silent = (step // T) % 2 == 1
        actions = {a: levels - 1 if silent else sending[a] for a in env.rra_agents}
        _, _, terminated, _, infos = env.step(actions)
        for agent in env.possible_agents:
            if infos[agent]["closes_interval"]:
                if infos[agent]["cam_delivered"]:
                    paid += infos[agent]["ivoi"] != 0.0
                else:
                    assert infos[agent]["ivoi"] == 0.0
                    unpaid += 1
        assert not any(terminated.values())
    assert paid > 0 and unpaid > 0
    with pytest.raises(ConfigError, match="cam_lost baseline"):
        TwoTimescaleEnv(seed=6, ivoi_estimator=estimator)


def test_rollout_ivoi_is_zero_for_the_reference_action_and_negative_for_a_bad_one():
    env = PlatoonControlEnv(seed=0)
    env.reset(seed=0)
    twin = env.twin
    estimator = RolloutIVoIEstimator(horizon_intervals=20)
    from vdtn_marl.policies.cacc import CACCController

    reference = CACCController(twin.params.platoon)(twin.vehicle_observation(perfect=True))
    record = twin.finish_interval(reference, perfect=True)
    assert torch.allclose(estimator(twin, record), torch.zeros(1, 3), atol=1e-6)
    twin.begin_interval()
    record = twin.finish_interval(torch.full((1, 3), 2.6), perfect=True)  # full throttle
    xi = estimator(twin, record)
    assert (xi < 0).all()


def test_control_env_collision_terminates_everyone():
    env = PlatoonControlEnv(seed=0, traces="constant")
    env.reset(seed=0)
    for _ in range(200):
        actions = {
            "vehicle_1": np.array([2.6], np.float32),
            "vehicle_2": np.zeros(1, np.float32),
            "vehicle_3": np.zeros(1, np.float32),
        }
        _, rewards, terminated, truncated, infos = env.step(actions)
        if any(terminated.values()):
            break
    assert all(terminated.values()) and not any(truncated.values())
    assert infos["vehicle_1"]["collided"] and rewards["vehicle_1"] < -100
    assert env.agents == []


def test_impaired_env_uses_given_rra_policy():
    calls = []

    def silent_policy(obs):
        calls.append(obs.shape)
        return np.full(obs.shape[:-1], 15)  # sub-channel 3, power off: no CAM ever arrives

    env = PlatoonControlEnv(impaired=True, rra_policy=silent_policy, seed=0)
    obs, _ = env.reset(seed=0)
    assert len(calls) == T and calls[0] == (1, 3, env.twin.rra_obs_dim)
    obs, _, _, _, infos = env.step({a: np.zeros(1, np.float32) for a in env.agents})
    assert not infos["vehicle_1"]["cam_delivered"] and infos["vehicle_1"]["cam_delay_ms"] == -1.0
    assert obs["vehicle_1"][5] == T  # command would take force only at the next interval
    assert obs["vehicle_1"][6] >= T  # CAM content is at least one interval old


@pytest.mark.parametrize(
    "action, fragment",
    [
        (np.array([np.nan], np.float32), "outside"),
        (np.array([3.0], np.float32), r"\[-2.6, 2.6\]"),
        (np.array([0.0, 1.0], np.float32), "shape"),
        ("left", r"vehicle_2 = 'left' must be one number \(m/s²\) in \[-2.6, 2.6\]"),
        ("1.5", r"vehicle_2 = '1.5' must be one number"),  # not read as 1.5 m/s²
        (None, r"vehicle_2 = None must be one number"),
        (0.5, r"vehicle_2 = 0.5 has shape \(\), expected \(1,\)"),  # as Box(1,).contains
        (np.float32(0.5), r"shape \(\), expected \(1,\)"),
    ],
)
def test_bad_vehicle_actions_raise(action, fragment):
    env = PlatoonControlEnv(seed=0)
    env.reset(seed=0)
    actions = {a: np.zeros(1, np.float32) for a in env.agents} | {"vehicle_2": action}
    with pytest.raises(ValueError, match=fragment):
        env.step(actions)


def test_bad_rra_actions_and_agent_names_raise():
    env = TwoTimescaleEnv(seed=0)
    env.reset(seed=0)
    ok = {a: 0 for a in env.rra_agents}
    with pytest.raises(ValueError, match=r"\[0, 15\]"):
        env.step(ok | {"rra_2": 16})
    with pytest.raises(ValueError, match="integer"):
        env.step(ok | {"rra_2": 1.5})
    with pytest.raises(KeyError, match="rra_9"):
        env.step(ok | {"rra_9": 0})
    with pytest.raises(KeyError, match="missing"):
        env.step({"rra_1": 0})


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"kappa1": 1.5}, "kappa1=1.5"),
        ({"kappa1": -0.1}, "kappa1=-0.1"),
        ({"kappa1": 0.5, "kappa2": 0.6}, "must equal 1"),
        ({"kappa1": 0.5, "kappa2": 1.2}, "kappa2=1.2"),
        ({"reward": "vibes"}, "reward='vibes'"),
        ({"num_vehicles": 0}, "num_vehicles=0"),
        ({"render_mode": "human"}, "render_mode='human'"),
        ({"traces": "synthetic", "trace_source": "udds"}, "both choose the leader traces"),
    ],
)
def test_bad_config_raises_naming_value(kwargs, fragment):
    with pytest.raises(ConfigError, match=fragment):
        TwoTimescaleEnv(**kwargs)


def test_unknown_agent_in_space_lookup():
    env = PlatoonControlEnv()
    with pytest.raises(KeyError, match="vehicle_7"):
        env.observation_space("vehicle_7")


def test_drra_reward_pays_progress_and_miss_penalty():
    env = TwoTimescaleEnv(seed=0, reward="drra", kappa1=0.0, miss_penalty=2.0)
    env.reset(seed=0)
    silent = {a: 15 for a in env.rra_agents}  # power off all interval: no progress, CAM lost
    for step in range(T):
        actions = silent | (
            {a: np.zeros(1, np.float32) for a in env.vehicle_agents} if step == T - 1 else {}
        )
        _, rewards, *_ = env.step(actions)
        expected = -2.0 if step == T - 1 else 0.0
        assert all(math.isclose(rewards[a], expected, abs_tol=1e-6) for a in env.rra_agents)


@pytest.mark.parametrize("kappa2, accepted", [(0.7000005, True), (0.701, False)])
def test_config_and_environment_accept_the_same_kappa_sums(kappa2, accepted):
    """κ1 + κ2 = 1 up to one shared tolerance: a pair the config accepts builds the env."""
    from dataclasses import replace

    from vdtn_marl.experiment.config import RunConfig, validate

    cfg = RunConfig()
    cfg = replace(cfg, rra=replace(cfg.rra, kappa1=0.3, kappa2=kappa2))
    if accepted:
        validate(cfg)
        TwoTimescaleEnv(kappa1=0.3, kappa2=kappa2)
    else:
        with pytest.raises(ConfigError, match="sum to 1"):
            validate(cfg)
        with pytest.raises(ConfigError, match="must equal 1"):
            TwoTimescaleEnv(kappa1=0.3, kappa2=kappa2)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_face_says_why_a_collision_ended_the_episode(env_id):
    """A follower placed 0.2 m behind its predecessor and 5 m/s faster collides in the next
    interval: the episode is terminated, and every agent's info carries ``collided``, true for
    the agents of that follower (its vehicle and the RRA agent of the link that feeds it)."""
    from dataclasses import replace

    env = vdtn_marl.make(env_id, seed=0, traces="constant")
    env.reset(seed=0)
    state = env.twin.platoon
    position, speed = state.position_m.clone(), state.speed_mps.clone()
    position[:, 1] = position[:, 0] - env.twin.params.platoon.vehicle_length_m - 0.2
    speed[:, 1] = speed[:, 0] + 5.0
    env.twin.platoon = replace(state, position_m=position, speed_mps=speed)
    terminated = {}
    for _ in range(2 * T):
        actions = {a: env.action_space(a).sample() for a in env.agents}
        _, _, terminated, truncated, infos = env.step(actions)
        if any(terminated.values()):
            break
    assert terminated and all(terminated.values()) and not any(truncated.values()), env_id
    assert all("collided" in info for info in infos.values()), infos
    for name, info in infos.items():
        assert info["collided"] == name.endswith("_1"), (name, info)
