"""``rgb_array`` rendering of a digital twin (scenario 0 only).

Top panel: the road, vehicles drawn to scale at their positions relative to the (first) leader,
one drawn lane per lane of the scenario, each gap annotated with its gap error and the
follower's speed. Bottom row, left to right: per V2V link, the fraction of the bits of this
interval's CAM received so far, coloured by the CAM's state (delivered, in progress, lost: the
interval ended first) and labelled with it; per V2V link, the transmit power of the last
subframe (dBm, "off"; from the RRA actions the twin was last stepped with, where known); per
sub-channel, the V2I rate (Mbps) averaged over this interval's subframes so far, with the
V2V links that shared it in the last subframe. For a twin without radio (perfect observation)
the row says so instead.

Matplotlib is used through an explicit ``Figure`` + Agg canvas, never pyplot, so rendering has no
global state and works headless.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch, Rectangle

from vdtn_marl.sim.link import cam_delivered

FIG_SIZE_IN = (8.0, 4.5)
DPI = 100

STATE_COLOURS = {"delivered": "#2ca02c", "pending": "#ff7f0e", "lost": "#d62728"}
#: The legend's names of the CAM states (``pending``: bits still to send, the interval runs).
STATE_LABELS = {
    "delivered": "delivered",
    "pending": "in progress",
    "lost": "lost (interval ended first)",
}
POWER_COLOUR = "#9467bd"
V2I_COLOUR = "#17becf"
LEADER_COLOUR = "#1f77b4"
FOLLOWER_COLOUR = "#7f7f7f"
COLLIDED_COLOUR = "#d62728"


def _np(x) -> np.ndarray:
    """A NumPy copy of a torch tensor or array."""
    if hasattr(x, "detach"):
        x = x.detach().cpu().numpy()
    return np.asarray(x)


def _last_actions(twin, rra_actions=None) -> np.ndarray | None:
    """The RRA actions [L] of scenario 0 in the last subframe: ``rra_actions`` ([B, L] or
    [L]) where given, else what the twin was last stepped with (``last_rra_actions``, set by
    :class:`~vdtn_marl.core.interval.IntervalEngine`), else None."""
    actions = rra_actions if rra_actions is not None else getattr(twin, "last_rra_actions", None)
    if actions is None:
        return None
    actions = _np(actions).astype(int)
    return actions[0] if actions.ndim > 1 else actions


def _last_subchannels(twin, actions: np.ndarray | None) -> np.ndarray | None:
    """Sub-channel each link used in the last subframe, [L] for scenario 0, if known."""
    link_state = getattr(twin, "link_state", None)
    for owner, name in ((link_state, "subchannel"), (twin, "last_subchannel")):
        value = getattr(owner, name, None) if owner is not None else None
        if value is not None:
            return _np(value)[0].astype(int)
    if actions is not None:
        return actions // twin.params.radio.num_power_levels
    return None


def _last_powers_dbm(twin, actions: np.ndarray | None) -> np.ndarray | None:
    """Transmit power [L] (dBm; NaN: off) each link chose in the last subframe, if known.
    A link whose CAM had been delivered before that subframe was silent (NaN) whatever it
    chose."""
    if actions is None:
        return None
    levels = tuple(twin.params.radio.v2v_power_levels_dbm)  # the last level, P − 1, is off
    level = actions % twin.params.radio.num_power_levels
    power = np.array([levels[k] if k < len(levels) else np.nan for k in level], dtype=float)
    delay = _np(twin.link_state.delay_subframes)[0].astype(int)
    power[delay < twin.subframe] = np.nan  # delivered in an earlier subframe: silent
    return power


def _v2i_rates_mbps(twin, record) -> tuple[np.ndarray | None, str]:
    """V2I rate per sub-channel [M] (Mbps) of scenario 0 averaged over this interval's
    subframes so far, or the previous interval's mean before the first subframe; and which."""
    running = getattr(twin, "_v2i_rate_sum", None)
    if running is not None and twin.subframe > 0:
        return _np(running)[0].astype(float) / twin.subframe / 1e6, "this interval so far"
    if record is not None and getattr(record, "v2i_rate_bps", None) is not None:
        return _np(record.v2i_rate_bps)[0].astype(float) / 1e6, "previous interval"
    return None, ""


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
        if r <= 0 or cam_delivered(d, t):
            states.append("delivered")
        elif twin.subframe >= t:
            states.append("lost")
        else:
            states.append("pending")
    return fraction, states


