"""Does CAM delivery rise across JOCC iterations? Per-iteration evaluation of benchmark cells.

Each learned-RRA cell of a benchmark run (``vdtn-marl bench``) evaluates the acting system
after every JOCC iteration (π*, π̃, RRA, then evaluation) and logs it in the cell's
``evaluation.csv``, one row per JOCC iteration. This script reads those rows for the chosen
methods of one scenario and reports, per JOCC iteration, the mean over seeds with its 95%
Student-t interval of the CAM delivery rate, the |gap error| (m), the |speed error| (m/s) and
the V2I throughput per link (Mbps), and the paired change from the first to the last
iteration. It reads finished runs only; it trains nothing.

    python benchmarks/jocc_iterations.py outputs/bench/reduced-v3.0 \
        --methods jocc_k050,drra,throughput          # writes results/jocc_iterations.json
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch
from rich.console import Console
from rich.table import Table

from vdtn_marl.io.files import EVALUATION_FILE, SUMMARY_FILE, atomic_write_json, read_csv_rows
from vdtn_marl.reporting.benchmarking import ci_summary, parse_names, provenance

RESULTS = Path(__file__).parent / "results" / "jocc_iterations.json"
METRICS = (
    ("cam_delivery_rate", "CAM delivery"),
    ("gap_error_abs_m", "|gap error| (m)"),
    ("speed_error_abs_mps", "|speed error| (m/s)"),
    ("v2i_throughput_mbps_per_link", "V2I per link (Mbps)"),
)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", type=Path, help="a benchmark's out_dir (<scenario>/<method>/seed<k>/)")
    p.add_argument("--scenario", default="platoon4")
    p.add_argument("--methods", default="jocc_k050,drra,throughput", help="comma-separated")
    p.add_argument("--output", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if not (args.runs / args.scenario).is_dir():
        p.error(f"runs={args.runs}: no folder {args.scenario}/ (a benchmark's out_dir)")
    present = tuple(sorted(d.name for d in (args.runs / args.scenario).iterdir() if d.is_dir()))
    args.methods = parse_names("--methods", args.methods, present)
    return args


def method_rows(runs: Path, scenario: str, method: str) -> dict[int, list[dict[str, str]]]:
    """seed → the evaluation rows (one per JOCC iteration) of the method's complete cells."""
    cells = {}
    for cell in sorted((runs / scenario / method).glob("seed*")):
        if (cell / SUMMARY_FILE).is_file() and (cell / EVALUATION_FILE).is_file():
            cells[int(cell.name.removeprefix("seed"))] = read_csv_rows(cell / EVALUATION_FILE)
    if not cells:
        raise SystemExit(f"error: no complete cell in {runs / scenario / method}")
    lengths = {len(rows) for rows in cells.values()}
    if len(lengths) != 1:
        raise SystemExit(f"error: {method}: cells differ in JOCC iterations ({sorted(lengths)})")
    return cells


def summarise(cells: dict[int, list[dict[str, str]]]) -> dict:
    iterations = len(next(iter(cells.values())))
    out = {"seeds": sorted(cells), "iterations": []}
    for k in range(iterations):
        values = {
            m: torch.tensor([float(rows[k][m]) for rows in cells.values()]) for m, _ in METRICS
        }
        out["iterations"].append({m: ci_summary(v) for m, v in values.items()})
    out["last_minus_first"] = {
        m: ci_summary(torch.tensor([float(r[-1][m]) - float(r[0][m]) for r in cells.values()]))
        for m, _ in METRICS
    }
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    results = {m: summarise(method_rows(args.runs, args.scenario, m)) for m in args.methods}
    table = Table(title=f"{args.scenario}: per JOCC iteration, mean over seeds [95% t CI]")
    table.add_column("method")
    table.add_column("JOCC it.", justify="right")
    for _, label in METRICS:
        table.add_column(label, justify="right")
    for method, result in results.items():
        rows = [(str(k + 1), it) for k, it in enumerate(result["iterations"])]
        for name, stats in [*rows, ("last − first", result["last_minus_first"])]:
            cells = [f"{s['mean']:+.3f} [{s['low']:+.3f}, {s['high']:+.3f}]" for s in
                     (stats[m] for m, _ in METRICS)]  # fmt: skip
            table.add_row(f"{method} (n = {len(result['seeds'])})", name, *cells)
    Console(width=160).print(table)
    atomic_write_json(
        args.output,
        {
            **provenance("jocc_iterations"),
            "runs": str(args.runs),
            "scenario": args.scenario,
            "metrics": [m for m, _ in METRICS],
            "methods": results,
        },
    )
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
