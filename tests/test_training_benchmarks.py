"""The arithmetic of the training-throughput benchmarks (stage_throughput.py,
paper_batch_pairing.py, activation_cost.py, draw_ahead.py and two_cores.py): ratios in the
same repeat, the size choice, the iteration estimate, the paired differences and the refusal
of bad arguments. The timed runs themselves are benchmarks, never tests."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_bench_{name}", ROOT / "benchmarks" / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


stages = _script("stage_throughput.py")
pairing = _script("paper_batch_pairing.py")
activation = _script("activation_cost.py")
draw_ahead = _script("draw_ahead.py")


def _run(stage, batch, repeat, seconds, cpu_seconds, frames=25_600):
    return {
        "stage": stage,
        "batch": batch,
        "repeat": repeat,
        "frames_per_s": frames / seconds,
        "collect_frames_per_s": 2 * frames / seconds,
        "seconds_per_iteration": seconds,
        "scaling_s": 1.0,
        "scaling_cpu_s": 0.5,
        "frames_per_cpu_s": frames / cpu_seconds,
        "cpu_seconds_per_iteration": cpu_seconds,
        "update_s": [0.25],
        "rollout_steps": frames // batch,
        "frames_per_iteration": frames,
        "peak_rss_mb": 100.0 + batch,
    }


def test_ratios_are_taken_against_the_reference_of_the_same_repeat():
    runs = [
        _run("pi_star", 64, 0, 10.0, 8.0),
        _run("pi_star", 256, 0, 5.0, 2.0),  # 2x (wall) and 4x (CPU) the reference of repeat 0
        _run("pi_star", 64, 1, 20.0, 8.0),  # a slow repeat: the machine was busy
        _run("pi_star", 256, 1, 8.0, 4.0),  # 2.5x and 2x the reference of repeat 1
    ]
    rows = {row["batch"]: row for row in stages.summarise("pi_star", runs, reference=64)}
    assert rows[64]["ratio_to_reference"] == 1.0
    assert rows[256]["ratio_to_reference"] == pytest.approx((2.0 + 2.5) / 2)
    assert rows[256]["cpu_ratio_to_reference"] == pytest.approx((4.0 + 2.0) / 2)
    assert rows[256]["seconds_per_iteration"] == pytest.approx(6.5)
    assert rows[256]["peak_rss_mb"] == 356.0


def _rows(seconds: dict[int, float]) -> list[dict]:
    rows = []
    for stage in stages.CONTROL_STAGES:
        runs = [_run(stage, b, 0, s, s / 2) for b, s in seconds.items()]
        rows += stages.summarise(stage, runs, reference=64)
    return rows


def test_the_choice_is_the_fastest_size_with_long_enough_rollouts():
    args = stages.parse_args(["--control-batches", "64,256,512"])
    rows = _rows({64: 10.0, 256: 4.0, 512: 3.0})  # 512: rollouts of 50 intervals
    assert stages._choice(args, rows) == {"control": 256}
    args = stages.parse_args(["--control-batches", "64,256,512", "--min-control-rollout", "50"])
    assert stages._choice(args, rows) == {"control": 512}
    args = stages.parse_args(["--choose", "control=64"])
    assert stages._choice(args, rows) == {"control": 64}


def test_the_iteration_estimate_adds_each_stages_budget():
    rows = _rows({64: 10.0, 256: 4.0})
    rows += stages.summarise("rra", [_run("rra", 128, 0, 3.0, 2.0, frames=64_000)], 128)
    rows.append({"stage": "evaluate", "batch": None, "seconds": 60.0, "cpu_seconds": 50.0,
                 "checkpoint_s": 0.5})  # fmt: skip
    rows.append({"stage": "warm_start", "batch": None, "seconds": 100.0, "cpu_seconds": 90.0})
    budgets = {"control_iterations": 10, "rra_iterations": 5, "checkpoints": 4}
    est = stages.estimate(rows, {"control": 256, "rra": 128}, budgets)
    # first: warm start, π* and π̃ (random RRA) with their scaling fits, RRA, evaluation, saves
    first = 100.0 + 2 * (10 * 4.0 + 1.0) + (5 * 3.0 + 1.0) + 60.0 + 4 * 0.5
    assert est["first_iteration_s"] == pytest.approx(first)
    # later: π* and π̃ (learned RRA), RRA, evaluation, saves; no warm start, no scaling fits
    assert est["later_iteration_s"] == pytest.approx(2 * 10 * 4.0 + 5 * 3.0 + 60.0 + 2.0)
    assert est["missing"] == []
    cpu = stages.estimate(rows, {"control": 256, "rra": 128}, budgets, cpu=True)
    assert cpu["later_iteration_s"] == pytest.approx(2 * 10 * 2.0 + 5 * 2.0 + 50.0 + 2.0)
    assert stages.estimate(rows, {"control": 512}, budgets)["missing"][:3] == list(
        stages.CONTROL_STAGES
    )


@pytest.mark.parametrize(
    ("argv", "flag"),
    [
        (["--control-batches", "64,300"], "--control-batches"),  # 25,600 / 300 is no whole
        (["--rra-batches", "0"], "--rra-batches"),
        (["--stages", "pi_star,warp"], "--stages"),
    ],
)
def test_stage_throughput_refuses_bad_arguments(argv, flag, capsys):
    with pytest.raises(SystemExit) as refused:
        stages.parse_args(argv)
    assert flag in capsys.readouterr().err + str(refused.value.code)


@pytest.mark.parametrize(
    ("argv", "flag"),
    [
        (["--new", "256x50"], "--new"),  # fewer samples per iteration than the old arm
        (["--old", "64"], "--old"),
        (["--eval-every", "0"], "--eval-every"),
        (["--new-overrides", "algo.activation"], "--new-overrides"),  # not key=value
    ],
)
def test_pairing_refuses_bad_arguments(argv, flag, capsys):
    with pytest.raises(SystemExit) as refused:
        pairing.parse_args(argv)
    assert flag in capsys.readouterr().err + str(refused.value.code)


def test_pairing_differences_are_taken_seed_by_seed():
    def arm(arm, seed, costs, cpu):
        evaluations = [
            {"iteration": 10 * i, "frames": 256_000 * i, "control_cost": c}
            for i, c in enumerate(costs)
        ]
        return {"stage": "pi_star", "arm": arm, "seed": seed, "evaluations": evaluations,
                "cpu_s_per_iteration": cpu}  # fmt: skip

    runs = [
        arm("old", 0, [0.5, 0.30], 4.0),
        arm("new", 0, [0.5, 0.20], 2.0),
        arm("old", 1, [0.6, 0.40], 4.0),
        arm("new", 1, [0.6, 0.45], 1.0),
    ]
    rows = pairing.pair_rows(runs, "pi_star")
    assert [row["iteration"] for row in rows] == [0, 10]
    assert rows[0]["diff_mean"] == 0.0
    last = rows[-1]
    assert last["cost_old"] == pytest.approx(0.35) and last["cost_new"] == pytest.approx(0.325)
    assert last["diff_mean"] == pytest.approx(-0.025)
    assert (last["diff_min"], last["diff_max"]) == pytest.approx((-0.10, 0.05))
    # mean ± t_{1, 0.975} · s/√2 of (−0.10, +0.05): s = 0.15/√2, so ± 12.706 · 0.075
    half = 12.7062047 * 0.075
    assert (last["diff_t95_low"], last["diff_t95_high"]) == pytest.approx(
        (-0.025 - half, -0.025 + half), rel=1e-6
    )
    assert last["cpu_ratio_new_to_old"] == pytest.approx((0.5 + 0.25) / 2)
    assert pairing.pair_rows(runs, "pi_tilde") == []
    # an arm with collector workers: their CPU seconds count; unrecorded, no ratio at all
    for run in runs[1::2]:
        run.update(overrides=["algo.collector_workers=2"], worker_cpu_s_per_iteration=2.0)
    last = pairing.pair_rows(runs, "pi_star")[-1]
    assert last["cpu_ratio_new_to_old"] == pytest.approx((1.0 + 0.75) / 2)
    del runs[1]["worker_cpu_s_per_iteration"]
    last = pairing.pair_rows(runs, "pi_star")[-1]
    assert last["cpu_ratio_new_to_old"] is None and last["cpu_s_per_iteration_new"] is None


timings = _script("paper_stage_timings.py")


def _fake_run(path: Path, seconds: dict[tuple[int, str], list[float]], evaluate: list[float]):
    path.mkdir()
    lines = ["jocc_iteration,stage,iteration,frames,seconds"]
    for (jocc_iteration, stage), values in seconds.items():
        frames = 64_000 if stage == "rra" else 25_600
        lines += [f"{jocc_iteration},{stage},{i},{frames},{s}" for i, s in enumerate(values)]
    (path / "metrics.csv").write_text("\n".join(lines) + "\n")
    (path / "jocc.log").write_text(
        "".join(
            f"[x] - JOCC iteration {i}, stage evaluate done in {s} s\n"
            for i, s in enumerate(evaluate)
        )  # fmt: skip
    )
    (path / "config.yaml").write_text("algo:\n  num_envs: 256\n  rollout_steps: 100\n")


def test_paper_stage_timings_reads_runs_and_extrapolates(tmp_path):
    _fake_run(
        tmp_path / "run",
        {
            (0, "control_perfect"): [9.0, 2.0, 4.0],  # the first fits the scaling: left out
            (0, "control_impaired"): [20.0, 6.0],
            (1, "control_impaired"): [12.0, 14.0],  # learned RRA: every iteration counts
            (0, "rra"): [5.0, 3.0],
        },
        evaluate=[30.0, 50.0],
    )
    run = timings.read_run(tmp_path / "run")
    stages = run["stages"]
    assert stages["pi_star"]["seconds_per_iteration"] == 3.0
    assert stages["pi_tilde_random"]["seconds_per_iteration"] == 6.0
    assert stages["pi_tilde_learned"]["seconds_per_iteration"] == 13.0
    assert stages["rra"]["frames_per_s"] == pytest.approx(64_000 / 3.0)
    assert run["batch"]["num_envs"] == 256 and run["evaluate_s"] == [30.0, 50.0]
    est = timings.paper_iteration(run, control_iterations=10, rra_iterations=4)
    assert est["first_s"] == pytest.approx(10 * (3.0 + 6.0) + 4 * 3.0 + 40.0)
    assert est["later_s"] == pytest.approx(10 * (3.0 + 13.0) + 4 * 3.0 + 40.0)


def test_paper_stage_timings_refuses_bad_arguments(tmp_path, capsys):
    with pytest.raises(SystemExit):
        timings.parse_args([f"old={tmp_path}"])  # no metrics.csv there
    assert "metrics.csv" in capsys.readouterr().err
    _fake_run(tmp_path / "run", {(0, "rra"): [1.0]}, [])
    with pytest.raises(SystemExit):
        timings.parse_args([f"new={tmp_path / 'run'}", "--cpu-share", "new=300/100"])
    assert "--cpu-share" in capsys.readouterr().err


def test_pairing_summarize_recomputes_a_results_table(tmp_path, capsys):
    runs = [
        {"stage": "pi_star", "arm": arm, "seed": seed, "cpu_s_per_iteration": 1.0,
         "evaluations": [{"iteration": 0, "frames": 0, "control_cost": cost}]}
        for seed, arm, cost in [(0, "old", 0.3), (0, "new", 0.4), (1, "old", 0.3), (1, "new", 0.2)]
    ]  # fmt: skip
    result = tmp_path / "pairing.json"
    result.write_text(json.dumps({"benchmark": "paper_batch_pairing", "rows": [], "runs": runs}))
    assert pairing.main(["--summarize", str(result)]) == 0
    rows = json.loads(result.read_text())["rows"]
    assert len(rows) == 1 and rows[0]["diff_mean"] == pytest.approx(0.0)
    assert rows[0]["diff_t95_low"] < 0 < rows[0]["diff_t95_high"]
    assert "95% t interval" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        pairing.parse_args(["--summarize", str(tmp_path / "missing.json")])
    assert "--summarize" in capsys.readouterr().err
    result.write_text(json.dumps({"rows": []}))
    with pytest.raises(SystemExit, match="no runs"):
        pairing.main(["--summarize", str(result)])


def test_pairing_arms_take_their_own_overrides():
    args = pairing.parse_args(
        ["--old", "256x100", "--new", "256x100", "--new-overrides", "algo.activation=tanh_sigmoid"]
    )
    assert args.old_overrides == [] and args.new_overrides == ["algo.activation=tanh_sigmoid"]


def test_activation_ratios_are_tanhs_time_over_the_others_in_the_same_repeat():
    runs = [
        {"part": "k", "name": "tanh", "repeat": 0, "us": 100.0},
        {"part": "k", "name": "tanh_sigmoid", "repeat": 0, "us": 25.0},
        {"part": "k", "name": "tanh", "repeat": 1, "us": 300.0},  # a slow repeat for both
        {"part": "k", "name": "tanh_sigmoid", "repeat": 1, "us": 100.0},
        {"part": "k", "name": "tanh", "repeat": 2, "us": 120.0},
        {"part": "k", "name": "tanh_sigmoid", "repeat": 2, "us": 60.0},
    ]
    rows = {r["name"]: r for r in activation._ratio_rows(runs, "us")}
    assert rows["tanh"]["tanh_over_this"] == 1.0
    assert rows["tanh_sigmoid"]["tanh_over_this"] == 3.0  # median of 4, 3, 2
    assert rows["tanh_sigmoid"]["us"] == 60.0 and rows["tanh_sigmoid"]["runs"] == 3


def test_activation_cost_refuses_bad_arguments(capsys):
    with pytest.raises(SystemExit) as refused:
        activation.parse_args(["--stages", "pi_star,warp"])
    assert "--stages" in capsys.readouterr().err + str(refused.value.code)
    assert activation.parse_args(["--stages", "none"]).stages == []


def _pair(stage, pair, ahead, at_start):
    common = {"stage": stage, "pair": pair}
    return [
        {**common, "setting": "ahead", "wall_s": ahead, "cpu_s": ahead + 1},
        {**common, "setting": "at_start", "wall_s": at_start, "cpu_s": at_start},
    ]


def test_draw_ahead_ratios_are_paired_and_the_iteration_adds_each_budget():
    runs = [
        *_pair("pi_star", 0, 1.0, 1.0),
        *_pair("pi_tilde_random", 0, 2.0, 2.4),
        *_pair("pi_tilde_learned", 0, 4.0, 5.0),
        *_pair("pi_tilde_learned", 1, 8.0, 8.8),  # a slow pair: its own ratio, 1.1
        *_pair("pi_tilde_learned", 2, 4.0, 6.0),
        *_pair("rra", 0, 3.0, 3.0),
    ]
    rows = {r["stage"]: r for r in draw_ahead.summarise(runs)}
    learned = rows["pi_tilde_learned"]
    assert learned["at_start_over_ahead"] == pytest.approx(1.25)  # median of 1.25, 1.1, 1.5
    assert (learned["ratio_min"], learned["ratio_max"], learned["pairs"]) == (1.1, 1.5, 3)
    assert learned["wall_s_ahead"] == 4.0 and learned["cpu_s_ahead"] == 5.0
    minutes = draw_ahead.iteration_minutes(
        list(rows.values()), {"control_iterations": 500, "rra_iterations": 300}
    )
    assert minutes["first_ahead"] == pytest.approx((500 * 1.0 + 500 * 2.0 + 300 * 3.0) / 60)
    assert minutes["later_at_start"] == pytest.approx((500 * 1.0 + 500 * 6.0 + 300 * 3.0) / 60)
    partial = draw_ahead.iteration_minutes([rows["rra"]], {"control_iterations": 1})
    assert partial == {}  # stages missing: no estimate


def test_draw_ahead_refuses_bad_arguments(capsys):
    with pytest.raises(SystemExit) as refused:
        draw_ahead.parse_args(["--stages", "pi_star,warp"])
    assert "--stages" in capsys.readouterr().err + str(refused.value.code)
    with pytest.raises(SystemExit):
        draw_ahead.parse_args(["--repeats", "0"])
    assert "--repeats" in capsys.readouterr().err


def test_the_reference_sizes_are_the_paper_configs_and_fit_the_sweep():
    budgets = stages._budgets()
    reference = stages.reference_batches(budgets)
    assert reference == {
        "control": budgets["paper_algo"]["num_envs"],
        "rra": budgets["paper_algo"]["rra_num_envs"],
    }
    # the paper sizes keep the samples per iteration the sweep compares at
    algo = budgets["paper_algo"]
    assert algo["num_envs"] * algo["rollout_steps"] == stages.CONTROL_FRAMES
    assert algo["rra_num_envs"] * algo["rra_rollout_steps"] == stages.RRA_FRAMES


def test_paper_stage_timings_measures_whole_jocc_iterations(tmp_path, capsys):
    run = tmp_path / "run"
    _fake_run(run, {(0, "control_perfect"): [1.0, 1.0], (1, "control_perfect"): [1.0]}, [])
    lines = [
        ("10:00:00,000", "jocc seed=0 in run: ..."),
        ("10:03:00,000", "JOCC iteration 0, stage control_perfect done in 60.0 s"),
        ("10:10:00,500", "JOCC iteration 0, stage evaluate done in 30.0 s"),
        ("10:12:00,500", "JOCC iteration 1, stage control_perfect done in 90.0 s"),
    ]
    (run / "jocc.log").write_text(
        "".join(f"[2026-12-05 {at}][vdtn_marl][INFO] - {text}\n" for at, text in lines)
    )
    measured = timings.read_run(run)["measured"]
    assert [m["jocc_iteration"] for m in measured] == [0, 1]
    first, second = measured
    assert first["wall_s"] == pytest.approx(600.5)  # warm start and checkpoints included
    assert first["stages"] == {"control_perfect": 60.0, "evaluate": 30.0} and first["complete"]
    assert second["wall_s"] == pytest.approx(120.0) and not second["complete"]
    assert first["ppo_iterations"] == {"control_perfect": 2}
    report = tmp_path / "time.txt"
    report.write_text(
        "\tUser time (seconds): 100.5\n\tSystem time (seconds): 9.5\n"
        "\tElapsed (wall clock) time (h:mm:ss or m:ss): 1:01:40\n"
        "\tMaximum resident set size (kbytes): 2048000\n"
    )
    out = tmp_path / "out.json"
    assert timings.main([f"run={run}", "--time-v", f"run={report}", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["time_v"]["run"]["peak_rss_mb"] == pytest.approx(2000.0)
    assert data["time_v"]["run"]["wall_s"] == pytest.approx(3700.0)
    assert data["time_v"]["run"]["cpu_s"] == pytest.approx(110.0)
    assert "JOCC iteration 0 measured: 10.0 min (complete" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        timings.parse_args([f"run={run}", "--time-v", f"run={tmp_path / 'none.txt'}"])
    assert "--time-v" in capsys.readouterr().err


two_cores = _script("two_cores.py")


def _arm(stage, arm, repeat, collect, update_1=0.5, update_2=0.4, frames=25_600):
    row = {
        "stage": stage,
        "arm": arm,
        "repeat": repeat,
        "frames_per_iteration": frames,
        "collect_s": list(collect),
        "peak_rss_mb": 500.0 if arm == "one" else 400.0,
    }
    if arm == "one":
        row["update_1_thread_s"] = [update_1] * len(collect)
        row["update_2_thread_s"] = [update_2] * len(collect)
    return row


def test_two_cores_pairs_the_arms_within_a_repeat_and_estimates_the_budget():
    runs = []
    for stage, one, shards in (
        ("pi_star", 0.2, 0.2),
        ("pi_tilde_random", 3.0, 2.0),
        ("pi_tilde_learned", 4.0, 2.0),
        ("rra", 1.0, 0.8),
    ):
        runs += [_arm(stage, "one", 0, [one] * 3), _arm(stage, "shards", 0, [shards] * 3)]
    # a slow repeat of both arms: paired, its ratio is the same 2.0
    runs += [
        _arm("pi_tilde_learned", "one", 1, [8.0, 8.0, 9.0]),
        _arm("pi_tilde_learned", "shards", 1, [4.0, 4.0, 3.0]),
    ]
    rows = {r["stage"]: r for r in two_cores.summarise(runs, list(two_cores.STAGES))}
    learned = rows["pi_tilde_learned"]
    assert learned["one_over_shards"] == pytest.approx(2.0)
    assert learned["one_over_shards_range"] == [2.0, 2.0]
    assert learned["update_1_over_2"] == pytest.approx(1.25)
    assert learned["peak_rss_mb_one"] == 500.0 and learned["peak_rss_mb_shards"] == 400.0
    sizes = {"control_iterations": 500, "rra_iterations": 300}
    est = two_cores.estimate(list(rows.values()), sizes)
    later_one = (500 * (0.2 + 0.5) + 500 * (learned["collect_one_s"] + 0.5) + 300 * 1.5) / 60
    later_two = (500 * (0.2 + 0.4) + 500 * (learned["collect_shards_s"] + 0.4) + 300 * 1.2) / 60
    assert est["later"]["one_min"] == pytest.approx(later_one)
    assert est["later"]["two_cores_min"] == pytest.approx(later_two)
    later_threads = (500 * 0.6 + 500 * (learned["collect_one_s"] + 0.4) + 300 * 1.4) / 60
    assert est["later"]["update_threads_min"] == pytest.approx(later_threads)
    assert est["first"]["one_over_two"] == pytest.approx(
        (500 * 0.7 + 500 * 3.5 + 300 * 1.5) / (500 * 0.6 + 500 * 2.4 + 300 * 1.2)
    )
    assert two_cores.estimate([rows["rra"]], sizes) is None  # stages missing: no estimate


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--stages", "pi_star,warp"], "--stages"),
        (["--shards", "1"], "--shards"),
        (["--iterations", "0"], "--iterations"),
    ],
)
def test_two_cores_refuses_bad_arguments(argv, flag, capsys):
    with pytest.raises(SystemExit) as refused:
        two_cores.parse_args(argv)
    assert flag in capsys.readouterr().err + str(refused.value.code)


def test_two_cores_summarise_refuses_a_file_that_is_not_its_results(tmp_path):
    bad = tmp_path / "other.json"
    bad.write_text(json.dumps({"runs": []}))
    with pytest.raises(SystemExit) as refused:
        two_cores.main(["--summarise", str(bad)])
    assert "--summarise" in str(refused.value.code) and "other.json" in str(refused.value.code)


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
