"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-01-rra-positive-control/test_ivoi_noise.py``."""

import importlib.util
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from vdtn_marl.experiment.config import (
    AlgoConfig,
    ExperimentConfig,
    RRAConfig,
    ScenarioConfig,
)

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _load(name: str):
    return _script(f"{name}.py")


TINY_ALGO = AlgoConfig(
    num_envs=4, rollout_steps=10, rra_num_envs=4, rra_rollout_steps=50, minibatch_size=64, epochs=1
)


TINY_EXPERIMENT = ExperimentConfig(
    control_iterations=1, rra_iterations=1, eval_episodes=2, eval_intervals=20, checkpoint_every=0
)


def test_synthetic_ivoi_pays_delivered_cams_plus_seeded_noise():
    noise_module = _load("ivoi_noise")
    twin = SimpleNamespace(subframes_per_interval=50)
    record = SimpleNamespace(cam_delay_subframes=torch.tensor([[3, 50, 51], [51, 12, 99]]))
    exact = noise_module.SyntheticIVoI(effect=0.5, noise=0.0, seed=0)
    assert exact(twin, record).tolist() == [[0.5, 0.5, 0.0], [0.0, 0.5, 0.0]]
    noisy = [noise_module.SyntheticIVoI(0.5, 0.1, seed=4)(twin, record) for _ in range(2)]
    torch.testing.assert_close(noisy[0], noisy[1])  # seeded
    assert not torch.equal(noisy[0], exact(twin, record))
    with pytest.raises(ValueError, match="noise=-1"):
        noise_module.SyntheticIVoI(0.5, -1, seed=0)


def test_rra_training_reads_the_synthetic_ivoi():
    noise_module = _load("ivoi_noise")
    cfg = replace(
        noise_module.reduced_config(seed=2),
        scenario=ScenarioConfig(episode_intervals=20),
        algo=TINY_ALGO,
        experiment=TINY_EXPERIMENT,
    )
    summary = noise_module.train_with_synthetic_ivoi(cfg, effect=0.035, noise=0.1)
    # the RRA environment asked the synthetic IVoI, not the td estimator, for ξ
    assert summary["synthetic_ivoi_calls"] >= 1
    assert 0.0 <= summary["cam_delivery_rate"] <= 1.0
    with pytest.raises(ValueError, match="κ2 > 0"):
        noise_module.train_with_synthetic_ivoi(replace(cfg, rra=RRAConfig(kappa1=1.0)), 0.035, 0.1)
    with pytest.raises(SystemExit, match="--kappa1 1.0 must be in"):
        noise_module.main(["--kappa1", "1"])
