"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-06-paper-batch-pairing/test_paper_batch_pairing.py``."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


pairing = _script("paper_batch_pairing.py")


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
