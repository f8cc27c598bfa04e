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


# --- one run's summary on the terminal ------------------------------------------------------

#: The groups of a run's printed summary, in order (:func:`summary_sections`).
SUMMARY_SECTIONS = ("run", "training", "control", "radio", "VoI", "reference check", "timing")

#: The unit (or what a number counts) of a summary key, by its flattened name; a key ending in
#: ``.seconds`` or ``_seconds`` is in s. Keys without an entry are names, flags or counts.
SUMMARY_UNITS = {
    "kappa1": "RRA reward weight",
    "kappa2": "RRA reward weight",
    "iterations": "JOCC iterations",
    "warm_start.rounds": "rounds",
    "warm_start.samples": "samples",
    "warm_start.rms_error_mps2": "m/s²",
    "critic_warmup.batches": "batches",
    "critic_warmup.loss_critic": "MSE of returns",
    "critic_warmup.explained_variance": "fraction",
    "control_return": "discounted return per follower",
    "control_cost": "−reward per follower-interval",
    "optimal_control_cost": "−reward per follower-interval",
    "cacc_control_cost": "−reward per follower-interval",
    "gap_error_abs_m": "m",
    "speed_error_abs_mps": "m/s",
    "collision_rate": "fraction of scenarios",
    "cam_delivery_rate": "fraction of CAMs sent",
    "cam_latency_ms_mean": "ms, delivered CAMs",
    "cam_latency_ms_p50": "ms, delivered CAMs",
    "cam_latency_ms_p95": "ms, delivered CAMs",
    "aoi_ms_mean": "ms",
    "peak_aoi_ms_mean": "ms",
    "v2i_throughput_mbps_per_link": "Mbps per V2I link",
    "ivoi_mean": "ξ (unscaled)",
    "ivoi_std": "ξ (unscaled)",
    "ivoi_mean_delivered": "ξ (unscaled)",
    "ivoi_mean_lost": "ξ (unscaled)",
    "ivoi_sum": "ξ summed per scenario",
    "evoi": "J̃ − J*, discounted return",
}

#: What the terms of the summary mean, printed under the table where their keys are shown.
SUMMARY_TERMS = {
    "aoi_ms_mean": "AoI (Age of Information): at each recipient, the time since the newest CAM "
    "it holds was generated, sampled every subframe and averaged over all of them "
    "(docs/model.md §4.8)",
    "peak_aoi_ms_mean": "peak AoI: the AoI just before each refresh (a delivered CAM replacing "
    "the held one), averaged over the delivered CAMs",
    "cam_latency_ms_mean": "CAM latency: over the delivered CAMs only (a lost CAM has none)",
    "evoi": "EVoI: J̃ − J*, the acting system's discounted control return minus that of π* on "
    "perfect observations, on the same scenarios (below 0: the acting system does worse)",
    "ivoi_mean": "IVoI ξ: the estimator's value of one follower's CAM in one interval",
    "pi_star_minus_cacc": "J* − J: π*'s discounted control return minus the comparator's, on the "
    "same scenarios (reference_ok is False where π* is worse)",
}

#: Keys (flattened) of each group, by name or by prefix (``name.``); the first group whose
#: rule matches wins; a key no group names goes to ``run``.
_SECTION_KEYS = (
    ("timing", ("seconds", "eval_seconds")),
    (
        "training",
        (
            "iterations",
            "trainer_iterations",
            "selected_iterations",
            "warm_start",
            "critic_warmup",
            "rra_warm_start",
            "term_scales",
            "value_fit",
        ),
    ),  # fmt: skip
    (
        "control",
        (
            "control_return",
            "control_cost",
            "optimal_control_cost",
            "cacc_control_cost",
            "gap_error_abs_m",
            "speed_error_abs_mps",
            "collision_rate",
        ),
    ),  # fmt: skip
    (
        "radio",
        (
            "cam_delivery_rate",
            "cam_latency_ms_mean",
            "cam_latency_ms_p50",
            "cam_latency_ms_p95",
            "aoi_ms_mean",
            "peak_aoi_ms_mean",
            "v2i_throughput_mbps_per_link",
        ),
    ),  # fmt: skip
    ("VoI", ("evoi", "ivoi_mean", "ivoi_std", "ivoi_mean_delivered", "ivoi_mean_lost", "ivoi_sum")),
    ("reference check", ("pi_star_minus_", "reference_ok", "reference_problems")),
)

#: The groups of metrics: a metric that is None (undefined, or not scored) is shown as ``-``,
#: while metadata that is None (not set in this run) is left out.
_METRIC_SECTIONS = ("control", "radio", "VoI", "reference check")


