"""Tables and plots of run results: one table for a sweep, the κ1 Pareto front.

``vdtn-marl bench summarize SWEEP_DIR`` calls :func:`summarize_sweep`: it finds every job of a
Hydra sweep (a directory with ``.hydra/`` or ``summary.json``), reads the job's ``summary.json``
and its configuration (``config.yaml`` written by the CLI, else ``.hydra/config.yaml``, plus
``.hydra/overrides.yaml``), and writes one CSV row per job and a PNG of control cost against
V2I throughput per link, coloured by κ1, with the Pareto front of the κ1 sweep.
"""

from __future__ import annotations

import io
import math
import re
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from vdtn_marl.runs import (
    CONFIG_FILE,
    SUMMARY_FILE,
    atomic_write_bytes,
    atomic_write_text,
    read_json,
)

CONTROL_COST = "control_cost"
V2I_THROUGHPUT = "v2i_throughput_mbps_per_link"
TABLE_FILE = "summary.csv"
PARETO_FILE = "pareto_kappa1.png"

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
    "gap_error_abs_m": "|gap err| m",
    "speed_error_abs_mps": "|speed err| m/s",
    "collision_rate": "collisions",
    "evoi": "EVoI",
}
AXIS_LABELS = {
    CONTROL_COST: "control cost (dimensionless; lower is better)",
    V2I_THROUGHPUT: "V2I throughput per link (Mbps)",
}


@dataclass
class SweepSummary:
    """What :func:`summarize_sweep` found and wrote."""

    table: Any  # pandas.DataFrame, one row per job with a summary.json
    missing: list[str] = field(default_factory=list)  # jobs without summary.json
    notes: list[str] = field(default_factory=list)  # warnings for the user, one line each
    csv_path: Path | None = None
    plot_path: Path | None = None


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


def pareto_mask(cost: Sequence[float], value: Sequence[float]) -> list[bool]:
    """True for the points no other point beats: lower-or-equal cost and higher-or-equal value,
    one of them strictly."""
    points = list(zip(cost, value, strict=True))
    mask = []
    for i, (c_i, v_i) in enumerate(points):
        dominated = any(
            c_j <= c_i and v_j >= v_i and (c_j < c_i or v_j > v_i)
            for j, (c_j, v_j) in enumerate(points)
            if j != i
        )
        mask.append(not dominated)
    return mask


