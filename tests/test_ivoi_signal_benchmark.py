"""benchmarks/ivoi_signal.py on a tiny JOCC run's checkpoint."""

import importlib.util
import json
from dataclasses import replace
from pathlib import Path

import pytest
import torch

from vdtn_marl.algos.jocc import JointOptimisation
from vdtn_marl.config import AlgoConfig, ExperimentConfig, RunConfig, ScenarioConfig

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "ivoi_signal.py"


def _script():
    spec = importlib.util.spec_from_file_location("ivoi_signal", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    run_dir = tmp_path_factory.mktemp("jocc")
    cfg = RunConfig(
        scenario=ScenarioConfig(episode_intervals=20),
        algo=AlgoConfig(
            num_envs=4,
            rollout_steps=10,
            rra_num_envs=4,
            rra_rollout_steps=50,
            minibatch_size=64,
            epochs=1,
        ),  # fmt: skip
        experiment=ExperimentConfig(
            control_iterations=1,
            rra_iterations=1,
            eval_episodes=2,
            eval_intervals=20,
            checkpoint_every=0,
        ),  # fmt: skip
        progress=False,
    )
    JointOptimisation(replace(cfg, seed=3), run_dir).run()
    return run_dir / "checkpoints" / "last.pt"


def test_measures_every_rra_policy_and_estimator(checkpoint, tmp_path):
    out = tmp_path / "signal.json"
    args = [str(checkpoint), "--episodes", "3", "--rra", "learned,greedy,random"]
    assert _script().main([*args, "--estimators", "td,rollout", "--output", str(out)]) == 0
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
    script = _script()
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
    script = _script()
    with pytest.raises(SystemExit, match="--rra 'greedy,bogus'"):
        script.main([str(checkpoint), "--rra", "greedy,bogus"])
    with pytest.raises(SystemExit, match="'weight_foo=1': expected KEY=VALUE"):
        script.main([str(checkpoint), "--reward", "weight_foo=1"])
    with pytest.raises(SystemExit, match="collision_penalty=5.0 is outside"):
        script.main([str(checkpoint), "--reward", "collision_penalty=5"])
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
    with pytest.raises(SystemExit, match="truncated or not a vdtn-marl checkpoint"):
        script.main([str(broken), "--output", str(tmp_path / "x.json")])
    assert not (tmp_path / "x.json").exists()