def _link_ticks(ax, twin) -> None:
    n_links = twin.num_links
    ax.set_xlim(-0.6, n_links - 0.4)
    ax.set_xticks(range(n_links))
    pairs = zip(twin.topology.link_tx, twin.topology.link_rx, strict=True)
    ax.set_xticklabels([f"link {rx}\n{tx}\u2192{rx}" for tx, rx in pairs], fontsize=7)
    ax.tick_params(labelsize=7)


def _no_radio(axes) -> None:
    for ax in axes:
        ax.set_axis_off()
    axes[0].text(
        0.5 * len(axes),
        0.5,
        "perfect observation\n(CAMs exact and instantaneous, no radio)",
        transform=axes[0].transAxes,
        ha="center",
        va="center",
        fontsize=10,
        color="#444444",
    )


def _draw_cams(ax, twin, record, subch) -> None:
    """Per link: the fraction of this interval's CAM bits received, by the CAM's state."""
    n_links = twin.num_links
    _link_ticks(ax, twin)
    fraction, states = _link_states(twin)
    colours = [STATE_COLOURS[s] for s in states]
    ax.bar(range(n_links), fraction, color=colours, edgecolor="black", lw=0.6, width=0.6)
    ax.set_ylim(0, 1.75)
    ax.set_yticks([0, 0.5, 1.0])
    ax.set_ylabel("fraction of CAM bits\nreceived", fontsize=7)
    ax.axhline(1.0, color="black", lw=0.5, ls=":")
    delay = _np(twin.link_state.delay_subframes)[0].astype(int)
    for i in range(n_links):
        if states[i] == "delivered":
            label = f"delivered\n@{delay[i] * twin.subframe_ms:g} ms"
        elif states[i] == "lost":
            label = f"lost\n{100 * fraction[i]:.0f}% of bits"
        else:
            label = f"{100 * fraction[i]:.0f}% of bits"
        if subch is not None:
            label += f"\nsub-ch {subch[i]}"
        ax.text(i, min(fraction[i], 1.0) + 0.04, label, ha="center", va="bottom", fontsize=6)
    title = "CAM of this interval"
    if record is not None:
        last = _np(record.cam_delay_subframes)[0].astype(int)
        ok = int((last <= twin.subframes_per_interval).sum())
        title += f" (previous: {ok}/{len(last)} delivered)"
    ax.set_title(title, fontsize=7)
    ax.legend(
        handles=[Patch(color=c, label=STATE_LABELS[s]) for s, c in STATE_COLOURS.items()],
        loc="upper left",
        fontsize=6,
        ncol=2,
        frameon=False,
    )


def _draw_powers(ax, twin, powers) -> None:
    """Per link: the transmit power of the last subframe (dBm), "off" where silent."""
    n_links = twin.num_links
    _link_ticks(ax, twin)
    levels = tuple(twin.params.radio.v2v_power_levels_dbm)
    low, high = min(0.0, min(levels)), max(levels)
    ax.set_ylim(low, high + 0.45 * (high - low or 1.0))
    ax.set_ylabel("V2V transmit\npower (dBm)", fontsize=7)
    when = "\n(of the previous interval)" if twin.subframe == 0 else ""
    ax.set_title(f"transmit power, last subframe{when}", fontsize=7)
    if powers is None:
        ax.text(0.5, 0.5, "not known\n(no RRA actions recorded)", transform=ax.transAxes,
                ha="center", va="center", fontsize=7, color="#444444")  # fmt: skip
        return
    shown = np.nan_to_num(powers, nan=0.0)
    ax.bar(range(n_links), shown, color=POWER_COLOUR, edgecolor="black", lw=0.6, width=0.6)
    for i, p in enumerate(powers):
        text = "off" if np.isnan(p) else f"{p:g}"
        ax.text(i, max(shown[i], 0.0) + 0.02 * (high - low or 1.0), text, ha="center",
                va="bottom", fontsize=6)  # fmt: skip