def is_finite(value: Any) -> bool:
    """Whether ``value`` is a finite int or float (not a bool, None or NaN)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _label_points(ax: Any, xs: list[float], ys: list[float], labels: list[str]) -> None:
    """Label points to their right, moving labels up (with a leader line) so that labels of
    points closer than a line of text apart do not print on top of each other."""
    import numpy as np

    ax.autoscale_view()
    pixels = ax.transData.transform(np.column_stack([xs, ys]))
    per_point = ax.figure.dpi / 72.0  # pixels per typographic point
    gap = 11.0 * per_point  # one line of 8-point text
    placed: list[tuple[float, float]] = []  # (x, y) pixels of labels already placed
    for i in np.argsort(pixels[:, 1], kind="stable"):
        x_px, y_px = pixels[i]
        y_label = y_px
        for px, py in sorted(placed, key=lambda p: p[1]):
            if abs(px - x_px) < 60.0 * per_point and abs(py - y_label) < gap:
                y_label = py + gap
        placed.append((x_px, y_label))
        shift = (y_label - y_px) / per_point
        ax.annotate(
            labels[i], (xs[i], ys[i]), textcoords="offset points", xytext=(8, shift),
            fontsize=8, va="center",
            arrowprops={"arrowstyle": "-", "lw": 0.5, "color": "0.4"} if shift > 1 else None,
        )  # fmt: skip


def plot_kappa1_pareto(
    table: Any,
    path: str | Path,
    x: str = CONTROL_COST,
    y: str = V2I_THROUGHPUT,
    title: str = "κ1 sweep: control cost vs V2I throughput",
    note: str | None = None,
) -> Path:
    """Control cost (x) against V2I throughput per link (y), one point per job coloured by κ1;
    the mean over seeds of each configuration is marked and the Pareto front of the means is
    drawn. ``note`` is printed small under the axes (e.g. a benchmark's version). Writes a PNG
    atomically and returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = table[[c for c in table.columns if c in (x, y, "rra.kappa1", "seed", *CONFIG_COLUMNS)]]
    data = data[data[x].map(is_finite) & data[y].map(is_finite)].copy()
    if data.empty:
        raise ValueError(f"no job has finite values of both {x!r} and {y!r}")
    has_kappa = "rra.kappa1" in data.columns and data["rra.kappa1"].map(is_finite).all()

    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=120)
    if has_kappa:
        points = ax.scatter(
            data[x], data[y], c=data["rra.kappa1"], cmap="viridis", vmin=0.0, vmax=1.0,
            s=22, alpha=0.55, label="job (one seed)",
        )  # fmt: skip
        fig.colorbar(points, ax=ax, label="κ1 (weight of V2I throughput in the RRA reward)")
    else:
        ax.scatter(data[x], data[y], s=22, alpha=0.55, label="job")

    # Mean over seeds of every configuration that differs in more than the seed.
    group_keys = [
        c for c in CONFIG_COLUMNS if c in data.columns and c != "seed" and data[c].nunique() > 1
    ]
    if group_keys:
        means = data.groupby(group_keys, dropna=False)[[x, y]].mean().reset_index()
    else:
        means = data[[x, y]].mean().to_frame().T
    kappa_means = has_kappa and "rra.kappa1" in means.columns
    if len(data) > len(means):
        colour = (
            {"c": means["rra.kappa1"], "cmap": "viridis", "vmin": 0.0, "vmax": 1.0}
            if kappa_means
            else {"facecolors": "none"}
        )
        ax.scatter(means[x], means[y], marker="D", s=48, edgecolors="black", linewidths=1.0,
                   label="mean over seeds", zorder=3, **colour)  # fmt: skip
    if kappa_means:
        labels = [f"κ1={k:g}" for k in means["rra.kappa1"]]
        _label_points(ax, list(means[x]), list(means[y]), labels)

    front = means[pareto_mask(list(means[x]), list(means[y]))].sort_values(x)
    if len(front) > 1:
        ax.step(front[x], front[y], where="post", color="black", linestyle="--", linewidth=1,
                label="Pareto front")  # fmt: skip
    elif len(means) > 1:  # one configuration dominates every other one
        ax.scatter(front[x], front[y], marker="*", s=140, facecolors="none", edgecolors="black",
                   label="Pareto front (dominates all)")  # fmt: skip
    ax.ticklabel_format(axis="both", style="sci", scilimits=(-3, 4), useOffset=False)
    ax.set_xlabel(AXIS_LABELS.get(x, x))
    ax.set_ylabel(AXIS_LABELS.get(y, y))
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    return save_figure(fig, Path(path), note)


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


# --- plots of one run -----------------------------------------------------------------------

TRAINING_CURVES_FILE = "training_curves.png"
ERROR_TRACES_FILE = "error_traces.png"
LATENCY_CDF_FILE = "cam_latency_cdf.png"


def save_figure(fig: Any, path: Path, note: str | None = None) -> Path:
    """Write ``fig`` as a PNG atomically (``note``: small grey text at the bottom right, e.g.
    the command) and close it."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    if note:
        fig.subplots_adjust(bottom=fig.subplotpars.bottom + 0.04)
        fig.text(0.995, 0.005, note, ha="right", va="bottom", fontsize=7, color="0.35")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    return atomic_write_bytes(path, buffer.getvalue())


def pyplot_agg():
    """matplotlib.pyplot on the file-only Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


STAGE_LABELS = {
    "control_perfect": "π* (perfect observation), per 50 ms interval",
    "control_impaired": "π̃ (impaired observation), per 50 ms interval",
    "rra": "RRA agents, per 1 ms subframe",
}


