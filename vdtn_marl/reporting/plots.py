"""Plots of run results (PNG, written atomically): the κ1 Pareto front of a sweep, a run's
training curves, error traces and CAM latency CDF, and bars of a metric across methods."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from vdtn_marl.io.files import atomic_write_bytes
from vdtn_marl.reporting.tables import CONFIG_COLUMNS, CONTROL_COST, V2I_THROUGHPUT, is_finite

AXIS_LABELS = {
    CONTROL_COST: "control cost (dimensionless; lower is better)",
    V2I_THROUGHPUT: "V2I throughput per link (Mbps)",
}


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


GAP_ERROR = "gap_error_abs_m"
#: The roles of the methods in :func:`plot_methods_pareto` (``{method: {"role", "kappa1"}}``):
#: a baseline (its RRA or its control is not learned), a point of the JOCC κ1 sweep (learned
#: RRA with the jocc reward, learned control), or another learned-RRA method (e.g. DRRA).
METHOD_ROLES = ("baseline", "sweep", "learned")
_PARETO_AXES = {
    GAP_ERROR: "mean |gap error| (m)    ← better",
    CONTROL_COST: "control cost (dimensionless)    ← better",
    V2I_THROUGHPUT: "V2I throughput per link (Mbps)",
}
_ROLE_STYLE = {  # legend text, marker, colour
    "baseline": ("baseline (RRA or control not learned)", "s", "0.45"),
    "learned": ("learned RRA", "D", "C1"),
    "sweep": ("JOCC κ1 sweep (learned RRA and control)", "o", "C0"),
}


def _interval_bars(stat: Mapping[str, Any]) -> list[list[float]] | None:
    """``[[mean − low], [high − mean]]`` of a statistic, or None without a finite interval
    (one run: no interval)."""
    mean, low, high = (stat.get(k) for k in ("mean", "ci_low", "ci_high"))
    if not (is_finite(low) and is_finite(high)):
        return None
    return [[max(0.0, float(mean) - float(low))], [max(0.0, float(high) - float(mean))]]


def plot_methods_pareto(
    stats: Mapping[str, Mapping[str, Mapping[str, Any]]],
    path: str | Path,
    roles: Mapping[str, Mapping[str, Any]] | None = None,
    x: str = GAP_ERROR,
    y: str = V2I_THROUGHPUT,
    title: str | None = None,
    note: str | None = None,
) -> Path:
    """Every method of one scenario as a point at its mean over seeds, its interval as error
    bars in both axes: ``x`` (default mean |gap error|, lower is better) against ``y`` (default
    V2I throughput per link, higher is better).

    ``stats`` is one scenario of the leaderboard's statistics, ``{method: {metric: {"mean",
    "ci_low", "ci_high", "n"}}}``; a statistic without a finite interval (one run) is drawn
    without its error bar. ``roles`` (:data:`METHOD_ROLES`) gives ``{method: {"role",
    "kappa1"}}``: baselines and other learned-RRA methods are markers labelled with their name,
    the κ1 sweep a line through its points in the order of κ1, each labelled ``κ1=…``; a method
    missing from ``roles`` counts as ``learned``. Methods without a finite mean of both
    metrics are left out; they and those without an interval are named in the legend.
    ``note`` is printed small under the axes. Writes a PNG (7 × 5 in, 120 dpi) atomically and
    returns its path."""
    if not stats:
        raise ValueError(
            "no method to plot: the statistics are empty (expected {method: {metric: "
            "{mean, ci_low, ci_high, n}}})"
        )
    roles = roles or {}
    points, missing = [], []
    for method, metrics in stats.items():
        sx, sy = metrics.get(x) or {}, metrics.get(y) or {}
        if not (is_finite(sx.get("mean")) and is_finite(sy.get("mean"))):
            missing.append(method)
            continue
        role = dict(roles.get(method) or {})
        kind = role.get("role", "learned")
        if kind not in METHOD_ROLES:
            raise ValueError(f"role {kind!r} of {method!r} is not one of {', '.join(METHOD_ROLES)}")
        kappa1 = role.get("kappa1")
        if kind == "sweep" and not is_finite(kappa1):
            kind = "learned"  # a sweep point needs its κ1
        points.append({"method": method, "role": kind, "kappa1": kappa1, "x": sx, "y": sy})
    if not points:
        raise ValueError(
            f"no method has a finite mean of both {x!r} and {y!r} (methods: {', '.join(stats)})"
        )

    plt = pyplot_agg()
    from matplotlib.lines import Line2D

    fig, ax = plt.subplots(figsize=(7.0, 5.0), dpi=120)
    points.sort(key=lambda p: (p["role"] != "sweep", p["kappa1"] if p["role"] == "sweep" else 0))
    for p in points:
        _, marker, colour = _ROLE_STYLE[p["role"]]
        ax.errorbar(
            float(p["x"]["mean"]), float(p["y"]["mean"]), xerr=_interval_bars(p["x"]),
            yerr=_interval_bars(p["y"]), fmt=marker, color=colour, markersize=6,
            markeredgecolor="black", markeredgewidth=0.6, ecolor=colour, elinewidth=1.0,
            capsize=3, alpha=0.9, zorder=3,
        )  # fmt: skip
    sweep = [p for p in points if p["role"] == "sweep"]
    if len(sweep) > 1:
        ax.plot([float(p["x"]["mean"]) for p in sweep], [float(p["y"]["mean"]) for p in sweep],
                color=_ROLE_STYLE["sweep"][2], linewidth=1.4, zorder=2)  # fmt: skip

    handles = [
        Line2D([], [], marker=_ROLE_STYLE[r][1], color=_ROLE_STYLE[r][2], markeredgecolor="black",
               markeredgewidth=0.6, linestyle="-" if r == "sweep" and len(sweep) > 1 else "none",
               label=_ROLE_STYLE[r][0])
        for r in ("sweep", "learned", "baseline")
        if any(p["role"] == r for p in points)
    ]  # fmt: skip
    alone = [p["method"] for p in points if not all(map(_interval_bars, (p["x"], p["y"])))]
    for names, what in ((alone, "no interval (one run)"), (missing, "not drawn (no value)")):
        if names:
            handles.append(Line2D([], [], linestyle="none", label=f"{what}: {', '.join(names)}"))
    _better_axes(ax, x, y, title)
    ax.autoscale_view()
    low, high = ax.get_xlim()
    ax.set_xlim(low, high + 0.06 * (high - low))  # room for the labels of the rightmost points
    legend = ax.legend(handles=handles, loc="best", fontsize=8)
    labels = [f"κ1={p['kappa1']:g}" if p["role"] == "sweep" else p["method"] for p in points]
    _place_labels(
        ax,
        [float(p["x"]["mean"]) for p in points],
        [float(p["y"]["mean"]) for p in points],
        labels,
        [_ROLE_STYLE[p["role"]][2] for p in points],
        legend,
    )
    return save_figure(fig, Path(path), note)


def _better_axes(ax: Any, x: str, y: str, title: str | None) -> None:
    """Axis labels of :func:`plot_methods_pareto` with the better direction: ``← better`` in
    the x label, ``better ↑`` upright above the y axis."""
    ax.set_xlabel(_PARETO_AXES.get(x, x))
    ax.set_ylabel(_PARETO_AXES.get(y, y))
    ax.annotate(
        "better ↑", (0.0, 1.0), xycoords="axes fraction", xytext=(-6, 4),
        textcoords="offset points", ha="right", va="bottom", fontsize=9,
    )  # fmt: skip
    ax.grid(True, alpha=0.3)
    if title:
        ax.set_title(title, fontsize=10)


def _place_labels(
    ax: Any,
    xs: list[float],
    ys: list[float],
    labels: list[str],
    colours: list[str],
    legend: Any = None,
) -> None:
    """Label each point beside it, at the first of a few places around it (right, left, above,
    below, then further out with a leader line) where the label overlaps no marker, no label
    already placed and stays inside the axes; else where it overlaps least. Labels sit on a
    white box above the error bars; none covers ``legend``."""
    import numpy as np

    fig = ax.figure
    fig.tight_layout()  # the layout the labels are placed in (save_figure keeps it close)
    if not hasattr(fig.canvas, "get_renderer"):
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig)
    renderer = fig.canvas.get_renderer()
    pixels = ax.transData.transform(np.column_stack([xs, ys]))
    per_point = fig.dpi / 72.0
    half = 5.0 * per_point  # half a marker, pixels
    boxes = [(px - half, py - half, px + half, py + half) for px, py in pixels]
    frame = ax.get_window_extent(renderer)
    if legend is not None:  # where "best" put it, fixed there (the labels would move it)
        e = legend.get_window_extent(renderer)
        corner = ax.transAxes.inverted().transform((e.x0, e.y0))
        legend.set_bbox_to_anchor(tuple(corner), transform=ax.transAxes)
        legend.set_loc("lower left")
        legend.borderaxespad = 0.0
        boxes.append((e.x0, e.y0, e.x1, e.y1))
    near = [  # (dx, dy) points, horizontal alignment
        ((8, 0), "left"), ((-8, 0), "right"), ((0, 10), "center"), ((0, -10), "center"),
        ((8, 9), "left"), ((-8, 9), "right"), ((8, -9), "left"), ((-8, -9), "right"),
    ]  # fmt: skip
    far = [((dx * 2.2, dy * 2.2 if dy else 16), ha) for (dx, dy), ha in near if dx]
    far += [((0, 24), "center"), ((0, -24), "center"), ((24, 0), "left"), ((-24, 0), "right")]

    def overlap(a: tuple, b: tuple) -> float:
        w = min(a[2], b[2]) - max(a[0], b[0])
        h = min(a[3], b[3]) - max(a[1], b[1])
        return w * h if w > 0 and h > 0 else 0.0

    # the most crowded points first: they have the fewest free places
    crowd = [sum(np.hypot(*(pixels[j] - pixels[i])) < 60 * per_point for j in range(len(xs)))
             for i in range(len(xs))]  # fmt: skip
    for i in sorted(range(len(xs)), key=lambda i: -crowd[i]):
        best = None
        for (dx, dy), ha in near + far:
            text = ax.annotate(
                labels[i], (xs[i], ys[i]), textcoords="offset points", xytext=(dx, dy),
                fontsize=8, ha=ha, va="center", color=colours[i], zorder=5,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8},
            )  # fmt: skip
            e = text.get_window_extent(renderer)
            box = (e.x0, e.y0, e.x1, e.y1)
            score = sum(overlap(box, b) for b in boxes)
            outside = e.x0 < frame.x0 or e.x1 > frame.x1 or e.y0 < frame.y0 or e.y1 > frame.y1
            score += 1e6 if outside else 0.0
            if best is None or score < best[0]:
                if best is not None:
                    best[1].remove()
                best = (score, text, box, (dx, dy))
            else:
                text.remove()
            if score == 0.0:
                break
        _, text, box, (dx, dy) = best
        if abs(dx) > 10 or abs(dy) > 12:  # far from its point: a leader line
            ax.annotate("", (xs[i], ys[i]), xytext=text.xyann, textcoords="offset points",
                        arrowprops={"arrowstyle": "-", "lw": 0.5, "color": "0.5"},
                        zorder=4)  # fmt: skip
        boxes.append(box)


TRAINING_CURVES_FILE = "training_curves.png"
ERROR_TRACES_FILE = "error_traces.png"
LATENCY_CDF_FILE = "cam_latency_cdf.png"


def save_figure(fig: Any, path: Path, note: str | None = None) -> Path:
    """Write ``fig`` as a PNG atomically (``note``: small grey text at the bottom right, e.g.
    the command) and close it."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    for _ in range(3):  # wrapping a title moves the axes: check again after the new layout
        if not _fit_titles(fig):
            break
        fig.tight_layout()
    if note:
        fig.subplots_adjust(bottom=fig.subplotpars.bottom + 0.04)
        fig.text(0.995, 0.005, note, ha="right", va="bottom", fontsize=7, color="0.35")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    plt.close(fig)
    return atomic_write_bytes(path, buffer.getvalue())


