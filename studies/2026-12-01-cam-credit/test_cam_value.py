"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-01-cam-credit/test_cam_value.py``."""

import importlib.util
import json
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RunConfig,
    ScenarioConfig,
)
from vdtn_marl.experiment.jocc import JointOptimisation

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


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    run_dir = tmp_path_factory.mktemp("jocc")
    cfg = RunConfig(
        # synthetic traces: every one of a few random-RRA episodes delivers some CAMs
        scenario=ScenarioConfig(episode_intervals=20, traces="synthetic"),
        algo=TINY_ALGO,
        experiment=TINY_EXPERIMENT,
        control=ControlConfig(warm_start="none"),
        progress=False,
    )
    JointOptimisation(replace(cfg, seed=3), run_dir).run()
    return run_dir / "checkpoints" / "last.pt"


def test_cam_value_pairs_twins_that_differ_only_by_the_dropped_cam(checkpoint, tmp_path):
    """The one-step credit is computed in one copy, as an environment would; the td credit
    from the two paired copies. With one interval of horizon the value is the platoon's reward
    difference in the interval of the drop, and the credits agree closely (they differ only in
    what the other followers do in the one-step branches)."""
    script = _load("cam_value")
    out = tmp_path / "value.json"
    args = ["--episodes", "8", "--starts", "4,9", "--horizon", "1", "--no-progress"]
    assert script.main([str(checkpoint), *args, "--output", str(out)]) == 0
    data = json.loads(out.read_text())
    assert out.with_suffix(".png").read_bytes().startswith(b"\x89PNG")
    result = data["runs"][0]["result"]
    assert data["horizon"] == 1 and result["rra"] == "random"
    assert 0 < result["cams"] <= 16  # at most one dropped CAM per scenario and start
    assert result["value"]["n"] == result["td_credit"]["n"] == result["cams"]
    delivery = result["delivery"]
    assert 0 < delivery["in_time"] < 1 and 0 <= delivery["after_miss"] <= 1
    assert 0 <= delivery["after_in_time"] <= 1
    assert result["td_credit"]["mean"] == pytest.approx(
        result["one_step_credit"]["mean"], abs=0.05 + 0.2 * abs(result["td_credit"]["mean"])
    )
    # the credit entry: with one interval of horizon Δξ is the td credit alone
    credit = result["credit"]
    assert credit["full_value"]["mean"] == pytest.approx(result["td_credit"]["mean"])
    assert credit["full_value"]["n"] == result["cams"]
    assert len(credit["delta_xi_mean_by_j"]) == 1
    assert 1 <= credit["transmitting_subframes"]["mean"] <= 49  # delivered by subframe T−2
    assert [row["name"] for row in credit["settings"]] == [
        "legacy", "paper", "paper_long_gae", "legacy_lambda1", "paper_lambda1",
    ]  # fmt: skip
    for row in credit["settings"]:
        assert row["credit"]["mean"] == pytest.approx(row["credit_from_j0"]["mean"])
        assert row["credit"]["n"] == result["cams"]
    assert 0 <= result["cams_no_collision"] <= result["cams"]
    assert result["credit_no_collision"]["full_value"]["n"] == result["cams_no_collision"]
    for bad, message in (
        (["--starts", "19", "--horizon", "5"], "must lie in"),
        (["--rra", "best"], "is not one of"),
        (["--episodes", "1"], "must be >= 2"),
    ):
        with pytest.raises(SystemExit, match=message):
            script.main([str(checkpoint), *bad, "--output", str(tmp_path / "x.json")])
    assert not (tmp_path / "x.json").exists()


def test_delivery_persistence_counts_consecutive_pairs_of_running_scenarios():
    persistence = _load("cam_value").delivery_persistence
    # one scenario, one link: in, in, out, in, out (and a dead scenario that must not count)
    in_time = torch.tensor([[1, 1], [1, 1], [0, 1], [1, 1], [0, 1]], dtype=torch.bool)[..., None]
    alive = torch.tensor([[True, False]] * 5)
    result = persistence(in_time, alive)
    assert result["in_time"] == pytest.approx(3 / 5)
    assert result["after_in_time"] == pytest.approx(1 / 3)  # in→in once, in→out twice
    assert result["after_miss"] == pytest.approx(1.0)  # out→in once


