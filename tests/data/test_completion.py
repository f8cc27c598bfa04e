"""Data completion and prediction (docs/model.md §4.7), trace sets by name in the registry."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torchrl.envs.utils import check_env_specs

import vdtn_marl
from vdtn_marl.algos.completion import train_completion_predictor
from vdtn_marl.data import TraceInfo, trace_set_provenance, trace_source_names
from vdtn_marl.envs.torchrl import MODES as TORCHRL_MODES
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.sim import DigitalTwin, TwinParams
from vdtn_marl.sim.completion import (
    CAM_ACCEL,
    CAM_AGE,
    CAM_COMMAND,
    COMPLETION_MODES,
    CompletionPredictor,
    HoldCompletion,
    KalmanCompletion,
    LearnedCompletion,
    NoCompletion,
    load_completion_predictor,
    make_completion,
    save_completion_predictor,
)
from vdtn_marl.sim.params import ConfigError

PZ_ENVS = tuple(
    env_id for env_id in vdtn_marl.list_envs(api="pettingzoo") if env_id.startswith("vdtn/")
)
"""Every built-in id, from the registry."""
SHORT = {"episode_intervals": 3, "subframes_per_interval": 5}


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A small predictor trained on a few short rollouts, and its file."""
    params = TwinParams.from_overrides(episode_intervals=40)
    predictor = train_completion_predictor(params, seed=0, batch_size=4, epochs=4)
    path = tmp_path_factory.mktemp("completion") / "predictor.pt"
    save_completion_predictor(predictor, path)
    return predictor, path


def completion_kwargs(mode: str, path) -> dict:
    return {"completion": mode} | ({"completion_predictor": str(path)} if mode == "learned" else {})


def _pz_rollout(env_id: str, **kwargs) -> list[dict]:
    """A full short episode with fixed random actions; the vehicle observations at each step."""
    env = vdtn_marl.make(env_id, seed=0, **SHORT, **kwargs)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    seen = [obs]
    while env.agents:
        actions = {}
        for agent in env.agents:
            space = env.action_space(agent)
            if agent.startswith("vehicle_"):
                actions[agent] = rng.uniform(-1.0, 1.0, size=(1,)).astype(np.float32)
            else:
                actions[agent] = np.int64(rng.integers(space.n))
        obs, rewards, _, _, _ = env.step(actions)
        assert all(np.isfinite(r) for r in rewards.values())
        for agent, value in obs.items():
            assert env.observation_space(agent).contains(value), (agent, value)
        seen.append(obs)
    return [{a: v for a, v in o.items() if a.startswith("vehicle_")} for o in seen]


# ------------------------------------------------------------------ every env, every mode
@pytest.mark.parametrize("env_id", PZ_ENVS)
def test_every_mode_runs_in_pettingzoo_envs(env_id, trained):
    baseline = _pz_rollout(env_id)
    runs = {m: _pz_rollout(env_id, **completion_kwargs(m, trained[1])) for m in COMPLETION_MODES}
    # 'none' is today's behaviour bit for bit; 'hold' gives the same numbers (docs §4.7)
    for mode in ("none", "hold"):
        for a, b in zip(runs[mode], baseline, strict=True):
            assert a.keys() == b.keys()
            for agent in a:
                np.testing.assert_array_equal(a[agent], b[agent])
    for mode in ("kalman", "learned"):
        changed = False
        for a, b in zip(runs[mode], baseline, strict=True):
            for agent in a:
                keep = [i for i in range(8) if i not in (CAM_ACCEL, CAM_COMMAND)]
                np.testing.assert_array_equal(a[agent][keep], b[agent][keep])
                if b[agent][CAM_AGE] == 0:  # fresh CAM content is left as it is
                    np.testing.assert_array_equal(a[agent], b[agent])
                changed |= not np.array_equal(a[agent], b[agent])
        spec = vdtn_marl.spec(env_id)
        impaired = spec.kwargs.get("impaired", True)
        if impaired and "vehicle" in spec.clocks:  # vehicle agents with impaired observations
            assert changed, f"{mode} never completed a stale observation in {env_id}"
        if not impaired:  # perfect observation: a no-op
            assert not changed


