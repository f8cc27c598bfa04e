"""``algo.update_threads``: each PPO update runs on that many torch threads and gives the
caller's back, and an update on a given thread count is reproducible by seed."""

from __future__ import annotations

import pytest
import torch

from vdtn_marl.algos.ppo import PPOTrainer
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.experiment.config import AlgoConfig


def _trainer(update_threads: int) -> PPOTrainer:
    env = VDTNTorchRLEnv("control", batch_size=8, seed=0, episode_intervals=20)
    algo = AlgoConfig(
        num_envs=8, rollout_steps=20, minibatch_size=80, epochs=2, update_threads=update_threads
    )
    return PPOTrainer(env, "vehicle", algo, seed=3)


@pytest.fixture
def one_thread():
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


@pytest.mark.parametrize("update_threads, during", [(0, 1), (1, 1), (2, 2)])
def test_the_update_runs_on_its_threads_and_restores_the_callers(
    update_threads, during, one_thread, monkeypatch
):
    trainer = _trainer(update_threads)
    seen = []
    inner = trainer._update
    monkeypatch.setattr(
        trainer, "_update", lambda data: seen.append(torch.get_num_threads()) or inner(data)
    )
    trainer.train_iteration()
    assert seen == [during]
    assert torch.get_num_threads() == 1


def test_an_update_on_two_threads_is_reproducible_by_seed(one_thread):
    weights = []
    for _ in range(2):
        torch.manual_seed(0)
        trainer = _trainer(2)
        trainer.train_iteration()
        weights.append([p.detach().clone() for p in trainer.loss.parameters()])
    assert all(torch.equal(a, b) for a, b in zip(*weights, strict=True))


def test_the_caller_gets_its_threads_back_when_the_update_fails(one_thread, monkeypatch):
    trainer = _trainer(2)

    def fail(data):
        raise RuntimeError("boom")

    monkeypatch.setattr(trainer, "_update", fail)
    with pytest.raises(RuntimeError, match="boom"):
        trainer.update(trainer.collect())
    assert torch.get_num_threads() == 1
