"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-01-jocc-v1-diagnosis/test_ivoi_signal.py``."""

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


def test_measures_every_rra_policy_and_estimator(checkpoint, tmp_path):
    out = tmp_path / "signal.json"
    args = [str(checkpoint), "--episodes", "3", "--rra", "learned,greedy,random"]
    assert (
        _load("ivoi_signal").main([*args, "--estimators", "td,rollout", "--output", str(out)]) == 0
    )
    data = json.loads(out.read_text())
    (run,) = data["runs"]
    assert run["seed"] == 3 and run["rra_reward"] == "jocc"
    rows = run["rows"]
    assert [(r["rra"], r["estimator"]) for r in rows] == [
        (rra, est) for rra in ("jocc (learned)", "greedy", "random") for est in ("td", "rollout")
    ]
    for row in rows:
        assert 0.0 <= row["cam_delivery_rate"] <= 1.0
        evoi = row["evoi"]
        assert evoi["low"] <= evoi["mean"] <= evoi["high"] and evoi["n"] == 3
        if row["cam_delivery_rate"] == 1.0:  # nothing lost: no 'lost' mean, no difference
            assert row["ivoi_lost"]["n"] == 0 and row["ivoi_delivered_minus_lost"]["n"] == 0
        for key in ("ivoi_delivered", "ivoi_lost", "ivoi_delivered_minus_lost"):
            assert 0 <= row[key]["n"] <= 3
    # the same scenarios and policies: the estimator changes ξ, not what happened
    by_rra = {}
    for row in rows:
        by_rra.setdefault(row["rra"], []).append(row)
    for td_row, rollout_row in by_rra.values():
        assert td_row["cam_delivery_rate"] == rollout_row["cam_delivery_rate"]
        assert td_row["evoi"] == rollout_row["evoi"]
    assert not list(checkpoint.parent.parent.glob("ivoi_signal*"))


def test_reward_overrides_change_what_is_measured(checkpoint, tmp_path):
    script = _load("ivoi_signal")
    base = ["--episodes", "3", "--rra", "random", "--estimators", "rollout"]
    figures = {}
    for name, extra in (("default", []), ("no_jerk", ["--reward", "weight_jerk=0"])):
        out = tmp_path / f"{name}.json"
        assert script.main([str(checkpoint), *base, *extra, "--output", str(out)]) == 0
        data = json.loads(out.read_text())
        figures[name] = data["runs"][0]["rows"][0]
        assert data["reward_overrides"] == ({"weight_jerk": 0.0} if extra else {})
    # the same trajectories (same CAM outcomes), scored without the jerk term
    assert figures["default"]["cam_delivery_rate"] == figures["no_jerk"]["cam_delivery_rate"]
    assert figures["default"]["evoi"]["mean"] != figures["no_jerk"]["evoi"]["mean"]


def test_bad_arguments_name_the_value(checkpoint, tmp_path):
    script = _load("ivoi_signal")
    with pytest.raises(SystemExit, match="--rra 'greedy,bogus'"):
        script.main([str(checkpoint), "--rra", "greedy,bogus"])
    with pytest.raises(SystemExit, match="'weight_foo=1': expected KEY=VALUE"):
        script.main([str(checkpoint), "--reward", "weight_foo=1"])
    with pytest.raises(SystemExit, match="collision_penalty=5.0 is outside"):
        script.main([str(checkpoint), "--reward", "collision_penalty=5"])
    with pytest.raises(SystemExit, match="--clip 0.0 must be > 0"):
        script.main([str(checkpoint), "--clip", "0"])
    with pytest.raises(SystemExit, match="--episodes 1 must be >= 2"):
        script.main([str(checkpoint), "--episodes", "1"])
    payload = torch.load(checkpoint, weights_only=True)
    payload["task"] = "control"
    control_only = tmp_path / "control.pt"
    torch.save(payload, control_only)
    with pytest.raises(SystemExit, match="task='control', which trains no π̃"):
        script.main([str(control_only), "--output", str(tmp_path / "x.json")])
    broken = tmp_path / "broken.pt"
    broken.write_bytes(b"not a checkpoint")
    with pytest.raises(SystemExit, match="is not a vdtn-marl checkpoint"):
        script.main([str(broken), "--output", str(tmp_path / "x.json")])
    assert not (tmp_path / "x.json").exists()


