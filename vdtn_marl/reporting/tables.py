"""Tables of run results: a run's summary and the jobs of a sweep, one row per job.

A sweep's jobs are the directories with ``.hydra/`` or ``summary.json`` (:func:`find_jobs`);
:func:`load_job` reads a job's ``summary.json`` and its configuration (``config.yaml`` written by
the CLI, else ``.hydra/config.yaml``, plus ``.hydra/overrides.yaml``) into one flat row.
:func:`print_table` and :func:`print_summary` print them on the terminal.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from vdtn_marl.io.files import CONFIG_FILE, SUMMARY_FILE, read_json

CONTROL_COST = "control_cost"
V2I_THROUGHPUT = "v2i_throughput_mbps_per_link"

# Configuration keys copied into the table (when the job's config has them).
CONFIG_COLUMNS = (
    "scenario.name",
    "algo.name",
    "control.name",
    "rra.name",
    "rra.kappa1",
    "rra.kappa2",
    "experiment.name",
    "seed",
)

# Summary keys printed by `bench summarize`, in this order, when present (the CSV has all).
TABLE_METRICS = (
    CONTROL_COST,
    V2I_THROUGHPUT,
    "cam_delivery_rate",
    "cam_latency_ms_mean",
    "aoi_ms_mean",
    "gap_error_abs_m",
    "evoi",
)

# Short headers of the printed table (the CSV keeps the full keys).
SHORT_NAMES = {
    "rra.kappa1": "κ1",
    "rra.kappa2": "κ2",
    "scenario.name": "scenario",
    "algo.name": "algo",
    "control.name": "control",
    "rra.name": "rra",
    "experiment.name": "experiment",
    CONTROL_COST: "control cost",
    V2I_THROUGHPUT: "V2I Mbps/link",
    "cam_delivery_rate": "CAM delivered",
    "cam_latency_ms_mean": "CAM ms",
    "aoi_ms_mean": "AoI ms",
    "gap_error_abs_m": "|gap err| m",
    "speed_error_abs_mps": "|speed err| m/s",
    "collision_rate": "collisions",
    "evoi": "EVoI",
}


def flatten(data: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested mappings to ``{"a.b": value}``; lists are kept only when they hold no mapping."""
    out: dict[str, Any] = {}
    for key, value in data.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{name}."))
        elif isinstance(value, list | tuple):
            if not any(isinstance(v, Mapping | list | tuple) for v in value):
                out[name] = value
        else:
            out[name] = value
    return out


def find_jobs(root: str | Path) -> list[Path]:
    """Job directories under ``root``: those holding ``.hydra/`` or ``summary.json``."""
    root = Path(root)
    jobs = {p.parent for p in root.rglob(".hydra") if p.is_dir()}
    jobs |= {p.parent for p in root.rglob(SUMMARY_FILE) if p.is_file()}
    # A multirun's top directory has no .hydra of its own, but guard against odd layouts:
    # a directory is a job only if no other job lies inside it.
    return sorted(jobs, key=lambda p: (len(p.parts), _natural_key(p)))


def _natural_key(path: Path) -> tuple[tuple[str | int, ...], ...]:
    """Sort key reading the digits in ``path``'s parts as numbers: Hydra's job folders
    0, 1, 2, ..., 10, 11 come in job order, not as text (0, 1, 10, 11, 2)."""
    # re.split with a group alternates text (even places) and digits (odd places)
    return tuple(
        tuple(int(c) if i % 2 else c for i, c in enumerate(re.split(r"(\d+)", part)))
        for part in path.parts
    )


def _read_yaml(path: Path) -> Any:
    with open(path, encoding="utf-8") as handle:
        return yaml.safe_load(handle)


