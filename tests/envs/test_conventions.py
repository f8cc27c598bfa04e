"""What users of other libraries expect, for every registered face: the batched face by id with
its ``group_map``, PettingZoo's ``max_cycles`` and ``state_space``, and the Gymnasium
single-agent face (Gymnasium's env checker, and the same numbers as the PettingZoo face)."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from pettingzoo.test.state_test import test_parallel_env as pettingzoo_state_test
from torchrl.envs.utils import check_env_specs

import vdtn_marl
from vdtn_marl.envs.central import CentralControlEnv
from vdtn_marl.envs.control import PlatoonControlEnv
from vdtn_marl.errors import ConfigError

PETTINGZOO_IDS = vdtn_marl.list_envs(api="pettingzoo")
GYMNASIUM_IDS = vdtn_marl.list_envs(api="gymnasium")
BATCHED_IDS = [i for i in vdtn_marl.list_envs() if vdtn_marl.spec(i).vector_entry_point]


def steps_are_intervals(env_id: str) -> bool:
    """Whether one step of ``env_id`` is one control interval (no agent acts every subframe)."""
    return all(period > 1 for period in vdtn_marl.spec(env_id).clocks.values())


def test_the_registry_has_faces_of_every_kind():
    assert GYMNASIUM_IDS and BATCHED_IDS
    assert any(steps_are_intervals(i) for i in PETTINGZOO_IDS)
    assert not all(steps_are_intervals(i) for i in PETTINGZOO_IDS)


# --- the batched face by id ------------------------------------------------------------------
@pytest.mark.parametrize("env_id", BATCHED_IDS)
@pytest.mark.parametrize("scenario, num_vehicles", [("platoon", 4), ("two_platoons", 8)])
def test_batched_face_by_id_has_the_pettingzoo_agents_in_its_group_map(
    env_id, scenario, num_vehicles
):
    kwargs = dict(seed=0, episode_intervals=2, scenario=scenario, num_vehicles=num_vehicles)
    batched = vdtn_marl.make(env_id, batch_size=3, **kwargs)
    check_env_specs(batched, seed=0)
    agents = vdtn_marl.make(env_id, **kwargs).possible_agents
    groups = batched.group_map
    assert [a for group in groups.values() for a in group] == agents
    for group, names in groups.items():
        assert batched.full_action_spec[group].shape == (3, len(names))
        assert all(name.startswith(f"{group}_") for name in names)


# --- max_cycles --------------------------------------------------------------------------------
def _pettingzoo_steps(env) -> int:
    env.reset(seed=1)
    for agent in env.possible_agents:
        env.action_space(agent).seed(1)
    steps = 0
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
        steps += 1
    return steps


@pytest.mark.parametrize("env_id", [i for i in PETTINGZOO_IDS if steps_are_intervals(i)])
def test_max_cycles_is_the_episode_length_where_a_step_is_an_interval(env_id):
    assert _pettingzoo_steps(vdtn_marl.make(env_id, seed=0, max_cycles=3)) == 3
    batched = vdtn_marl.make(env_id, batch_size=2, seed=0, max_cycles=3)
    rollout = batched.rollout(10, break_when_any_done=True)
    assert rollout.batch_size[-1] == 3
    assert rollout["next", "truncated"][:, -1].all()


@pytest.mark.parametrize("env_id", GYMNASIUM_IDS)
def test_max_cycles_is_the_episode_length_of_the_gymnasium_face(env_id):
    env = vdtn_marl.make(env_id, seed=0, max_cycles=4)
    env.reset(seed=0)
    env.action_space.seed(0)
    for step in range(1, 5):
        *_, terminated, truncated, _ = env.step(env.action_space.sample())
        assert (terminated, truncated) == (False, step == 4)


@pytest.mark.parametrize("env_id", [i for i in PETTINGZOO_IDS if not steps_are_intervals(i)])
@pytest.mark.parametrize("batched", [False, True])
def test_max_cycles_is_refused_where_a_step_is_a_subframe(env_id, batched):
    kwargs = {"batch_size": 2} if batched else {}
    with pytest.raises(ConfigError, match="max_cycles=5.*episode_intervals"):
        vdtn_marl.make(env_id, max_cycles=5, **kwargs)


def test_max_cycles_and_a_different_episode_intervals_are_refused():
    with pytest.raises(ConfigError, match="max_cycles=5 and episode_intervals=6"):
        vdtn_marl.make("vdtn/platoon-control-v0", max_cycles=5, episode_intervals=6)


# --- state_space -------------------------------------------------------------------------------
@pytest.mark.parametrize("env_id", PETTINGZOO_IDS)
def test_state_stays_in_state_space(env_id):
    env = vdtn_marl.make(env_id, seed=0, episode_intervals=3)
    pettingzoo_state_test(env, seed=0)  # PettingZoo's own check, at reset
    n = env.twin.params.platoon.num_vehicles
    assert env.state_space.shape == (3 * n,)
    rng = np.random.default_rng(0)
    for agent in env.possible_agents:
        env.action_space(agent).seed(int(rng.integers(100)))
    while env.agents:
        env.step({a: env.action_space(a).sample() for a in env.agents})
        state = env.state()
        assert env.state_space.contains(state), state
    assert np.all(np.diff(state[:n]) < 0)  # positions: the leader ahead, each follower behind


# --- the Gymnasium single-agent face -----------------------------------------------------------
@pytest.mark.parametrize("env_id", GYMNASIUM_IDS)
def test_gymnasium_face_passes_gymnasiums_env_checker(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gymnasium.make(f"vdtn_marl.envs.central:{env_id}", max_cycles=6, render_mode="rgb_array")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the advice to rescale the actions to [-1, 1]
        check_env(env.unwrapped)
    frame = env.unwrapped.render()
    assert frame.ndim == 3 and frame.shape[2] == 3


@pytest.mark.parametrize("env_id", GYMNASIUM_IDS)
def test_gymnasium_face_is_the_pettingzoo_face_seen_by_one_agent(env_id):
    central = vdtn_marl.make(env_id, seed=5, max_cycles=5)
    assert isinstance(central, CentralControlEnv)
    multi = PlatoonControlEnv(**vdtn_marl.spec(env_id).kwargs, seed=5, max_cycles=5)
    obs, _ = central.reset(seed=5)
    multi_obs, _ = multi.reset(seed=5)
    names = multi.possible_agents
    np.testing.assert_array_equal(obs, np.concatenate([multi_obs[a] for a in names]))
    assert central.action_space.shape == (len(names),)
    rng = np.random.default_rng(0)
    done = False
    while not done:
        action = rng.uniform(-2.0, 2.0, len(names)).astype(np.float32)
        obs, reward, terminated, truncated, info = central.step(action)
        multi_obs, rewards, *_ = multi.step({a: action[i : i + 1] for i, a in enumerate(names)})
        np.testing.assert_array_equal(obs, np.concatenate([multi_obs[a] for a in names]))
        assert reward == pytest.approx(sum(rewards.values()), abs=1e-12)
        assert info["rewards"] == rewards
        done = terminated or truncated


@pytest.mark.parametrize(
    "action, fragment",
    [(np.zeros(2, np.float32), "must be 3 commands"), ("fast", "must be 3 commands")],
)
def test_gymnasium_face_refuses_an_action_of_the_wrong_shape(action, fragment):
    env = vdtn_marl.make(GYMNASIUM_IDS[0], seed=0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=fragment):
        env.step(action)


def test_gymnasium_face_refuses_a_command_out_of_range():
    env = vdtn_marl.make(GYMNASIUM_IDS[0], seed=0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="vehicle_2 = nan"):
        env.step(np.array([0.0, np.nan, 0.0], np.float32))


def test_every_gymnasium_id_is_registered_with_gymnasium_too():
    import vdtn_marl.envs.central as central

    assert central.register_with_gymnasium() == GYMNASIUM_IDS
    for env_id in GYMNASIUM_IDS:
        assert gymnasium.spec(env_id).kwargs == vdtn_marl.spec(env_id).kwargs


MAKE_EVERY_GYMNASIUM_ID = """
import sys
{imports}
import gymnasium
ids = vdtn_marl.list_envs(api="gymnasium")
for env_id in ids:
    env = gymnasium.make(env_id, max_cycles=2)  # the plain id, no "module:" before it
    env.reset(seed=0)
    env.step(env.action_space.sample())
    assert type(env.unwrapped).__name__ == "CentralControlEnv", env_id
    assert env.spec.kwargs == {{**vdtn_marl.spec(env_id).kwargs, "max_cycles": 2}}, env_id
