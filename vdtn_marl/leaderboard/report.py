"""The leaderboard's report: LEADERBOARD.md, the JSON/CSV statistics, marl-eval JSON and
plots of the complete cells, and the rich table that ``vdtn-marl bench`` prints.
"""

from __future__ import annotations

import datetime as _dt
import os
import platform
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from vdtn_marl import __version__
from vdtn_marl.data.profiles import TIME_SPLIT_TRAIN_FRACTION
from vdtn_marl.data.selection import split_in_time
from vdtn_marl.data.traces import trace_set_provenance
from vdtn_marl.errors import LeaderboardError
from vdtn_marl.experiment.compose import hydra_compose
from vdtn_marl.experiment.config import BenchConfig
from vdtn_marl.experiment.metrics import AOI_KEYS, METRICS
from vdtn_marl.experiment.reference import REFERENCE_WARNING, row_problems
from vdtn_marl.io.files import atomic_write_json, atomic_write_text, read_json
from vdtn_marl.leaderboard import pi_star
from vdtn_marl.leaderboard.grid import Cell, compose_cell, plan, with_submissions
from vdtn_marl.leaderboard.plots import write_plots
from vdtn_marl.leaderboard.stats import (
    IQM_TRIM,
    MIN_RUNS_FOR_IQM,
    best_methods,
    collect_runs,
    describe_interval,
    iqm_interval,
    is_extra_run,
    marl_eval_data,
    paired_differences,
    statistics,
)
from vdtn_marl.leaderboard.target import check_target, target_markdown
from vdtn_marl.leaderboard.videos import LeaderboardVideo, write_videos
from vdtn_marl.reporting.tables import is_finite

REPORT_FILE = "LEADERBOARD.md"
STATS_JSON = "leaderboard.json"
MARL_EVAL_JSON = "leaderboard_marl_eval.json"
STATS_CSV = "leaderboard.csv"
RUNS_CSV = "leaderboard_runs.csv"


def _fmt(value: Any) -> str:
    if not is_finite(value):
        return "–"
    value = float(value)
    if value != 0 and (abs(value) < 1e-3 or abs(value) >= 1e5):
        return f"{value:.3e}"
    return f"{value:.4g}"


def _stat_cell(stat: Mapping[str, Any], prefix: str = "", bold: bool = False) -> str:
    mean = stat.get(prefix or "mean")
    if not is_finite(mean):
        return "–"
    text = _fmt(mean)
    if bold:
        text = f"**{text}**"
    low, high = (
        stat.get(f"{prefix}_ci_low" if prefix else "ci_low"),
        stat.get(f"{prefix}_ci_high" if prefix else "ci_high"),
    )
    return f"{text}<br>[{_fmt(low)}, {_fmt(high)}]"


def _budget_lines(
    cfg: BenchConfig, composed: Mapping, rows: Sequence[Mapping[str, Any]]
) -> list[str]:
    b = cfg.benchmark
    first = next(iter(composed.values()))[0]
    e, a = first["experiment"], first["algo"]
    seconds = [float(r["seconds"]) for r in rows if is_finite(r.get("seconds"))]
    lines = [
        f"- **budget**: `experiment={b.experiment}`"
        + (f" with `{' '.join(b.overrides)}`" if b.overrides else "")
        + f"; {e['jocc_iterations']} JOCC iteration(s) per run; a PPO iteration collects "
        f"{a['num_envs']} scenarios × {a['rollout_steps']} control intervals (π*, π̃) or "
        f"{a.get('rra_num_envs', a['num_envs'])} scenarios × {a['rra_rollout_steps']} "
        "subframes (RRA agents); the Methods table lists the PPO iterations of each method",
        f"- **evaluation**: {e['eval_episodes']} held-out scenarios × {e['eval_intervals']} "
        f"control intervals ({e['eval_intervals'] * 0.05:g} s) per run, the same scenarios for "
        "every method (evaluation seed = run seed + 10⁹)",
        f"- **seeds**: {', '.join(str(s) for s in b.seeds)} ({len(b.seeds)} runs per scenario "
        "× method)" + _extra_seeds_text(cfg),
        _traces_line(composed),
    ]
    if seconds:
        lines.append(
            f"- **compute**: {len(seconds)} runs, {sum(seconds) / 60:.1f} min of run time in "
            "total, summed over the runs (wall time is shorter when shards run in parallel), "
            f"on {platform.machine()}, "
            f"{os.cpu_count()} CPU cores"
        )
    return lines