def plot_training_curves(
    metrics_csv: str | Path | Mapping[str, Sequence[str | Path]],
    path: str | Path,
    title: str | None = None,
    note: str | None = None,
) -> Path:
    """Mean reward per agent and step of every training stage against its PPO iteration
    (one panel per stage; the stages' clocks differ, so are their reward scales).

    ``metrics_csv`` is one run's ``metrics.csv``, or ``{label: [metrics.csv, ...]}`` to compare
    methods: one line per label, the mean over its runs (seeds), shaded between their minimum
    and maximum."""
    import numpy as np
    import pandas as pd

    plt = pyplot_agg()
    if isinstance(metrics_csv, Mapping):
        groups = {label: [pd.read_csv(f) for f in files] for label, files in metrics_csv.items()}
    else:
        groups = {None: [pd.read_csv(metrics_csv)]}
    tables = [t for ts in groups.values() for t in ts]
    stages = list(dict.fromkeys(s for t in tables for s in t["stage"]))
    if not stages:
        raise ValueError("no training rows to plot")
    fig, axes = plt.subplots(1, len(stages), figsize=(4.2 * len(stages), 3.6), dpi=120)
    axes = [axes] if len(stages) == 1 else list(axes)
    for ax, stage in zip(axes, stages, strict=True):
        for label, runs in groups.items():
            curves = [t[t["stage"] == stage] for t in runs]
            curves = [c for c in curves if not c.empty]
            if not curves:
                continue
            if label is None:
                ax.plot(curves[0]["iteration"], curves[0]["reward_mean"], marker=".", linewidth=1)
                continue
            joined = pd.concat(curves).groupby("iteration")["reward_mean"]
            mean, low, high = joined.mean(), joined.min(), joined.max()
            (line,) = ax.plot(mean.index, mean.values, linewidth=1.2, label=label)
            if len(curves) > 1:
                ax.fill_between(
                    mean.index, np.asarray(low), np.asarray(high), color=line.get_color(),
                    alpha=max(0.05, 0.3 / len(groups)), linewidth=0,
                )  # fmt: skip
        ax.set_title(STAGE_LABELS.get(stage, stage), fontsize=9)
        ax.set_xlabel("PPO iteration")
        ax.set_ylabel("mean reward per agent and step")
        ax.grid(True, alpha=0.3)
    if any(label is not None for label in groups):
        handles, labels = axes[-1].get_legend_handles_labels()
        for ax in axes:  # the legend of the panel with the most lines
            h, lab = ax.get_legend_handles_labels()
            if len(h) > len(handles):
                handles, labels = h, lab
        fig.legend(handles, labels, loc="upper center", ncol=min(len(labels), 6), fontsize=8,
                   bbox_to_anchor=(0.5, 1.0))  # fmt: skip
        fig.tight_layout(rect=(0, 0, 1, 0.9))
    if title:
        fig.suptitle(title, fontsize=10, y=0.02, va="bottom")
    return save_figure(fig, Path(path), note)


def plot_error_traces(
    gap_error_m: Any,
    speed_error_mps: Any,
    interval_s: float,
    path: str | Path,
    title: str = "platoon errors, evaluation scenario 0",
    vehicle_ids: Sequence[int] | None = None,
) -> Path:
    """|gap error| (m) and |speed error| (m/s) of every follower over one evaluation scenario;
    inputs [K, F] (intervals × followers). ``vehicle_ids`` [F] label the lines (the topology's
    followers; default 1..F, one platoon)."""
    plt = pyplot_agg()
    import numpy as np

    gap = np.asarray(gap_error_m)
    speed = np.asarray(speed_error_mps)
    time_s = np.arange(gap.shape[0]) * interval_s
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(6.4, 5.0), dpi=120, sharex=True)
    ids = list(vehicle_ids) if vehicle_ids is not None else range(1, gap.shape[1] + 1)
    for follower, vehicle in enumerate(ids):
        top.plot(time_s, gap[:, follower], linewidth=1, label=f"vehicle {vehicle}")
        bottom.plot(time_s, speed[:, follower], linewidth=1)
    top.legend(fontsize=8, ncol=min(gap.shape[1], 4))
    _label_error_axes(top, bottom, title)
    return save_figure(fig, Path(path))


def _label_error_axes(top: Any, bottom: Any, title: str, what: str = "") -> None:
    top.set_ylabel(f"|gap error| (m){what}")
    bottom.set_ylabel(f"|speed error| (m/s){what}")
    bottom.set_xlabel("time (s)")
    for ax in (top, bottom):
        ax.grid(True, alpha=0.3)
    top.set_title(title, fontsize=10)