print(",".join(ids))
"""


@pytest.mark.parametrize(
    "imports",
    [
        "import vdtn_marl\nassert 'gymnasium' not in sys.modules  # not imported for this",
        "import gymnasium\nimport vdtn_marl",
    ],
    ids=["vdtn_marl-first", "gymnasium-first"],
)
def test_gymnasium_makes_every_gymnasium_id_after_import_vdtn_marl(imports, tmp_path):
    code = MAKE_EVERY_GYMNASIUM_ID.format(imports=imports)
    done = subprocess.run(
        [sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, cwd=tmp_path
    )  # a fresh interpreter: nothing registered by this one; -W error: not a warning either
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().split(",") == GYMNASIUM_IDS


def test_a_gymnasium_id_registered_later_reaches_gymnasium():
    from vdtn_marl.envs import registration

    env_id = "test-plugin/platoon-control-central-v0"
    entry_point = "vdtn_marl.envs.central:CentralControlEnv"
    try:
        vdtn_marl.register(env_id, entry_point, api="gymnasium", impaired=True)
        assert gymnasium.spec(env_id).kwargs == {"impaired": True}
        vdtn_marl.register(env_id, entry_point, api="gymnasium", override=True, impaired=False)
        assert gymnasium.spec(env_id).kwargs == {"impaired": False}
    finally:
        registration._REGISTRY.pop(env_id, None)
        gymnasium.registry.pop(env_id, None)