def _extra_seeds_text(cfg: BenchConfig) -> str:
    """The extra seeds' part of the seeds line (empty without ``benchmark.extra_seeds``)."""
    parts = []
    for scenario, by_method in (cfg.benchmark.extra_seeds or {}).items():
        groups: dict[tuple[int, ...], list[str]] = {}
        for method, seeds in by_method.items():
            if seeds:
                groups.setdefault(tuple(int(s) for s in seeds), []).append(method)
        if groups:
            text = "; ".join(
                f"{', '.join(methods)}: {', '.join(str(s) for s in seeds)}"
                for seeds, methods in groups.items()
            )
            parts.append(f"{scenario} — {text}")
    if not parts:
        return ""
    return (
        "; extra seeds (these cells have more runs, paired differences use the seeds both "
        "methods have): " + "; ".join(parts)
    )


def _traces_line(composed: Mapping) -> str:
    """The leader traces of each scenario, as composed (``scenario.traces``/``trace_path``),
    with the trace set's provenance and how training and evaluation divide it."""
    settings: dict[tuple[str, str | None], list[str]] = {}
    for cell, (data, _) in composed.items():
        key = (data["scenario"]["traces"], data["scenario"].get("trace_path"))
        if cell.scenario not in settings.setdefault(key, []):
            settings[key].append(cell.scenario)
    provenance = trace_set_provenance()
    train = TIME_SPLIT_TRAIN_FRACTION
    parts = []
    for (traces, trace_path), scenarios in settings.items():
        if trace_path:
            what = f"`{traces}` file `{Path(trace_path).name}`, divided into train and eval parts"
        elif split_in_time(traces):
            what = (
                f"`{traces}` ({provenance[traces]['description']}; recorded: training draws "
                f"from the first {train:.0%} of each drive, evaluation from the last "
                f"{1 - train:.0%})"
            )
        elif traces in provenance and not provenance[traces].get("synthetic", True):
            what = (
                f"`{traces}` ({provenance[traces]['description']}; recorded: training and "
                "evaluation drives come from different vehicles)"
            )
        else:
            info = provenance.get(traces, {}).get("description", "generated")
            what = f"`{traces}` ({info}; generated: evaluation draws traces training never saw)"
        parts.append(f"{', '.join(scenarios)}: {what}")
    return "- **leader traces**: " + "; ".join(parts)


def _png(path: Path) -> str:
    return path.name


def _bca_fallbacks(stats: Mapping[str, Any], paired: Mapping[str, Any]) -> int:
    """How many intervals asked BCa and got the percentile bootstrap (BCa undefined)."""
    groups = [m for by_method in stats.values() for m in by_method.values()]
    groups += [p["differences"] for p in paired.values()]
    return sum(
        stat.get(key) == "percentile"
        for metrics in groups
        for stat in metrics.values()
        for key in ("ci_method", "iqm_ci_method")
    )


def _iqm_omitted_line(by_method: Mapping[str, Mapping[str, Any]]) -> str | None:
    """One line saying why the IQM is left out (fewer than MIN_RUNS_FOR_IQM runs)."""
    short = {
        method: metrics["control_cost"]["n"]
        for method, metrics in by_method.items()
        if metrics["control_cost"]["n"] < MIN_RUNS_FOR_IQM
    }
    if not short:
        return None
    counts = sorted(set(short.values()))
    n = ", ".join(str(c) for c in counts)
    which = "" if len(short) == len(by_method) else f" ({', '.join(short)})"
    return (
        f"IQM not reported{which}: {n} run(s) per method, fewer than the {MIN_RUNS_FOR_IQM} "
        "it needs (the middle half of fewer runs is too few values for a useful estimate)."
    )


