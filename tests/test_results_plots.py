"""Plot and table helpers of vdtn_marl.reporting that the end-to-end CLI tests cannot check."""

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from vdtn_marl.reporting.plots import _label_points  # noqa: E402


def _offsets(xs, ys):
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=120)
    ax.scatter(xs, ys)
    ax.set_xlim(0.0, 10.0)
    ax.set_ylim(0.0, 10.0)
    _label_points(ax, xs, ys, [f"κ1={i}" for i in range(len(xs))])
    offsets = {a.get_text(): a.xyann[1] for a in ax.texts}
    plt.close(fig)
    return [offsets[f"κ1={i}"] for i in range(len(xs))]


def test_labels_of_coinciding_points_are_stacked_a_line_apart():
    shifts = sorted(_offsets([5.0, 5.0, 5.0, 5.01], [5.0, 5.0, 5.01, 5.0]))
    assert shifts[0] == pytest.approx(0.0, abs=1.0)
    gaps = [b - a for a, b in zip(shifts, shifts[1:], strict=False)]
    assert min(gaps) >= 10.5  # one line of 8-point text apart (in points)


def test_labels_of_distant_points_stay_at_their_points():
    assert _offsets([1.0, 9.0, 5.0], [1.0, 9.0, 5.0]) == [0.0, 0.0, 0.0]


def test_the_summary_table_never_cuts_a_long_value():
    """A checkpoint path longer than the terminal wraps onto more lines instead of ending in …"""
    import io
    import re

    from rich.console import Console

    from vdtn_marl.reporting.tables import print_summary

    path = "/very/long/folder/of/runs/" + "x" * 90 + "/checkpoints/last.pt"
    out = io.StringIO()
    print_summary({"checkpoint": path, "seed": 3}, console=Console(file=out, width=60))
    text = out.getvalue()
    assert "…" not in text
    joined = re.sub(r"[\s│┃|]", "", text)
    assert path in joined


def test_a_title_wider_than_the_figure_is_wrapped_not_cut(tmp_path):
    from vdtn_marl.reporting.plots import save_figure

    long = "platoon4_1mhz: mean over seeds, 95% Student-t CI, dots = runs, and more words"
    fig, (ax, other) = plt.subplots(1, 2, figsize=(5.0, 4.2), dpi=120)
    ax.set_title(long, fontsize=10)
    other.set_title("short", fontsize=10)
    save_figure(fig, tmp_path / "bars.png")
    assert (tmp_path / "bars.png").stat().st_size > 0
    assert "\n" in ax.title.get_text() and ax.title.get_text().replace("\n", " ") == long
    assert other.title.get_text() == "short"
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(fig).get_renderer()  # save_figure closed the figure
    for title in (ax.title, other.title):
        extent = title.get_window_extent(renderer)
        assert extent.x0 >= 0 and extent.x1 <= fig.bbox.width


# --- every method's V2I throughput against |gap error| --------------------------------------

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _stat(mean, half=None):
    """One metric's statistics as the leaderboard's report has them (one run: no interval)."""
    if half is None:
        return {"n": 1, "mean": mean, "ci_low": None, "ci_high": None}
    return {"n": 5, "mean": mean, "ci_low": mean - half, "ci_high": mean + half}


def _method(gap, v2i, cost, half=0.05):
    return {
        "gap_error_abs_m": _stat(gap, half and half * gap),
        "v2i_throughput_mbps_per_link": _stat(v2i, half and half * v2i),
        "control_cost": _stat(cost, half and half * cost),
    }


STATS = {  # one scenario: {method: {metric: statistics}}
    "jocc_k075": _method(0.42, 2.0, 0.07),
    "jocc_k025": _method(0.37, 1.7, 0.068),
    "jocc_k050": _method(0.41, 1.9, 0.076),
    "drra": _method(0.08, 1.5, 0.036),
    "greedy": _method(0.06, 1.56, 0.035),
    "round_robin": _method(0.07, 1.05, 0.033),
    "oracle": _method(0.05, 1.53, 0.029, half=None),  # one run
}
ROLES = {
    **{f"jocc_k0{k}": {"role": "sweep", "kappa1": k / 100} for k in (25, 50, 75)},
    "drra": {"role": "learned", "kappa1": 0.5},
    "greedy": {"role": "baseline"},
    "round_robin": {"role": "baseline"},
    "oracle": {"role": "baseline"},
}


def _drawn(monkeypatch, *args, **kwargs):
    """plot_methods_pareto's figure, kept open past save_figure, and the PNG's path."""
    from vdtn_marl.reporting import plots

    figures = []
    save = plots.save_figure

    def keep(fig, path, note=None):
        figures.append(fig)
        return save(fig, path, note)

    monkeypatch.setattr(plots, "save_figure", keep)
    path = plots.plot_methods_pareto(*args, **kwargs)
    (fig,) = figures
    return fig, path


