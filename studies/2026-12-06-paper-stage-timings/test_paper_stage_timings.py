"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-06-paper-stage-timings/test_paper_stage_timings.py``."""

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


stages = _script("../../benchmarks/stage_throughput.py")


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
