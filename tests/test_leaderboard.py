"""The leaderboard: statistics on known inputs, benchmark validation, and the `smoke` benchmark
run end to end through `vdtn-marl bench` (files, schema, CI ordering, plots, resume)."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vdtn_marl import cli, cli_help, config, leaderboard
from vdtn_marl.config import ConfigError
from vdtn_marl.runs import RAW_EVALUATION_FILE

pytestmark = pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema")

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sys.executable).with_name("vdtn-marl")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
PLOT_KINDS = (
    "error_traces",
    "v2i_throughput",
    "cam_delivery",
    "control_cost",
    "cam_latency_cdf",
    "pareto_kappa1",
    "training_curves",
)


# --- statistics on known inputs ------------------------------------------------------------


def test_aggregate_known_values():
    stats = leaderboard.aggregate([1.0, 2.0, 3.0, 4.0, 10.0], resamples=5000)
    assert stats["n"] == 5
    assert stats["mean"] == pytest.approx(4.0)
    assert stats["std"] == pytest.approx(np.std([1, 2, 3, 4, 10], ddof=1))
    assert stats["iqm"] == pytest.approx(3.0)  # 25% cut on each side: mean of 2, 3, 4
    assert stats["ci_low"] <= stats["mean"] <= stats["ci_high"]
    assert stats["iqm_ci_low"] <= stats["iqm"] <= stats["iqm_ci_high"]
    # a percentile bootstrap of the mean stays inside the sample's range
    assert 1.0 <= stats["ci_low"] < 4.0 < stats["ci_high"] <= 10.0


def test_aggregate_is_deterministic_and_ignores_missing_values():
    values = [0.5, None, float("nan"), 0.7, 0.9, float("inf")]
    first = leaderboard.aggregate(values, resamples=2000)
    assert first == leaderboard.aggregate(values, resamples=2000)
    assert first["n"] == 3
    assert first["mean"] == pytest.approx(0.7)
    assert first["iqm"] is None  # fewer than MIN_RUNS_FOR_IQM runs


def test_aggregate_degenerate_samples():
    one = leaderboard.aggregate([2.5])
    assert (one["n"], one["mean"], one["ci_low"], one["ci_high"], one["std"]) == (
        1, 2.5, 2.5, 2.5, 0.0,
    )  # fmt: skip
    same = leaderboard.aggregate([1.0] * 6)
    assert same["ci_low"] == same["ci_high"] == same["mean"] == same["iqm"] == 1.0
    empty = leaderboard.aggregate([None, float("nan")])
    assert empty["n"] == 0 and all(empty[k] is None for k in leaderboard.STAT_KEYS if k != "n")


def test_bootstrap_ci_width_matches_normal_theory():
    x = np.random.default_rng(1).normal(0.0, 1.0, size=200)
    mean, low, high = leaderboard.bootstrap_ci(x, np.mean, resamples=5000)
    half_width = 1.96 * x.std(ddof=1) / math.sqrt(x.size)
    assert low < mean < high
    assert (high - low) / 2 == pytest.approx(half_width, rel=0.15)


def test_best_methods_follow_direction_and_keep_ties():
    stats = {
        "a": {"control_cost": {"mean": 1.0}, "v2i_throughput_mbps_per_link": {"mean": 2.0}},
        "b": {"control_cost": {"mean": 0.5}, "v2i_throughput_mbps_per_link": {"mean": 2.0}},
        "c": {"control_cost": {"mean": None}, "v2i_throughput_mbps_per_link": {"mean": 1.0}},
    }
    by_key = {m.key: m for m in leaderboard.METRICS}
    assert leaderboard.best_methods(stats, by_key["control_cost"]) == {"b"}
    assert leaderboard.best_methods(stats, by_key["v2i_throughput_mbps_per_link"]) == {"a", "b"}
    same = {m: {"collision_rate": {"mean": 0.0}} for m in "ab"}
    assert leaderboard.best_methods(same, by_key["collision_rate"]) == set()  # nothing to mark


def test_marl_eval_export_layout():
    benchmark = config.BenchmarkConfig(name="t", version="9", methods={"m": ["rra=random"]})
    rows = []
    for seed in (0, 1):
        row = {"scenario": "platoon4", "method": "m", "seed": seed, "trainer_iterations.pi_star": 3}
        row.update({key: 0.1 * (seed + 1) for key in leaderboard.METRIC_KEYS})
        rows.append(row)
    rows[1]["cam_latency_ms_p50"] = None  # a run that delivered no CAM
    data, dropped = leaderboard.marl_eval_data(rows, benchmark)
    assert dropped == ["cam_latency_ms_p50"]
    runs = data["vdtn-t-v9"]["platoon4"]["m"]
    assert list(runs) == ["seed_0", "seed_1"]
    for run in runs.values():
        assert list(run) == ["step_1", "absolute_metrics"]  # marl-eval reads the last key
        assert run["step_1"]["step_count"] == 3
        assert set(run["absolute_metrics"]) == set(leaderboard.METRIC_KEYS) - set(dropped)
        assert all(len(v) == 1 and math.isfinite(v[0]) for v in run["absolute_metrics"].values())


# --- benchmark definitions -----------------------------------------------------------------


def _bench(**changes) -> config.BenchConfig:
    benchmark = dict(
        name="t", version="1", experiment="smoke", methods={"a": ["rra=random"], "b": []},
        seeds=[0, 1],
    )  # fmt: skip
    benchmark.update(changes)
    return config.BenchConfig(benchmark=config.BenchmarkConfig(**benchmark))


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"budgets": {"c": ["experiment.rra_iterations=2"]}}, "benchmark.budgets.c names no"),
        ({"methods": {"a": ["seed=3"]}}, "benchmark.methods.a sets 'seed=3'"),
        ({"methods": {"a": ["scenario=platoon8"]}}, "sets 'scenario=platoon8'"),
        ({"overrides": ["experiment=paper"]}, "benchmark.overrides sets 'experiment=paper'"),
        ({"trace_methods": ["a", "zz"]}, "names 'zz', which is not a method"),
        ({"seeds": [0, 0]}, "lists a value twice"),
        ({"methods": {"a b": []}}, "not a plain name"),
        ({"version": ""}, "benchmark.version"),
        ({"bootstrap_resamples": 10}, "benchmark.bootstrap_resamples=10"),
    ],
)
def test_bad_benchmarks_are_rejected(changes, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(").replace("[", r"\[")):
        config.validate_benchmark(_bench(**changes))


def test_shipped_benchmarks_plan_their_grid():
    for name, cells in (("smoke", 12), ("reduced", 165), ("leaderboard", 165)):
        data = cli_help.read_conf_yaml("benchmark", f"{name}.yaml")
        cfg = config.validate_benchmark(
            config.BenchConfig(benchmark=config.BenchmarkConfig(**data))
        )
        assert len(leaderboard.plan(cfg)) == cells, name
        assert data["version"] and len(data["trace_methods"]) == 2
    lb = cli_help.read_conf_yaml("benchmark", "leaderboard.yaml")
    assert len(lb["seeds"]) >= 5
    assert {"platoon4", "platoon8", "platoon4_1mhz"} <= set(lb["scenarios"])


def test_methods_must_share_the_evaluation_scenarios():
    cfg = _bench(budgets={"b": ["experiment.eval_episodes=3"]})
    cells = leaderboard.plan(cfg)
    with leaderboard.grid.hydra_compose():
        composed = {c: leaderboard.compose_cell(c, "cpu")[0] for c in cells}
    with pytest.raises(leaderboard.LeaderboardError, match="experiment.eval_episodes"):
        leaderboard.check_eval_pairing(composed)


def test_bench_rejects_unequal_evaluation_budgets_before_running(tmp_path, capsys):
    code = cli.main(
        ["bench", "benchmark=smoke", f"out_dir={tmp_path / 'o'}",
         "benchmark.budgets.jocc_k075=['experiment.eval_intervals=3']"]
    )  # fmt: skip
    assert code == cli.EXIT_CONFIG_ERROR
    assert "must be evaluated on the same held-out scenarios" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_out_dir_of_another_definition_is_refused(tmp_path):
    cfg = _bench()
    cfg.out_dir = str(tmp_path)
    leaderboard.check_out_dir(cfg)  # empty: fine
    (tmp_path / leaderboard.MANIFEST_FILE).write_text(json.dumps(leaderboard.manifest(cfg)))
    leaderboard.check_out_dir(cfg)  # same definition: fine
    cfg.benchmark.description = "a new description changes no run"
    leaderboard.check_out_dir(cfg)
    cfg.benchmark.seeds = [0, 1, 2]
    with pytest.raises(leaderboard.LeaderboardError, match="benchmark.seeds"):
        leaderboard.check_out_dir(cfg)


def test_finished_cell_with_another_config_is_an_error(tmp_path):
    data = {"seed": 0, "experiment": {"jocc_iterations": 1}, "rra": {"kappa1": 0.5}}
    summary = {k: 0.0 for k in leaderboard.METRIC_KEYS}
    summary.update(iterations=1, config={**data, "device": "cuda", "progress": True})
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    assert leaderboard.complete_summary(tmp_path, data) is not None  # device may differ
    unfinished = {**data, "experiment": {"jocc_iterations": 2}}
    assert leaderboard.complete_summary(tmp_path, unfinished) is None
    with pytest.raises(leaderboard.LeaderboardError, match="rra.kappa1=0.5"):
        leaderboard.complete_summary(tmp_path, {**data, "rra": {"kappa1": 0.25}})
    (tmp_path / "summary.json").write_text("{truncated")
    assert leaderboard.complete_summary(tmp_path, data) is None


# --- the smoke benchmark end to end ---------------------------------------------------------


def _run_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [str(SCRIPT), *args], cwd=cwd, capture_output=True, text=True, timeout=600, env=env
    )


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    """`vdtn-marl bench benchmark=smoke` once for the tests below."""
    base = tmp_path_factory.mktemp("bench")
    out, report = base / "runs", base / "report"
    args = ("bench", "benchmark=smoke", f"out_dir={out}", f"report_dir={report}")
    result = _run_cli(*args, cwd=base)
    assert result.returncode == 0, result.stderr[-3000:]
    cfg = config.BenchConfig(
        benchmark=config.BenchmarkConfig(**cli_help.read_conf_yaml("benchmark", "smoke.yaml")),
        out_dir=str(out),
        report_dir=str(report),
    )
    return {"out": out, "report": report, "result": result, "cfg": cfg, "args": args, "cwd": base}


def _strict_json(path: Path):
    def no_constant(name):
        raise AssertionError(f"{path} holds {name}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=no_constant)


def test_smoke_writes_statistics_with_ordered_intervals(smoke):
    cfg = smoke["cfg"]
    data = _strict_json(smoke["report"] / leaderboard.STATS_JSON)
    b = cfg.benchmark
    assert (data["benchmark"], data["version"]) == (b.name, b.version)
    assert data["command"].startswith("vdtn-marl bench benchmark=smoke")
    assert data["cells"] == {"total": 12, "complete": 12}
    assert list(data["statistics"]) == b.scenarios
    for scenario, by_method in data["statistics"].items():
        assert list(by_method) == list(b.methods)
        for method, metrics in by_method.items():
            assert set(metrics) == set(leaderboard.METRIC_KEYS)
            runs = [r for r in data["runs"] if (r["scenario"], r["method"]) == (scenario, method)]
            delivering = sum(r["cam_delivery_rate"] > 0 for r in runs)
            for key, stat in metrics.items():
                assert set(stat) == set(leaderboard.STAT_KEYS)
                # latency is undefined (null) for a run that delivered no CAM
                expected = delivering if key in leaderboard.CAM_LATENCY_KEYS else len(b.seeds)
                assert stat["n"] == expected, (method, key)
                if expected == 0:
                    assert stat["mean"] is None
                    continue
                for name in ("mean", "ci_low", "ci_high", "std"):
                    assert math.isfinite(stat[name]), (method, key, name)
                assert stat["ci_low"] <= stat["mean"] <= stat["ci_high"], (method, key)
    runs = data["runs"]
    assert len(runs) == 12
    assert {r["version"] for r in runs} == {b.version}
    for run in runs:
        for key in ("control_cost", "gap_error_abs_m", "v2i_throughput_mbps_per_link", "evoi"):
            assert math.isfinite(run[key])


def test_smoke_writes_marl_eval_json_and_csv(smoke):
    b = smoke["cfg"].benchmark
    raw = _strict_json(smoke["report"] / leaderboard.MARL_EVAL_JSON)
    assert list(raw) == [f"vdtn-{b.name}-v{b.version}"]
    (tasks,) = raw.values()
    keys = None
    for algorithms in tasks.values():
        assert list(algorithms) == list(b.methods)
        for runs in algorithms.values():
            assert list(runs) == [f"seed_{s}" for s in b.seeds]
            for run in runs.values():
                assert list(run)[-1] == "absolute_metrics" and "step_count" in run["step_1"]
                keys = keys or set(run["absolute_metrics"])
                assert set(run["absolute_metrics"]) == keys  # same metrics in every run
                for values in run["absolute_metrics"].values():
                    assert len(values) == 1 and math.isfinite(values[0])
    assert {"control_cost", "v2i_throughput_mbps_per_link"} <= keys
    with open(smoke["report"] / leaderboard.STATS_CSV, newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == len(b.scenarios) * len(b.methods) * len(leaderboard.METRICS)
    assert {r["version"] for r in rows} == {b.version}
    with open(smoke["report"] / leaderboard.RUNS_CSV, newline="", encoding="utf-8") as handle:
        assert len(list(csv.DictReader(handle))) == 12


def test_smoke_writes_markdown_and_plots(smoke):
    b = smoke["cfg"].benchmark
    text = (smoke["report"] / leaderboard.REPORT_FILE).read_text(encoding="utf-8")
    assert f"`{b.name}` v{b.version}" in text
    assert "vdtn-marl bench benchmark=smoke" in text
    assert "## platoon4" in text and "**" in text  # a table per scenario, best marked
    assert "- **leader traces**: platoon4: `udds` (EPA Urban" in text  # the scenario's default
    assert "training draws from the first 80% of each drive" in text
    for method in b.methods:
        assert f"| {method} |" in text
    for kind in PLOT_KINDS:
        path = smoke["report"] / f"leaderboard_platoon4_{kind}.png"
        assert path.is_file(), kind
        data = path.read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000, kind
        assert f"({path.name})" in text, kind
    cell = smoke["out"] / "platoon4" / "drra" / "seed0"
    for name in ("summary.json", "config.yaml", "metrics.csv", RAW_EVALUATION_FILE):
        assert (cell / name).is_file(), name


def test_smoke_resume_skips_finished_cells(smoke):
    cfg = smoke["cfg"]
    summaries = sorted(smoke["out"].rglob("summary.json"))
    assert len(summaries) == 12
    before = {p: p.stat().st_mtime_ns for p in summaries}
    redo = smoke["out"] / "platoon4" / "greedy" / "seed1" / "summary.json"
    redo.unlink()
    cfg.progress = False
    result = leaderboard.run_benchmark(cfg, command="test")
    assert [c.name for c in result.ran] == ["platoon4/greedy/seed1"]
    assert len(result.done) == 12 and not result.failed and not result.pending
    for path, mtime in before.items():
        if path != redo:
            assert path.stat().st_mtime_ns == mtime, path
    assert redo.is_file()
    assert result.report is not None and result.report["markdown"].is_file()
    # and through the CLI: nothing left to run
    again = _run_cli(*smoke["args"], cwd=smoke["cwd"])
    assert again.returncode == 0, again.stderr[-3000:]
    assert "0 cell(s) run now, 12 already complete" in again.stdout


def test_script_forwards_to_the_cli():
    result = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "leaderboard.py"), "--help"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert result.returncode == 0
    assert "bench benchmark=NAME" in result.stdout


def test_report_names_each_scenarios_leader_traces():
    from vdtn_marl.leaderboard.report import _traces_line

    def cell(scenario, traces, trace_path=None):
        data = {"scenario": {"traces": traces, "trace_path": trace_path}}
        return leaderboard.Cell(scenario, "m", 0, ()), (data, None)

    composed = dict(
        [
            cell("a", "synthetic"),
            cell("b", "udds"),
            cell("c", "synthetic"),
            cell("d", "csv", "data/drive.csv"),
        ]
    )
    line = _traces_line(composed)
    assert line.startswith("- **leader traces**: a, c: `synthetic` (bounded stochastic")
    assert "evaluation draws traces training never saw); b: `udds` (EPA Urban" in line
    assert "the first 80% of each drive, evaluation from the last 20%)" in line
    assert line.endswith("d: `csv` file `drive.csv`, divided into train and eval parts")
