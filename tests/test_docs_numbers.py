"""Figures quoted in the README come from the committed, generated results (no retyping)."""

from __future__ import annotations

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
HEADLINE = json.loads((ROOT / "benchmarks/results/headline-v1.0/leaderboard.json").read_text())


def _one_line(text: str) -> str:
    return re.sub(r"\s+", " ", text)


def test_readme_quotes_the_headline_target_as_generated():
    criteria = {c["metric"]: c for c in HEADLINE["target"]["criteria"]}
    assert HEADLINE["target"]["status"] == "missed"
    gap, speed = criteria["gap_error_abs_m"], criteria["speed_error_abs_mps"]
    expected = (
        f"its |gap error| is {gap['estimate']:.2f} times DRRA's "
        f"[{gap['ci_low']:.2f}, {gap['ci_high']:.2f}] and its |speed error| "
        f"{speed['estimate']:.2f} times [{speed['ci_low']:.2f}, {speed['ci_high']:.2f}]"
    )
    assert expected in _one_line(README)


def test_readme_quotes_the_headline_cam_delivery_as_generated():
    stats = HEADLINE["statistics"][HEADLINE["target"]["scenario"]]
    jocc = 100 * stats[HEADLINE["target"]["method"]]["cam_delivery_rate"]["mean"]
    drra = 100 * stats[HEADLINE["target"]["reference"]]["cam_delivery_rate"]["mean"]
    assert f"({jocc:.1f} % delivered, DRRA {drra:.1f} %)" in _one_line(README)


HEADLINE_2 = json.loads((ROOT / "benchmarks/results/headline/leaderboard.json").read_text())


def test_readme_quotes_the_headline_2_target_as_generated():
    """`headline` 2.x's target (jocc_k050_ws against DRRA on platoon4 and platoon8), the
    opportunistic RRA's V2I beside it and the runs whose reference check failed, from the
    report in benchmarks/results/headline/."""
    target = HEADLINE_2["target"]
    assert HEADLINE_2["version"].startswith("2.") and target["status"] == "met"
    text = _one_line(README)
    assert f"`headline` {HEADLINE_2['version']}" in text
    for scenario in target["scenarios"]:
        criteria = {c["metric"]: c for c in target["criteria"] if c["scenario"] == scenario}
        gap, speed = criteria["gap_error_abs_m"], criteria["speed_error_abs_mps"]
        v2i = criteria["v2i_throughput_mbps_per_link"]
        stats = HEADLINE_2["statistics"][scenario]
        opp = stats["opportunistic"]["v2i_throughput_mbps_per_link"]["mean"]
        expected = (
            f"{scenario}: |gap error| {gap['estimate']:.2f} times DRRA's "
            f"[{gap['ci_low']:.2f}, {gap['ci_high']:.2f}], |speed error| "
            f"{speed['estimate']:.2f} times [{speed['ci_low']:.2f}, {speed['ci_high']:.2f}], "
            f"V2I {v2i['estimate']:+.3f} Mbps per link [{v2i['ci_low']:+.3f}, "
            f"{v2i['ci_high']:+.3f}] ({v2i['mean_method']:.3f} against "
            f"{v2i['mean_reference']:.3f}; the opportunistic RRA {opp:.3f})"
        )
        assert expected in text, expected
    runs, fails = HEADLINE_2["runs"], HEADLINE_2["reference_failures"]
    below = sorted({r["seed"] for r in fails if "causal MPC" in r["problems"]})
    above = [r for r in fails if "EVoI's interval lies above 0" in r["problems"]]
    expected = (
        f"The reference check fails in {len(fails)} of {len(runs)} runs: π* is below the "
        f"causal MPC on platoon4 seeds {below[0]} and {below[1]} (every method's cell), and "
        f"EVoI's interval lies above 0 in {len(above)} more"
    )
    assert len(below) == 2 and expected in text, expected


def _gap(name: str) -> dict:
    data = json.loads((ROOT / "benchmarks/results" / name).read_text())
    return data["pi_star_causal_mpc_gap_to_oracle_percent"]


def test_readme_quotes_pi_stars_gap_to_the_oracle_as_generated():
    """π* warm-started from the causal MPC against the MPC oracle: the city cycle
    (`training.json`), the highway cycle (`training_hwfet_64.json`) and cmap
    (`training_cmap.json`, with its best and worst seed)."""
    city, highway, cmap = (
        _gap(f) for f in ("training.json", "training_hwfet_64.json", "training_cmap.json")
    )
    expected = (
        f"{city['mean']:.1f} % above it on the held-out city cycle and {highway['mean']:.1f} % "
        f"on the highway cycle, but {cmap['mean']:.1f} % ({cmap['best_seed']:.1f} to "
        f"{cmap['worst_seed']:.1f} over 3 seeds) on `cmap`"
    )
    assert expected in _one_line(README)


def test_performance_page_quotes_the_side_by_side_run_as_generated():
    """docs/performance.md's side-by-side table comes from the committed JSON of
    benchmarks/throughput.py."""
    page = _one_line((ROOT / "docs/performance.md").read_text(encoding="utf-8"))
    file = "throughput_peer_liang.json"
    side = json.loads((ROOT / "benchmarks/results" / file).read_text())
    assert f"`benchmarks/results/{file}`" in page
    rows = {r["name"]: r for r in side["results"]}
    for name, digits in (
        ("TwoTimescaleEnv kappa1=0.5 (rollout VoI)", 2),
        ("DigitalTwin B=4096 torch/cpu", 0),
        ("DigitalTwin B=4096 torch/cpu, draw-ahead off", 0),
    ):
        r = rows[name]
        runs = r["peer_ratio_runs"]
        quoted = (
            f"{r['agent_steps_per_s']:,.0f} | {r['peer_ratio']:.{digits}f} "
            f"({min(runs):.{digits}f}–{max(runs):.{digits}f}) |"
        )
        assert quoted in page, (file, quoted)


