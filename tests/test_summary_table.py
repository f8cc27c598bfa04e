"""The summary a run prints at its end: grouped, with units, AoI and peak AoI defined."""

from __future__ import annotations

import io
import re

from rich.cells import cell_len
from rich.console import Console

from vdtn_marl.experiment.outputs import format_table
from vdtn_marl.reporting.tables import (
    SUMMARY_SECTIONS,
    print_summary,
    summary_sections,
    summary_terms,
)

SUMMARY = {
    "vdtn_marl_version": "0.1.0",
    "task": "jocc",
    "seed": 0,
    "kappa1": 0.5,
    "rra": "jocc",
    "trace_path": None,  # metadata not set in this run: left out
    "iterations": 1,
    "trainer_iterations": {"pi_star": 8, "rra": 16},
    "warm_start": {"teacher": "causal_mpc", "samples": 57600, "seconds": 170.0},
    "critic_warmup": {"batches": 10, "explained_variance": 0.9},
    "rra_warm_start": None,
    "seconds": 260.0,
    "control_cost": 0.025,
    "gap_error_abs_m": 0.05,
    "speed_error_abs_mps": 0.02,
    "collision_rate": 0.0,
    "cam_delivery_rate": 0.98,
    "cam_latency_ms_mean": 25.9,
    "cam_latency_ms_p50": None,  # undefined metric: shown as -
    "aoi_ms_mean": 51.6,
    "peak_aoi_ms_mean": 76.6,
    "v2i_throughput_mbps_per_link": 1.37,
    "evoi": -0.29,
    "evoi_ci_low": -0.37,
    "evoi_ci_high": -0.20,
    "ivoi_mean": 0.009,
    "eval_seconds": 4.5,
    "pi_star_minus_cacc": 0.19,
    "pi_star_minus_cacc_ci_low": 0.09,
    "pi_star_minus_cacc_ci_high": 0.28,
    "reference_ok": True,
    "reference_problems": "",
    "per_iteration": [{"jocc_iteration": 0, "evoi": -0.29}],
    "plots": ["a.png"],
    "config": {"seed": 0},
}


def _groups(summary):
    return {section: {key: (value, unit) for key, value, unit in rows}
            for section, rows in summary_sections(summary)}  # fmt: skip


def test_the_summary_is_grouped_in_order_with_units():
    groups = _groups(SUMMARY)
    assert list(groups) == list(SUMMARY_SECTIONS)
    assert set(groups["run"]) == {"vdtn_marl_version", "task", "seed", "kappa1", "rra"}
    assert "trainer_iterations.rra" in groups["training"]
    assert "warm_start.samples" in groups["training"]
    assert {"control_cost", "gap_error_abs_m", "collision_rate"} <= set(groups["control"])
    assert {"cam_delivery_rate", "aoi_ms_mean", "peak_aoi_ms_mean"} <= set(groups["radio"])
    assert {"evoi", "ivoi_mean"} <= set(groups["VoI"])
    assert {"pi_star_minus_cacc", "reference_ok"} <= set(groups["reference check"])
    assert set(groups["timing"]) == {"seconds", "eval_seconds", "warm_start.seconds"}
    assert groups["control"]["gap_error_abs_m"][1] == "m"
    assert groups["control"]["speed_error_abs_mps"][1] == "m/s"
    assert groups["radio"]["aoi_ms_mean"][1] == "ms"
    assert groups["radio"]["peak_aoi_ms_mean"][1] == "ms"
    assert "delivered" in groups["radio"]["cam_latency_ms_mean"][1]
    assert "Mbps" in groups["radio"]["v2i_throughput_mbps_per_link"][1]
    assert groups["timing"]["seconds"][1] == "s"
    # a mean and its CI are one row; an undefined metric is shown, unset metadata is not
    assert groups["VoI"]["evoi"][0] == "-0.29 [-0.37, -0.2]"
    assert not any(k.endswith(("_ci_low", "_ci_high")) for g in groups.values() for k in g)
    assert groups["radio"]["cam_latency_ms_p50"][0] == "-"
    flat = {k for g in groups.values() for k in g}
    assert "trace_path" not in flat and "rra_warm_start" not in flat and "plots" not in flat


def test_aoi_and_peak_aoi_are_defined_where_they_are_shown():
    terms = " ".join(summary_terms(SUMMARY))
    assert "AoI (Age of Information)" in terms and "peak AoI" in terms
    assert "delivered CAMs only" in terms
    bare = {k: v for k, v in SUMMARY.items() if "aoi" not in k}
    assert not any("AoI" in t for t in summary_terms(bare))


def test_the_printed_summary_has_groups_units_and_definitions():
    out = io.StringIO()
    print_summary(SUMMARY, console=Console(file=out, width=120), title="jocc summary")
    text = out.getvalue()
    assert "unit" in text and "value [95% CI]" in text
    positions = [text.index(f"│ {section} ") for section in SUMMARY_SECTIONS]
    assert positions == sorted(positions)
    (aoi_row,) = [line for line in text.splitlines() if "  aoi_ms_mean" in line]
    assert re.search(r"51\.6\s*│\s*ms\s*│", aoi_row)
    assert "AoI (Age of Information):" in text and "peak AoI:" in text


def test_a_narrow_terminal_wraps_units_and_keeps_keys_whole():
    out = io.StringIO()
    print_summary(SUMMARY, console=Console(file=out, width=72))
    text = out.getvalue()
    assert all(cell_len(line) <= 72 for line in text.splitlines())  # J̃: a combining mark
    assert "v2i_throughput_mbps_per_link" in text and "…" not in text


def test_the_plain_table_of_the_module_entry_point_is_grouped_too():
    text = format_table(SUMMARY)
    lines = text.splitlines()
    assert [line for line in lines if line.endswith(":")] == [f"{s}:" for s in SUMMARY_SECTIONS]
    (row,) = [line for line in lines if line.strip().startswith("gap_error_abs_m")]
    assert row.split()[-2:] == ["0.05", "m"]
    assert "AoI (Age of Information)" in text
