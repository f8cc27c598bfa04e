"""The benchmark's headline figure from a finished report, without rerunning anything: per
scenario, every method's V2I throughput per link against its mean |gap error| (and, in a second
file, against its control cost), at its mean over seeds with the report's intervals as error
bars; the baselines and the other learned-RRA methods labelled, the JOCC κ1 sweep a line.

    python benchmarks/pareto_figure.py        # benchmarks/results and benchmarks/results/headline
    python benchmarks/pareto_figure.py outputs/bench/reduced-v3.0/leaderboard.json

Each report's ``leaderboard.json`` (its ``statistics`` and ``runs``) gives
``pareto_<scenario>.png`` and ``pareto_<scenario>_control_cost.png`` beside it (``--out-dir``
to write elsewhere). The figures are those of the report's own ``pareto_methods`` plots
(``vdtn_marl.leaderboard.plots.write_pareto_methods``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from vdtn_marl.leaderboard.plots import PARETO_METHODS_X, method_roles, write_pareto_methods
from vdtn_marl.leaderboard.stats import describe_interval

RESULTS = Path(__file__).parent / "results"
REPORTS = (RESULTS / "leaderboard.json", RESULTS / "headline" / "leaderboard.json")
SUFFIXES = {"pareto_methods": "", "pareto_methods_cost": "_control_cost"}


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "reports",
        nargs="*",
        type=Path,
        default=list(REPORTS),
        help="leaderboard.json files (default: the committed full and headline reports)",
    )
    p.add_argument("--out-dir", type=Path, default=None, help="default: beside each report")
    return p.parse_args(argv)


def figures(report: Path, out_dir: Path | None = None) -> list[Path]:
    """Write the figures of every scenario of ``report`` (a ``leaderboard.json``); returns
    their paths."""
    data = json.loads(Path(report).read_text())
    for key in ("statistics", "runs"):
        if key not in data:
            raise ValueError(f"{report} has no {key!r} entry: not a leaderboard report")
    method_ = data.get("statistics_method", {})
    interval = describe_interval(
        method_.get("interval_method", "t"),
        method_.get("confidence", 0.95),
        method_.get("resamples", 10_000),
    )["short"]
    definition = data.get("definition", {})
    overrides = {**definition.get("methods", {}), **data.get("submissions", {})}
    name, version = data.get("benchmark", "?"), data.get("version", "?")
    note = f"vdtn-marl {data.get('vdtn_marl_version', '?')} · benchmark {name} v{version}"
    out_dir = Path(out_dir) if out_dir is not None else Path(report).parent
    written = []
    for scenario, by_method in data["statistics"].items():
        rows = [r for r in data["runs"] if r["scenario"] == scenario]
        roles = method_roles(rows, overrides)
        for kind, x in PARETO_METHODS_X.items():
            path = out_dir / f"pareto_{scenario}{SUFFIXES[kind]}.png"
            written.append(
                write_pareto_methods(by_method, roles, scenario, x, path, interval, note)
            )
    return written


def main(argv=None) -> int:
    args = parse_args(argv)
    for report in args.reports:
        for path in figures(report, args.out_dir):
            print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