def _section_of(key: str) -> str:
    if key.endswith((".seconds", "_seconds")):
        return "timing"
    for section, names in _SECTION_KEYS:
        for name in names:
            if (
                key == name
                or key.startswith(f"{name}.")
                or (name.endswith("_") and key.startswith(name))
            ):
                return section
    return "run"


def _unit_of(key: str) -> str:
    if key in SUMMARY_UNITS:
        return SUMMARY_UNITS[key]
    if key.endswith((".seconds", "_seconds")) or key == "seconds":
        return "s"
    if key.startswith("trainer_iterations.") or key.startswith("selected_iterations."):
        return "trainer iterations"
    if key.startswith("pi_star_minus_") and not key.endswith(("_ci_low", "_ci_high")):
        return "J* − J, discounted return"
    return ""


def summary_sections(summary: Mapping[str, Any]) -> list[tuple[str, list[tuple[str, str, str]]]]:
    """A run's summary grouped for the terminal: ``[(group, [(key, value, unit), ...]), ...]``
    in the order of :data:`SUMMARY_SECTIONS`, groups without entries left out. Keys are those
    of ``summary.json`` (flattened, ``warm_start.samples``); a ``key`` with ``key_ci_low`` and
    ``key_ci_high`` is one row, ``value [low, high]`` (its 95% CI over scenarios); lists
    (plots, notes) and metadata that is None are left out."""
    flat = {
        k: v for k, v in flatten(metrics_of(summary)).items() if not isinstance(v, list | tuple)
    }
    groups: dict[str, list[tuple[str, str, str]]] = {s: [] for s in SUMMARY_SECTIONS}
    for key, value in flat.items():
        if key.endswith(("_ci_low", "_ci_high")) and key.rpartition("_ci_")[0] in flat:
            continue  # shown with its mean
        section = _section_of(key)
        if value is None and section not in _METRIC_SECTIONS:
            continue
        text = _format_cell(value)
        low, high = flat.get(f"{key}_ci_low"), flat.get(f"{key}_ci_high")
        unit = _unit_of(key)
        if value is not None and (low is not None or high is not None):
            text += f" [{_format_cell(low)}, {_format_cell(high)}]"
        if key == "reference_problems" and value == "":
            text = "none"
        groups[section].append((key, text, unit))
    return [(s, rows) for s, rows in groups.items() if rows]


def summary_terms(summary: Mapping[str, Any]) -> list[str]:
    """The definitions (:data:`SUMMARY_TERMS`) of the terms whose keys the summary shows."""
    flat = flatten(metrics_of(summary))
    return [text for key, text in SUMMARY_TERMS.items() if key in flat]


def format_summary(summary: Mapping[str, Any]) -> str:
    """A run's summary as plain text (:func:`summary_sections`): one block per group, then the
    definitions of the terms shown."""
    sections = summary_sections(summary)
    rows = [row for _, group in sections for row in group]
    if not rows:
        return ""
    width = max(len(key) for key, _, _ in rows)
    value_width = max(len(value) for _, value, _ in rows)
    lines: list[str] = [f"{'quantity (summary.json key)':<{width + 2}}  value [95% CI]  unit"]
    for section, group in sections:
        lines.append(f"\n{section}:")
        for key, value, unit in group:
            lines.append(f"  {key:<{width}}  {value:>{value_width}}  {unit}".rstrip())
    terms = summary_terms(summary)
    if terms:
        lines += ["", *terms]
    return "\n".join(lines)


def print_summary(summary: Mapping[str, Any], console: Any = None, title: str = "summary") -> None:
    """Print one run's summary as a rich table grouped as :func:`summary_sections` does, with
    a unit column, and under it the definitions of the terms shown (AoI, peak AoI, EVoI, ...)."""
    from rich.console import Console
    from rich.table import Table
    from rich.text import Text

    # piped output (logs, CI) is not cut at rich's default 80 columns
    console = console or Console(width=None if sys.stdout.isatty() else 120)
    rich_table = Table(title=title)
    sections = summary_sections(summary)
    # the keys stay whole (no_wrap: the other columns wrap first); a value never is cut
    rich_table.add_column("quantity (summary.json key)", no_wrap=True)
    rich_table.add_column(
        "value [95% CI]", justify="right", overflow="fold"
    )  # a path wraps, never cut
    rich_table.add_column("unit", overflow="fold")
    for i, (section, rows) in enumerate(sections):
        if i:
            rich_table.add_section()
        rich_table.add_row(Text(section, style="bold"), "", "")
        for key, value, unit in rows:  # Text: a value is never read as rich markup
            rich_table.add_row(Text(f"  {key}"), Text(value), Text(unit))
    console.print(rich_table)
    for term in summary_terms(summary):
        console.print(term, markup=False, highlight=False)