def test_estimator_specs_pick_horizon_and_bootstrap(checkpoint, tmp_path):
    script = _load("ivoi_signal")
    assert script.parse_estimators("td, rollout:1,rollout:12:mc") == [
        "td", "rollout:1", "rollout:12:mc"
    ]  # fmt: skip
    assert script.parse_estimators("rollout:1:lost,rollout:9:mc:lost") == [
        "rollout:1:lost", "rollout:9:mc:lost"
    ]  # fmt: skip
    bad_specs = ("rollout:0", "rollout:x", "td:5", "rollout:5:nope", "rollout:5:lost:mc", "")
    for bad in (*bad_specs, "paired", "td:lost"):
        with pytest.raises(SystemExit, match="must list some of td, rollout"):
            script.parse_estimators(bad)
    loop = JointOptimisation.from_checkpoint(checkpoint, tmp_path / "scratch")
    default = script.make_estimator(loop, "rollout")  # the run's rra.rollout_* (10, bootstrap)
    assert default.horizon_intervals == 10 and default.terminal_value is not None
    short = script.make_estimator(loop, "rollout:1")
    assert short.horizon_intervals == 1 and short.terminal_value is not None
    mc = script.make_estimator(loop, "rollout:12:mc")
    assert mc.horizon_intervals == 12 and mc.terminal_value is None
    assert short.baseline == mc.baseline == "optimal"
    lost = script.make_estimator(loop, "rollout:9:mc:lost")
    assert lost.baseline == "cam_lost" and lost.terminal_value is None
    assert script.make_estimator(loop, "rollout:1:lost", clip=1.0).needs_command_if_lost
    with pytest.raises(ValueError, match="needs the rollout estimator"):
        loop.ivoi_estimator("td", baseline="cam_lost")
    rra = replace(loop.cfg.rra, rollout_intervals=4, rollout_bootstrap=False)
    loop.cfg = replace(loop.cfg, rra=rra)
    configured = loop.ivoi_estimator("rollout")
    assert configured.horizon_intervals == 4 and configured.terminal_value is None
    with pytest.raises(ValueError, match="horizon_intervals=0 must be >= 1"):
        loop.ivoi_estimator("rollout", rollout_intervals=0)
    out = tmp_path / "specs.json"
    args = ["--episodes", "3", "--rra", "random", "--estimators", "rollout:1,rollout:12:mc"]
    assert script.main([str(checkpoint), *args, "--output", str(out)]) == 0
    rows = json.loads(out.read_text())["runs"][0]["rows"]
    assert [row["estimator"] for row in rows] == ["rollout:1", "rollout:12:mc"]
    assert rows[0]["ivoi_sum"] != rows[1]["ivoi_sum"]
    assert all(row["ivoi_std"] > 0 for row in rows)
    clipped = tmp_path / "clipped.json"
    assert script.main([str(checkpoint), *args, "--clip", "1e-6", "--output", str(clipped)]) == 0
    data = json.loads(clipped.read_text())
    assert data["clip"] == 1e-6
    for row in data["runs"][0]["rows"]:
        assert row["ivoi_std"] <= 1e-6 and abs(row["ivoi_sum"]["mean"]) <= 20 * 1e-6


def test_lost_baseline_is_zero_on_lost_cams_in_the_signal_benchmark(checkpoint, tmp_path):
    out = tmp_path / "lost.json"
    args = ["--episodes", "3", "--rra", "random", "--estimators", "rollout:1:lost"]
    assert _load("ivoi_signal").main([str(checkpoint), *args, "--output", str(out)]) == 0
    (row,) = json.loads(out.read_text())["runs"][0]["rows"]
    assert row["ivoi_lost"]["mean"] == 0.0 and row["ivoi_delivered"]["n"] == 3
