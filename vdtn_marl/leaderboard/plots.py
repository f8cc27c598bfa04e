"""The leaderboard's PNG plots per scenario (every method's V2I throughput against its |gap
error| and its control cost, error traces, bars with CIs, CAM latency CDF, κ1 Pareto front,
training curves, Age of Information).
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from vdtn_marl import __version__
from vdtn_marl.experiment.config import BenchConfig
from vdtn_marl.io.files import CONFIG_FILE, METRICS_FILE, RAW_EVALUATION_FILE
from vdtn_marl.leaderboard.grid import Cell
from vdtn_marl.leaderboard.stats import describe_interval
from vdtn_marl.reporting.tables import is_finite


def load_raw_evaluation(cell_dir: Path) -> dict[str, Any] | None:
    """The arrays of a cell's ``evaluation_raw.npz`` (None when it has none)."""
    import numpy as np

    path = Path(cell_dir) / RAW_EVALUATION_FILE
    if not path.is_file():
        return None
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


#: Overrides of a method that place it in the JOCC κ1 sweep rather than set it apart from it.
_SWEEP_KEYS = ("rra", "rra.name", "rra.kappa1", "rra.kappa2", "control", "control.name")


def method_roles(
    rows: Sequence[Mapping[str, Any]], overrides: Mapping[str, Sequence[str]] | None = None
) -> dict[str, dict[str, Any]]:
    """``{method: {"role", "kappa1"}}`` for :func:`~vdtn_marl.reporting.plots.plot_methods_pareto`
    from the runs of one scenario (each with ``method``, ``rra``, ``control`` and ``kappa1``, as
    a run's summary has them) and the methods' overrides (``benchmark.methods``).

    ``baseline``: the RRA or the control is one of the non-learned policies
    (:data:`~vdtn_marl.policies.registry.RRA_BASELINES`, ``CONTROL_BASELINES``). ``sweep``:
    ``rra=jocc`` with learned control and a κ1, the methods whose other overrides agree (the
    largest such group, e.g. not ``control.augmentation=false``). ``learned``: the others
    (DRRA, throughput-only, a jocc method set apart by an override)."""
    from vdtn_marl.policies.registry import CONTROL_BASELINES, RRA_BASELINES

    overrides = overrides or {}
    first: dict[str, Mapping[str, Any]] = {}
    for row in rows:
        first.setdefault(row["method"], row)
    roles: dict[str, dict[str, Any]] = {}
    groups: dict[tuple[str, ...], list[str]] = {}
    for method, row in first.items():
        rra, control, kappa1 = row.get("rra"), row.get("control"), row.get("kappa1")
        kappa1 = float(kappa1) if is_finite(kappa1) else None
        role = "learned"
        if rra in RRA_BASELINES or control in CONTROL_BASELINES:
            role = "baseline"
        elif rra == "jocc" and control == "learned" and kappa1 is not None:
            others = tuple(
                sorted(
                    o
                    for o in overrides.get(method, ())
                    if o.split("=", 1)[0].lstrip("+~") not in _SWEEP_KEYS
                )
            )
            groups.setdefault(others, []).append(method)
        roles[method] = {"role": role, "kappa1": kappa1}
    if groups:
        key = max(groups, key=lambda k: (len(groups[k]), -len(k)))
        for method in groups[key]:
            roles[method]["role"] = "sweep"
    return roles


def _run_choices(row: Mapping[str, Any]) -> Mapping[str, Any]:
    """``row`` with its ``rra``, ``control`` and ``kappa1``, read from the run's config where
    its summary lacks them (runs written before summaries named them)."""
    if all(row.get(k) is not None for k in ("rra", "control", "kappa1")):
        return row
    from vdtn_marl import reporting

    cfg_file = Path(row["run_dir"]) / CONFIG_FILE
    config = reporting.tables._read_yaml(cfg_file) if cfg_file.is_file() else {}
    flat = reporting.flatten(config or {})
    return {
        **row,
        "rra": row.get("rra") or flat.get("rra.name"),
        "control": row.get("control") or flat.get("control.name"),
        "kappa1": row.get("kappa1") if row.get("kappa1") is not None else flat.get("rra.kappa1"),
    }


