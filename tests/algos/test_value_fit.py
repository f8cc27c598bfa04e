"""rra.value_fit=acting: the td estimator's v* fitted on the acting system's states."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch
from test_training import TINY_ALGO, TINY_EXPERIMENT, tiny_config  # the tiny run of its tests

from vdtn_marl.algos.ppo import CriticValue, PPOTrainer
from vdtn_marl.algos.value_fit import fit_critic
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.experiment.config import ConfigError, RRAConfig, validate
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.platoon import perfect_observation
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi import bootstrapped_return, discounted_rollout


def _critic():
    trainer = PPOTrainer(VDTNTorchRLEnv("control", batch_size=4, seed=0), "vehicle", TINY_ALGO)
    return trainer.critic


def test_fit_critic_learns_a_target_it_could_not_predict():
    """Targets that are a fixed function of the observation: the MSE falls on the fitted
    scenarios and on the held-out ones."""
    torch.manual_seed(0)
    critic = _critic()
    scaler = critic.module[0]  # the critic's own standardisation: targets on its scale
    kept = torch.nonzero(scaler.keep).flatten()
    a, b = int(kept[0]), int(kept[-1])
    z = torch.randn(4000, 3, 8) * scaler.keep
    observations = scaler.center + z / scaler.scale.where(scaler.keep > 0, torch.ones(()))
    targets = 2.0 * z[..., a] - z[..., b] + 0.5
    scenarios = torch.arange(4000) // 40
    before, after, held_before, held_after = fit_critic(
        critic, "vehicle", observations, targets, scenarios, epochs=15, seed=0
    )
    assert after < 0.2 * before and held_after < 0.2 * held_before, (before, after)
    with torch.no_grad():
        fitted = CriticValue(critic, "vehicle")(observations[:10])
    assert torch.allclose(fitted, targets[:10], atol=1.0)


def test_the_bootstrapped_return_is_the_rollout_plus_the_discounted_tail_value():
    params = TwinParams.from_overrides(episode_intervals=40)
    twin = DigitalTwin(params, batch_size=3, seed=0, radio=False, backend="torch")
    twin.reset(seed=0)
    from vdtn_marl.policies.cacc import CACCController

    cacc = CACCController(params.platoon)
    state, interval = twin.platoon, torch.zeros(3, dtype=torch.long)
    plain, final = discounted_rollout(twin, state, interval, cacc, 7, 0.9)
    assert torch.allclose(bootstrapped_return(twin, state, interval, cacc, 7, 0.9), plain)
    value = lambda obs: obs[..., 0] * 0.0 + 2.0  # noqa: E731 - a constant v
    both = bootstrapped_return(twin, state, interval, cacc, 7, 0.9, value)
    assert torch.allclose(both, plain + 0.9**7 * 2.0)
    assert perfect_observation(final, params.platoon).shape[-1] == 8


@pytest.mark.slow
def test_a_jocc_run_with_value_fit_fits_a_copy_and_the_estimator_reads_it(tmp_path):
    cfg = tiny_config(
        rra=RRAConfig(value_fit="acting", value_fit_horizon=5),
        experiment=replace(TINY_EXPERIMENT, control_iterations=1, rra_iterations=1),
    )
    loop = JointOptimisation(cfg, tmp_path)
    summary = loop.run()
    (fit,) = summary["value_fit"]
    assert fit["jocc_iteration"] == 0 and fit["samples"] > 0
    assert fit["mse_after"] < fit["mse_before"]
    star = [p.detach().clone() for p in loop.pi_star.critic.parameters()]
    fitted = [p.detach().clone() for p in loop.v_fit.parameters()]
    assert any(not torch.equal(a, b) for a, b in zip(star, fitted, strict=True))
    estimator = loop.ivoi_estimator("td")
    assert isinstance(estimator.value, CriticValue) and estimator.value.critic is loop.v_fit
    # the checkpoint holds the fitted copy: a loop built from it values states the same way
    again = JointOptimisation.from_checkpoint(tmp_path / "checkpoints" / "last.pt", tmp_path)
    for a, b in zip(fitted, again.v_fit.parameters(), strict=True):
        assert torch.equal(a, b)
    # without value_fit nothing is fitted and the estimator reads π*'s critic
    plain = JointOptimisation(tiny_config(), tmp_path / "plain")
    assert plain.v_fit is None
    assert plain.ivoi_estimator("td").value.critic is plain.pi_star.critic


@pytest.mark.parametrize(
    "rra, key",
    [
        (RRAConfig(value_fit="bogus"), "rra.value_fit='bogus'"),
        (RRAConfig(value_fit="acting", ivoi_estimator="rollout"), "rra.value_fit='acting'"),
        (RRAConfig(value_fit="acting", value_fit_horizon=0), "rra.value_fit_horizon=0"),
    ],
)
def test_bad_value_fit_settings_name_the_key(rra, key):
    with pytest.raises(ConfigError, match=key):
        validate(tiny_config(rra=rra))
