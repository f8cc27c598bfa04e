"""Every registered scenario, from the registry (never a hand-written list of names): it has a
YAML, builds, steps on every face, wires its links, CAMs and IVoI by its own topology, and keeps
the physics' invariants."""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch
from pettingzoo.test import parallel_api_test
from torchrl.envs.utils import check_env_specs

import vdtn_marl
from vdtn_marl.envs.torchrl import MODES, VDTNTorchRLEnv
from vdtn_marl.errors import ConfigError
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.scenarios import SCENARIOS, get_scenario, scenario_params
from vdtn_marl.sim.layout import VEHICLE_OBS_FEATURES
from vdtn_marl.sim.platoon import PlatoonState
from vdtn_marl.sim.twin import DigitalTwin

NAMES = sorted(SCENARIOS)
ENV_IDS = [env_id for env_id in vdtn_marl.list_envs(api="pettingzoo") if env_id.startswith("vdtn/")]
CONF = Path(vdtn_marl.__file__).parent / "conf" / "scenario"
CAM_AGE = VEHICLE_OBS_FEATURES.index("cam_age_ms")
CAM_DELAY = VEHICLE_OBS_FEATURES.index("cam_delay_ms")
CAM_ACCEL = VEHICLE_OBS_FEATURES.index("cam_pred_accel_mps2")


@functools.cache
def scenario_configs() -> dict:
    """Every ``conf/scenario/*.yaml``, composed and validated: file stem → RunConfig."""
    from vdtn_marl.experiment.compose import (
        compose_config,
        hydra_compose,
        job_config,
        to_run_config,
    )

    with hydra_compose():
        return {
            path.stem: to_run_config(
                job_config(compose_config("config", [f"scenario={path.stem}"]))
            )
            for path in sorted(CONF.glob("*.yaml"))
        }


@functools.cache
def model_kwargs(name: str) -> dict:
    """``scenario=`` and the model keywords of the first YAML of scenario ``name``."""
    for cfg in scenario_configs().values():
        if cfg.scenario.kind == name:
            return cfg.scenario.model_kwargs()
    raise AssertionError(f"no conf/scenario/*.yaml has kind: {name}")


def test_every_scenario_has_a_yaml_and_every_yaml_a_scenario():
    kinds = {cfg.scenario.kind for cfg in scenario_configs().values()}
    assert kinds == set(SCENARIOS)


@pytest.mark.parametrize("name", NAMES)
def test_links_agents_and_names_follow_the_topology(name):
    scenario = get_scenario(name)
    topology = scenario_params(**model_kwargs(name)).platoon.topology
    assert topology.link_rx == topology.followers
    for tx, rx in zip(topology.link_tx, topology.link_rx, strict=True):
        assert tx == topology.predecessor[rx] and tx != -1
    vehicles, rras = scenario.vehicle_agents(topology), scenario.rra_agents(topology)
    assert len(vehicles) == len(set(vehicles)) == topology.num_followers
    assert len(rras) == len(set(rras)) == topology.num_links
    # rra agent of link l serves (and is paid the IVoI of) vehicle agent l
    assert [r.removeprefix("rra_") for r in rras] == [v.removeprefix("vehicle_") for v in vehicles]


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("name", NAMES)
def test_parallel_api_on_every_face(name, env_id):
    env = vdtn_marl.make(env_id, seed=0, **model_kwargs(name))
    topology = env.twin.topology
    assert env.scenario.name == name and env.twin.num_followers == topology.num_followers
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parallel_api_test(env, num_cycles=300)


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("name", NAMES)
def test_torchrl_specs_on_every_mode(name, mode):
    env = VDTNTorchRLEnv(
        mode, batch_size=3, seed=1, **{**model_kwargs(name), "episode_intervals": 3}
    )
    check_env_specs(env)
    topology = env.twin.topology
    for group, rows in (("vehicle", topology.num_followers), ("rra", topology.num_links)):
        if group in env.full_action_spec.keys():
            assert env.full_action_spec[group, "action"].shape[1] == rows


@pytest.mark.parametrize("name", NAMES)
def test_a_delivered_cam_reaches_only_its_recipient(name):
    params = scenario_params(**{**model_kwargs(name), "cam_size_bits": 1})
    topology, radio = params.platoon.topology, params.radio
    off, full_power = radio.num_power_levels - 1, 0  # sub-channel 0, last level (off) / 23 dBm
    t, interval_ms = params.platoon.subframes_per_interval, params.platoon.control_interval_s * 1e3
    cacc = CACCController(params.platoon)
    for link in range(topology.num_links):
        twin = DigitalTwin(params, seed=link)
        for k in range(3):  # two intervals with every link silent, then only `link` sends
            actions = torch.full((1, topology.num_links), off)
            if k == 2:
                actions[0, link] = full_power
            for _ in range(t):
                twin.step_subframe(actions)
            obs = twin.vehicle_observation(perfect=False)
            if k < 2:
                twin.finish_interval(cacc(obs), perfect=False)
                twin.begin_interval()
        age_ms = obs[0, :, CAM_AGE].tolist()
        stale = 3 * interval_ms  # nothing received since the reset before interval 0
        assert age_ms == [0.0 if f == link else stale for f in range(topology.num_links)]
        assert 0 < float(obs[0, link, CAM_DELAY]) < t  # it arrived within the interval
        sender = topology.link_tx[link]
        torch.testing.assert_close(obs[0, link, CAM_ACCEL], twin.platoon.accel_mps2[0, sender])
        delay = twin.finish_interval(cacc(obs), perfect=False).cam_delay_subframes[0]
        assert [d <= t for d in delay.tolist()] == [f == link for f in range(topology.num_links)]


