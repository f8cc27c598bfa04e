"""benchmarks/ivoi_signal.py on a tiny JOCC run's checkpoint; benchmarks/ivoi_noise.py's
synthetic IVoI and its training path on a tiny budget."""

import importlib.util
import json
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RRAConfig,
    RunConfig,
    ScenarioConfig,
)
from vdtn_marl.experiment.jocc import JointOptimisation

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _script():
    return _load("ivoi_signal")


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


def test_estimator_specs_pick_horizon_and_bootstrap(checkpoint, tmp_path):
    script = _script()
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
    assert _script().main([str(checkpoint), *args, "--output", str(out)]) == 0
    (row,) = json.loads(out.read_text())["runs"][0]["rows"]
    assert row["ivoi_lost"]["mean"] == 0.0 and row["ivoi_delivered"]["n"] == 3


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