def test_performance_page_quotes_the_stage_sweep_as_generated():
    """docs/performance.md's batch-size table and iteration estimates come from the committed
    JSON of benchmarks/stage_throughput.py."""
    page = _one_line((ROOT / "docs/performance.md").read_text(encoding="utf-8"))
    sweep = json.loads((ROOT / "benchmarks/results/stage_throughput.json").read_text())
    rows = [r for r in sweep["rows"] if "frames_per_s" in r]
    assert rows
    for r in rows:
        quoted = (
            f"{r['batch']} × {r['rollout_steps']} | {r['frames_per_s']:,.0f} | "
            f"{r['seconds_per_iteration']:.2f} | {r['update_s']:.2f} | "
            f"{r['ratio_to_reference']:.2f} | {r['cpu_ratio_to_reference']:.2f} | "
            f"{r['peak_rss_mb']:,.0f} |"
        )
        assert quoted in page, quoted
    paper, best = sweep["estimate_paper"], sweep["estimate"]
    quoted = (
        f"at the `paper` sizes {paper['first_iteration_min']:.1f} min (first) and "
        f"{paper['later_iteration_min']:.1f} min (later), at the fastest sizes measured "
        f"({best['chosen_batches']['control']} × "
    )
    assert quoted in page, quoted
    assert f"{best['first_iteration_min']:.1f} and {best['later_iteration_min']:.1f} min" in page


def test_performance_page_quotes_the_clean_whole_run_as_generated():
    """docs/performance.md's *A clean whole run* table comes from the committed JSON of
    studies/2026-12-06-paper-stage-timings/paper_stage_timings.py over that run."""
    page = _one_line((ROOT / "docs/performance.md").read_text(encoding="utf-8"))
    run = json.loads(
        (ROOT / "studies/2026-12-06-paper-stage-timings/paper_iteration_clean.json").read_text()
    )
    paper = run["runs"]["paper"]
    assert [m["complete"] for m in paper["measured"]] == [True, True]
    for m in paper["measured"]:
        st = m["stages"]
        quoted = (
            f"| {st['control_perfect'] / 60:.1f} | {st['control_impaired'] / 60:.1f} | "
            f"{st['rra'] / 60:.1f} | {st['evaluate'] / 60:.1f} | {m['wall_s'] / 60:.1f} | 30 |"
        )
        assert quoted in page, quoted
    peak = run["time_v"]["paper"]["peak_rss_mb"]
    assert f"peak RSS {peak:,.0f} MB" in page


def test_performance_page_quotes_the_sharded_collection_run_as_generated():
    """docs/performance.md's estimate for algo.collector_workers, and CHANGELOG.md's lines on
    it, come from the committed JSON of
    studies/2026-12-06-sharded-collection/sharded_collection.py."""
    page = _one_line((ROOT / "docs/performance.md").read_text(encoding="utf-8"))
    run = json.loads(
        (ROOT / "studies/2026-12-06-sharded-collection/sharded_collection.json").read_text()
    )
    rows = {r["stage"]: r for r in run["rows"]}
    e = run["estimate"]
    quoted = (
        f"take {e['one']['later_min']:.1f} min in one process, {e['sharded']['later_min']:.1f} "
        f"min with two workers and {e['sharded_threads']['later_min']:.1f} min with the update "
        f"on two threads too (first iteration {e['one']['first_min']:.1f}, "
        f"{e['sharded']['first_min']:.1f} and {e['sharded_threads']['first_min']:.1f} min)"
    )
    assert quoted in page, quoted
    learned = f"{rows['pi_tilde_learned']['one_over_sharded']:.2f}×"
    changelog = _one_line((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))
    assert f"learned RRA {learned} faster with 2 workers" in changelog
    assert (
        f"training stages {e['sharded']['later_min']:.1f} min against "
        f"{e['one']['later_min']:.1f}" in changelog
    )


def test_performance_page_quotes_pi_tildes_budget_at_the_paper_sizes_as_generated():
    """docs/performance.md quotes studies/2026-12-05-pi-tilde-budget/pi_tilde_budget.py's
    budget at the experiment=paper sizes (its JSON's ``budget.paper``)."""
    run = json.loads((ROOT / "studies/2026-12-05-pi-tilde-budget/pi_tilde_budget.json").read_text())
    paper = run["budget"]["paper"]
    assert paper["chosen_control_batch"] == 256 and not paper["reachable_at_the_floor"]
    page = _one_line((ROOT / "docs/performance.md").read_text(encoding="utf-8"))
    quoted = (
        f"it would need {paper['needed_speedup']:.2f}× at B = 256, against "
        f"{paper['floor_speedup_here']:.2f}× that its arithmetic allows"
    )
    assert quoted in page, quoted


def test_readme_quotes_the_default_runs_time_as_generated():
    """The README's time for the default run comes from that run's committed summary
    (benchmarks/results/default_run/)."""
    summary = json.loads((ROOT / "benchmarks/results/default_run/summary.json").read_text())
    assert summary["task"] == "jocc" and summary["warm_start"]["teacher"] == "causal_mpc"
    expected = (
        f"{summary['seconds'] / 60:.1f} min on a quiet 2-core CPU, "
        f"{summary['warm_start']['seconds'] / 60:.1f} of them π*'s warm start"
    )
    assert expected in _one_line(README), expected