def load_job(job_dir: Path, root: Path) -> dict[str, Any]:
    """One table row: ``run``, ``overrides``, config columns, then the summary's scalars."""
    row: dict[str, Any] = {"run": str(job_dir.relative_to(root)) if job_dir != root else "."}
    overrides_file = job_dir / ".hydra" / "overrides.yaml"
    if overrides_file.is_file():
        overrides = _read_yaml(overrides_file) or []
        row["overrides"] = " ".join(str(o) for o in overrides)
    summary = read_json(job_dir / SUMMARY_FILE)
    if not isinstance(summary, Mapping):
        raise ValueError(f"{job_dir / SUMMARY_FILE} holds a {type(summary).__name__}, not a dict")
    config = None
    for config_file in (job_dir / CONFIG_FILE, job_dir / ".hydra" / "config.yaml"):
        if config_file.is_file():
            config = _read_yaml(config_file)
            break
    if not isinstance(config, Mapping):
        config = summary.get("config")  # the entry points copy the config into the summary
    if isinstance(config, Mapping):
        flat = flatten(config)
        row.update({key: flat[key] for key in CONFIG_COLUMNS if key in flat})
    if row.get("rra.kappa2") is None and isinstance(row.get("rra.kappa1"), int | float):
        row["rra.kappa2"] = 1.0 - row["rra.kappa1"]  # κ2 defaults to 1 − κ1
    for key, value in flatten(metrics_of(summary)).items():
        row.setdefault(key, value)
    return row


def metrics_of(summary: Mapping[str, Any]) -> dict[str, Any]:
    """A summary without its copy of the run's config (``config``)."""
    return {k: v for k, v in summary.items() if k != "config"}


def metric_column(columns: Sequence[str], key: str) -> str | None:
    """``key`` itself, else the one flattened column ending in ``.key`` (e.g. ``eval.key``)."""
    if key in columns:
        return key
    matches = [c for c in columns if c.endswith(f".{key}")]
    return matches[0] if len(matches) == 1 else None


def is_finite(value: Any) -> bool:
    """Whether ``value`` is a finite int or float (not a bool, None or NaN)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _format_cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    if isinstance(value, str):  # numbers read back from a CSV (a resumed run's rows)
        try:
            value = float(value) if value.strip().lower() not in ("nan", "inf", "-inf") else value
        except ValueError:
            return value
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def print_table(table: Any, console: Any = None, title: str | None = None) -> None:
    """Print ``table`` with rich: the run, the config columns that vary, the main metrics."""
    from rich.console import Console
    from rich.table import Table

    # Piped output (logs, CI) is not cut at rich's default 80 columns.
    console = console or Console(width=None if sys.stdout.isatty() else 160)
    config_cols = [
        c
        for c in CONFIG_COLUMNS
        if c in table.columns and (c == "rra.kappa1" or table[c].nunique(dropna=False) > 1)
    ]
    columns = list(table.columns)
    metric_cols = [m for m in (metric_column(columns, k) for k in TABLE_METRICS) if m]
    if not metric_cols:  # unknown summary layout: its first numeric columns
        metric_cols = [
            c
            for c in columns
            if c not in ("run", "overrides", *CONFIG_COLUMNS)
            and table[c].map(lambda v: is_finite(v) or v is None).all()
            and table[c].map(is_finite).any()
        ][:8]
    shown = ["run", *config_cols, *metric_cols]
    cells = [[_format_cell(row.get(c)) for c in shown] for _, row in table.iterrows()]
    rich_table = Table(title=title, show_lines=False)
    for i, column in enumerate(shown):
        name = SHORT_NAMES.get(column.rpartition(".")[2] if column.startswith("eval.") else column)
        rich_table.add_column(
            name or column.replace("_", " "),  # wraps at spaces; values are never cut
            justify="left" if column == "run" else "right",
            min_width=max([len(r[i]) for r in cells] + [2]),
        )
    for row_cells in cells:
        rich_table.add_row(*row_cells)
    console.print(rich_table)


def print_summary(summary: Mapping[str, Any], console: Any = None, title: str = "summary") -> None:
    """Print the scalar entries of one run's summary as a two-column rich table."""
    from rich.console import Console
    from rich.table import Table

    console = console or Console()
    rich_table = Table(title=title)
    rich_table.add_column("metric", overflow="fold")
    rich_table.add_column("value", justify="right", overflow="fold")  # a path wraps, never cut
    for key, value in flatten(metrics_of(summary)).items():
        if isinstance(value, list | tuple):
            continue
        rich_table.add_row(key, _format_cell(value))
    console.print(rich_table)
