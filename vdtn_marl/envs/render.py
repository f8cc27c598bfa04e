"""``rgb_array`` rendering of a digital twin (scenario 0 only).

Top panel: the road, vehicles drawn to scale at their positions relative to the leader, each gap
annotated with its gap error and the follower's speed. Bottom panel: one bar per V2V link with
the fraction of the current CAM delivered in this interval, coloured by state; for a twin without
radio (perfect observation) the panel says so instead.

Matplotlib is used through an explicit ``Figure`` + Agg canvas, never pyplot, so rendering has no
global state and works headless.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch, Rectangle

FIG_SIZE_IN = (8.0, 4.5)
DPI = 100

STATE_COLOURS = {"delivered": "#2ca02c", "pending": "#ff7f0e", "lost": "#d62728"}
LEADER_COLOUR = "#1f77b4"
FOLLOWER_COLOUR = "#7f7f7f"
COLLIDED_COLOUR = "#d62728"


def _np(x) -> np.ndarray:
    """A NumPy copy of a torch tensor or array."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)


def _last_subchannels(twin) -> np.ndarray | None:
    """Sub-channel each link used in the last subframe, [L] for scenario 0, if the twin keeps it."""
    link_state = getattr(twin, "link_state", None)
    for owner, name in ((link_state, "subchannel"), (twin, "last_subchannel")):
        value = getattr(owner, name, None) if owner is not None else None
        if value is not None:
            return _np(value)[0].astype(int)
    actions = getattr(twin, "last_rra_actions", None)
    if actions is not None:
        return _np(actions)[0].astype(int) // twin.params.radio.num_power_levels
    return None


def _draw_road(ax, twin, record) -> None:
    pp = twin.params.platoon
    state = twin.platoon
    pos = _np(state.position_m)[0].astype(float)
    speed = _np(state.speed_mps)[0].astype(float)
    x = pos - pos[0]  # leader at 0, followers behind (negative)
    length = pp.vehicle_length_m
    gaps = x[:-1] - x[1:] - length
    desired = pp.standstill_gap_m + pp.time_headway_s * speed[1:]
    gap_error = gaps - desired
    collided = gaps <= 0
    if record is not None:
        collided = collided | _np(record.collided)[0].astype(bool)

    lane_y, car_h = 0.0, 1.8
    left = float(x.min() - length - 2.0)
    right = float(max(x.max(), 0.0) + 3.0)
    ax.axhspan(lane_y - 0.8, lane_y + car_h + 2.6, color="#e8e8e8", zorder=0)
    ax.axhline(lane_y - 0.8, color="black", lw=1.0)
    ax.axhline(lane_y + car_h + 2.6, color="black", lw=1.0)
    for i, front in enumerate(x):
        if i == 0:
            colour = LEADER_COLOUR
        else:
            colour = COLLIDED_COLOUR if collided[i - 1] else FOLLOWER_COLOUR
        ax.add_patch(
            Rectangle(
                (front - length, lane_y), length, car_h, facecolor=colour, edgecolor="black", lw=0.8
            )
        )
        ax.text(
            front - length / 2,
            lane_y + car_h / 2,
            str(i),
            ha="center",
            va="center",
            color="white",
            fontsize=8,
            fontweight="bold",
        )
    ax.text(
        x[0] - length / 2,
        lane_y - 1.1,
        f"leader\n{speed[0]:.1f} m/s",
        ha="center",
        va="top",
        fontsize=7,
    )
    for i in range(len(gaps)):
        mid = (x[i] - length + x[i + 1]) / 2
        colour = COLLIDED_COLOUR if collided[i] else "black"
        ax.annotate(
            "",
            xy=(x[i] - length, lane_y + car_h + 0.6),
            xytext=(x[i + 1], lane_y + car_h + 0.6),
            arrowprops={"arrowstyle": "<->", "lw": 0.7, "color": colour},
        )
        ax.text(
            mid,
            lane_y + car_h + 0.9,
            f"e={gap_error[i]:+.2f} m",
            ha="center",
            va="bottom",
            fontsize=7,
            color=colour,
        )
        ax.text(
            mid, lane_y - 1.1, f"v{i + 1}={speed[i + 1]:.1f} m/s", ha="center", va="top", fontsize=7
        )
    ax.set_xlim(left, right)
    ax.set_ylim(lane_y - 4.0, lane_y + car_h + 3.4)
    ax.set_yticks([])
    ax.set_xlabel("position relative to the leader (m)", fontsize=8)
    ax.tick_params(labelsize=7)