class _VehicleIdIVoI:
    """ξ of follower row f = its vehicle id (so a payment shows whose IVoI it is)."""

    def __init__(self, followers):
        self.ids = torch.tensor(followers, dtype=torch.float32)

    def __call__(self, twin, record):
        return self.ids.to(record.reward.device).expand(twin.batch_size, -1)


@pytest.mark.parametrize("name", NAMES)
def test_ivoi_of_each_follower_is_paid_to_its_links_rra_agent(name):
    kw = {**model_kwargs(name), "kappa1": 0.0, "kappa2": 1.0, "ivoi_scale": 1.0}
    topology = scenario_params(**model_kwargs(name)).platoon.topology
    estimator = _VehicleIdIVoI(topology.followers)
    env = vdtn_marl.make("vdtn/v2x-rra-v1", seed=0, ivoi_estimator=estimator, **kw)
    env.reset(seed=0)
    for _ in range(env.twin.subframes_per_interval):
        _, rewards, _, _, infos = env.step({a: 0 for a in env.agents})
    paid = {a: (infos[a]["ivoi"], rewards[a]) for a in env.agents}
    assert paid == {f"rra_{v}": (float(v), float(v)) for v in topology.followers}

    torchrl_env = VDTNTorchRLEnv("rra", batch_size=2, seed=0, ivoi_estimator=estimator, **kw)
    td = torchrl_env.reset()
    for _ in range(torchrl_env.twin.subframes_per_interval):
        td["rra", "action"] = torch.zeros(2, topology.num_links, dtype=torch.long)
        td = torchrl_env.step(td)
        reward = td["next", "rra", "reward"]
        td = td["next"]
    assert reward[:, :, 0].tolist() == [list(map(float, topology.followers))] * 2


@pytest.mark.parametrize("name", NAMES)
def test_followers_track_their_own_predecessor_and_leaders_their_traces(name):
    params = scenario_params(**model_kwargs(name))
    pp, topology = params.platoon, params.platoon.topology
    twin = DigitalTwin(params, batch_size=4, seed=2, radio=False)
    cacc, gen = CACCController(pp), torch.Generator().manual_seed(0)
    for k in range(8):
        noise = 0.3 * torch.randn(4, topology.num_followers, generator=gen)
        record = twin.finish_interval(cacc(twin.vehicle_observation(True)) + noise, perfect=True)
        twin.begin_interval()
        after = record.state_after
        for f, (tx, rx) in enumerate(zip(topology.link_tx, topology.link_rx, strict=True)):
            gap = after.position_m[:, tx] - after.position_m[:, rx] - pp.vehicle_length_m
            desired = pp.standstill_gap_m + pp.time_headway_s * after.speed_mps[:, rx]
            torch.testing.assert_close(record.gap_error_m[:, f], gap - desired)
            speed_error = after.speed_mps[:, tx] - after.speed_mps[:, rx]
            torch.testing.assert_close(record.speed_error_mps[:, f], speed_error)
        for j, leader in enumerate(topology.leaders):
            trace = twin.leader_speed_mps[:, j, k + 1]
            torch.testing.assert_close(after.speed_mps[:, leader], trace, atol=1e-3, rtol=0)
    if topology.num_leaders > 1:  # each leader drives its own trace window
        assert not torch.equal(twin.leader_speed_mps[:, 0], twin.leader_speed_mps[:, 1])


@pytest.mark.parametrize("row", ["first", "last"])
@pytest.mark.parametrize("name", NAMES)
def test_a_collision_of_any_follower_ends_the_scenario(name, row):
    env = vdtn_marl.make("vdtn/platoon-control-v0", seed=0, **model_kwargs(name))
    env.reset(seed=0)
    topology = env.twin.topology
    f = 0 if row == "first" else topology.num_followers - 1
    rx, tx = topology.link_rx[f], topology.link_tx[f]
    state = env.twin.platoon
    position = state.position_m.clone()
    position[0, rx] = position[0, tx] - 1.0  # 3 m inside its predecessor
    env.twin.platoon = PlatoonState(position, state.speed_mps, state.accel_mps2, state.command_mps2)
    actions = {a: np.zeros(1, np.float32) for a in env.agents}
    _, rewards, terminations, _, infos = env.step(actions)
    assert all(terminations.values()) and env.agents == []
    crashed = f"vehicle_{rx}"
    assert [a for a in infos if infos[a]["collided"]] == [crashed]
    assert rewards[crashed] <= env.twin.params.platoon.collision_penalty