def test_every_method_figure_has_baselines_a_kappa1_sweep_and_better_directions(
    tmp_path, monkeypatch
):
    from matplotlib.container import ErrorbarContainer

    note = "vdtn-marl 0.0 · benchmark reduced v3.0"
    fig, path = _drawn(
        monkeypatch, STATS, tmp_path / "pareto.png", ROLES, title="platoon4: every method",
        note=note,
    )  # fmt: skip
    assert path == tmp_path / "pareto.png" and path.read_bytes()[:8] == PNG_MAGIC
    assert tuple(fig.get_size_inches()) == (7.0, 5.0) and fig.dpi == 120
    ax = fig.axes[0]
    texts = {t.get_text() for t in ax.texts}
    assert {"κ1=0.25", "κ1=0.5", "κ1=0.75", "drra", "greedy", "round_robin", "oracle"} <= texts
    assert "better ↑" in texts and "← better" in ax.get_xlabel()
    assert "|gap error|" in ax.get_xlabel() and "V2I throughput" in ax.get_ylabel()
    assert ax.get_title() == "platoon4: every method"
    assert note in {t.get_text() for t in fig.texts}
    # the sweep: one line through its means in the order of κ1
    (line,) = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 3]
    assert list(line.get_xdata()) == [0.37, 0.41, 0.42]
    assert list(line.get_ydata()) == [1.7, 1.9, 2.0]
    # every method a point with its interval in both axes, but the one-run oracle without
    bars = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
    assert len(bars) == len(STATS)
    assert sum(c.has_xerr and c.has_yerr for c in bars) == len(STATS) - 1
    (alone,) = [c for c in bars if not c.has_xerr]
    assert not alone.has_yerr and tuple(alone.lines[0].get_xydata()[0]) == (0.05, 1.53)
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(t.startswith("JOCC κ1 sweep") for t in legend)
    assert any(t.startswith("baseline") for t in legend)
    assert "no interval (one run): oracle" in legend
    plt.close(fig)


def test_every_method_figure_against_control_cost(tmp_path, monkeypatch):
    fig, path = _drawn(monkeypatch, STATS, tmp_path / "cost.png", ROLES, x="control_cost")
    assert path.read_bytes()[:8] == PNG_MAGIC
    assert "control cost" in fig.axes[0].get_xlabel() and "← better" in fig.axes[0].get_xlabel()
    plt.close(fig)


def test_every_method_figure_refuses_empty_input_naming_what_is_missing(tmp_path):
    from vdtn_marl.reporting.plots import plot_methods_pareto

    with pytest.raises(ValueError, match="no method to plot: the statistics are empty"):
        plot_methods_pareto({}, tmp_path / "empty.png")
    no_values = {"greedy": {"control_cost": _stat(0.1, 0.01)}}
    with pytest.raises(ValueError, match="'gap_error_abs_m' and 'v2i_throughput_mbps_per_link'"):
        plot_methods_pareto(no_values, tmp_path / "empty.png")
    assert not (tmp_path / "empty.png").exists()


def test_a_method_with_one_run_is_drawn_without_error_bars(tmp_path):
    from vdtn_marl.reporting.plots import plot_methods_pareto

    one = {"jocc_k050": _method(0.31, 1.83, 0.05, half=None)}
    path = plot_methods_pareto(one, tmp_path / "one.png", {"jocc_k050": ROLES["jocc_k050"]})
    assert path.read_bytes()[:8] == PNG_MAGIC


def _runs(scenario="platoon4"):
    """Runs as a report's JSON has them: method, its RRA, control and κ1 (two seeds each)."""
    choices = {
        "jocc_k025": ("jocc", "learned", 0.25), "jocc_k050": ("jocc", "learned", 0.5),
        "jocc_k075": ("jocc", "learned", 0.75), "drra": ("drra", "learned", 0.5),
        "throughput": ("throughput", "learned", 1.0), "greedy": ("greedy", "learned", 0.5),
        "no_augmentation": ("jocc", "learned", 0.5), "cacc": ("jocc", "cacc", 0.5),
        "oracle": ("greedy", "oracle", 0.5),
    }  # fmt: skip
    return [
        {"scenario": scenario, "method": m, "seed": seed, "rra": rra, "control": control,
         "kappa1": kappa1}
        for m, (rra, control, kappa1) in choices.items()
        for seed in (0, 1)
    ]  # fmt: skip


