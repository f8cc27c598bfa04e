"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-05-pi-tilde-budget/test_pi_tilde_budget.py``."""

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


def _estimate(later_s, pi_tilde_s, iterations, control):
    return {
        "seconds": {"pi_tilde_learned": pi_tilde_s},
        "budgets": {"control_iterations": iterations},
        "later_iteration_s": later_s,
        "chosen_batches": {"control": control, "rra": 512},
    }


def _stages_file(path, later_s, pi_tilde_s, iterations=500, control=1024, paper=None):
    """A stage_throughput.py result; ``paper`` (later_s, pi_tilde_s) adds its estimate at the
    experiment=paper sizes (control batch 256)."""
    data = {
        "written": "2026-01-01",
        "estimate": _estimate(later_s, pi_tilde_s, iterations, control),
    }
    if paper is not None:
        data["estimate_paper"] = _estimate(*paper, iterations, 256)
    path.write_text(json.dumps(data))
    return path


def test_pi_tilde_budget_leaves_pi_tilde_what_the_other_stages_leave_of_30_minutes(tmp_path):
    module = _script("pi_tilde_budget.py")
    stages = _stages_file(tmp_path / "st.json", later_s=3000.0, pi_tilde_s=2000.0)
    # other stages 1000 s: π̃ gets (1800 − 1000) / 500 = 1.6 s per iteration, 2.5× less than 4 s
    slow = module.budget(stages, [{"batch_size": 1024, "eager_over_floor": 2.0}])
    assert slow["allowed_pi_tilde_s_per_iteration"] == pytest.approx(1.6)
    assert slow["needed_speedup"] == pytest.approx(2.5)
    assert slow["reachable_at_the_floor"] is False
    fast = module.budget(stages, [{"batch_size": 1024, "eager_over_floor": 3.0}])
    assert fast["reachable_at_the_floor"] is True
    other_size = module.budget(stages, [{"batch_size": 256, "eager_over_floor": 9.0}])
    assert "reachable_at_the_floor" not in other_size
    assert module.budget(tmp_path / "absent.json", [])["missing"]
    assert "paper" not in slow  # the file has no estimate at the paper sizes


def test_pi_tilde_budget_also_fits_the_paper_sizes_and_recomputes_from_stored_rows(tmp_path):
    module = _script("pi_tilde_budget.py")
    # fastest sizes: others 1000 s, π̃ may take 1.6 s (needs 2.5×); paper sizes: others
    # 1200 s, π̃ may take 1.2 s of its 6 s (needs 5×)
    stages = _stages_file(tmp_path / "st.json", 3000.0, 2000.0, paper=(4200.0, 3000.0))
    rows = [
        {"batch_size": 1024, "eager_over_floor": 3.0},
        {"batch_size": 256, "eager_over_floor": 4.0},
    ]
    fit = module.budget(stages, rows)
    assert fit["reachable_at_the_floor"] is True
    paper = fit["paper"]
    assert paper["chosen_control_batch"] == 256
    assert paper["allowed_pi_tilde_s_per_iteration"] == pytest.approx(1.2)
    assert paper["needed_speedup"] == pytest.approx(5.0)
    assert paper["floor_speedup_here"] == 4.0 and paper["reachable_at_the_floor"] is False
    # rows timed at other samples per iteration are not set against the budget
    other_frames = module.budget(stages, rows, frames=16)
    assert "floor_speedup_here" not in other_frames
    assert "floor_speedup_here" not in other_frames["paper"]
    # --budget-only rewrites the budget of a stored result, its rows untouched
    out = tmp_path / "pt.json"
    stored = {"frames_per_iteration": module.CONTROL_FRAMES, "rows": rows, "budget": {}}
    out.write_text(json.dumps(stored))
    assert module.main(["--budget-only", "--stages", str(stages), "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["rows"] == rows
    assert result["budget"]["paper"]["reachable_at_the_floor"] is False
    with pytest.raises(SystemExit, match="--out"):
        module.main(["--budget-only", "--out", str(tmp_path / "absent.json")])


def test_pi_tilde_budget_refuses_batch_sizes_that_do_not_divide_the_frames(capsys):
    module = _script("pi_tilde_budget.py")
    with pytest.raises(SystemExit):
        module.parse_args(["--batch-sizes", "3", "--frames", "16"])
    assert "--batch-sizes" in capsys.readouterr().err


@pytest.mark.slow
def test_pi_tilde_budget_times_eager_and_compiled_iterations_and_their_floor(tmp_path):
    module = _script("pi_tilde_budget.py")
    out = tmp_path / "pt.json"
    stages = _stages_file(tmp_path / "st.json", later_s=3000.0, pi_tilde_s=2000.0, control=8)
    argv = ["--batch-sizes", "8", "--frames", "16", "--repeats", "1", "--calls", "2"]
    assert module.main([*argv, "--stages", str(stages), "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    (row,) = result["rows"]
    assert row["batch_size"] == 8 and len(row["eager"]) == 1
    assert row["eager"][0]["intervals"] == 2
    # one radio run per interval at least (more where scenarios ended and were reset)
    assert row["radio_runs_per_interval"] >= 1.0
    assert 0 < row["update_s"] < row["floor_s"]
    assert row["floor_s"] == pytest.approx(sum(row["floor_parts_s"].values()))
    if row["compiled"]:  # a machine with a C++ compiler
        assert isinstance(row["policy_actions_bit_identical"], bool)
        assert row["compiled_s"] > 0 and row["kernel_compiled_us"] > 0
    else:
        assert row["error"]
    # not the paper's samples per iteration: no floor against the 30-minute budget
    assert "floor_speedup_here" not in result["budget"]