@pytest.mark.parametrize("name", NAMES)
def test_numpy_and_torch_backends_agree(name):
    params = scenario_params(**model_kwargs(name))
    twins = [DigitalTwin(params, seed=4, backend=b) for b in ("numpy", "torch")]
    gen = torch.Generator().manual_seed(1)
    cacc = CACCController(params.platoon)
    for _ in range(3):
        actions = torch.randint(0, params.radio.num_actions, (1, twins[0].num_links), generator=gen)
        records = []
        for twin in twins:
            for _ in range(twin.subframes_per_interval):
                twin.step_subframe(actions.numpy() if twin.backend == "numpy" else actions)
            obs = twin.vehicle_observation(perfect=False)
            records.append((obs, twin.finish_interval(cacc(obs), perfect=False)))
            twin.begin_interval()
        (obs_np, rec_np), (obs_t, rec_t) = records
        torch.testing.assert_close(obs_np, obs_t, rtol=1e-6, atol=1e-6)
        torch.testing.assert_close(rec_np.reward, rec_t.reward, rtol=1e-6, atol=1e-6)
        assert torch.equal(rec_np.cam_delay_subframes, rec_t.cam_delay_subframes)


def test_an_unknown_scenario_is_one_clear_error():
    allowed = ", ".join(SCENARIOS)
    with pytest.raises(ConfigError, match=f"scenario='nowhere' is not a registered .*{allowed}"):
        vdtn_marl.make("vdtn/platoon-control-v0", scenario="nowhere")
    with pytest.raises(ConfigError, match="scenario='nowhere'"):
        VDTNTorchRLEnv("control", scenario="nowhere")
    from dataclasses import replace

    from vdtn_marl.experiment.config import RunConfig, validate

    cfg = RunConfig()
    with pytest.raises(ConfigError, match=f"scenario.kind='nowhere' .* {allowed}"):
        validate(replace(cfg, scenario=replace(cfg.scenario, kind="nowhere")))


@pytest.mark.parametrize("name", NAMES)
def test_the_oracles_model_every_topology_as_the_twin_moves_it(name):
    from vdtn_marl.policies.exact_oracle import ExactOracleController
    from vdtn_marl.policies.mpc_oracle import OracleController
    from vdtn_marl.sim.platoon import control_reward, gaps_m, spacing_errors

    intervals = 20
    kw = {**model_kwargs(name), "episode_intervals": intervals, "traces": "synthetic"}
    params = scenario_params(**kw)
    pp, f = params.platoon, params.platoon.num_followers
    # the exact oracle's plan, replayed, earns what its linear program predicted
    twin = DigitalTwin(params, batch_size=2, seed=11, radio=False)
    oracle = ExactOracleController(tail_intervals=0)
    predicted = [oracle.solve(twin, b).planned_cost for b in range(2)]
    bound, earned = oracle.bind(twin), torch.zeros(2, dtype=torch.float64)
    for _ in range(intervals):
        record = twin.finish_interval(bound(twin.vehicle_observation(True)), perfect=True)
        twin.begin_interval()
        earned += record.reward.double().sum(-1)
        assert not bool(record.collided.any())
    # to the solver's tolerance (about 1e-4 of cost here, 0.5 % of an episode of 20 intervals)
    np.testing.assert_allclose(-earned.numpy(), predicted, rtol=1e-3, atol=2e-4)
    assert min(predicted) > 0.01
    # the MPC oracle's planned return of a command plan is the twin's own
    twin = DigitalTwin(params, batch_size=3, seed=5, radio=False)
    gen = torch.Generator().manual_seed(0)
    plan = torch.rand(3, 10, f, generator=gen) * 2.0 - 1.0
    state, expected = twin.platoon, torch.zeros(3)
    follower = pp.topology.followers_of
    for k in range(10):
        leader = twin.leader_accel_mps2(twin.interval + k)  # [B, Λ]
        after = twin.integrator.integrate(state, leader, plan[:, k], torch.zeros(3, f).long())
        gap_error, speed_error = spacing_errors(after, pp)
        reward = control_reward(
            gap_error, speed_error, follower(after.command_mps2), follower(state.command_mps2), pp
        )
        reward = reward + (gaps_m(after.position_m, pp) <= 0).float() * pp.collision_penalty
        expected, state = expected + reward.sum(-1), after
    got = OracleController(horizon_intervals=10).planned_return(twin, plan)
    torch.testing.assert_close(got, expected, atol=1e-3, rtol=1e-4)
