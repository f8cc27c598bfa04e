"""The arithmetic of the training-throughput benchmark (benchmarks/stage_throughput.py): ratios in
the same repeat, the size choice, the iteration estimate and the refusal of bad arguments. The
timed runs themselves are benchmarks, never tests."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_bench_{name}", ROOT / "benchmarks" / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


stages = _script("stage_throughput.py")


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
