"""The CAM latency CDF says it is over delivered CAMs only, and how many."""

from __future__ import annotations

from types import SimpleNamespace

import torch

from vdtn_marl.reporting import plots


def _capture(monkeypatch):
    seen = {}
    original = plots.save_figure

    def save(fig, path, note=None):
        ax = fig.axes[0]
        seen.update(
            title=ax.get_title(),
            ylabel=ax.get_ylabel(),
            legend=[t.get_text() for t in ax.get_legend().get_texts()],
        )
        return original(fig, path, note)

    monkeypatch.setattr(plots, "save_figure", save)
    return seen


def test_the_latency_cdf_is_titled_as_over_delivered_cams_only(tmp_path, monkeypatch):
    seen = _capture(monkeypatch)
    path = plots.plot_latency_cdf({"greedy": [3.0, 7.0, 12.0]}, 50.0, tmp_path / "cdf.png")
    assert path.stat().st_size > 0
    assert "delivered CAMs only" in seen["title"]
    assert "delivered CAMs" in seen["ylabel"] and "lost" in seen["ylabel"]


def test_a_run_latency_cdf_names_the_count_of_delivered_cams(tmp_path, monkeypatch):
    from vdtn_marl.experiment.outputs import write_run_plots
    from vdtn_marl.sim.params import TwinParams

    seen = _capture(monkeypatch)
    params = TwinParams()
    followers = len(params.platoon.topology.followers)
    acting = SimpleNamespace(
        traces={
            "gap_error_abs_m": torch.zeros(4, followers),
            "speed_error_abs_mps": torch.zeros(4, followers),
        },
        cam_latency_ms=torch.tensor([2.0, 5.0, 9.0, 30.0, 41.0]),
        metrics={"cam_delivery_rate": 0.625},
    )
    written = write_run_plots(tmp_path, params, None, acting, "greedy RRA, cacc control")
    assert str(tmp_path / plots.LATENCY_CDF_FILE) in written
    (label, _deadline) = seen["legend"]
    assert label == "greedy RRA, cacc control: 5 delivered CAMs, 62.5% of those sent"
    assert "delivered CAMs only" in seen["title"]
