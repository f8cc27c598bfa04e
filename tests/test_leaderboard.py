"""The leaderboard: statistics on known inputs, benchmark validation, and the `smoke` benchmark
run end to end through `vdtn-marl bench` (files, schema, CI ordering, plots, resume)."""

from __future__ import annotations

import csv
import json
import math
import os
import subprocess
import sys
import warnings
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


T_4_975 = 2.7764451051977987  # t quantile, 4 degrees of freedom, 0.975 (tables: 2.776)


def test_t_interval_of_a_small_sample_by_hand():
    # [1, 2, 3, 4, 5]: mean 3, s = sqrt(2.5) = 1.5811, half-width 2.7764 * 1.5811 / sqrt(5)
    half = T_4_975 * math.sqrt(2.5) / math.sqrt(5)
    assert half == pytest.approx(1.963243, abs=1e-6)
    for mean, low, high in (
        leaderboard.t_ci([1, 2, 3, 4, 5]),
        leaderboard.mean_ci([1, 2, 3, 4, 5]),  # t is the default
        leaderboard.mean_ci([5, 4, 3, 2, 1], confidence=0.95, interval="t"),
    ):
        assert mean == 3.0
        assert (low, high) == (pytest.approx(3 - half, abs=1e-9), pytest.approx(3 + half, abs=1e-9))
    stats = leaderboard.aggregate([1.0, 2.0, 3.0, 4.0, 5.0])
    assert (stats["ci_low"], stats["ci_high"]) == (pytest.approx(1.036757), pytest.approx(4.963243))
    assert stats["ci_method"] == "t"
    # 90%: t(4, 0.95) = 2.1318
    _, low, high = leaderboard.t_ci([1, 2, 3, 4, 5], confidence=0.9)
    assert high - 3 == pytest.approx(2.131847 * math.sqrt(2.5 / 5), abs=1e-6)
    assert low == pytest.approx(3 - (high - 3))


def test_aggregate_known_values():
    values = [1.0, 2.0, 3.0, 4.0, 10.0]
    stats = leaderboard.aggregate(values)
    assert stats["n"] == 5
    assert stats["mean"] == pytest.approx(4.0)
    assert stats["std"] == pytest.approx(np.std(values, ddof=1))
    half = T_4_975 * float(np.std(values, ddof=1)) / math.sqrt(5)
    assert (stats["ci_low"], stats["ci_high"]) == (pytest.approx(4 - half), pytest.approx(4 + half))
    assert stats["ci_low"] < 1.0  # a t interval may leave the sample's range
    assert stats["iqm"] is None and stats["iqm_ci_method"] is None  # 5 < MIN_RUNS_FOR_IQM
    boot = leaderboard.aggregate(values, resamples=5000, interval="percentile")
    assert boot["ci_method"] == "percentile" and boot["mean"] == pytest.approx(4.0)
    # a percentile bootstrap of the mean stays inside the sample's range, and is narrower
    assert 1.0 <= boot["ci_low"] < 4.0 < boot["ci_high"] <= 10.0
    assert boot["ci_high"] - boot["ci_low"] < 0.75 * (stats["ci_high"] - stats["ci_low"])
    bca = leaderboard.aggregate(values, resamples=5000, interval="bca")
    assert bca["ci_method"] == "bca"
    assert bca["ci_low"] < 4.0 < bca["ci_high"]
    assert (bca["ci_low"], bca["ci_high"]) != (boot["ci_low"], boot["ci_high"])


def test_iqm_needs_ten_runs():
    assert leaderboard.MIN_RUNS_FOR_IQM == 10
    nine = leaderboard.aggregate([1, 2, 3, 4, 5, 6, 7, 8, 100], resamples=1000)
    assert nine["n"] == 9 and nine["mean"] == pytest.approx(136 / 9)
    assert all(nine[k] is None for k in ("iqm", "iqm_ci_low", "iqm_ci_high", "iqm_ci_method"))
    ten = leaderboard.aggregate([1, 2, 3, 4, 5, 6, 7, 8, 9, 100], resamples=1000)
    assert ten["iqm"] == pytest.approx(5.5)  # 2 cut on each side: mean of 3..8
    assert ten["iqm_ci_method"] == "bca"  # no t interval for the IQM: BCa under interval=t
    assert ten["iqm_ci_low"] < 5.5 < ten["iqm_ci_high"] < 100
    assert ten["ci_method"] == "t"
    boot = leaderboard.aggregate([1, 2, 3, 4, 5, 6, 7, 8, 9, 100], 1000, interval="percentile")
    assert boot["iqm_ci_method"] == "percentile" and boot["iqm"] == pytest.approx(5.5)