OVERRIDES = {
    "jocc_k025": ["rra=jocc", "rra.kappa1=0.25", "control=learned"],
    "jocc_k050": ["rra=jocc", "rra.kappa1=0.5", "control=learned"],
    "jocc_k075": ["rra=jocc", "rra.kappa1=0.75", "control=learned"],
    "drra": ["rra=drra", "control=learned"],
    "throughput": ["rra=throughput", "control=learned"],
    "greedy": ["rra=greedy", "control=learned"],
    "no_augmentation": ["rra=jocc", "rra.kappa1=0.5", "control=learned",
                        "control.augmentation=false"],
    "cacc": ["rra=jocc", "rra.kappa1=0.5", "control=cacc"],
    "oracle": ["rra=greedy", "control=oracle"],
}  # fmt: skip


def test_method_roles_split_baselines_the_kappa1_sweep_and_learned_rra():
    from vdtn_marl.leaderboard.plots import method_roles

    roles = method_roles(_runs(), OVERRIDES)
    by_role = {r: sorted(m for m, v in roles.items() if v["role"] == r) for r in
               ("baseline", "sweep", "learned")}  # fmt: skip
    assert by_role == {
        "baseline": ["cacc", "greedy", "oracle"],  # RRA or control not learned
        "sweep": ["jocc_k025", "jocc_k050", "jocc_k075"],
        "learned": ["drra", "no_augmentation", "throughput"],  # set apart by an override
    }
    assert roles["jocc_k025"]["kappa1"] == 0.25


def _leaderboard_json(path):
    """A tiny report: two scenarios, the methods of _runs, statistics from their runs."""
    import json

    from vdtn_marl.leaderboard.stats import aggregate

    runs = []
    for scenario in ("platoon4", "platoon8"):
        for i, run in enumerate(_runs(scenario)):
            runs.append({**run, "gap_error_abs_m": 0.05 + 0.01 * i,
                         "v2i_throughput_mbps_per_link": 1.0 + 0.1 * i,
                         "control_cost": 0.03 + 0.001 * i})  # fmt: skip
    runs = [r for r in runs if not (r["scenario"] == "platoon8" and r["seed"] == 1)]  # n = 1
    keys = ("gap_error_abs_m", "v2i_throughput_mbps_per_link", "control_cost")
    statistics = {}
    for run in runs:
        same = [r for r in runs if (r["scenario"], r["method"]) == (run["scenario"], run["method"])]
        statistics.setdefault(run["scenario"], {})[run["method"]] = {
            k: aggregate([r[k] for r in same]) for k in keys
        }
    data = {
        "benchmark": "tiny", "version": "1.0", "vdtn_marl_version": "0.0",
        "definition": {"methods": OVERRIDES},
        "statistics_method": {"interval_method": "t", "confidence": 0.95, "resamples": 100},
        "statistics": statistics, "runs": runs,
    }  # fmt: skip
    path.write_text(json.dumps(data))
    return path


def test_pareto_figure_script_writes_every_scenario_of_a_report(tmp_path, capsys):
    import importlib.util
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "benchmarks" / "pareto_figure.py"
    spec = importlib.util.spec_from_file_location("pareto_figure", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    report = _leaderboard_json(tmp_path / "leaderboard.json")
    assert module.main([str(report)]) == 0
    names = [f"pareto_{s}{c}.png" for s in ("platoon4", "platoon8") for c in ("", "_control_cost")]
    for name in names:
        assert (tmp_path / name).read_bytes()[:8] == PNG_MAGIC, name
    printed = capsys.readouterr().out
    assert all(f"wrote {tmp_path / name}" in printed for name in names)
    (tmp_path / "other.json").write_text('{"statistics": {}}')
    with pytest.raises(ValueError, match="no 'runs' entry"):
        module.main([str(tmp_path / "other.json")])


def test_the_leaderboard_report_draws_every_method(tmp_path):
    """write_plots writes the every-method figures (kinds pareto_methods, pareto_methods_cost)
    from the report's statistics, for runs without plot files of their own."""
    from vdtn_marl.experiment import config
    from vdtn_marl.leaderboard.plots import write_plots
    from vdtn_marl.leaderboard.stats import statistics

    rows = [
        {**r, "run_dir": str(tmp_path / "cells" / r["method"]), "gap_error_abs_m": 0.1 + 0.01 * i,
         "v2i_throughput_mbps_per_link": 1.5 + 0.01 * i, "control_cost": 0.03}
        for i, r in enumerate(_runs())
    ]  # fmt: skip
    b = config.BenchmarkConfig(
        name="tiny", version="1.0", scenarios=["platoon4"], methods=OVERRIDES, seeds=[0, 1]
    )
    cfg = config.BenchConfig(benchmark=b, out_dir=str(tmp_path / "cells"))
    plots = write_plots(cfg, rows, statistics(rows, b), tmp_path)["platoon4"]
    for kind in ("pareto_methods", "pareto_methods_cost"):
        assert plots[kind] == tmp_path / f"leaderboard_platoon4_{kind}.png"
        assert plots[kind].read_bytes()[:8] == PNG_MAGIC