def reference_failures(rows: Sequence[Mapping[str, Any]]) -> list[dict[str, Any]]:
    """The runs that fail the reference check (:mod:`vdtn_marl.experiment.reference`): scenario,
    method, seed and why."""
    return [
        {"scenario": r.get("scenario"), "method": r.get("method"), "seed": r.get("seed"),
         "problems": problems}
        for r in rows
        if (problems := row_problems(r))
    ]  # fmt: skip


def _reference_lines(failures: Sequence[Mapping[str, Any]], n_runs: int) -> list[str]:
    if not failures:
        return [
            f"- **reference check**: passed in all {n_runs} runs (π* on perfect observations is "
            "no worse than its start, and not significantly worse than the causal MPC, the CACC "
            "or the acting system)"
        ]
    lines = [
        f"- **reference check FAILED in {len(failures)} of {n_runs} runs**: "
        + REFERENCE_WARNING.rstrip(": ")
        + "; their EVoI and IVoI are not measured against an optimum:",
        "",
        "| scenario | method | seed | problem |",
        "|---|---|--:|---|",
    ]
    lines += [
        f"| {f['scenario']} | {f['method']} | {f['seed']} | {f['problems']} |" for f in failures
    ]
    return lines + [""]


def _markdown(
    cfg: BenchConfig,
    rows: Sequence[Mapping[str, Any]],
    stats: Mapping[str, Any],
    paired: Mapping[str, Any],
    plots: Mapping[str, Mapping[str, Path]],
    command: str,
    composed: Mapping,
    n_cells: int,
    n_done: int,
    dropped: Sequence[str],
    target: Mapping[str, Any] | None = None,
    marl_eval_left_out: int = 0,
    videos: Sequence[LeaderboardVideo] = (),
    shared_pi_star: Sequence[Mapping[str, Any]] = (),
) -> str:
    b = cfg.benchmark
    table_metrics = [m for m in METRICS if m.table]
    ci = describe_interval(b.interval, b.confidence, b.bootstrap_resamples)
    iqm_ci = describe_interval(iqm_interval(b.interval), b.confidence, b.bootstrap_resamples)
    fallbacks = _bca_fallbacks(stats, paired)
    lines = [
        f"# Leaderboard: `{b.name}` v{b.version}",
        "",
        f"- **benchmark**: `{b.name}`, version `{b.version}` (conf/benchmark/{b.name}.yaml)"
        + (f": {b.description.strip()}" if b.description else ""),
        f"- **command**: `{command}`" if command else "- **command**: (not recorded)",
        f"- **vdtn-marl**: {__version__}; written {_dt.date.today().isoformat()} on "
        f"{platform.machine()} ({platform.python_implementation()} "
        f"{platform.python_version()})",
        *_budget_lines(cfg, composed, rows),
        f"- **statistics**: per scenario × method across seeds (`benchmark.interval="
        f"{b.interval}`): mean with its {ci['mean']}; IQM (interquartile mean), where there "
        f"are ≥ {MIN_RUNS_FOR_IQM} runs, with its {ci['iqm']}; paired differences with the "
        "mean's interval. Every method is evaluated on the same held-out scenarios "
        "(same evaluation seed per run seed). **Bold**: best mean of a column (↓ lower is "
        "better, ↑ higher); EVoI = J̃ − J* (discounted return of the acting system minus that "
        "of π* with perfect observation, per follower) has no best.",
    ]
    if cfg.submissions:
        lines.append(
            f"- **submissions**: {', '.join(cfg.submissions)}: methods of the user's own "
            "(`submissions`), not part of the definition, run on the same scenarios and seeds "
            "and evaluated on the same held-out scenarios as its methods"
        )
    if fallbacks:
        lines.append(
            f"- **BCa undefined** for {fallbacks} interval(s) (degenerate samples, e.g. all runs "
            "but one or two equal): those use the percentile bootstrap (`ci_method` / "
            f"`iqm_ci_method` in {STATS_JSON})"
        )
    if n_done < n_cells:
        how = "rerun the command" if cfg.run else "rerun the command without `run=false`"
        lines.append(
            f"- **incomplete**: {n_done} of {n_cells} runs are complete; {how} to finish the others"
        )
    lines += _reference_lines(reference_failures(rows), len(rows))
    if target is not None:
        lines += ["", *target_markdown(target)]
    if shared_pi_star:
        lines += ["", *pi_star.report_markdown(shared_pi_star)]
    lines += [
        "",
        "## Methods",
        "",
        "| method | overrides (method; budget) | PPO iterations per run: π*, π̃, RRA |",
        "|---|---|---|",
    ]
    for method, overrides in b.methods.items():
        extra = b.budgets.get(method, [])
        text = f"`{' '.join(overrides)}`" + (f"; `{' '.join(extra)}`" if extra else "")
        if method in cfg.submissions:
            text += " (submission)"
        done = [r for r in rows if r["method"] == method]
        counts = "–"
        if done:
            counts = ", ".join(
                str(int(done[0].get(f"trainer_iterations.{k}") or 0))
                for k in ("pi_star", "pi_tilde", "rra")
            )
        lines.append(f"| {method} | {text} | {counts} |")
    for scenario, by_method in stats.items():
        lines += ["", f"## {scenario}", ""]
        header = ["method", "n"] + [
            m.label + {"min": " ↓", "max": " ↑"}.get(m.better or "", "") for m in table_metrics
        ]
        lines.append("| " + " | ".join(header) + " |")
        lines.append("|" + "|".join(["---"] + ["--:"] * (len(header) - 1)) + "|")
        best = {m.key: best_methods(by_method, m) for m in table_metrics}
        for method, metrics in by_method.items():
            cells = [method, str(metrics["control_cost"]["n"])]
            cells += [_stat_cell(metrics[m.key], bold=method in best[m.key]) for m in table_metrics]
            lines.append("| " + " | ".join(cells) + " |")
        if any(metrics["control_cost"]["iqm"] is not None for metrics in by_method.values()):
            lines += [
                "",
                f"<details><summary>IQM (interquartile mean) [{iqm_ci['short']}]</summary>",
                "",
                "| method | " + " | ".join(m.label for m in table_metrics) + " |",
                "|" + "|".join(["---"] + ["--:"] * len(table_metrics)) + "|",
            ]
            for method, metrics in by_method.items():
                cells = [method] + [_stat_cell(metrics[m.key], "iqm") for m in table_metrics]
                lines.append("| " + " | ".join(cells) + " |")
            lines += ["", "</details>"]
        omitted = _iqm_omitted_line(by_method)
        if omitted:
            lines += ["", omitted]
        pair = paired.get(scenario)
        if pair:
            lines += [
                "",
                f"Paired by seed (same held-out scenarios): **{pair['a']} − {pair['b']}**, "
                f"mean difference over {len(pair['seeds'])} seeds [{ci['short']}]:",
                "",
                "| " + " | ".join(m.label for m in table_metrics) + " |",
                "|" + "|".join(["--:"] * len(table_metrics)) + "|",
                "| "
                + " | ".join(_stat_cell(pair["differences"][m.key]) for m in table_metrics)
                + " |",
            ]
        missing_latency = [
            method
            for method, metrics in by_method.items()
            if metrics["cam_latency_ms_p50"]["n"] < metrics["control_cost"]["n"]
        ]
        if missing_latency:
            lines += [
                "",
                "CAM latency is undefined for a run that delivered no CAM; those runs are left "
                "out of the latency columns (their n is smaller): "
                + ", ".join(
                    f"{m} ({by_method[m]['cam_latency_ms_p50']['n']} of "
                    f"{by_method[m]['control_cost']['n']})"
                    for m in missing_latency
                )
                + ".",
            ]
        missing_aoi = [
            method
            for method, metrics in by_method.items()
            if min(metrics[k]["n"] for k in AOI_KEYS) < metrics["control_cost"]["n"]
        ]
        if missing_aoi:
            lines += [
                "",
                "Age of Information is missing from runs written before vdtn-marl reported it, "
                "and peak AoI is undefined for a run that delivered no CAM; those runs are left "
                "out of the AoI columns: "
                + ", ".join(
                    f"{m} (AoI {by_method[m]['aoi_ms_mean']['n']}, peak AoI "
                    f"{by_method[m]['peak_aoi_ms_mean']['n']} of "
                    f"{by_method[m]['control_cost']['n']})"
                    for m in missing_aoi
                )
                + ".",
            ]
        scenario_plots = plots.get(scenario, {})
        captions = {
            "pareto_methods": "V2I per link against |gap error|, every method",
            "pareto_methods_cost": "V2I per link against control cost, every method",
            "error_traces": "Gap and speed errors over time",
            "v2i_throughput": "V2I throughput per link",
            "cam_delivery": "CAM delivery rate",
            "aoi": "Age of Information",
            "cam_latency_cdf": "CAM latency CDF",
            "pareto_kappa1": "κ1 Pareto front",
            "control_cost": "Control cost",
            "training_curves": "Training curves",
        }
        if scenario_plots:
            lines.append("")
            for kind, caption in captions.items():
                if kind in scenario_plots:
                    lines.append(f"![{scenario}: {caption}]({_png(scenario_plots[kind])})")
        mine = [v for v in videos if v.cell.scenario == scenario]
        if mine:
            lines += [
                "",
                "Videos (one frame per control interval) of the held-out evaluation scenario with "
                "the highest (best) and the lowest (worst) control return: "
                + ", ".join(
                    f"[{v.cell.method} seed {v.cell.seed} {v.label} (scenario "
                    f"{v.scenario_index})]({_png(v.path)})"
                    for v in mine
                )
                + ".",
            ]
    lines += [
        "",
        "## Files",
        "",
        f"- `{STATS_JSON}`: the statistics above and every run's metrics",
        f"- `{STATS_CSV}`: statistics, one row per scenario × method × metric",
        f"- `{RUNS_CSV}`: one row per run (all summary metrics)",
        f"- `{MARL_EVAL_JSON}`: the runs in marl-eval's raw-data format",
    ]
    if dropped:
        lines[-1] += f" (left out, not finite in every run: {', '.join(dropped)})"
    if marl_eval_left_out:
        lines[-1] += (
            f"; the {marl_eval_left_out} run(s) of `extra_seeds` are left out, since marl-eval "
            "needs the same runs for every task and algorithm (they are in the other files)"
        )
    return "\n".join(lines) + "\n"