def _draw_v2i(ax, twin, record) -> None:
    """Per sub-channel: the V2I rate (Mbps) and the V2V links that shared it."""
    rates, when = _v2i_rates_mbps(twin, record)
    m = twin.num_subchannels
    occupancy = _np(twin.link_state.occupancy)[0]
    ax.set_xlim(-0.6, m - 0.4)
    ax.set_xticks(range(m))
    ax.set_xticklabels(
        [f"{k}\n{int(round(float(o)))} V2V" for k, o in enumerate(occupancy)], fontsize=6
    )
    ax.tick_params(labelsize=7)
    ax.set_ylabel("V2I rate (Mbps)", fontsize=7)
    ax.set_xlabel("sub-channel (V2V links on it, last subframe)", fontsize=6)
    if rates is None:
        ax.set_title("V2I traffic: no subframe yet", fontsize=7)
        return
    ax.bar(range(m), rates, color=V2I_COLOUR, edgecolor="black", lw=0.6, width=0.6)
    ax.set_ylim(0, max(float(rates.max()) * 1.3, 1e-3))
    ax.set_title(f"V2I traffic, mean of {when}\n{rates.sum():.2f} Mbps in all", fontsize=7)


def _draw_links(axes, twin, record, rra_actions=None) -> None:
    if not getattr(twin, "radio_enabled", False) or getattr(twin, "link_state", None) is None:
        _no_radio(axes)
        return
    actions = _last_actions(twin, rra_actions)
    cams, powers, v2i = axes
    _draw_cams(cams, twin, record, _last_subchannels(twin, actions))
    _draw_powers(powers, twin, _last_powers_dbm(twin, actions))
    _draw_v2i(v2i, twin, record)


def render_twin(twin, record=None, rra_actions=None) -> np.ndarray:
    """RGB image (uint8 ``[H, W, 3]``, ~800×450) of scenario 0 of ``twin``.

    ``record`` is the last :class:`~vdtn_marl.sim.twin.IntervalRecord` (optional): it adds the
    previous interval's reward and CAM outcome. ``rra_actions`` ([B, L] or [L], optional): the
    last subframe's RRA actions, for the transmit powers and sub-channels; by default those
    the twin was last stepped with (``twin.last_rra_actions``), where it keeps them.
    """
    fig = Figure(figsize=FIG_SIZE_IN, dpi=DPI)
    canvas = FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 3, height_ratios=[1.0, 1.15], width_ratios=[1.5, 1.0, 1.0])
    road_ax = fig.add_subplot(grid[0, :])
    link_axes = [fig.add_subplot(grid[1, k]) for k in range(3)]
    interval = int(_np(twin.interval)[0])
    title = f"interval k={interval}"
    if getattr(twin, "radio_enabled", False):
        title += f"   subframe {twin.subframe}/{twin.subframes_per_interval}"
    if record is not None:
        title += f"   last reward (mean) {float(_np(record.reward)[0].mean()):+.3f}"
    fig.suptitle(title, fontsize=10)
    _draw_road(road_ax, twin, record)
    _draw_links(link_axes, twin, record, rra_actions)
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    canvas.draw()
    image = np.asarray(canvas.buffer_rgba())[..., :3]
    return np.ascontiguousarray(image, dtype=np.uint8)
