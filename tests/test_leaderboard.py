"""The leaderboard: statistics on known inputs, benchmark validation, and the `smoke` benchmark
run end to end through `vdtn-marl bench` (files, schema, CI ordering, plots, resume)."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import subprocess
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vdtn_marl import cli, leaderboard
from vdtn_marl.cli import help as cli_help
from vdtn_marl.experiment import config
from vdtn_marl.experiment.compose import hydra_compose
from vdtn_marl.experiment.config import ConfigError
from vdtn_marl.io.files import RAW_EVALUATION_FILE

pytestmark = pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema")

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sys.executable).with_name("vdtn-marl")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
PLOT_KINDS = (
    "error_traces",
    "v2i_throughput",
    "cam_delivery",
    "control_cost",
    "aoi",
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
    for interval in leaderboard.INTERVALS:
        # one run: its value, but no interval (a zero-width one would read as certainty)
        one = leaderboard.aggregate([2.5], interval=interval)
        assert (one["n"], one["mean"]) == (1, 2.5)
        assert one["ci_low"] is one["ci_high"] is one["ci_method"] is one["std"] is None
        # identical runs: an interval of zero width, whatever the method
        same = leaderboard.aggregate([3.0] * 4, interval=interval)
        assert same["ci_low"] == same["ci_high"] == same["mean"] == 3.0, interval
        assert same["ci_method"] == interval
    same = leaderboard.aggregate([1.0] * 10)
    assert same["ci_low"] == same["ci_high"] == same["mean"] == same["iqm"] == 1.0
    assert same["iqm_ci_low"] == same["iqm_ci_high"] == 1.0
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
        (
            {"extra_seeds": {"platoon9": {"a": [5]}}},
            "benchmark.extra_seeds.platoon9 names no scenario of the benchmark; allowed: platoon4",
        ),
        (
            {"extra_seeds": {"platoon4": {"zz": [5]}}},
            "benchmark.extra_seeds.platoon4.zz names no method; allowed: a, b",
        ),
        (
            {"extra_seeds": {"platoon4": {"a": [5, "6"]}}},
            "benchmark.extra_seeds.platoon4.a=[5, '6'] lists '6', which is not an integer seed",
        ),
        (
            {"extra_seeds": {"platoon4": {"a": [5, 2.5]}}},
            "benchmark.extra_seeds.platoon4.a=[5, 2.5] lists 2.5, which is not an integer seed",
        ),
        (
            {"extra_seeds": {"platoon4": {"a": [5, 6, 5]}}},
            "benchmark.extra_seeds.platoon4.a=[5, 6, 5] lists 5 twice",
        ),
        (
            {"extra_seeds": {"platoon4": {"a": [1, 5]}}},
            "benchmark.extra_seeds.platoon4.a=[1, 5] lists 1, which benchmark.seeds=[0, 1] "
            "already runs",
        ),
        (
            {"target": {"method": "zz", "reference": "b", "error_metrics": ["gap_error_abs_m"]}},
            "benchmark.target.method='zz' is not a method of the benchmark; allowed: a, b",
        ),
        (
            {"target": {"method": "a", "reference": "a", "gain_metric": "evoi", "min_seeds": 2}},
            "benchmark.target.reference='a' is benchmark.target.method too",
        ),
        (
            {"target": {"method": "a", "reference": "b", "error_metrics": ["gap_error_m"]}},
            "benchmark.target names the metric 'gap_error_m', which the leaderboard does not "
            "report; allowed: control_cost, gap_error_abs_m",
        ),
        (
            {"target": {"scenarios": ["platoon8"], "method": "a", "reference": "b"}},
            "benchmark.target.scenarios names 'platoon8', which is not a scenario",
        ),
        (
            {"target": {"method": "a", "reference": "b", "min_seeds": 2}},
            "benchmark.target sets neither error_metrics nor gain_metric",
        ),
        (
            {"target": {"method": "a", "reference": "b", "gain_metric": "evoi", "min_seed": 2}},
            "benchmark.target.min_seed is not a known key; allowed keys of benchmark.target: "
            "error_metrics, gain_metric",
        ),
        (
            {"target": {"method": "a", "reference": "b", "gain_metric": "evoi"}},
            "benchmark.target.min_seeds=10 but the benchmark runs a and b on platoon4 for 2 "
            "common seed(s), so the target could never be decided",
        ),
        (
            {
                "target": {
                    "method": "a",
                    "reference": "b",
                    "gain_metric": "evoi",
                    "min_seeds": 2,
                    "max_error_ratio": 0.0,
                }
            },  # fmt: skip
            "benchmark.target.max_error_ratio=0.0 is outside the allowed range (0.0,",
        ),
    ],
)
def test_bad_benchmarks_are_rejected(changes, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        config.validate_benchmark(_bench(**changes))


def test_shipped_benchmarks_plan_their_grid():
    shipped = (
        ("smoke", 16), ("reduced", 205), ("leaderboard", 195), ("sensitivity", 25),
        ("headline", 80), ("value_fit", 15),
    )  # fmt: skip
    for name, cells in shipped:
        data = cli_help.read_conf_yaml("benchmark", f"{name}.yaml")
        cfg = config.validate_benchmark(
            config.BenchConfig(benchmark=config.BenchmarkConfig(**data))
        )
        assert len(leaderboard.plan(cfg)) == cells, name
        assert data["version"] and len(data["trace_methods"]) == 2
    lb = cli_help.read_conf_yaml("benchmark", "leaderboard.yaml")
    assert len(lb["seeds"]) >= 5
    assert {"platoon4", "platoon8", "platoon4_1mhz"} <= set(lb["scenarios"])


def test_reduced_checks_the_headline_target_on_ten_seeds():
    data = cli_help.read_conf_yaml("benchmark", "reduced.yaml")
    cfg = config.validate_benchmark(config.BenchConfig(benchmark=config.BenchmarkConfig(**data)))
    b = cfg.benchmark
    assert b.version == "3.1"
    t = b.target
    assert isinstance(t, config.BenchmarkTargetConfig)
    assert (t.scenarios, t.method, t.reference, t.max_error_ratio, t.min_seeds) == (
        ["platoon4"], "jocc_k050", "drra", 1.25, 10,
    )  # fmt: skip
    assert set(t.error_metrics) | {t.gain_metric} <= set(leaderboard.METRIC_KEYS)
    assert t.error_metrics == ["gap_error_abs_m", "speed_error_abs_mps"]
    assert t.gain_metric == "v2i_throughput_mbps_per_link"
    for method in ("jocc_k050", "drra", "throughput", "greedy", "opportunistic"):
        assert config.benchmark_seeds(b, "platoon4", method) == list(range(10)), method
    assert config.benchmark_seeds(b, "platoon8", "jocc_k050") == list(range(5))
    for method in ("jocc_k025", "jocc_k050", "jocc_k075", "drra", "throughput",
                   "no_augmentation", "cacc"):  # fmt: skip
        assert "experiment.jocc_iterations=3" in b.budgets[method], method
        assert "experiment.rra_iterations=16" in b.budgets[method], method
    assert not {"random", "round_robin", "greedy", "oracle"} & set(b.budgets)
    smoke = cli_help.read_conf_yaml("benchmark", "smoke.yaml")
    assert smoke["version"] == "2.2" and smoke["experiment"] == "smoke"
    assert not any("jocc_iterations" in str(o) for o in smoke.get("budgets", {}).values())
    sens = cli_help.read_conf_yaml("benchmark", "sensitivity.yaml")
    assert (sens["version"], sens["scenarios"]) == ("1.1", ["platoon4_noise90"])
    assert sens["overrides"] == data["overrides"]
    assert {m: sens["methods"][m] for m in sens["methods"]} == {
        m: data["methods"][m] for m in sens["methods"]
    }
    assert sens["budgets"] == {
        m: data["budgets"][m] for m in sens["methods"] if m in data["budgets"]
    }


def test_the_headline_and_value_fit_cells_are_reduced_cells():
    """`headline` and `value_fit` reuse `reduced` 3.1's runs: each of their JOCC and DRRA cells
    that `reduced` has is one of its cells, override for override (so it can be copied)."""

    def cells(name):
        data = cli_help.read_conf_yaml("benchmark", f"{name}.yaml")
        cfg = config.validate_benchmark(
            config.BenchConfig(benchmark=config.BenchmarkConfig(**data))
        )
        return {cell.name: cell.overrides for cell in leaderboard.plan(cfg)}

    reduced, headline, value_fit = cells("reduced"), cells("headline"), cells("value_fit")
    common = {
        name: o for name, o in headline.items()
        if name in reduced and name.split("/")[1] in ("jocc_k050", "drra")
    }  # fmt: skip
    assert len(common) == 30 and all(reduced[name] == o for name, o in common.items())
    shared = {name: o for name, o in value_fit.items() if "vfit" not in name}
    assert len(shared) == 10 and all(headline[name] == o for name, o in shared.items())
    fitted = {name: o for name, o in value_fit.items() if "vfit" in name}
    for name, overrides in fitted.items():
        plain = value_fit[name.replace("jocc_k050_vfit", "jocc_k050")]
        assert set(overrides) - set(plain) == {"rra.value_fit=acting"}, name


def test_extra_seeds_run_after_the_main_cells_seed_by_seed():
    cfg = _bench(
        methods={"a": ["rra=random"], "b": [], "c": []},
        extra_seeds={"platoon4": {"c": [3, 2], "a": [2]}},
    )
    config.validate_benchmark(cfg)
    names = [c.name for c in leaderboard.plan(cfg)]
    assert names == [
        *(f"platoon4/{m}/seed{s}" for s in (0, 1) for m in "abc"),
        "platoon4/a/seed2", "platoon4/c/seed2", "platoon4/c/seed3",
    ]  # fmt: skip
    cell = leaderboard.plan(cfg)[-1]
    assert cell.overrides[-1] == "seed=3" and cell.overrides[0] == "scenario=platoon4"
    assert config.benchmark_seeds(cfg.benchmark, "platoon4", "c") == [0, 1, 3, 2]
    assert config.benchmark_seeds(cfg.benchmark, "platoon4", "b") == [0, 1]
    # extra seeds decide runs: an out_dir of the same version without them is another definition
    assert "extra_seeds" in leaderboard.grid.RUN_FIELDS


def test_cells_select_by_glob_and_each_pattern_must_match():
    cfg = _bench(methods={"a": ["rra=random"], "b": []}, extra_seeds={"platoon4": {"b": [7]}})
    names = [c.name for c in leaderboard.plan(cfg)]
    assert config.selected_cells([], names) == names
    assert config.selected_cells(["*/b/*"], names) == [
        "platoon4/b/seed0", "platoon4/b/seed1", "platoon4/b/seed7"
    ]  # fmt: skip
    assert config.selected_cells(["platoon4/a/seed1", "*seed7"], names) == [
        "platoon4/a/seed1", "platoon4/b/seed7"
    ]  # fmt: skip
    cfg.cells = ["platoon4/a/*", "platoon4/c/*"]
    with pytest.raises(ConfigError, match=re.escape("cells: 'platoon4/c/*' matches no cell")):
        config.validate_benchmark(cfg)
    cfg.cells = "platoon4/a/*"
    with pytest.raises(ConfigError, match="cells="):
        config.validate_benchmark(cfg)


def test_bench_rejects_bad_extra_seeds_in_one_line(tmp_path, capsys):
    code = cli.main(
        ["bench", "benchmark=smoke", f"out_dir={tmp_path / 'o'}",
         "+benchmark.extra_seeds.platoon4={drra: [1, 7]}"]
    )  # fmt: skip
    assert code == cli.EXIT_CONFIG_ERROR
    err = capsys.readouterr().err.strip()
    assert err == (
        "error: benchmark.extra_seeds.platoon4.drra=[1, 7] lists 1, which benchmark.seeds=[0, 1] "
        "already runs; allowed: seeds outside benchmark.seeds"
    )
    assert not (tmp_path / "o").exists()


def test_methods_must_share_the_evaluation_scenarios():
    cfg = _bench(budgets={"b": ["experiment.eval_episodes=3"]})
    cells = leaderboard.plan(cfg)
    with hydra_compose():
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


@pytest.mark.slow
def test_a_cell_finished_before_aoi_was_reported_stays_finished(tmp_path):
    """A summary without the metrics that came later (AoI) is a finished cell: resuming a
    benchmark does not run it again, and its runs are left out of those columns only."""
    assert set(leaderboard.AOI_KEYS) <= set(leaderboard.METRIC_KEYS)
    data = {"seed": 0, "experiment": {"jocc_iterations": 1}}
    summary = {k: 0.0 for k in leaderboard.METRIC_KEYS if k not in leaderboard.AOI_KEYS}
    summary.update(iterations=1, config=data)
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    assert leaderboard.complete_summary(tmp_path, data) is not None
    stat = leaderboard.aggregate([summary.get("aoi_ms_mean")] * 3)
    assert stat["n"] == 0 and stat["mean"] is None


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
    cells = len(cfg.benchmark.methods) * len(cfg.benchmark.seeds)
    return {
        "out": out, "report": report, "result": result, "cfg": cfg, "args": args, "cwd": base,
        "cells": cells,
    }  # fmt: skip


def _strict_json(path: Path):
    def no_constant(name):
        raise AssertionError(f"{path} holds {name}")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=no_constant)


@pytest.mark.slow
def test_smoke_writes_statistics_with_ordered_intervals(smoke):
    cfg = smoke["cfg"]
    data = _strict_json(smoke["report"] / leaderboard.STATS_JSON)
    b = cfg.benchmark
    assert (data["benchmark"], data["version"]) == (b.name, b.version)
    assert data["command"].startswith("vdtn-marl bench benchmark=smoke")
    assert data["cells"] == {"total": smoke["cells"], "complete": smoke["cells"]}
    assert list(data["statistics"]) == b.scenarios
    for scenario, by_method in data["statistics"].items():
        assert list(by_method) == list(b.methods)
        for method, metrics in by_method.items():
            assert set(metrics) == set(leaderboard.METRIC_KEYS)
            runs = [r for r in data["runs"] if (r["scenario"], r["method"]) == (scenario, method)]
            delivering = sum(r["cam_delivery_rate"] > 0 for r in runs)
            for key, stat in metrics.items():
                assert set(stat) == set(leaderboard.STAT_KEYS)
                # latency and peak AoI are undefined (null) for a run that delivered no CAM
                expected = delivering if key in leaderboard.NO_DELIVERY_KEYS else len(b.seeds)
                assert stat["n"] == expected, (method, key)
                if expected == 0:
                    assert stat["mean"] is None
                    continue
                if expected == 1:  # one run (a latency of one delivering run): no interval
                    assert math.isfinite(stat["mean"]) and stat["ci_low"] is None, (method, key)
                    continue
                for name in ("mean", "ci_low", "ci_high", "std"):
                    assert math.isfinite(stat[name]), (method, key, name)
                assert stat["ci_low"] <= stat["mean"] <= stat["ci_high"], (method, key)
                assert stat["ci_method"] == "t" and stat["iqm"] is None, (method, key)
    method_info = data["statistics_method"]
    assert (method_info["interval_method"], method_info["iqm_interval_method"]) == ("t", "bca")
    assert method_info["interval"].startswith("95% Student-t CI")
    runs = data["runs"]
    assert len(runs) == smoke["cells"]
    assert {r["version"] for r in runs} == {b.version}
    for run in runs:
        for key in ("control_cost", "gap_error_abs_m", "v2i_throughput_mbps_per_link", "evoi"):
            assert math.isfinite(run[key])


@pytest.mark.slow
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
        assert len(list(csv.DictReader(handle))) == smoke["cells"]


@pytest.mark.slow
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
    assert "- **leader traces**: platoon4: `cmap` (recorded drives" in text  # the default
    assert "training and evaluation drives come from different vehicles" in text
    for method in b.methods:
        assert f"| {method} |" in text
    data = _strict_json(smoke["report"] / leaderboard.STATS_JSON)
    failed = [(r["method"], r["seed"]) for r in data["runs"] if not r["reference_ok"]]
    assert [(f["method"], f["seed"]) for f in data["reference_failures"]] == failed
    if failed:
        assert f"**reference check FAILED in {len(failed)} of {len(data['runs'])} runs**" in text
    else:
        assert f"**reference check**: passed in all {len(data['runs'])} runs" in text
    assert "AoI mean (ms) ↓" in text and "peak AoI (ms) ↓" in text
    for kind in PLOT_KINDS:
        path = smoke["report"] / f"leaderboard_platoon4_{kind}.png"
        assert path.is_file(), kind
        data = path.read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000, kind
        assert f"({path.name})" in text, kind
    cell = smoke["out"] / "platoon4" / "drra" / "seed0"
    for name in ("summary.json", "config.yaml", "metrics.csv", RAW_EVALUATION_FILE):
        assert (cell / name).is_file(), name


@pytest.mark.slow
def test_smoke_videos_show_the_trace_methods_best_and_worst_held_out_scenario(smoke, tmp_path):
    """video=true: per scenario and trace method, the first seed's run evaluated again on the
    same held-out scenarios; its best and worst scenario (by the acting system's control
    return, as the cell's own evaluation_raw.npz has them) as GIFs of one frame per interval."""
    iio = pytest.importorskip("imageio.v3")
    import numpy as np

    cfg = replace(smoke["cfg"], run=False, video=True, report_dir=str(tmp_path), progress=False)
    leaderboard.run_benchmark(cfg, command="test")
    b = cfg.benchmark
    text = (tmp_path / leaderboard.REPORT_FILE).read_text(encoding="utf-8")
    intervals = cli_help.read_conf_yaml("experiment", "smoke.yaml")["experiment"]["eval_intervals"]
    for scenario in b.scenarios:
        for method in b.trace_methods:
            seed = min(b.seeds)
            raw = np.load(smoke["out"] / scenario / method / f"seed{seed}" / "evaluation_raw.npz")
            expected = {"best": int(raw["returns"].argmax()), "worst": int(raw["returns"].argmin())}
            assert expected["best"] != expected["worst"]
            for label, index in expected.items():
                name = f"leaderboard_{scenario}_{method}_{label}.gif"
                assert iio.imread(tmp_path / name, index=None).shape[0] == intervals
                assert f"[{method} seed {seed} {label} (scenario {index})]({name})" in text
    assert not list(tmp_path.glob("*.tmp*")) and not list(smoke["report"].glob("*.gif"))


@pytest.mark.slow
def test_smoke_resume_skips_finished_cells(smoke):
    cfg = smoke["cfg"]
    summaries = sorted(smoke["out"].rglob("summary.json"))
    assert len(summaries) == smoke["cells"]
    before = {p: p.stat().st_mtime_ns for p in summaries}
    redo = smoke["out"] / "platoon4" / "greedy" / "seed1" / "summary.json"
    redo.unlink()
    cfg.progress = False
    # `cells` selects: a missing cell outside the patterns stays missing
    cfg.cells = ["platoon4/drra/*", "platoon4/cacc/seed0"]
    result = leaderboard.run_benchmark(cfg, command="test")
    assert not result.ran and len(result.done) == 3
    assert [c.name for c in result.pending] == ["platoon4/greedy/seed1"]
    cfg.cells = ["*/greedy/seed?"]
    result = leaderboard.run_benchmark(cfg, command="test")
    assert [c.name for c in result.ran] == ["platoon4/greedy/seed1"]
    assert len(result.done) == 2 and not result.failed and not result.pending
    cfg.cells = []
    result = leaderboard.run_benchmark(cfg, command="test")
    assert not result.ran
    assert len(result.done) == smoke["cells"] and not result.failed and not result.pending
    # run=false: nothing runs, the missing cell stays missing, the report is written
    redo.unlink()
    cfg.run = False
    result = leaderboard.run_benchmark(cfg, command="test")
    assert not result.ran and [c.name for c in result.pending] == ["platoon4/greedy/seed1"]
    assert not redo.exists() and result.report is not None
    cfg.run = True
    result = leaderboard.run_benchmark(cfg, command="test")
    assert [c.name for c in result.ran] == ["platoon4/greedy/seed1"]
    for path, mtime in before.items():
        if path != redo:
            assert path.stat().st_mtime_ns == mtime, path
    assert redo.is_file()
    assert result.report is not None and result.report["markdown"].is_file()
    # and through the CLI: nothing left to run
    again = _run_cli(*smoke["args"], cwd=smoke["cwd"])
    assert again.returncode == 0, again.stderr[-3000:]
    assert f"0 cell(s) run now, {smoke['cells']} already complete" in again.stdout


@pytest.mark.slow
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


# --- the target check ------------------------------------------------------------------------


T_3_975 = 3.182446305284263  # t quantile, 3 degrees of freedom, 0.975 (tables: 3.182)


def test_fieller_interval_of_a_ratio_by_hand():
    # y = [1, 2, 3, 4], x = [2, 3, 5, 6]: x̄ = 4, ȳ = 2.5, ratio 1.6; s_yy = 5/3, s_xx = 10/3,
    # s_xy = 7/3; q = t(3)² / 4 = 2.531991; a = 6.25 − q·5/3 = 2.030015,
    # b/2 = 10 − q·7/3 = 4.092021, c = 16 − q·10/3 = 7.560030;
    # roots (b/2 ∓ √((b/2)² − a·c)) / a = (4.092021 ∓ 1.182226) / 2.030015 = 1.43339, 2.59813
    x, y = [2.0, 3.0, 5.0, 6.0], [1.0, 2.0, 3.0, 4.0]
    q = T_3_975**2 / 4
    a, half_b, c = 6.25 - q * 5 / 3, 10 - q * 7 / 3, 16 - q * 10 / 3
    assert (a, half_b, c) == (
        pytest.approx(2.030015, abs=1e-6), pytest.approx(4.092021, abs=1e-6),
        pytest.approx(7.560030, abs=1e-6),
    )  # fmt: skip
    ratio, low, high = leaderboard.fieller_ratio_ci(x, y)
    assert ratio == pytest.approx(1.6)
    assert (low, high) == (pytest.approx(1.43339, abs=1e-5), pytest.approx(2.59813, abs=1e-5))
    assert low < ratio < high  # asymmetric around the ratio, unlike the delta method
    assert high - ratio > ratio - low
    # the defining property: at each bound the paired t statistic of x − ρ·y is ±t(3)
    for rho in (low, high):
        d = np.asarray(x) - rho * np.asarray(y)
        stat = d.mean() / (d.std(ddof=1) / 2.0)
        assert abs(stat) == pytest.approx(T_3_975, rel=1e-9)
    # and a bound above the interval is exactly one where the t interval of x − bound·y < 0
    for bound, below in ((2.7, True), (2.5, False), (1.3, False)):
        _, _, d_high = leaderboard.t_ci(list(np.asarray(x) - bound * np.asarray(y)))
        assert (d_high < 0) == below == (high < bound), bound
    # x = 1.2·y exactly: a zero-width interval at 1.2 (x − ρ·y = (1.2 − ρ)·y has the t
    # statistic of y, far from 0 here); one pair: zero width
    assert leaderboard.fieller_ratio_ci([12.0, 13.2, 14.4], [10.0, 11.0, 12.0]) == pytest.approx(
        (1.2, 1.2, 1.2)
    )
    # ... but with y = [1, 2, 3] (t statistic 3.46 < t(2) = 4.30) every ρ is in the set
    assert leaderboard.fieller_ratio_ci([1.2, 2.4, 3.6], [1.0, 2.0, 3.0])[1:] == (None, None)
    assert leaderboard.fieller_ratio_ci([3.0], [2.0]) == (1.5, 1.5, 1.5)
    # a reference mean not distinguishable from 0: unbounded; a zero mean: no ratio
    assert leaderboard.fieller_ratio_ci([1.0, 2.0, 1.5], [-1.0, 1.5, 0.2])[1:] == (None, None)
    assert leaderboard.fieller_ratio_ci([1.0, 2.0], [-1.0, 1.0]) == (None, None, None)


def _target_rows(
    errors: dict[str, list[float]], gain: dict[str, list[float]], scenario: str = "platoon4"
) -> list[dict]:
    """Rows of methods "jocc" and "drra" on ``scenario``: per seed, gap error = errors[m][k],
    speed error = errors[m][k] / 2, V2I throughput = gain[m][k]."""
    rows = []
    for method in ("jocc", "drra"):
        for seed, (error, v2i) in enumerate(zip(errors[method], gain[method], strict=True)):
            rows.append(
                {"scenario": scenario, "method": method, "seed": seed,
                 "gap_error_abs_m": error, "speed_error_abs_mps": error / 2,
                 "v2i_throughput_mbps_per_link": v2i}
            )  # fmt: skip
    return rows


def _target_benchmark(
    min_seeds: int = 10, scenarios: tuple[str, ...] = ("platoon4",)
) -> config.BenchmarkConfig:
    return config.BenchmarkConfig(
        name="t",
        scenarios=list(scenarios),
        methods={"jocc": [], "drra": []},
        seeds=list(range(10)),
        target=config.BenchmarkTargetConfig(
            scenarios=list(scenarios), method="jocc", reference="drra", max_error_ratio=1.25,
            error_metrics=["gap_error_abs_m", "speed_error_abs_mps"],
            gain_metric="v2i_throughput_mbps_per_link", min_seeds=min_seeds,
        ),
    )  # fmt: skip


DRRA_ERRORS = [0.40, 0.55, 0.30, 0.62, 0.48, 0.35, 0.51, 0.44, 0.58, 0.39]
DRRA_V2I = [1.30, 1.42, 1.25, 1.51, 1.38, 1.29, 1.47, 1.33, 1.40, 1.36]


def test_target_met_by_hand_made_summaries():
    # JOCC's errors 1.05-1.15 × DRRA's seed by seed, its throughput 0.05-0.09 Mbps higher
    factors = [1.05, 1.10, 1.15, 1.08, 1.12, 1.06, 1.14, 1.09, 1.11, 1.07]
    rows = _target_rows(
        {"jocc": [e * f for e, f in zip(DRRA_ERRORS, factors, strict=True)], "drra": DRRA_ERRORS},
        {"jocc": [v + 0.05 + 0.004 * k for k, v in enumerate(DRRA_V2I)], "drra": DRRA_V2I},
    )
    result = leaderboard.check_target(rows, _target_benchmark())
    assert result["status"] == "met"
    gap, speed, v2i = result["criteria"]
    assert [c["metric"] for c in result["criteria"]] == [
        "gap_error_abs_m", "speed_error_abs_mps", "v2i_throughput_mbps_per_link",
    ]  # fmt: skip
    for c in (gap, speed):
        assert c["kind"] == "error_ratio" and c["n"] == 10 and c["seeds"] == list(range(10))
        jocc = sum(e * f for e, f in zip(DRRA_ERRORS, factors, strict=True))
        assert c["estimate"] == pytest.approx(jocc / sum(DRRA_ERRORS))  # ratio of means
        assert c["ci_low"] < c["estimate"] < c["ci_high"] <= 1.25
        assert (c["status"], c["verdict"]) == ("met", "met")
    assert speed["estimate"] == pytest.approx(gap["estimate"])  # the same ratio, halved errors
    diffs = [0.05 + 0.004 * k for k in range(10)]
    mean, low, high = leaderboard.t_ci(diffs)
    assert (v2i["kind"], v2i["interval"]) == ("gain_difference", "t")
    assert (v2i["estimate"], v2i["ci_low"], v2i["ci_high"]) == (
        pytest.approx(mean), pytest.approx(low), pytest.approx(high),
    )  # fmt: skip
    assert mean == pytest.approx(0.068) and low > 0 and v2i["verdict"] == "met"
    from vdtn_marl.leaderboard.target import target_markdown

    text = "\n".join(target_markdown(result))
    assert text.startswith("## Target: jocc against drra on platoon4")
    assert "| platoon4 | \\|gap error\\| (m): ratio | 10 |" in text
    assert "| platoon4 | V2I throughput per link (Mbps): difference | 10 |" in text
    assert "| ratio ≤ 1.25 | met |" in text and "**Target met.**" in text


def test_target_missed_by_hand_made_summaries():
    # JOCC's errors twice DRRA's (±), its throughput lower by 0.10-0.14
    factors = [1.9, 2.1, 2.0, 1.95, 2.05, 2.0, 1.9, 2.1, 2.0, 2.0]
    jocc = [e * f for e, f in zip(DRRA_ERRORS, factors, strict=True)]
    rows = _target_rows(
        {"jocc": jocc, "drra": DRRA_ERRORS},
        {"jocc": [v - 0.10 - 0.004 * k for k, v in enumerate(DRRA_V2I)], "drra": DRRA_V2I},
    )
    result = leaderboard.check_target(rows, _target_benchmark())
    assert result["status"] == "missed"
    gap, _, v2i = result["criteria"]
    ratio = sum(jocc) / sum(DRRA_ERRORS)
    assert gap["estimate"] == pytest.approx(ratio) and gap["ci_low"] > 1.25
    assert gap["status"] == "missed" and gap["verdict"] == f"missed by {ratio - 1.25:.3g}"
    assert v2i["ci_high"] < 0 and v2i["estimate"] == pytest.approx(-0.118)
    assert v2i["verdict"] == "missed by 0.118"


def test_target_on_two_scenarios_is_met_only_when_met_on_both():
    factors = [1.05, 1.10, 1.15, 1.08, 1.12, 1.06, 1.14, 1.09, 1.11, 1.07]
    good = _target_rows(
        {"jocc": [e * f for e, f in zip(DRRA_ERRORS, factors, strict=True)], "drra": DRRA_ERRORS},
        {"jocc": [v + 0.05 + 0.004 * k for k, v in enumerate(DRRA_V2I)], "drra": DRRA_V2I},
        scenario="platoon4",
    )
    bad = _target_rows(
        {"jocc": [2 * e for e in DRRA_ERRORS], "drra": DRRA_ERRORS},
        {"jocc": [v + 0.05 + 0.004 * k for k, v in enumerate(DRRA_V2I)], "drra": DRRA_V2I},
        scenario="platoon8",
    )
    both = _target_benchmark(scenarios=("platoon4", "platoon8"))
    result = leaderboard.check_target(good + bad, both)
    assert result["scenarios"] == ["platoon4", "platoon8"] and result["status"] == "missed"
    by = {(c["scenario"], c["metric"]): c["status"] for c in result["criteria"]}
    assert len(by) == 6 and by[("platoon4", "gap_error_abs_m")] == "met"
    assert by[("platoon8", "gap_error_abs_m")] == "missed"
    assert by[("platoon8", "v2i_throughput_mbps_per_link")] == "met"
    # met on platoon4, and platoon8 has no cells yet: not decided, never met
    result = leaderboard.check_target(good, both)
    assert result["status"] == "not decided"
    from vdtn_marl.leaderboard.target import target_markdown

    text = "\n".join(target_markdown(result))
    assert text.startswith("## Target: jocc against drra on platoon4, platoon8")
    assert "| platoon8 | \\|gap error\\| (m): ratio | 0 |" in text


def test_target_not_decided_with_few_seeds_or_a_wide_interval():
    # 5 seeds of an otherwise clear miss: not decided, whatever the interval says
    rows = _target_rows(
        {"jocc": [2 * e for e in DRRA_ERRORS[:5]], "drra": DRRA_ERRORS[:5]},
        {"jocc": [v + 0.2 for v in DRRA_V2I[:5]], "drra": DRRA_V2I[:5]},
    )
    result = leaderboard.check_target(rows, _target_benchmark())
    assert result["status"] == "not decided"
    assert {c["verdict"] for c in result["criteria"]} == {"not decided: n = 5 < min_seeds = 10"}
    assert leaderboard.check_target(rows, _target_benchmark(min_seeds=5))["status"] == "missed"
    # ratios scattered around 1.25 and throughput gains around 0: both straddle
    factors = [0.9, 1.6, 1.1, 1.5, 1.0, 1.45, 1.2, 1.3, 1.05, 1.4]
    rows = _target_rows(
        {"jocc": [e * f for e, f in zip(DRRA_ERRORS, factors, strict=True)], "drra": DRRA_ERRORS},
        {"jocc": [v + (0.1 if k % 2 else -0.1) for k, v in enumerate(DRRA_V2I)], "drra": DRRA_V2I},
    )
    result = leaderboard.check_target(rows, _target_benchmark())
    assert result["status"] == "not decided"
    for c in result["criteria"]:
        assert c["ci_low"] < c["bound"] < c["ci_high"], c["metric"]
        bound = "1.25" if c["kind"] == "error_ratio" else "0"
        assert c["verdict"] == f"not decided: the interval straddles the bound ({bound})"
    # seeds pair by seed: a seed only one method has is left out, and so is a missing value
    rows = [r for r in rows if not (r["method"] == "drra" and r["seed"] == 9)]
    rows[0]["gap_error_abs_m"] = None
    result = leaderboard.check_target(rows, _target_benchmark(min_seeds=8))
    assert [c["n"] for c in result["criteria"]] == [8, 9, 9]
    assert result["criteria"][0]["seeds"] == list(range(1, 9))
    # no target: no target report
    assert leaderboard.check_target(rows, config.BenchmarkConfig(name="t")) is None


# --- a report of cells with different n (extra seeds), from hand-made run directories -------


def _fake_run(cfg: config.BenchConfig, cell, data: dict) -> None:
    k, method = cell.seed, cell.method
    shift = {"a": 0.0, "b": 0.1, "c": 0.3, "d": 0.4}[method]
    summary = {key: 1.0 + shift + 0.01 * k for key in leaderboard.METRIC_KEYS}
    summary.update(
        gap_error_abs_m=0.5 * (1 + shift) + 0.02 * k,
        v2i_throughput_mbps_per_link=1.0 - shift + 0.003 * k * k,
        iterations=1,
        seconds=2.0,
        trainer_iterations={"pi_star": 1, "pi_tilde": 1, "rra": 1 if method != "c" else 0},
        config=data,
    )
    directory = cell.directory(cfg.out_dir)
    directory.mkdir(parents=True)
    (directory / "summary.json").write_text(json.dumps(summary))


def _fake_grid(cfg: config.BenchConfig, cells) -> dict:
    """Every cell finished by :func:`_fake_run`; the composed config of each (for the report)."""
    composed = {}
    for cell in cells:
        data = {
            "seed": cell.seed,
            "scenario": {"name": "platoon4", "traces": "udds", "trace_path": None},
            "experiment": {"name": "t", "jocc_iterations": 1, "eval_episodes": 2,
                           "eval_intervals": 5},
            "algo": {"num_envs": 2, "rollout_steps": 8, "rra_rollout_steps": 16},
            "rra": {"name": "jocc", "kappa1": 0.5}, "control": {"name": "learned"},
        }  # fmt: skip
        _fake_run(cfg, cell, data)
        composed[cell] = (data, None)
    return composed


def test_report_of_cells_with_different_n(tmp_path):
    cfg = _bench(
        methods={"a": [], "b": [], "c": []},
        seeds=[0, 1, 2],
        extra_seeds={"platoon4": {"a": [3, 4], "b": [3, 4, 5], "c": [3]}},
        trace_methods=["a", "b"],
        target={"method": "a", "reference": "b", "error_metrics": ["gap_error_abs_m"],
                "gain_metric": "v2i_throughput_mbps_per_link", "min_seeds": 5},
    )  # fmt: skip
    cfg.out_dir, cfg.report_dir = str(tmp_path / "runs"), str(tmp_path / "report")
    config.validate_benchmark(cfg)
    cells = leaderboard.plan(cfg)
    assert len(cells) == 9 + 6
    composed = _fake_grid(cfg, cells)
    written = leaderboard.write_report(cfg, command="test", cells=cells, composed=composed)
    data = _strict_json(written["json"])
    assert data["cells"] == {"total": 15, "complete": 15}
    stats = data["statistics"]["platoon4"]
    assert {m: stats[m]["control_cost"]["n"] for m in "abc"} == {"a": 5, "b": 6, "c": 4}
    gap_a = [0.5 + 0.02 * k for k in range(5)]
    assert stats["a"]["gap_error_abs_m"]["mean"] == pytest.approx(np.mean(gap_a))
    pair = data["paired_differences"]["platoon4"]
    assert pair["seeds"] == [0, 1, 2, 3, 4]  # the seeds both have (b's seed 5 is left out)
    assert pair["differences"]["gap_error_abs_m"]["n"] == 5
    assert pair["differences"]["gap_error_abs_m"]["mean"] == pytest.approx(-0.05)
    target = data["target"]
    assert [c["n"] for c in target["criteria"]] == [5, 5]
    assert target["criteria"][0]["estimate"] == pytest.approx(0.54 / 0.59)  # 0.91 ≤ 1.25
    assert target["criteria"][0]["status"] == "met"
    assert target["criteria"][1]["estimate"] == pytest.approx(0.1)  # a − b = +0.1 each seed
    assert target["status"] == "met"
    assert len(data["runs"]) == 15
    # marl-eval needs the same runs everywhere: only the runs of `seeds`
    raw = _strict_json(written["marl_eval"])
    runs = raw["vdtn-t-v1"]["platoon4"]
    assert {m: list(r) for m, r in runs.items()} == {
        m: ["seed_0", "seed_1", "seed_2"] for m in "abc"
    }
    with open(written["runs_csv"], newline="", encoding="utf-8") as handle:
        assert len(list(csv.DictReader(handle))) == 15
    text = written["markdown"].read_text(encoding="utf-8")
    assert "## Target: a against b on platoon4" in text and "**Target met.**" in text
    assert text.index("## Target") < text.index("## Methods")
    assert "- **seeds**: 0, 1, 2 (3 runs per scenario × method); extra seeds" in text
    assert "methods have): platoon4 — a: 3, 4; b: 3, 4, 5; c: 3\n" in text
    assert "| a | 5 |" in text and "| b | 6 |" in text and "| c | 4 |" in text
    assert "mean difference over 5 seeds" in text
    assert "IQM not reported: 4, 5, 6 run(s) per method" in text
    assert "the 6 run(s) of `extra_seeds` are left out" in text
    for kind in ("v2i_throughput", "cam_delivery", "control_cost"):
        assert written[f"platoon4/{kind}"].read_bytes().startswith(PNG_MAGIC)
    # the rich table and the target verdicts
    from rich.console import Console

    console = Console(record=True, width=200)
    leaderboard.print_leaderboard(written["json"], console=console)
    printed = console.export_text()
    assert "target (a against b on platoon4): met" in printed
    # `bench summarize` tables every run, whatever the n of its method
    assert cli.main(["bench", "summarize", cfg.out_dir, "--csv", str(tmp_path / "s.csv")]) == 0
    with open(tmp_path / "s.csv", newline="", encoding="utf-8") as handle:
        table = list(csv.DictReader(handle))
    assert len(table) == 15
    assert sorted(r["run"] for r in table if "/b/" in r["run"]) == [
        f"platoon4/b/seed{k}" for k in range(6)
    ]
    # without a target: no target report
    cfg.benchmark.target = None
    written = leaderboard.write_report(cfg, command="test", cells=cells, composed=composed)
    assert "target" not in _strict_json(written["json"])
    assert "## Target" not in written["markdown"].read_text(encoding="utf-8")


# --- submissions: methods of the user's own beside the benchmark's ---------------------------


def test_submissions_run_on_every_seed_of_their_scenario_after_the_methods():
    cfg = _bench(methods={"a": ["rra=random"], "b": []}, extra_seeds={"platoon4": {"b": [3, 2]}})
    cfg.submissions = {"mine": ["rra=greedy"]}
    config.validate_benchmark(cfg)
    names = [c.name for c in leaderboard.plan(cfg)]
    assert names == [
        *(f"platoon4/{m}/seed{s}" for s in (0, 1) for m in ("a", "b", "mine")),
        "platoon4/b/seed2", "platoon4/mine/seed2", "platoon4/b/seed3", "platoon4/mine/seed3",
    ]  # fmt: skip
    mine = [c for c in leaderboard.plan(cfg) if c.method == "mine"][0]
    assert mine.overrides[2:4] == ("rra=greedy", "seed=0")  # its overrides, no budget
    # the definition is the benchmark's: the manifest keeps the submissions apart, and an
    # out_dir of the definition accepts runs with and without them
    written = leaderboard.manifest(cfg)
    assert "mine" not in written["benchmark"]["methods"]
    assert written["submissions"] == {"mine": ["rra=greedy"]}
    assert leaderboard.with_submissions(cfg).benchmark.methods["mine"] == ["rra=greedy"]


@pytest.mark.parametrize(
    ("submissions", "message"),
    [
        ({"a": ["rra=greedy"]}, "submissions.a has the name of a method"),
        ({"my method": ["rra=greedy"]}, "submissions.my method is not a plain name"),
        ({"mine": ["seed=3"]}, "submissions.mine sets 'seed=3'"),
        ({"mine": "rra=greedy"}, "submissions.mine='rra=greedy' must be a list"),
    ],
)
def test_bad_submissions_are_rejected(submissions, message):
    cfg = _bench()
    cfg.submissions = submissions
    with pytest.raises(ConfigError, match=re.escape(message)):
        config.validate_benchmark(cfg)


def test_out_dir_of_the_definition_takes_submissions(tmp_path):
    cfg = _bench()
    cfg.out_dir = str(tmp_path)
    (tmp_path / leaderboard.MANIFEST_FILE).write_text(json.dumps(leaderboard.manifest(cfg)))
    cfg.submissions = {"mine": ["rra=greedy"]}
    leaderboard.check_out_dir(cfg)  # the definition is unchanged
    cfg.benchmark.seeds = [0, 1, 2]
    with pytest.raises(leaderboard.LeaderboardError, match="benchmark.seeds"):
        leaderboard.check_out_dir(cfg)


def test_a_later_submission_keeps_the_earlier_ones_in_grid_and_report(tmp_path):
    first = _bench(methods={"a": [], "b": []}, seeds=[0, 1, 2])
    first.submissions = {"c": ["rra=greedy"]}
    first.out_dir, first.report_dir = str(tmp_path / "runs"), str(tmp_path / "report")
    config.validate_benchmark(first)
    composed = _fake_grid(first, leaderboard.plan(first))
    (tmp_path / "runs" / leaderboard.MANIFEST_FILE).write_text(
        json.dumps(leaderboard.manifest(first))
    )
    # a second job adds submission d: c, recorded in out_dir, stays beside it
    second = _bench(methods={"a": [], "b": []}, seeds=[0, 1, 2])
    second.submissions = {"d": ["rra=round_robin"]}
    second.out_dir, second.report_dir = first.out_dir, first.report_dir
    config.validate_benchmark(second)
    merged = leaderboard.with_recorded_submissions(second)
    assert merged.submissions == {"c": ["rra=greedy"], "d": ["rra=round_robin"]}
    cells = leaderboard.plan(merged)
    assert {c.method for c in cells} == {"a", "b", "c", "d"}
    composed.update(_fake_grid(merged, [c for c in cells if c.method == "d"]))
    written = leaderboard.write_report(merged, command="test", cells=cells, composed=composed)
    data = _strict_json(written["json"])
    assert list(data["statistics"]["platoon4"]) == ["a", "b", "c", "d"]
    assert data["submissions"] == {"c": ["rra=greedy"], "d": ["rra=round_robin"]}
    # the same name with other overrides is refused, naming it
    second.submissions = {"c": ["rra=random"]}
    with pytest.raises(leaderboard.LeaderboardError, match="submissions.c="):
        leaderboard.with_recorded_submissions(second)


def test_run_benchmark_keeps_recorded_submissions_in_the_manifest(tmp_path):
    first = _bench()
    first.submissions = {"c": ["rra=greedy"]}
    first.out_dir = str(tmp_path)
    (tmp_path / leaderboard.MANIFEST_FILE).write_text(json.dumps(leaderboard.manifest(first)))
    second = _bench()
    second.submissions = {"d": ["rra=round_robin"]}
    second.out_dir, second.run, second.report, second.progress = str(tmp_path), False, False, False
    result = leaderboard.run_benchmark(second, command="test")
    written = json.loads((tmp_path / leaderboard.MANIFEST_FILE).read_text())
    assert written["submissions"] == {"c": ["rra=greedy"], "d": ["rra=round_robin"]}
    assert {c.method for c in result.pending} == {"a", "b", "c", "d"}


def test_report_puts_a_submission_beside_the_methods(tmp_path):
    cfg = _bench(methods={"a": [], "b": []}, seeds=[0, 1, 2])
    cfg.submissions = {"c": ["rra=greedy"]}
    cfg.out_dir, cfg.report_dir = str(tmp_path / "runs"), str(tmp_path / "report")
    config.validate_benchmark(cfg)
    cells = leaderboard.plan(cfg)
    composed = _fake_grid(cfg, cells)
    written = leaderboard.write_report(cfg, command="test", cells=cells, composed=composed)
    data = _strict_json(written["json"])
    assert "c" not in data["definition"]["methods"] and data["submissions"] == {"c": ["rra=greedy"]}
    stats = data["statistics"]["platoon4"]
    assert list(stats) == ["a", "b", "c"]
    assert stats["c"]["gap_error_abs_m"]["mean"] == pytest.approx(0.5 * 1.3 + 0.02)
    markdown = written["markdown"].read_text()
    assert "| c | `rra=greedy` (submission) |" in markdown
    assert "- **submissions**: c:" in markdown
    row = [line for line in markdown.splitlines() if line.startswith("| c | 3 |")]
    assert len(row) == 1  # its row in the scenario's table, with its 3 runs
