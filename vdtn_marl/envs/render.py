"""``rgb_array`` rendering of a digital twin (scenario 0 only).

Top panel: the road, vehicles drawn to scale at their positions relative to the (first) leader,
one drawn lane per lane of the scenario, each gap annotated with its gap error and the
follower's speed. Bottom panel: one bar per V2V link with
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
    topology = pp.topology
    state = twin.platoon
    pos = _np(state.position_m)[0].astype(float)
    speed = _np(state.speed_mps)[0].astype(float)
    x = pos - pos[topology.leaders[0]]  # the first leader at 0, followers behind (negative)
    length = pp.vehicle_length_m
    followers = list(topology.followers)
    predecessor = list(topology.link_tx)
    gaps = x[predecessor] - x[followers] - length
    desired = pp.standstill_gap_m + pp.time_headway_s * speed[followers]
    gap_error = gaps - desired
    collided = gaps <= 0
    if record is not None:
        collided = collided | _np(record.collided)[0].astype(bool)

    # one drawn lane per lateral offset, the lane nearest the base stations on top
    offsets = topology.lateral_offset_m or (0.0,) * topology.num_vehicles
    lane_of = {y: k for k, y in enumerate(sorted(set(offsets)))}
    car_h, lane_h = 1.8, 7.5
    lane_y = [lane_of[y] * lane_h for y in offsets]
    left = float(x.min() - length - 2.0)
    right = float(max(x.max(), 0.0) + 3.0)
    for k in range(len(lane_of)):
        ax.axhspan(k * lane_h - 0.8, k * lane_h + car_h + 2.6, color="#e8e8e8", zorder=0)
        ax.axhline(k * lane_h - 0.8, color="black", lw=1.0)
        ax.axhline(k * lane_h + car_h + 2.6, color="black", lw=1.0)
    row = {v: f for f, v in enumerate(followers)}
    for i, front in enumerate(x):
        if i in row:
            colour = COLLIDED_COLOUR if collided[row[i]] else FOLLOWER_COLOUR
        else:
            colour = LEADER_COLOUR
        ax.add_patch(
            Rectangle(
                (front - length, lane_y[i]),
                length,
                car_h,
                facecolor=colour,
                edgecolor="black",
                lw=0.8,
            )
        )
        ax.text(
            front - length / 2,
            lane_y[i] + car_h / 2,
            str(i),
            ha="center",
            va="center",
            color="white",
            fontsize=8,
            fontweight="bold",
        )
    for lead in topology.leaders:
        ax.text(
            x[lead] - length / 2,
            lane_y[lead] - 1.1,
            f"leader\n{speed[lead]:.1f} m/s",
            ha="center",
            va="top",
            fontsize=7,
        )
    for f, (p, v) in enumerate(zip(predecessor, followers, strict=True)):
        mid = (x[p] - length + x[v]) / 2
        y = lane_y[v]
        colour = COLLIDED_COLOUR if collided[f] else "black"
        ax.annotate(
            "",
            xy=(x[p] - length, y + car_h + 0.6),
            xytext=(x[v], y + car_h + 0.6),
            arrowprops={"arrowstyle": "<->", "lw": 0.7, "color": colour},
        )
        ax.text(
            mid,
            y + car_h + 0.9,
            f"e={gap_error[f]:+.2f} m",
            ha="center",
            va="bottom",
            fontsize=7,
            color=colour,
        )
        ax.text(mid, y - 1.1, f"v{v}={speed[v]:.1f} m/s", ha="center", va="top", fontsize=7)
    ax.set_xlim(left, right)
    ax.set_ylim(-4.0, max(lane_y) + car_h + 3.4)
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
    pairs = zip(twin.topology.link_tx, twin.topology.link_rx, strict=True)
    ax.set_xticklabels([f"link {rx}\n{tx}\u2192{rx}" for tx, rx in pairs], fontsize=7)
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
