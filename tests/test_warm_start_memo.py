"""The memo of π*'s warm start (vdtn_marl.experiment.warm_start): a run that loads a warm start
goes on exactly as the run that computed it."""

import functools
from dataclasses import replace

import pytest
import torch

from vdtn_marl.algos import imitation
from vdtn_marl.experiment import warm_start
from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RRAConfig,
    RunConfig,
    ScenarioConfig,
)
from vdtn_marl.experiment.jocc import JointOptimisation

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)

CFG = RunConfig(
    scenario=ScenarioConfig(episode_intervals=20),
    algo=AlgoConfig(num_envs=4, rollout_steps=10, minibatch_size=20, epochs=1, rra_num_envs=2),
    experiment=ExperimentConfig(
        control_iterations=1,
        rra_iterations=1,
        checkpoint_every=0,
        eval_episodes=2,
        eval_intervals=10,
    ),
    control=ControlConfig(warm_start="causal_mpc"),
    rra=RRAConfig(name="drra"),
    seed=5,
    progress=False,
)


def small_distillation(monkeypatch):
    """The real distillation with a small budget (the memo does not care how long it takes)."""
    small = functools.partial(imitation.distill_teacher, rounds=1, scenarios=4, fit_steps=20)
    monkeypatch.setattr("vdtn_marl.experiment.jocc.distill_teacher", small)


def warm_then_one_iteration(cfg: RunConfig, run_dir) -> tuple[JointOptimisation, dict]:
    loop = JointOptimisation(cfg, run_dir, task="jocc")
    loop._warm_start_pi_star()
    rng_after_warm_start = torch.get_rng_state()
    stats = loop.pi_star.train_iteration()  # the first PPO iteration after it
    numbers = {k: v for k, v in stats.__dict__.items() if k != "seconds"}
    return loop, {"rng": rng_after_warm_start, "stats": numbers}


def same_state(a: dict, b: dict) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same_state(a[k], b[k]) for k in a)
    if isinstance(a, list | tuple):
        return len(a) == len(b) and all(same_state(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, torch.Tensor):
        return torch.equal(a, b)
    return a == b or (a != a and b != b)  # NaN == NaN here


def test_a_loaded_warm_start_continues_bit_for_bit_like_a_computed_one(tmp_path, monkeypatch):
    small_distillation(monkeypatch)
    memo = tmp_path / "memo"
    computed, after_computed = warm_then_one_iteration(CFG, tmp_path / "computed")
    stored, _ = warm_then_one_iteration(replace(CFG, warm_start_cache=str(memo)), tmp_path / "a")
    loaded, after_loaded = warm_then_one_iteration(
        replace(CFG, warm_start_cache=str(memo), rra=RRAConfig(name="jocc")), tmp_path / "b"
    )  # another method whose loop starts the warm start from the same state
    assert stored.position["warm_start"]["memo"] == "stored"
    assert loaded.position["warm_start"]["memo"] == "loaded"
    assert len(list(memo.glob("*.pt"))) == 1
    assert torch.equal(after_loaded["rng"], after_computed["rng"])
    assert same_state(after_loaded["stats"], after_computed["stats"])
    assert same_state(loaded.pi_star.state_dict(), computed.pi_star.state_dict())
    assert (
        loaded.position["warm_start"]["rms_error_mps2"]
        == (computed.position["warm_start"]["rms_error_mps2"])
    )


def test_a_warm_start_from_other_inputs_is_not_loaded(tmp_path, monkeypatch):
    small_distillation(monkeypatch)
    memo = str(tmp_path / "memo")
    first = JointOptimisation(replace(CFG, warm_start_cache=memo), tmp_path / "a", task="jocc")
    first._warm_start_pi_star()
    second = JointOptimisation(replace(CFG, warm_start_cache=memo), tmp_path / "b", task="jocc")
    torch.manual_seed(321)  # the same config, but the warm start starts from another RNG state
    second._warm_start_pi_star()
    assert [r.position["warm_start"]["memo"] for r in (first, second)] == ["stored"] * 2
    assert len(list(tmp_path.joinpath("memo").glob("*.pt"))) == 2


def test_the_memo_key_follows_every_input():
    base = dict(trainer={"w": torch.zeros(3)}, rng=torch.zeros(4, dtype=torch.uint8), seed=1)
    key = warm_start.memo_key(**base)
    assert key == warm_start.memo_key(**base)
    assert key != warm_start.memo_key(**{**base, "trainer": {"w": torch.tensor([0.0, 0.0, 1e-9])}})
    assert key != warm_start.memo_key(**{**base, "rng": torch.ones(4, dtype=torch.uint8)})
    assert key != warm_start.memo_key(**{**base, "seed": 2})