def test_cam_credit_gae_weights_per_subframe_and_per_interval():
    script = _load("cam_value")
    subframe, interval, paper = script.parse_credits("legacy, paper_long_gae,paper")
    assert (subframe.gamma_scale, subframe.lmbda_scale) == ("subframe", "subframe")
    assert (interval.gamma_scale, interval.lmbda_scale) == ("interval", "interval")
    assert (paper.gamma_scale, paper.lmbda_scale) == ("interval", "subframe")
    assert script.parse_credits("0.99:interval:0.95:interval")[0].per_subframe(50) == (
        interval.per_subframe(50)
    )
    per_subframe = script.gae_weights(subframe, 50, 3)  # [T, H]
    per_interval = script.gae_weights(interval, 50, 3)
    assert per_subframe.shape == per_interval.shape == (50, 3)
    # ξ of interval k is paid at t = T−1: 49 subframes after the interval's first action
    assert float(per_subframe[0, 0]) == pytest.approx((0.99 * 0.95) ** 49)
    assert float(per_subframe[0, 0]) == pytest.approx(0.0495, abs=5e-5)
    assert float(per_subframe[49, 0]) == 1.0
    assert float(per_subframe[49, 1]) == pytest.approx((0.99 * 0.95) ** 50)
    assert float(per_interval[0, 0]) == pytest.approx((0.99 * 0.95) ** (49 / 50))
    assert float(per_interval[49, 1]) == pytest.approx(0.99 * 0.95)  # γλ per interval
    assert float(per_interval[0, 2]) == pytest.approx((0.99 * 0.95) ** (2 + 49 / 50))
    assert interval.per_subframe(50) == pytest.approx((0.99**0.02, 0.95**0.02))
    assert paper.per_subframe(50) == pytest.approx((0.99**0.02, 0.95))
    assert float(script.gae_weights(paper, 50, 1)[0, 0]) == pytest.approx((0.99**0.02 * 0.95) ** 49)
    # a Δξ only at j = 0: the credit is the mean over the transmitting subframes of w(t, 0)·Δξ
    transmitting = torch.zeros(2, 50, dtype=torch.bool)
    transmitting[0, :5] = True
    transmitting[1, :30] = True
    delta_xi = torch.tensor([[0.2, 0.0, 0.0], [-0.1, 0.0, 0.0]], dtype=torch.float64)
    for weights in (per_subframe, per_interval):
        credit = script.credit_to_carriers(weights, transmitting, delta_xi)
        expected = [0.2 * float(weights[:5, 0].mean()), -0.1 * float(weights[:30, 0].mean())]
        assert credit.tolist() == pytest.approx(expected)
    later = torch.tensor([[0.0, 1.0, 0.0]], dtype=torch.float64)
    only_first = torch.zeros(1, 50, dtype=torch.bool)
    only_first[0, 0] = True  # sent in subframe 0: the ξ of interval k+1 is 99 subframes away
    assert float(script.credit_to_carriers(per_subframe, only_first, later)[0]) == pytest.approx(
        (0.99 * 0.95) ** 99
    )
    full = script.discounted_sum(torch.ones(1, 3, dtype=torch.float64), 0.99)
    assert float(full[0]) == pytest.approx(1 + 0.99 + 0.99**2)
    share = script.ratio_of_means(torch.tensor([1.0, 2.0, 3.0]), torch.tensor([2.0, 4.0, 6.0]))
    assert share["ratio"] == pytest.approx(0.5) and share["n"] == 3
    assert share["low"] == pytest.approx(0.5) and share["high"] == pytest.approx(0.5)
    summary = script.credit_summary(delta_xi, transmitting, [subframe, interval], 0.99, 50)
    assert summary["full_value_share_j0"]["ratio"] == pytest.approx(1.0)
    assert summary["full_value_share_later"]["ratio"] == pytest.approx(0.0, abs=1e-12)
    for row in summary["settings"]:
        assert row["credit"]["mean"] == pytest.approx(row["credit_from_j0"]["mean"])
    survived = torch.tensor([True, False])
    runs = [(delta_xi, transmitting, survived, 0.99, 50)] * 2
    pooled = script.pooled_credit(
        [*runs[:1], (delta_xi[:1], transmitting[:1], survived[:1], 0.99, 50)], [subframe]
    )
    assert pooled["runs"] == 2 and pooled["cams"] == 3 and pooled["cams_no_collision"] == 2
    assert pooled["credit"]["full_value"]["mean"] == pytest.approx((0.2 - 0.1 + 0.2) / 3)
    assert pooled["credit_no_collision"]["full_value"]["mean"] == pytest.approx(0.2)
    assert script.pooled_credit(runs[:1], [subframe]) is None
    assert script.pooled_credit([runs[0], (*runs[0][:4], 10)], [subframe]) is None
    bad_specs = ("bogus", "0.99:minute:0.95:subframe", "0.99:subframe", "1.5:interval:1:interval")
    for bad in (*bad_specs, "x:subframe:1:subframe"):
        with pytest.raises(SystemExit, match="GAMMA:SCALE:LAMBDA:SCALE"):
            script.parse_credits(bad)
