"""The renderer's radio row: CAM states labelled unambiguously, transmit power and V2I traffic
drawn."""

from __future__ import annotations

import numpy as np
import pytest

from vdtn_marl.envs import render
from vdtn_marl.envs.render import STATE_LABELS, render_twin


@pytest.fixture
def drawn(monkeypatch):
    """The texts of every axes of the last figure render_twin drew, by axes."""
    seen: list[list[str]] = []
    original = render.FigureCanvasAgg.draw

    def draw(canvas, *args, **kwargs):
        seen.clear()
        for ax in canvas.figure.axes:
            texts = [t.get_text() for t in ax.texts]
            texts += [ax.get_title(), ax.get_ylabel(), ax.get_xlabel()]
            texts += [t.get_text() for t in ax.get_xticklabels()]
            legend = ax.get_legend()
            if legend is not None:
                texts += [t.get_text() for t in legend.get_texts()]
            seen.append(texts)
        return original(canvas, *args, **kwargs)

    monkeypatch.setattr(render.FigureCanvasAgg, "draw", draw)
    return seen


def _engine_after_interval():
    """The twin of a two-timescale env whose first interval ran and closed (random actions
    through the engine), and that interval's record."""
    from vdtn_marl.envs import TwoTimescaleEnv

    env = TwoTimescaleEnv(kappa1=1.0, seed=0)
    _, infos = env.reset(seed=0)
    rng = np.random.default_rng(0)
    while env.last_record is None:
        actions = {}
        for agent in env.agents:
            if infos.get(agent, {}).get("acts", True):
                space = env.action_space(agent)
                space.seed(int(rng.integers(1 << 31)))
                actions[agent] = space.sample()
        _, _, _, _, infos = env.step(actions)
    return env.twin, env.last_record


def test_the_cam_bars_say_what_they_measure_and_lost_is_not_a_fraction(drawn):
    twin, record = _engine_after_interval()
    remaining = twin.link_state.remaining_bits
    remaining[0, 0] = 0.03 * twin.params.radio.cam_size_bits  # 97% of the bits, then the end
    twin.link_state.delay_subframes[0, 0] = twin.subframes_per_interval + 1
    remaining[0, 1] = 0.0
    twin.link_state.delay_subframes[0, 1] = 3
    twin.subframe = twin.subframes_per_interval  # the interval's end: a CAM still short is lost
    render_twin(twin, record)
    cams = drawn[1]
    assert "fraction of CAM bits\nreceived" in cams
    bars = [t for t in cams if "% of bits" in t or t.startswith("delivered\n")]
    assert bars[0].startswith("lost\n97% of bits")  # 97% of the bits came, the CAM did not
    assert bars[1].startswith("delivered\n@3 ms")
    assert STATE_LABELS["lost"] in cams and "lost" not in STATE_LABELS.values()


def test_transmit_power_and_v2i_traffic_are_drawn(drawn):
    twin, record = _engine_after_interval()
    assert twin.last_rra_actions is not None  # the engine keeps the last subframe's actions
    p = twin.params.radio.num_power_levels
    actions = np.zeros((2, twin.num_links), dtype=np.int64)  # sub-channel 0, the first level
    actions[0, 1] = p - 1  # the "off" level
    twin.link_state.delay_subframes[0, :2] = twin.subframes_per_interval + 1  # still sending
    image = render_twin(twin, record, rra_actions=actions)
    assert image.dtype == np.uint8 and image.shape[2] == 3
    powers, v2i = drawn[2], drawn[3]
    assert "V2V transmit\npower (dBm)" in powers
    first = f"{twin.params.radio.v2v_power_levels_dbm[0]:g}"
    assert powers[0] == first and powers[1] == "off"
    assert "V2I rate (Mbps)" in v2i
    (title,) = [t for t in v2i if t.startswith("V2I traffic")]
    total = float(record.v2i_rate_bps[0].sum()) / 1e6
    assert title.endswith(f"{total:.2f} Mbps in all")
    assert len(v2i_bars := [t for t in v2i if t.endswith("V2V")]) == twin.num_subchannels
    assert v2i_bars


def test_without_recorded_actions_the_power_panel_says_so(drawn):
    twin, record = _engine_after_interval()
    twin.last_rra_actions = None
    render_twin(twin, record)
    assert any("not known" in t for t in drawn[2])