#: The every-method figures: their kinds (plot keys) in the report and their x metrics.
PARETO_METHODS_X = {"pareto_methods": "gap_error_abs_m", "pareto_methods_cost": "control_cost"}
_PARETO_X_WORDS = {"gap_error_abs_m": "|gap error|", "control_cost": "control cost"}


def write_pareto_methods(
    by_method: Mapping[str, Mapping[str, Mapping[str, Any]]],
    roles: Mapping[str, Mapping[str, Any]],
    scenario: str,
    x: str,
    path: Path,
    interval: str,
    note: str | None = None,
) -> Path:
    """One scenario's every-method figure: V2I throughput per link against ``x`` (a metric of
    :data:`PARETO_METHODS_X`), each method at its mean over seeds with its ``interval`` (e.g.
    ``95% Student-t CI``) as error bars; ``roles`` from :func:`method_roles`. Raises
    ValueError when no method has both means."""
    from vdtn_marl.reporting.plots import plot_methods_pareto

    return plot_methods_pareto(
        by_method,
        path,
        roles,
        x=x,
        title=f"{scenario}: V2I throughput against {_PARETO_X_WORDS.get(x, x)}, every method\n"
        f"mean over seeds, bars: {interval}",
        note=note,
    )


def write_plots(
    cfg: BenchConfig,
    rows: Sequence[Mapping[str, Any]],
    stats: Mapping[str, Any],
    report_dir: Path,
) -> dict[str, dict[str, Path]]:
    """The leaderboard's plots per scenario; returns ``{scenario: {kind: path}}``."""
    import numpy as np
    import pandas as pd

    from vdtn_marl import reporting

    b = cfg.benchmark
    note = f"vdtn-marl {__version__} · benchmark {b.name} v{b.version}"
    ci = describe_interval(b.interval, b.confidence, b.bootstrap_resamples)["short"]
    out: dict[str, dict[str, Path]] = {}
    for scenario, by_method in stats.items():
        plots: dict[str, Path] = {}
        prefix = f"leaderboard_{scenario}_"
        scenario_rows = [r for r in rows if r["scenario"] == scenario]
        n_runs = {m: by_method[m]["control_cost"]["n"] for m in by_method}
        # the seeds of each method's complete runs (extra_seeds: methods may differ in n)
        seeds_of = {
            m: sorted({int(r["seed"]) for r in scenario_rows if r["method"] == m})
            for m in by_method
        }

        def raw(method: str, seed: int, scenario: str = scenario) -> dict | None:
            return load_raw_evaluation(Cell(scenario, method, seed, ()).directory(cfg.out_dir))

        # 0. every method: V2I throughput against |gap error| and against control cost
        roles = method_roles([_run_choices(r) for r in scenario_rows], b.methods)
        for kind, x in PARETO_METHODS_X.items():
            with contextlib.suppress(ValueError):  # no method with both means
                plots[kind] = write_pareto_methods(
                    by_method, roles, scenario, x, report_dir / f"{prefix}{kind}.png", ci, note
                )

        # 1. error traces of the trace methods, same scenario and seed
        pair = [m for m in b.trace_methods if m in by_method]
        common = set.intersection(*(set(seeds_of[m]) for m in pair)) if pair else set()
        for seed in sorted(common):
            traces = {m: raw(m, seed) for m in pair}
            if pair and all(t is not None and "gap_error_abs_m" in t for t in traces.values()):
                interval = float(next(iter(traces.values()))["interval_s"])
                plots["error_traces"] = reporting.plot_error_trace_comparison(
                    {
                        m: (t["gap_error_abs_m"], t["speed_error_abs_mps"])
                        for m, t in traces.items()
                    },
                    interval,
                    report_dir / f"{prefix}error_traces.png",
                    title=f"{scenario}: {' vs '.join(pair)}, seed {seed}, evaluation scenario 0",
                    note=note,
                )
                break

        # 2. bars with CIs
        for key, kind, ylabel in (
            (reporting.V2I_THROUGHPUT, "v2i_throughput", "V2I throughput per link (Mbps)"),
            ("cam_delivery_rate", "cam_delivery", "CAM delivery rate (fraction within interval)"),
            ("control_cost", "control_cost", "control cost (dimensionless; lower is better)"),
            ("aoi_ms_mean", "aoi", "Age of Information of CAM content, mean (ms)"),
        ):
            if not any(by_method[method][key]["n"] for method in by_method):
                continue  # runs written before the metric was reported (AoI)
            bars = [
                {
                    "label": method,
                    **by_method[method][key],
                    "values": [r.get(key) for r in scenario_rows if r["method"] == method],
                }
                for method in by_method
            ]
            plots[kind] = reporting.plot_metric_bars(
                bars,
                report_dir / f"{prefix}{kind}.png",
                ylabel,
                title=f"{scenario}: mean over seeds, {ci}, dots = runs",
                note=note,
            )

        # 3. CAM latency CDF, every run's delivered CAMs pooled per method
        latencies: dict[str, Any] = {}
        interval_s = None
        for method in by_method:
            pooled = []
            for seed in seeds_of[method]:
                data = raw(method, seed)
                if data is not None and "cam_latency_ms" in data:
                    pooled.append(data["cam_latency_ms"])
                    interval_s = float(data["interval_s"])
            if pooled:
                delivered = by_method[method]["cam_delivery_rate"]["mean"]
                share = f"{100 * delivered:.1f}%" if is_finite(delivered) else "–"
                label = f"{method} ({share} of CAMs delivered)"
                latencies[label] = np.concatenate(pooled)
        if latencies and interval_s is not None:
            plots["cam_latency_cdf"] = reporting.plot_latency_cdf(
                latencies,
                interval_s * 1000.0,
                report_dir / f"{prefix}cam_latency_cdf.png",
                title=f"{scenario}: latency of delivered CAMs, all runs pooled",
                note=note,
            )

        # 4. κ1 Pareto front of the learned-RRA methods with learned control
        pareto_rows = []
        for row in scenario_rows:
            cfg_file = Path(row["run_dir"]) / CONFIG_FILE
            config = reporting.tables._read_yaml(cfg_file) if cfg_file.is_file() else {}
            flat = reporting.flatten(config or {})
            if (
                flat.get("rra.name") in ("jocc", "throughput")
                and flat.get("control.name") == "learned"
            ):
                pareto_rows.append(
                    {
                        **{k: flat.get(k) for k in reporting.CONFIG_COLUMNS},
                        **row,
                        "rra.kappa1": flat.get("rra.kappa1"),
                    }
                )
        table = pd.DataFrame(pareto_rows)
        if len(table) and table["rra.kappa1"].nunique() > 1:
            with contextlib.suppress(ValueError):
                plots["pareto_kappa1"] = reporting.plot_kappa1_pareto(
                    table,
                    report_dir / f"{prefix}pareto_kappa1.png",
                    title=f"{scenario}: κ1 of the RRA reward (learned control)",
                    note=note,
                )

        # 5. training curves of the methods with a learned RRA policy
        curves: dict[str, list[Path]] = {}
        for method in by_method:
            files = [
                Cell(scenario, method, s, ()).directory(cfg.out_dir) / METRICS_FILE
                for s in seeds_of[method]
            ]
            files = [f for f in files if f.is_file()]
            rra_learned = any(
                r.get("trainer_iterations.rra") for r in scenario_rows if r["method"] == method
            )
            if files and rra_learned:
                curves[f"{method} (n={n_runs[method]})"] = files
        if curves:
            plots["training_curves"] = reporting.plot_training_curves(
                curves,
                report_dir / f"{prefix}training_curves.png",
                title=f"{scenario}: mean over seeds (band: min–max)",
                note=note,
            )
        out[scenario] = plots
    return out