def test_bca_falls_back_to_the_percentile_bootstrap_on_degenerate_samples():
    # the IQM's jackknife values of nine equal runs and one other are all equal: BCa undefined
    values = [0.0] * 9 + [1.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning escapes, no NaN bound
        for interval in ("t", "bca"):
            stats = leaderboard.aggregate(values, resamples=1000, interval=interval)
            assert stats["iqm"] == 0.0 and stats["iqm_ci_method"] == "percentile"
            assert stats["iqm_ci_low"] == 0.0 and math.isfinite(stats["iqm_ci_high"])
        # the mean's BCa interval is defined here and stays BCa
        assert stats["ci_method"] == "bca" and stats["ci_low"] <= 0.1 <= stats["ci_high"]
        point, low, high = leaderboard.bootstrap_ci(values, np.median, 500, method="bca")
        assert point == low == 0.0 and math.isfinite(high)


def test_interval_must_be_a_known_method():
    with pytest.raises(ValueError, match=r"interval='normal' is not allowed; choose one of t, bca"):
        leaderboard.aggregate([1.0, 2.0], interval="normal")
    with pytest.raises(ValueError, match=r"interval='t' is not allowed; choose one of bca, perc"):
        leaderboard.bootstrap_ci([1.0, 2.0], np.mean, method="t")


def test_t_interval_covers_at_its_level_where_the_percentile_bootstrap_does_not():
    """2000 samples of n = 5 from N(0, 1): the 95% t interval covers 0 in about 95% of them,
    the 95% percentile bootstrap (200 resamples each) in only about 83%."""
    samples = np.random.default_rng(12345).standard_normal((2000, 5))
    t_cover = np.mean([low <= 0.0 <= high for _, low, high in map(leaderboard.t_ci, samples)])
    boot_cover = np.mean(
        [
            low <= 0.0 <= high
            for _, low, high in (
                leaderboard.bootstrap_ci(x, np.mean, resamples=200, seed=i)
                for i, x in enumerate(samples)
            )
        ]
    )
    assert 0.93 <= t_cover <= 0.97, t_cover
    assert boot_cover < 0.91, boot_cover
    assert boot_cover > 0.75, boot_cover  # and it is an interval, not a point


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
    same = leaderboard.aggregate([1.0] * 10)
    assert same["ci_low"] == same["ci_high"] == same["mean"] == same["iqm"] == 1.0
    assert same["iqm_ci_low"] == same["iqm_ci_high"] == 1.0
    for interval in leaderboard.INTERVALS:  # zero width whatever the method
        for values in ([2.5], [3.0] * 4):
            stat = leaderboard.aggregate(values, interval=interval)
            assert stat["ci_low"] == stat["ci_high"] == stat["mean"], (interval, values)
            assert stat["ci_method"] == interval
    empty = leaderboard.aggregate([None, float("nan")])
    assert empty["n"] == 0 and all(empty[k] is None for k in leaderboard.STAT_KEYS if k != "n")


def test_bootstrap_ci_width_matches_normal_theory():
    x = np.random.default_rng(1).normal(0.0, 1.0, size=200)
    mean, low, high = leaderboard.bootstrap_ci(x, np.mean, resamples=5000)
    half_width = 1.96 * x.std(ddof=1) / math.sqrt(x.size)
    assert low < mean < high
    assert (high - low) / 2 == pytest.approx(half_width, rel=0.15)


def _paired_rows(a: list[float], b: list[float]) -> list[dict]:
    rows = []
    for method, values in (("a", a), ("b", b)):
        for seed, value in enumerate(values):
            rows.append({"scenario": "platoon4", "method": method, "seed": seed,
                         "control_cost": value})  # fmt: skip
    return rows


def test_paired_differences_get_a_t_interval_of_the_differences():
    b = [10.0, 20.0, 5.0, 40.0, 30.0]  # seeds differ a lot, the method difference little
    a = [x + d for x, d in zip(b, [0.1, 0.3, 0.2, 0.5, 0.4], strict=True)]
    benchmark = config.BenchmarkConfig(
        name="t", methods={"a": [], "b": []}, seeds=[0, 1, 2, 3, 4], trace_methods=["a", "b"]
    )
    paired = leaderboard.paired_differences(_paired_rows(a, b), benchmark)
    pair = paired["platoon4"]
    assert (pair["a"], pair["b"], pair["seeds"]) == ("a", "b", [0, 1, 2, 3, 4])
    diff = pair["differences"]["control_cost"]
    # differences 0.1..0.5: mean 0.3, s = sqrt(0.025), half-width t(4) * s / sqrt(5)
    half = T_4_975 * math.sqrt(0.025) / math.sqrt(5)
    assert diff["n"] == 5 and diff["ci_method"] == "t"
    assert diff["mean"] == pytest.approx(0.3)
    assert (diff["ci_low"], diff["ci_high"]) == (
        pytest.approx(0.3 - half), pytest.approx(0.3 + half),
    )  # fmt: skip
    assert diff["ci_low"] > 0  # paired: the method difference is clear despite the seeds
    unpaired = leaderboard.statistics(_paired_rows(a, b), benchmark)["platoon4"]
    assert unpaired["a"]["control_cost"]["ci_high"] - unpaired["a"]["control_cost"]["ci_low"] > 20
    benchmark.interval = "percentile"
    boot = leaderboard.paired_differences(_paired_rows(a, b), benchmark)["platoon4"]
    assert boot["differences"]["control_cost"]["ci_method"] == "percentile"
    assert 0.1 <= boot["differences"]["control_cost"]["ci_low"] < 0.3


def test_report_names_the_interval_and_why_the_iqm_is_missing():
    from vdtn_marl.leaderboard.report import _iqm_omitted_line

    text = leaderboard.describe_interval("t", 0.95, 2000)
    assert text["short"] == "95% Student-t CI"
    assert "scipy.stats.t" in text["mean"]
    assert text["iqm"].startswith("95% BCa bootstrap CI (2000 resamples")
    assert text["iqm"].endswith("; a t interval is not defined for the IQM)")
    assert leaderboard.describe_interval("bca", 0.95, 2000)["iqm"] == (
        "95% BCa bootstrap CI (2000 resamples, scipy.stats.bootstrap; percentile where BCa is "
        "undefined)"
    )
    assert leaderboard.describe_interval("bca")["short"] == "95% BCa bootstrap CI"
    boot = leaderboard.describe_interval("percentile", 0.9)
    assert boot["short"] == "90% percentile-bootstrap CI"
    assert boot["iqm"] == "90% percentile-bootstrap CI (10000 resamples, scipy.stats.bootstrap)"
    five = {m: {"control_cost": {"n": 5}} for m in ("a", "b")}
    assert _iqm_omitted_line(five) == (
        "IQM not reported: 5 run(s) per method, fewer than the 10 it needs (the middle half of "
        "fewer runs is too few values for a useful estimate)."
    )
    mixed = {"a": {"control_cost": {"n": 10}}, "b": {"control_cost": {"n": 9}}}
    assert _iqm_omitted_line(mixed).startswith("IQM not reported (b): 9 run(s)")
    assert _iqm_omitted_line({"a": {"control_cost": {"n": 10}}}) is None


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
        (
            {"interval": "normal"},
            "benchmark.interval='normal' is not allowed; choose one of t, bca, percentile",
        ),
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


def test_bench_rejects_an_unknown_interval_in_one_line(tmp_path, capsys):
    code = cli.main(
        ["bench", "benchmark=smoke", f"out_dir={tmp_path / 'o'}", "benchmark.interval=normal"]
    )
    assert code == cli.EXIT_CONFIG_ERROR
    err = capsys.readouterr().err.strip()
    assert err == (
        "error: benchmark.interval='normal' is not allowed; choose one of t, bca, percentile"
    )
    assert not (tmp_path / "o").exists()
    assert config.BenchmarkConfig().interval == "t"  # the shipped YAML files need no key


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
                assert stat["ci_method"] == "t" and stat["iqm"] is None, (method, key)
    method_info = data["statistics_method"]
    assert (method_info["interval_method"], method_info["iqm_interval_method"]) == ("t", "bca")
    assert method_info["interval"].startswith("95% Student-t CI")
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
    assert "mean with its 95% Student-t CI (mean ± t(n−1) · s/√n, scipy.stats.t)" in text
    assert "a t interval is not defined for the IQM" in text
    assert "seeds [95% Student-t CI]:" in text  # the paired differences
    assert "percentile-bootstrap" not in text
    assert text.count("IQM not reported: 2 run(s) per method, fewer than the 10") == len(
        b.scenarios
    )
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
