"""The summary of a sweep: one table for its jobs and the κ1 Pareto front.

``vdtn-marl bench summarize SWEEP_DIR`` calls :func:`summarize_sweep`: it finds every job of a
Hydra sweep (:func:`~vdtn_marl.reporting.tables.find_jobs`), writes one CSV row per job
(:func:`~vdtn_marl.reporting.tables.load_job`) and a PNG of control cost against V2I throughput
per link, coloured by κ1, with the Pareto front of the κ1 sweep
(:func:`~vdtn_marl.reporting.plots.plot_kappa1_pareto`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from vdtn_marl.io.files import SUMMARY_FILE, atomic_write_text
from vdtn_marl.reporting.plots import plot_kappa1_pareto
from vdtn_marl.reporting.tables import (
    CONTROL_COST,
    V2I_THROUGHPUT,
    find_jobs,
    is_finite,
    load_job,
    metric_column,
)

TABLE_FILE = "summary.csv"
PARETO_FILE = "pareto_kappa1.png"


@dataclass
class SweepSummary:
    """What :func:`summarize_sweep` found and wrote."""

    table: Any  # pandas.DataFrame, one row per job with a summary.json
    missing: list[str] = field(default_factory=list)  # jobs without summary.json
    notes: list[str] = field(default_factory=list)  # warnings for the user, one line each
    csv_path: Path | None = None
    plot_path: Path | None = None


def summarize_sweep(
    root: str | Path,
    csv_path: str | Path | None = None,
    plot_path: str | Path | None = None,
    x: str = CONTROL_COST,
    y: str = V2I_THROUGHPUT,
) -> SweepSummary:
    """Collect every job under ``root`` into one table (CSV) and the κ1 Pareto plot (PNG).

    Defaults: ``root/summary.csv`` and ``root/pareto_kappa1.png``. Raises ``FileNotFoundError``
    when ``root`` is not a directory or holds no ``summary.json`` at all.
    """
    import pandas as pd

    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"{root} is not a directory")
    rows, missing, notes = [], [], []
    for job in find_jobs(root):
        if not (job / SUMMARY_FILE).is_file():
            missing.append(str(job.relative_to(root)) if job != root else ".")
            continue
        try:
            rows.append(load_job(job, root))
        except (OSError, ValueError, yaml.YAMLError) as exc:
            notes.append(f"skipped {job}: {type(exc).__name__}: {exc}")
    if missing:
        notes.append(
            f"{len(missing)} job(s) have no {SUMMARY_FILE} (failed, still running or not "
            f"started) and are left out: {', '.join(missing)}"
        )
    if not rows:
        raise FileNotFoundError(f"no {SUMMARY_FILE} under {root}; did the sweep's jobs finish?")

    table = pd.DataFrame(rows)
    summary = SweepSummary(table=table, missing=missing, notes=notes)
    summary.csv_path = atomic_write_text(csv_path or root / TABLE_FILE, table.to_csv(index=False))

    columns = {key: metric_column(list(table.columns), key) for key in (x, y)}
    absent = [key for key, column in columns.items() if column is None]
    if absent:
        notes.append(
            f"no Pareto plot: no job's {SUMMARY_FILE} has {' or '.join(map(repr, absent))} "
            f"(keys found: {', '.join(c for c in table.columns if c not in ('run', 'overrides'))})"
        )
        return summary
    x_col, y_col = columns[x], columns[y]
    incomplete = [
        r for r, a, b in zip(table["run"], table[x_col], table[y_col], strict=True)
        if not (is_finite(a) and is_finite(b))
    ]  # fmt: skip
    if incomplete:
        notes.append(
            f"{len(incomplete)} job(s) lack a finite {x!r} or {y!r} and are left out of the "
            f"plot: {', '.join(incomplete)}"
        )
    if len(incomplete) == len(table):
        notes.append("no Pareto plot: no job has both values")
        return summary
    summary.plot_path = plot_kappa1_pareto(
        table.rename(columns={x_col: x, y_col: y}), plot_path or root / PARETO_FILE, x, y
    )
    return summary
