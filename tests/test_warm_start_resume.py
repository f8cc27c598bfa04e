"""An interrupt during π*'s warm start (its imitation of the causal MPC, minutes of a default
run) keeps the rounds done: the checkpoint written after each round's rollouts and fit holds
them, and the resumed run goes on bit for bit as the uninterrupted one
(vdtn_marl.algos.imitation.distill_teacher, JointOptimisation._warm_start_pi_star)."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from vdtn_marl.algos import imitation
from vdtn_marl.algos.checkpoint import load_checkpoint
from vdtn_marl.io.interrupts import _Interrupt

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)

# A small warm start: per round, 4 intervals of rollouts and 2 ticks of fitting.
SMALL = {"scenarios": 2, "intervals": 4, "fit_steps": 200}
INTERRUPT_AT_TICK = 9  # in the rollouts of round 1 (ticks 7 to 10)


def _small_distillation(monkeypatch, interrupt_at: int | None) -> None:
    ticks = []

    def distill(*args, progress=None, **kwargs):
        def tick(n):
            ticks.append(n)
            if len(ticks) == interrupt_at:  # as a Ctrl-C or SIGTERM there would
                _Interrupt.requested = True
            progress(n)

        return imitation.distill_teacher(*args, progress=tick, **{**kwargs, **SMALL})

    monkeypatch.setattr("vdtn_marl.experiment.jocc.distill_teacher", distill)


@pytest.fixture
def cfg():
    from vdtn_marl.experiment.config import (
        AlgoConfig,
        ControlConfig,
        ExperimentConfig,
        RunConfig,
        ScenarioConfig,
    )

    return RunConfig(
        scenario=ScenarioConfig(episode_intervals=40),
        control=ControlConfig(warm_start="causal_mpc"),
        algo=AlgoConfig(num_envs=2, rollout_steps=8, rra_num_envs=2, rra_rollout_steps=16,
                        minibatch_size=16, epochs=1),
        experiment=ExperimentConfig(control_iterations=1, rra_iterations=1, eval_episodes=2,
                                    eval_intervals=5, checkpoint_every=0),
        progress=False,
    )  # fmt: skip


def test_an_interrupted_warm_start_keeps_its_rounds_and_resumes_bit_for_bit(
    cfg, tmp_path, monkeypatch
):
    from vdtn_marl.experiment.jocc import JointOptimisation

    _small_distillation(monkeypatch, interrupt_at=INTERRUPT_AT_TICK)
    with pytest.raises(KeyboardInterrupt):
        JointOptimisation(cfg, tmp_path / "cut").run()
    saved = load_checkpoint(tmp_path / "cut" / "checkpoints" / "last.pt")
    partial = saved["position"]["warm_start_partial"]
    assert (partial["round"], partial["fitted"]) == (0, True)  # round 0 is kept

    _small_distillation(monkeypatch, interrupt_at=None)
    resumed = JointOptimisation(dataclasses.replace(cfg, resume=True), tmp_path / "cut").run()
    torch.manual_seed(1234)  # the fresh run sets its own seeds
    whole = JointOptimisation(cfg, tmp_path / "whole").run()
    assert resumed["warm_start"]["rounds"] == whole["warm_start"]["rounds"] == 3
    assert resumed["warm_start"]["rms_error_mps2"] == whole["warm_start"]["rms_error_mps2"]
    assert resumed["control_cost"] == whole["control_cost"]
    ends = [load_checkpoint(tmp_path / r / "checkpoints" / "last.pt") for r in ("cut", "whole")]
    assert "warm_start_partial" not in ends[0]["position"]
    for name, tensor in ends[1]["trainers"]["pi_star"]["actor"].items():
        assert torch.equal(ends[0]["trainers"]["pi_star"]["actor"][name], tensor), name
