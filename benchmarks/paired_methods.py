"""Paired differences between leaderboard methods, by seed, from a report's runs table.

A leaderboard report (``vdtn-marl bench``) pairs only its target's two methods. This script
reads the report's per-run table (``leaderboard_runs.csv``: one row per scenario × method ×
seed, every method evaluated on the same held-out scenarios for a given seed) and reports, for
each pair ``method:reference`` on one scenario, the mean over the seeds both have of the
per-seed difference method − reference with its 95% Student-t interval, for the CAM delivery
rate, the |gap error| (m), the control cost and the V2I throughput per link (Mbps). It reads
finished runs only; it trains nothing.

    python benchmarks/paired_methods.py benchmarks/results/leaderboard_runs.csv \
        --pairs jocc_k025:random,jocc_k050:random,jocc_k075:random,throughput:random,\
round_robin:greedy,greedy:oracle          # writes results/paired_platoon4.json
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import torch
from rich.console import Console
from rich.table import Table

from vdtn_marl.io.files import atomic_write_json, read_csv_rows
from vdtn_marl.reporting.benchmarking import ci_summary, parse_names, provenance

RESULTS_DIR = Path(__file__).parent / "results"
METRICS = (
    ("cam_delivery_rate", "CAM delivery"),
    ("gap_error_abs_m", "|gap error| (m)"),
    ("control_cost", "control cost"),
    ("v2i_throughput_mbps_per_link", "V2I per link (Mbps)"),
)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs_csv", type=Path, help="a report's leaderboard_runs.csv")
    p.add_argument("--scenario", default="platoon4")
    p.add_argument(
        "--pairs",
        default="jocc_k050:random,throughput:random",
        help="comma-separated method:reference pairs",
    )
    p.add_argument("--output", type=Path, help="default: results/paired_<scenario>.json")
    args = p.parse_args(argv)
    if not args.runs_csv.is_file():
        p.error(f"runs_csv={args.runs_csv}: no such file (a report's leaderboard_runs.csv)")
    rows = [r for r in read_csv_rows(args.runs_csv) if r.get("scenario") == args.scenario]
    if not rows:
        p.error(f"--scenario={args.scenario!r}: no runs of it in {args.runs_csv}")
    present = tuple(sorted({r["method"] for r in rows}))
    pairs = []
    for text in (t.strip() for t in args.pairs.split(",") if t.strip()):
        if text.count(":") != 1:
            p.error(f"--pairs: {text!r} is not method:reference")
        method, reference = (parse_names("--pairs", name, present)[0] for name in text.split(":"))
        if method == reference:
            p.error(f"--pairs: {text!r} pairs a method with itself")
        pairs.append((method, reference))
    if not pairs:
        p.error("--pairs: give at least one method:reference")
    args.rows, args.pairs = rows, pairs
    args.output = args.output or RESULTS_DIR / f"paired_{args.scenario}.json"
    return args


def by_seed(rows: list[dict[str, str]], method: str, metric: str) -> dict[int, float]:
    """seed → the metric of the method's run (runs without a finite value are left out)."""
    out = {}
    for row in rows:
        if row["method"] == method and row.get(metric) not in (None, ""):
            value = float(row[metric])
            if math.isfinite(value):
                out[int(row["seed"])] = value
    return out


def paired(rows: list[dict[str, str]], method: str, reference: str) -> dict:
    """Per metric: the seeds both runs have and the t interval of method − reference."""
    out = {}
    for metric, _ in METRICS:
        a, b = by_seed(rows, method, metric), by_seed(rows, reference, metric)
        seeds = sorted(set(a) & set(b))
        diff = torch.tensor([a[s] - b[s] for s in seeds], dtype=torch.float64)
        out[metric] = {"seeds": seeds, **ci_summary(diff)}
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    results = {f"{m} - {r}": paired(args.rows, m, r) for m, r in args.pairs}
    table = Table(title=f"{args.scenario}: method − reference, paired by seed [95% t CI]")
    table.add_column("pair")
    for _, label in METRICS:
        table.add_column(label, justify="right")
    for name, result in results.items():
        cells = []
        for metric, _ in METRICS:
            s = result[metric]
            cells.append(f"{s['mean']:+.4g} [{s['low']:+.4g}, {s['high']:+.4g}] (n={s['n']})")
        table.add_row(name, *cells)
    Console(width=180).print(table)
    atomic_write_json(
        args.output,
        {
            **provenance("paired_methods"),
            "runs_csv": str(args.runs_csv),
            "scenario": args.scenario,
            "metrics": [m for m, _ in METRICS],
            "pairs": results,
        },
    )
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