def _link_states(twin) -> tuple[np.ndarray, list[str]]:
    """Delivered fraction [L] and state names of the CAM of every link (scenario 0)."""
    ls = twin.link_state
    cam_bits = float(twin.params.radio.cam_size_bits)
    remaining = _np(ls.remaining_bits)[0].astype(float)
    delay = _np(ls.delay_subframes)[0].astype(int)
    t = twin.subframes_per_interval
    fraction = np.clip(1.0 - remaining / cam_bits, 0.0, 1.0)
    states = []
    for r, d in zip(remaining, delay, strict=True):
        if r <= 0 or d <= t:
            states.append("delivered")
        elif twin.subframe >= t:
            states.append("lost")
        else:
            states.append("pending")
    return fraction, states


def _draw_links(ax, twin, record) -> None:
    n_links = twin.num_links
    ax.set_xlim(-0.6, n_links - 0.4)
    ax.set_xticks(range(n_links))
    ax.set_xticklabels([f"link {i + 1}\n{i}\u2192{i + 1}" for i in range(n_links)], fontsize=7)
    ax.tick_params(labelsize=7)
    if not getattr(twin, "radio_enabled", False) or getattr(twin, "link_state", None) is None:
        ax.set_ylim(0, 1)
        ax.set_yticks([])
        ax.text(
            0.5,
            0.5,
            "perfect observation\n(CAMs exact and instantaneous, no radio)",
            transform=ax.transAxes,
            ha="center",
            va="center",
            fontsize=10,
            color="#444444",
        )
        return
    fraction, states = _link_states(twin)
    colours = [STATE_COLOURS[s] for s in states]
    ax.bar(range(n_links), fraction, color=colours, edgecolor="black", lw=0.6, width=0.6)
    ax.set_ylim(0, 1.6)
    ax.set_yticks([0, 0.5, 1.0])
    ax.set_ylabel("CAM delivered", fontsize=8)
    ax.axhline(1.0, color="black", lw=0.5, ls=":")
    subch = _last_subchannels(twin)
    delay = _np(twin.link_state.delay_subframes)[0].astype(int)
    for i in range(n_links):
        label = states[i]
        if states[i] == "delivered":
            label += f" @{delay[i] * twin.subframe_ms:g} ms"
        if subch is not None:
            label += f"\nsub-ch {subch[i]}"
        ax.text(i, min(fraction[i], 1.0) + 0.04, label, ha="center", va="bottom", fontsize=7)
    occupancy = _np(twin.link_state.occupancy)[0]
    occ_text = "sub-channel occupancy (last subframe): " + " ".join(
        f"{m}:{int(round(float(o)))}" for m, o in enumerate(occupancy)
    )
    if record is not None:
        last = _np(record.cam_delay_subframes)[0].astype(int)
        ok = int((last <= twin.subframes_per_interval).sum())
        occ_text += f"   |   previous interval: {ok}/{len(last)} CAMs delivered"
    ax.text(0.01, 0.97, occ_text, transform=ax.transAxes, ha="left", va="top", fontsize=7)
    ax.legend(
        handles=[Patch(color=c, label=s) for s, c in STATE_COLOURS.items()],
        loc="upper right",
        fontsize=7,
        ncol=3,
        frameon=False,
        bbox_to_anchor=(1.0, 1.02),
    )


def render_twin(twin, record=None) -> np.ndarray:
    """RGB image (uint8 ``[H, W, 3]``, ~800×450) of scenario 0 of ``twin``.

    ``record`` is the last :class:`~vdtn_marl.sim.twin.IntervalRecord` (optional): it adds the
    previous interval's reward and CAM outcome.
    """
    fig = Figure(figsize=FIG_SIZE_IN, dpi=DPI)
    canvas = FigureCanvasAgg(fig)
    road_ax, link_ax = fig.subplots(2, 1, gridspec_kw={"height_ratios": [1.1, 1.0]})
    interval = int(_np(twin.interval)[0])
    title = f"interval k={interval}"
    if getattr(twin, "radio_enabled", False):
        title += f"   subframe {twin.subframe}/{twin.subframes_per_interval}"
    if record is not None:
        title += f"   last reward (mean) {float(_np(record.reward)[0].mean()):+.3f}"
    fig.suptitle(title, fontsize=10)
    _draw_road(road_ax, twin, record)
    _draw_links(link_ax, twin, record)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    canvas.draw()
    image = np.asarray(canvas.buffer_rgba())[..., :3]
    return np.ascontiguousarray(image, dtype=np.uint8)