def _fit_titles(fig: Any) -> bool:
    """Wrap each axes title that is wider than the figure leaves it (titles are centred over
    their axes) onto more lines, so that no title is cut at the figure's edge. Returns whether
    a title changed."""
    import textwrap

    if not hasattr(fig.canvas, "get_renderer"):  # a closed figure, or a canvas without one
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        FigureCanvasAgg(fig)
    renderer = fig.canvas.get_renderer()
    width = fig.bbox.width
    changed = False
    for ax in fig.axes:
        title = ax.title
        text = title.get_text()
        if not text or not title.get_visible():
            continue
        extent = title.get_window_extent(renderer)
        centre = (extent.x0 + extent.x1) / 2.0
        room = 2.0 * min(centre, width - centre) - 8.0  # pixels, a small margin each side
        if extent.width <= room:
            continue
        lines = text.splitlines()
        chars = max(12, int(0.95 * max(map(len, lines)) * room / extent.width))
        wrapped = "\n".join(textwrap.fill(line, chars) for line in lines)
        if wrapped == text:  # a single word longer than the room: nothing more to do
            continue
        title.set_text(wrapped)
        changed = True
    return changed


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


#: The latency CDF's title where its caller gives none.
LATENCY_CDF_TITLE = "CAM latency over delivered CAMs only (a lost CAM has no latency)"


def plot_latency_cdf(
    latencies_ms: Mapping[str, Any],
    deadline_ms: float,
    path: str | Path,
    title: str | None = None,
    note: str | None = None,
) -> Path:
    """Empirical CDF of delivered CAMs' latency (ms) per method; the interval deadline marked.
    A lost CAM has no latency: the CDF is over the delivered CAMs only, as the default
    ``title`` and the y axis say. A method that delivered no CAM has no curve (its label says
    so in the legend)."""
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
    ax.set_ylabel("fraction of delivered CAMs (lost CAMs not counted)")
    ax.set_ylim(0, 1.02)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or LATENCY_CDF_TITLE, fontsize=10)
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