@pytest.mark.parametrize("mode", TORCHRL_MODES)
def test_every_completion_mode_runs_in_the_torchrl_face(mode, trained):
    def rollout(**kwargs):
        env = VDTNTorchRLEnv(mode=mode, batch_size=4, seed=0, **SHORT, **kwargs)
        with torch.random.fork_rng():
            torch.manual_seed(0)
            return env, env.rollout(12, break_when_any_done=False)

    _, baseline = rollout()
    for completion in COMPLETION_MODES:
        env, out = rollout(**completion_kwargs(completion, trained[1]))
        for key, spec in env.full_observation_spec.items(True, True):
            values = out["next", key]
            assert all(spec.is_in(values[:, i]) for i in range(values.shape[1])), key
        reward_keys = [k for k in out["next"].keys(True, True) if k[-1] == "reward"]
        assert reward_keys and all(torch.isfinite(out["next"][k]).all() for k in reward_keys)
        if completion in ("none", "hold"):  # bit-identical to an env without the keyword
            for key in baseline["next"].keys(True, True):
                assert torch.equal(out["next"][key], baseline["next"][key]), key


@pytest.mark.parametrize(
    ("mode", "completion"), [("joint", "kalman"), ("control_impaired", "learned")]
)
def test_torchrl_specs_with_completion(mode, completion, trained):
    env = VDTNTorchRLEnv(
        mode=mode, batch_size=3, seed=2, **SHORT, **completion_kwargs(completion, trained[1])
    )
    check_env_specs(env)


def test_torchrl_partial_reset_resets_the_completer_by_mask():
    env = VDTNTorchRLEnv(
        mode="control_impaired", batch_size=4, seed=0, completion="kalman", episode_intervals=50
    )
    td = env.reset()
    for _ in range(3):
        td["vehicle", "action"] = torch.full((4, 3, 1), 0.3)
        td = env.step(td)["next"]
    before_obs = td["vehicle", "observation"].clone()
    before = {k: v.clone() for k, v in env.completion._state.items()}
    mask = torch.tensor([True, False, True, False])
    td = td.clone()
    td["_reset"] = mask[:, None]
    td = env.reset(td)
    state = env.completion._state
    assert state["interval"].tolist() == [0, 3, 0, 3]
    for key in before:  # the other scenarios' filters and observations are untouched
        torch.testing.assert_close(state[key][~mask], before[key][~mask], rtol=0, atol=0)
    torch.testing.assert_close(
        td["vehicle", "observation"][~mask], before_obs[~mask], rtol=0, atol=0
    )
    fresh = KalmanCompletion()  # the reset ones start from scratch
    expected = fresh.complete(env.twin.vehicle_observation(perfect=False), env.twin.interval)
    torch.testing.assert_close(td["vehicle", "observation"][mask], expected[mask])
    torch.testing.assert_close(state["x"][mask], fresh._state["x"][mask])


# ------------------------------------------------------------------ the predictors
class BrakingTraces:
    """Cruise at 25 m/s, brake hard (−2.5 m/s²) for 3 s at a random time, cruise again."""

    info = TraceInfo("braking", "cruise, hard braking, cruise", True, "generated (tests)")

    def sample(self, num_traces, num_points, dt_s, generator):
        t = torch.arange(num_points, device=generator.device) * dt_s
        onset = 1.0 + 2.0 * torch.rand(num_traces, 1, generator=generator, device=generator.device)
        braking = (t >= onset) & (t < onset + 3.0)
        accel = torch.where(braking, -2.5, 0.0)
        speed = 25.0 + dt_s * torch.cumsum(accel, dim=1)
        return torch.cat([torch.full_like(speed[:, :1], 25.0), speed[:, :-1]], dim=1)


def _prediction_rmse(completers: dict, batch=12, intervals=120, seed=0) -> dict:
    """RMSE of the predecessor's acceleration over stale decisions, same twin rollout for all."""
    params = TwinParams.from_overrides(episode_intervals=intervals)
    twin = DigitalTwin(params, batch_size=batch, seed=seed, trace_source=BrakingTraces())
    rra = RandomRRAPolicy(params.radio.num_actions, seed)
    controller = CACCController(params.platoon)
    sq = dict.fromkeys(completers, 0.0)
    stale_count = 0
    for _ in range(intervals):
        for _ in range(twin.subframes_per_interval):
            twin.step_subframe(rra(twin.rra_observation()), validated=True)
        obs = twin.vehicle_observation(perfect=False)
        stale = obs[..., CAM_AGE] > 0
        stale_count += int(stale.sum())
        truth = twin.cam_snapshot[..., 0]
        for name, completer in completers.items():
            done = completer.complete(obs, twin.interval)
            sq[name] += float(((done[..., CAM_ACCEL] - truth)[stale] ** 2).sum())
        twin.finish_interval(controller(obs), perfect=False)
        twin.begin_interval()
    assert stale_count > 100
    return {name: (value / stale_count) ** 0.5 for name, value in sq.items()}


