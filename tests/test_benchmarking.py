"""Option parsing, provenance and summaries shared by the benchmark scripts."""

import importlib.util
import json
import math
from pathlib import Path

import pytest
import torch

from vdtn_marl.experiment.config import RunConfig
from vdtn_marl.reporting.benchmarking import (
    checkpoint_run,
    ci_summary,
    cpu_model,
    parse_names,
    parse_numbers,
    parse_seeds,
    provenance,
)


def test_parse_names():
    assert parse_names("--x", " a, b ", ("a", "b", "c")) == ["a", "b"]
    assert parse_names("--x", "", ("a",), allow_empty=True) == []
    with pytest.raises(SystemExit, match=r"--x 'a,z' must list some of a, b$"):
        parse_names("--x", "a,z", ("a", "b"))
    with pytest.raises(SystemExit, match=r"--x '' must list some of a"):
        parse_names("--x", "", ("a",))


def test_parse_seeds_and_numbers():
    assert parse_seeds("--seeds", "0, 2") == [0, 2]
    for bad, message in (
        ("0,x", "comma-separated integers"),
        ("1,1", "each once"),
        ("", "at least one"),
    ):
        with pytest.raises(SystemExit, match=f"--seeds '{bad}' must .*{message}"):
            parse_seeds("--seeds", bad)
    assert parse_numbers("--noise", "0,0.1") == [0.0, 0.1]
    with pytest.raises(SystemExit, match=r"--noise '0,-0.1' must list numbers >= 0"):
        parse_numbers("--noise", "0,-0.1")
    with pytest.raises(SystemExit, match="comma-separated numbers"):
        parse_numbers("--noise", "a")


def test_provenance_names_the_command_without_the_interpreter_path():
    block = provenance("demo")
    assert block["benchmark"] == "demo"
    assert block["command"].startswith("python ")
    assert {"vdtn_marl", "torch", "written", "machine", "cpu", "python"} <= block.keys()


def test_cpu_model_reads_the_model_name_and_falls_back(tmp_path):
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: X\nmodel name\t: Example CPU 9000\n")
    assert cpu_model(info) == "Example CPU 9000"
    (tmp_path / "arm").write_text("processor\t: 0\nModel\t\t: Example Board\n")
    assert cpu_model(tmp_path / "arm") == "Example Board"
    fallback = cpu_model(tmp_path / "missing")  # no such file: platform's answer
    assert fallback and fallback != "Example CPU 9000"


def test_ci_summary_counts_only_finite_samples():
    summary = ci_summary(torch.tensor([1.0, float("nan"), 3.0, float("inf")]))
    assert summary["n"] == 2 and summary["mean"] == pytest.approx(2.0)
    assert summary["low"] < 2.0 < summary["high"]
    one = ci_summary(torch.tensor([5.0]))
    assert one["n"] == 1 and one["mean"] == 5.0 and math.isnan(one["low"])
    empty = ci_summary(torch.tensor([float("nan")]))
    assert empty["n"] == 0 and math.isnan(empty["mean"])


def test_checkpoint_run_names_the_run():
    described = checkpoint_run("runs/x/last.pt", RunConfig(seed=4))
    assert described == {
        "checkpoint": "runs/x/last.pt", "scenario": "platoon4", "seed": 4,
        "rra_reward": "jocc", "kappa1": 0.5,
    }  # fmt: skip


BENCHMARK_SCRIPTS = sorted(
    p
    for p in (Path(__file__).resolve().parents[1] / "benchmarks").glob("*.py")
    if p.name != "leaderboard.py"  # a thin front of `vdtn-marl bench` (tests/test_leaderboard.py)
)


@pytest.mark.parametrize("script", BENCHMARK_SCRIPTS, ids=lambda p: p.name)
def test_benchmark_script_imports_and_prints_help(script, capsys):
    """Every script under benchmarks/ imports what it uses from the package (a moved or renamed
    name fails here, not in someone's hours-long run) and answers --help."""
    spec = importlib.util.spec_from_file_location(f"_bench_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    with pytest.raises(SystemExit) as exit_info:
        module.main(["--help"])
    assert exit_info.value.code == 0
    assert "usage:" in capsys.readouterr().out


def test_jocc_iterations_reads_each_cells_evaluation_rows(tmp_path):
    """Two seeds × 2 JOCC iterations of one method: means per iteration and the paired
    last − first change, by hand."""
    spec = importlib.util.spec_from_file_location(
        "jocc_iterations", Path(__file__).resolve().parents[1] / "benchmarks/jocc_iterations.py"
    )
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    keys = [m for m, _ in script.METRICS]
    for seed, rows in {0: [0.1, 0.3], 1: [0.2, 0.6]}.items():
        cell = tmp_path / "platoon4" / "m" / f"seed{seed}"
        cell.mkdir(parents=True)
        (cell / "summary.json").write_text("{}")
        lines = [",".join(["jocc_iteration", *keys])]
        lines += [",".join([str(k), *[str(v)] * len(keys)]) for k, v in enumerate(rows)]
        (cell / "evaluation.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "platoon4" / "m" / "seed2").mkdir()  # not complete: ignored
    out = tmp_path / "out.json"
    assert script.main([str(tmp_path), "--methods", "m", "--output", str(out)]) == 0
    result = json.loads(out.read_text())["methods"]["m"]
    assert result["seeds"] == [0, 1]
    first, last = (it["cam_delivery_rate"]["mean"] for it in result["iterations"])
    assert math.isclose(first, 0.15, rel_tol=1e-6) and math.isclose(last, 0.45, rel_tol=1e-6)
    change = result["last_minus_first"]["gap_error_abs_m"]
    assert math.isclose(change["mean"], 0.3, rel_tol=1e-6) and change["n"] == 2
    with pytest.raises(SystemExit, match="--methods 'x' must list some of m"):
        script.main([str(tmp_path), "--methods", "x", "--output", str(out)])
