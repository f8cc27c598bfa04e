"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-06-sharded-collection/test_sharded_collection.py``."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


sharded = _script("sharded_collection.py")


class _FakeTrainer:
    """A trainer whose timed iterations take the seconds scripted for it, round by round."""

    def __init__(self, seconds):
        self.seconds = list(seconds)
        self.scaling_fitted = False
        self.warmed = 0

    def fit_observation_scaling(self):
        self.scaling_fitted = True

    def train_iteration(self):
        self.warmed += 1


def test_sharded_collection_pairs_the_arms_within_a_round_and_estimates(monkeypatch):
    # arm → per-round seconds: round 2 is slow for every arm; paired ratios stay 2.0 and 1.6
    scripts = {
        "one": [4.0, 8.0, 4.0],
        "sharded": [2.0, 4.0, 2.0],
        "sharded_threads": [2.5, 5.0, 2.5],
    }
    trainers = {arm: _FakeTrainer(s) for arm, s in scripts.items()}
    order = []
    monkeypatch.setattr(
        sharded.stage_throughput, "stage_trainer", lambda loop, stage: trainers[loop]
    )

    def timed(trainer):
        arm = next(a for a, t in trainers.items() if t is trainer)
        order.append(arm)
        s = trainer.seconds.pop(0)
        return {"seconds": s, "collect_s": s - 0.5, "update_s": 0.5, "intervals": 100}

    monkeypatch.setattr(sharded.stage_throughput, "timed_iteration", timed)
    loops = {arm: arm for arm in sharded.ARMS}
    row = sharded.measure_stage(loops, "pi_tilde_learned", 3)
    assert all(t.scaling_fitted and t.warmed == 1 for t in trainers.values())
    assert order[:3] == ["one", "sharded", "sharded_threads"]
    assert order[3:6] == ["sharded", "sharded_threads", "one"]  # the order rotates
    assert row["one_over_sharded"] == pytest.approx(2.0)
    assert row["one_over_sharded_threads"] == pytest.approx(1.6)
    assert row["collect_one_over_sharded"] == pytest.approx(3.5 / 1.5)
    assert row["one_s"] == 4.0 and row["sharded_s"] == 2.0
    rows = [
        {"stage": "pi_star", "one_s": 1.0, "sharded_s": 0.9, "sharded_threads_s": 0.8},
        {"stage": "pi_tilde_random", "one_s": 3.0, "sharded_s": 2.0, "sharded_threads_s": 1.5},
        row,
        {"stage": "rra", "one_s": 2.0},
    ]
    budgets = {"control_iterations": 500, "rra_iterations": 300}
    est = sharded.estimate(rows, budgets)
    assert est["one"]["later_min"] == pytest.approx((500 * 1.0 + 500 * 4.0 + 300 * 2.0) / 60)
    assert est["sharded_threads"]["first_min"] == pytest.approx(
        (500 * 0.8 + 500 * 1.5 + 300 * 2.0) / 60
    )
    assert sharded.estimate(rows[:3], budgets) is None  # the RRA stage missing: no estimate


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--stages", "pi_star,warp"], "--stages"),
        (["--workers", "0"], "--workers"),
        (["--pairs", "0"], "--pairs"),
    ],
)
def test_sharded_collection_refuses_bad_arguments(argv, flag, capsys):
    with pytest.raises(SystemExit) as refused:
        sharded.parse_args(argv)
    assert flag in capsys.readouterr().err + str(refused.value.code)