def test_kalman_beats_hold_on_a_braking_trace(trained):
    rmse = _prediction_rmse(
        {
            "hold": HoldCompletion(),
            "kalman": KalmanCompletion(),
            "learned": LearnedCompletion(trained[0]),
        }
    )
    assert rmse["hold"] > 0.5, rmse  # the braking makes stale content wrong
    assert rmse["kalman"] < 0.2 * rmse["hold"], rmse
    assert rmse["learned"] < rmse["hold"], rmse


def _random_observations(b=5, f=3, seed=0, age_ms=100.0):
    gen = torch.Generator().manual_seed(seed)
    obs = torch.randn(b, f, 8, generator=gen)
    obs[..., 5] = 50.0
    obs[..., CAM_AGE] = age_ms
    return obs


def test_repeated_calls_in_an_interval_do_not_advance_twice():
    seq = [_random_observations(seed=s) for s in range(4)]
    once, twice = KalmanCompletion(), KalmanCompletion()
    for k, obs in enumerate(seq):
        expected = once.complete(obs, torch.full((5,), k))
        twice.complete(seq[0] * 0.5, torch.full((5,), k))  # a provisional observation ...
        got = twice.complete(obs, torch.full((5,), k))  # ... replaced by the final one
        torch.testing.assert_close(got, expected, rtol=0, atol=0)
    # interval=None counts intervals itself
    auto = KalmanCompletion()
    outs = [auto.complete(obs) for obs in seq]
    torch.testing.assert_close(outs[-1], expected, rtol=0, atol=0)


def test_reset_and_complete_masks_act_per_scenario():
    seq = [_random_observations(seed=s) for s in range(3)]
    mask = torch.tensor([True, False, True, False, False])
    a = KalmanCompletion()
    for k, obs in enumerate(seq):
        a.complete(obs, torch.full((5,), k))
    before = {key: v.clone() for key, v in a._state.items()}
    a.reset(mask)
    fresh = KalmanCompletion()
    ref = fresh.complete(seq[0], torch.zeros(5, dtype=torch.long))
    got = a.complete(seq[0], torch.where(mask, 0, 3))
    torch.testing.assert_close(got[mask], ref[mask])
    # complete(mask=...) leaves the other scenarios' observations and states alone
    b = KalmanCompletion()
    b.complete(seq[0], torch.zeros(5, dtype=torch.long))
    out = b.complete(seq[1], torch.ones(5, dtype=torch.long), mask=mask)
    torch.testing.assert_close(out[~mask], seq[1][~mask], rtol=0, atol=0)
    assert (b._state["interval"][~mask] == 0).all() and (b._state["interval"][mask] == 1).all()
    assert before["interval"].tolist() == [2] * 5


def test_only_stale_cam_content_changes():
    obs = _random_observations(age_ms=0.0)
    obs[1, 2, CAM_AGE] = 150.0
    done = KalmanCompletion().complete(obs)
    changed = (done != obs).any(-1)
    assert changed.nonzero().tolist() == [[1, 2]]
    assert torch.equal(done[1, 2, CAM_AGE], obs[1, 2, CAM_AGE])
    assert NoCompletion().complete(obs) is obs
    assert torch.equal(HoldCompletion().complete(obs), obs)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_kalman_and_learned_run_on_cuda(trained):
    seq = [_random_observations(seed=s) for s in range(3)]
    for make in (KalmanCompletion, lambda: LearnedCompletion(trained[0])):
        cpu, gpu = make(), make()
        for k, obs in enumerate(seq):
            a = cpu.complete(obs, torch.full((5,), k))
            b = gpu.complete(obs.cuda(), torch.full((5,), k, device="cuda"))
            assert b.device.type == "cuda"
            torch.testing.assert_close(b.cpu(), a, atol=1e-4, rtol=1e-4)


# ------------------------------------------------------------------ learned: train, save, load
def test_learned_predictor_trains_saves_and_loads(trained, tmp_path):
    predictor, path = trained
    info = predictor.training_info
    assert info["stale_rows"] > 0 and np.isfinite(info["train_rmse_accel_mps2"])
    loaded = load_completion_predictor(path)
    x = torch.randn(7, predictor.num_inputs)
    torch.testing.assert_close(loaded(x), predictor(x))
    copy = save_completion_predictor(loaded, tmp_path / "copy.pt")
    obs = [_random_observations(seed=s) for s in range(3)]
    a, b = LearnedCompletion(predictor), LearnedCompletion(str(copy))
    for o in obs:
        torch.testing.assert_close(a.complete(o), b.complete(o))