def write_report(
    cfg: BenchConfig,
    command: str = "",
    cells: Sequence[Cell] | None = None,
    composed: Mapping | None = None,
) -> dict[str, Path]:
    """Aggregate the complete cells of ``cfg.out_dir`` and write the report files (see the
    module doc) into ``cfg.report_dir`` (default ``out_dir``); returns ``{kind: path}``."""
    import pandas as pd

    cells = list(cells if cells is not None else plan(cfg))
    if composed is None:
        with hydra_compose():
            composed = {cell: compose_cell(cell, cfg.device) for cell in cells}
    report_dir = Path(cfg.report_dir or cfg.out_dir)
    report_dir.mkdir(parents=True, exist_ok=True)
    definition = asdict(cfg.benchmark)
    cfg = with_submissions(cfg)  # the user's methods beside the benchmark's
    b = cfg.benchmark
    rows = collect_runs(cfg, cells, composed)
    if not rows:
        raise LeaderboardError(f"no complete run in {cfg.out_dir}; nothing to report")
    stats = statistics(rows, b)
    paired = paired_differences(rows, b)
    plots = write_plots(cfg, rows, stats, report_dir)
    videos = write_videos(cfg, cells, composed, report_dir) if cfg.video else []
    marl_eval, dropped = marl_eval_data(rows, b)
    marl_eval_left_out = sum(is_extra_run(r, b) for r in rows)
    target = check_target(rows, b)
    shared_pi_star = pi_star.report_rows(b, cells, cfg.out_dir)  # benchmark.pi_star
    ci = describe_interval(b.interval, b.confidence, b.bootstrap_resamples)
    fallbacks = _bca_fallbacks(stats, paired)
    header = {
        "benchmark": b.name,
        "version": b.version,
        "vdtn_marl_version": __version__,
        "command": command,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "definition": definition,
        **({"submissions": {k: list(v) for k, v in cfg.submissions.items()}}
           if cfg.submissions else {}),
    }  # fmt: skip
    written: dict[str, Path] = {}
    written["json"] = atomic_write_json(
        report_dir / STATS_JSON,
        {
            **header,
            "statistics_method": {
                "interval_method": b.interval,
                "interval": f"{ci['mean']} across seeds, of means and of paired differences",
                "confidence": b.confidence,
                "resamples": b.bootstrap_resamples,
                "iqm": f"scipy.stats.trim_mean(values, {IQM_TRIM}) where n >= {MIN_RUNS_FOR_IQM} "
                "(else null)",
                "iqm_interval_method": iqm_interval(b.interval),
                "iqm_interval": ci["iqm"],
                "bca_fallback": "where BCa is undefined (degenerate samples) the percentile "
                "bootstrap is used; ci_method / iqm_ci_method name the interval of each "
                f"statistic ({fallbacks} fallback(s) here)",
                "non_finite": "left out (n counts the finite values)",
            },
            "cells": {"total": len(cells), "complete": len(rows)},
            "metrics": {
                m.key: {"label": m.label.replace("\\", ""), "better": m.better} for m in METRICS
            },
            "statistics": stats,
            "paired_differences": paired,
            **({"target": target} if target is not None else {}),
            "reference_failures": reference_failures(rows),
            **({"shared_pi_star": shared_pi_star} if shared_pi_star else {}),
            "runs": rows,
        },
    )
    written["marl_eval"] = atomic_write_json(report_dir / MARL_EVAL_JSON, marl_eval)
    stat_rows = [
        {
            "benchmark": b.name,
            "version": b.version,
            "scenario": scenario,
            "method": method,
            "metric": metric,
            **values,
        }
        for scenario, by_method in stats.items()
        for method, metrics in by_method.items()
        for metric, values in metrics.items()
    ]
    written["csv"] = atomic_write_text(
        report_dir / STATS_CSV, pd.DataFrame(stat_rows).to_csv(index=False)
    )
    written["runs_csv"] = atomic_write_text(
        report_dir / RUNS_CSV, pd.DataFrame(rows).to_csv(index=False)
    )
    written["markdown"] = atomic_write_text(
        report_dir / REPORT_FILE,
        _markdown(
            cfg,
            rows,
            stats,
            paired,
            plots,
            command,
            composed,
            len(cells),
            len(rows),
            dropped,
            target,
            marl_eval_left_out,
            videos,
            shared_pi_star,
        ),
    )
    for scenario, kinds in plots.items():
        for kind, path in kinds.items():
            written[f"{scenario}/{kind}"] = path
    for video in videos:
        written[f"{video.cell.scenario}/video_{video.cell.method}_{video.label}"] = video.path
    return written


