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