def test_bad_checkpoint_files_raise_clearly(tmp_path, trained):
    missing = tmp_path / "missing.pt"
    with pytest.raises(ConfigError, match="does not exist"):
        load_completion_predictor(missing)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"this is not a checkpoint")
    with pytest.raises(ConfigError, match="garbage.pt.*could not be read"):
        load_completion_predictor(garbage)
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(ConfigError, match="other.pt.*is not a"):
        load_completion_predictor(other)
    unsafe = tmp_path / "unsafe.pt"
    torch.save({"format": CompletionPredictor}, unsafe)  # a class: refused by weights_only
    with pytest.raises(ConfigError, match="unsafe.pt.*could not be read"):
        load_completion_predictor(unsafe)
    wrong = tmp_path / "wrong.pt"
    payload = torch.load(trained[1], weights_only=True)
    payload["config"]["window"] += 1
    torch.save(payload, wrong)
    with pytest.raises(ConfigError, match="wrong.pt.*does not fit"):
        load_completion_predictor(wrong)
    with pytest.raises(ConfigError, match="garbage.pt"):
        vdtn_marl.make(
            "vdtn/platoon-control-impaired-v1", completion="learned", completion_predictor=garbage
        )


def test_learned_predictor_needs_a_matching_control_interval(trained):
    with pytest.raises(ConfigError, match="control_interval_s"):
        vdtn_marl.make(
            "vdtn/platoon-control-impaired-v1",
            completion="learned",
            completion_predictor=trained[0],
            control_interval_s=0.1,
        )


# ------------------------------------------------------------------ argument checks
@pytest.mark.parametrize("env_id", PZ_ENVS)
def test_bad_completion_values_raise(env_id):
    with pytest.raises(ConfigError) as info:
        vdtn_marl.make(env_id, completion="kalmann", **SHORT)
    msg = str(info.value)
    assert "'kalmann'" in msg and all(repr(m) in msg for m in COMPLETION_MODES)
    with pytest.raises(ConfigError, match="completion=3"):
        vdtn_marl.make(env_id, completion=3, **SHORT)
    with pytest.raises(ConfigError, match="needs a predictor"):
        vdtn_marl.make(env_id, completion="learned", **SHORT)
    with pytest.raises(ConfigError, match="only used with completion='learned'"):
        vdtn_marl.make(env_id, completion="kalman", completion_predictor="x.pt", **SHORT)


def test_bad_completion_values_raise_in_the_torchrl_face():
    with pytest.raises(ConfigError, match="'Kalman'"):
        VDTNTorchRLEnv(mode="joint", completion="Kalman")
    with pytest.raises(ConfigError, match="completion=None|neither"):
        VDTNTorchRLEnv(mode="rra", completion=object())


def test_a_completer_object_is_used_as_given():
    class Zero:
        def reset(self, mask=None):
            pass

        def complete(self, observation, interval=None, mask=None):
            out = observation.clone()
            out[..., CAM_ACCEL] = 0.0
            return out

    assert isinstance(make_completion(Zero()), Zero)
    env = VDTNTorchRLEnv(mode="control_impaired", batch_size=2, seed=0, completion=Zero(), **SHORT)
    assert (env.reset()["vehicle", "observation"][..., CAM_ACCEL] == 0).all()


# ------------------------------------------------------------------ trace sets by name
@pytest.mark.parametrize("name", trace_source_names())
def test_trace_sets_by_name_in_env_kwargs(name):
    env = vdtn_marl.make("vdtn/platoon-control-v0", traces=name, seed=0, **SHORT)
    assert env.twin.trace_source.info.name == name
    env.reset(seed=0)
    face = VDTNTorchRLEnv(mode="control", batch_size=2, traces=name, **SHORT)
    assert face.twin.trace_source.info.name == name


def test_unknown_trace_set_names_fail_clearly():
    with pytest.raises(ValueError) as info:
        vdtn_marl.make("vdtn/platoon-control-v0", traces="ngsim-i80")
    assert "'ngsim-i80'" in str(info.value)
    for name in trace_source_names():
        assert name in str(info.value)


def test_registry_lists_trace_set_provenance():
    listed = vdtn_marl.spec("vdtn/platoon-control-v0").data_sources
    assert set(listed) == set(trace_source_names()) == set(trace_set_provenance())
    assert listed["synthetic"]["synthetic"] is True
    for entry in listed.values():
        assert entry["source"] and entry["license"] and isinstance(entry["synthetic"], bool)
    for env_id in PZ_ENVS:
        s = vdtn_marl.spec(env_id)
        assert s.uses_traces and "traces" in s.data_source and s.data_sources == listed
