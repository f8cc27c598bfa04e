"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-01-rra-learning-curves/test_rra_learning_curves.py``."""

import importlib.util
from pathlib import Path

import pytest

from vdtn_marl.experiment.config import (
    AlgoConfig,
)

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _load(name: str):
    return _script(f"{name}.py")


def test_rra_learning_curve_plateau_rule_on_hand_made_curves():
    curves = _load("rra_learning_curves")
    iterations = [0, 10, 20, 30, 40, 50, 60]
    # delivery rises, then stays within 2 pp of the mean of its last 3 points from it 30 on;
    # V2I is flat from the start: the budget is the later of the two, 30
    rising = {
        "cam_delivery_rate": [0.05, 0.30, 0.60, 0.79, 0.80, 0.81, 0.80],
        "v2i_throughput_mbps_per_link": [1.60] * 7,
    }
    found = curves.plateau(iterations, rising)
    assert found["plateaued"] and found["budget_iterations"] == 30
    assert found["stable_points"] == 4
    assert found["metrics"]["v2i_throughput_mbps_per_link"]["stable_from_iteration"] == 0
    assert found["metrics"]["cam_delivery_rate"]["tolerance"] == pytest.approx(0.02)
    assert found["metrics"]["cam_delivery_rate"]["reference"] == pytest.approx(2.41 / 3)
    # still climbing at the end: only the reference window is near its own mean
    climbing = {**rising, "cam_delivery_rate": [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]}
    assert not curves.plateau(iterations, climbing)["plateaued"]
    assert curves.plateau(iterations, climbing)["budget_iterations"] is None
    # a wider tolerance: 0.4 is within 0.25 of the last points' 0.6, 0.3 is not
    tolerances = {"cam_delivery_rate": 0.25, "v2i_throughput_mbps_per_link": 0.02}
    wide = curves.plateau(iterations, climbing, tolerances)
    assert wide["metrics"]["cam_delivery_rate"]["tolerance"] == pytest.approx(0.25)
    assert wide["plateaued"] and wide["budget_iterations"] == 30
    # V2I stepping up 3 points before the end: a stretch of the window alone is no plateau
    late = {**rising, "v2i_throughput_mbps_per_link": [1.5] * 4 + [1.6] * 3}
    assert (
        curves.plateau(iterations, late)["metrics"]["v2i_throughput_mbps_per_link"]["stable_points"]
        == 3
    )
    assert not curves.plateau(iterations, late)["plateaued"]
    # a late excursion restarts the stable stretch
    assert curves.stable_from([1.0, 1.0, 1.0, 2.0, 1.0, 1.0, 1.0], 0.05) == 4
    with pytest.raises(ValueError, match="at least window=3 points"):
        curves.stable_from([1.0, 1.0], 0.1)
    ci = curves.interval([1.0, 2.0, 3.0])
    assert ci["mean"] == 2.0 and ci["n"] == 3
    assert ci["high"] - 2.0 == pytest.approx(4.302653 / 3**0.5, rel=1e-6)  # t(0.975, 2)·s/√n


def test_rra_learning_curve_arguments_fail_in_one_line():
    curves = _load("rra_learning_curves")
    for argv, message in (
        (["--methods", "jocc_k050,bogus"], "--methods 'jocc_k050,bogus' must list some of"),
        (["--credits", "paper,nope"], "--credits 'paper,nope' must list some of paper, legacy"),
        (["--seeds", "0,0"], "--seeds '0,0' must name at least one seed, each once"),
        (["--eval-every", "0"], "--eval-every 0 must be >= 1"),
        (["--eval-intervals", "201"], "--eval-intervals 201 exceeds the episode"),
        (["--report-only"], "--report-only needs at least one --merge file"),
    ):
        with pytest.raises(SystemExit, match=message) as err:
            curves.main(argv)
        assert "\n" not in str(err.value.code)
    cfg = curves.run_config("drra", "legacy", seed=4, warm_start=False)
    assert cfg.rra.name == "drra" and cfg.seed == 4 and cfg.control.warm_start == "none"
    assert cfg.algo.rra_credit == "subframe" and cfg.algo.rra_num_envs == 64
    assert curves.run_config("jocc_k050", "paper", seed=0).algo == AlgoConfig()