def plot_error_trace_comparison(
    traces: Mapping[str, tuple[Any, Any]],
    interval_s: float,
    path: str | Path,
    title: str = "platoon errors on the same evaluation scenario",
    note: str | None = None,
) -> Path:
    """|gap error| (m) and |speed error| (m/s) over one evaluation scenario for several methods
    (``{label: (gap [K, F], speed [K, F])}``, same scenario and seed): the mean over followers
    as a line, shaded between the followers' minimum and maximum."""
    plt = pyplot_agg()
    import numpy as np

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.0, 5.2), dpi=120, sharex=True)
    for label, (gap, speed) in traces.items():
        for ax, values in ((top, np.asarray(gap)), (bottom, np.asarray(speed))):
            time_s = np.arange(values.shape[0]) * interval_s
            (line,) = ax.plot(time_s, values.mean(axis=1), linewidth=1.2, label=label)
            if values.shape[1] > 1:
                ax.fill_between(time_s, values.min(axis=1), values.max(axis=1),
                                color=line.get_color(), alpha=0.15, linewidth=0)  # fmt: skip
    top.legend(fontsize=8, title="line: mean over followers; band: min–max", title_fontsize=7)
    _label_error_axes(top, bottom, title)
    return save_figure(fig, Path(path), note)


def plot_latency_cdf(
    latencies_ms: Mapping[str, Any],
    deadline_ms: float,
    path: str | Path,
    title: str | None = None,
    note: str | None = None,
) -> Path:
    """Empirical CDF of delivered CAMs' latency (ms) per method; the interval deadline marked.
    A method that delivered no CAM has no curve (its label says so in the legend)."""
    plt = pyplot_agg()
    import numpy as np

    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=120)
    for label, values in latencies_ms.items():
        x = np.sort(np.asarray(values, dtype=float))
        if x.size:
            ax.step(x, np.arange(1, x.size + 1) / x.size, where="post", label=label)
        else:
            ax.plot([], [], linestyle="none", label=f"{label}: no CAM delivered")
    ax.axvline(deadline_ms, color="black", linestyle="--", linewidth=1, label="interval deadline")
    ax.set_xlabel("CAM latency (ms)")
    ax.set_ylabel("fraction of delivered CAMs")
    ax.set_ylim(0, 1.02)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return save_figure(fig, Path(path), note)


def plot_metric_bars(
    rows: Sequence[Mapping[str, Any]],
    path: str | Path,
    ylabel: str,
    title: str | None = None,
    note: str | None = None,
) -> Path:
    """One bar per method: its mean with the confidence interval as error bar, and each run
    (seed) as a dot. ``rows``: ``{"label", "mean", "ci_low", "ci_high", "values"}`` each; a
    row without a finite mean is drawn as an empty slot labelled "n/a"."""
    plt = pyplot_agg()
    import numpy as np

    labels = [str(r["label"]) for r in rows]
    fig, ax = plt.subplots(figsize=(max(5.0, 0.75 * len(rows) + 2.0), 4.2), dpi=120)
    positions = np.arange(len(rows))
    for i, row in enumerate(rows):
        if not is_finite(row.get("mean")):
            ax.text(i, 0, "n/a", ha="center", va="bottom", fontsize=8)
            continue
        mean = float(row["mean"])
        low = float(row["ci_low"]) if is_finite(row.get("ci_low")) else mean
        high = float(row["ci_high"]) if is_finite(row.get("ci_high")) else mean
        ax.bar(i, mean, color=f"C{i % 10}", alpha=0.75, width=0.7)
        ax.errorbar(i, mean, yerr=[[mean - low], [high - mean]], color="black", capsize=4,
                    linewidth=1)  # fmt: skip
        values = [float(v) for v in row.get("values", ()) if is_finite(v)]
        if values:
            offsets = np.linspace(-0.15, 0.15, len(values)) if len(values) > 1 else [0.0]
            ax.scatter(i + np.asarray(offsets), values, s=10, color="black", zorder=3,
                       alpha=0.6)  # fmt: skip
    ax.set_xticks(positions)
    ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=8)
    ax.set_xlabel("method")
    ax.set_ylabel(ylabel)
    ax.grid(True, axis="y", alpha=0.3)
    if title:
        ax.set_title(title, fontsize=10)
    return save_figure(fig, Path(path), note)