def print_leaderboard(path: str | Path, console: Any = None) -> None:
    """Print the mean [CI] of the main metrics per scenario from ``leaderboard.json``."""
    import sys

    from rich.console import Console
    from rich.table import Table

    data = read_json(path)
    console = console or Console(width=None if sys.stdout.isatty() else 160)
    shown = (
        "control_cost",
        "gap_error_abs_m",
        "cam_delivery_rate",
        "v2i_throughput_mbps_per_link",
        "evoi",
    )
    labels = {m.key: m.label.replace("\\", "") for m in METRICS}
    for scenario, by_method in data["statistics"].items():
        table = Table(title=f"{data['benchmark']} v{data['version']}: {scenario}")
        table.add_column("method")
        table.add_column("n", justify="right")
        for key in shown:
            table.add_column(labels[key], justify="right")
        for method, metrics in by_method.items():
            cells = [method, str(metrics["control_cost"]["n"])]
            for key in shown:
                s = metrics[key]
                cells.append(
                    f"{_fmt(s['mean'])} [{_fmt(s['ci_low'])}, {_fmt(s['ci_high'])}]"
                    if is_finite(s["mean"])
                    else "–"
                )
            table.add_row(*cells)
        console.print(table)
    target = data.get("target")
    if target:
        console.print(
            f"target ({target['method']} against {target['reference']} on "
            f"{', '.join(target['scenarios'])}): {target['status']}"
        )
        for c in target["criteria"]:
            console.print(
                f"  {c['scenario']}, {c['label']} ({c['requirement']}, n = {c['n']}): "
                f"{c['verdict']}"
            )
