"""Per-subframe SINR, rates and CAM transmission (docs/model.md §4.4–4.5).

The work is split by timescale. At the start of each control interval :func:`build_interval_tables`
draws the fast fading of all T subframes at once and folds powers, antenna gains and noise
figures into linear tables ``[T, B, ...]``. The per-subframe kernel :func:`subframe_step` then
only gathers and does a few arithmetic operations.

The kernel is written against the array namespace of its inputs: the same code runs on torch
tensors (batched, CPU or CUDA) and on NumPy views of the same tables (the single-scenario
PettingZoo fast path, where eager torch's per-operation overhead would dominate). All random
draws happen in torch, so both paths see identical numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from functools import lru_cache

import numpy as np
import torch

from vdtn_marl.sim.backend import Array, cat, clamp, log10, sum_axis
from vdtn_marl.sim.channel import (
    db_to_linear,
    rayleigh_power_gain,
)
from vdtn_marl.sim.layout import RRA_OBS_GAIN_CLIP, RRA_OBS_GAIN_SCALE_DB
from vdtn_marl.sim.params import RadioParams
from vdtn_marl.sim.topology import Topology


def _xp(x: Array):
    return np if isinstance(x, np.ndarray) else torch


@dataclass(frozen=True)
class ActionTables:
    """Decoding of an RRA action a ∈ [0, M·P): sub-channel a // P, power level a % P.

    The last power level is "off" (0 mW). ``onehot`` is ``[A, M]``.
    """

    subchannel: Array  # [A] int64
    power_mw: Array  # [A] float32
    onehot: Array  # [A, M] float32

    @classmethod
    def build(cls, radio: RadioParams, device: torch.device) -> ActionTables:
        levels = radio.num_power_levels
        actions = torch.arange(radio.num_actions, device=device)
        power_dbm = torch.tensor(radio.v2v_power_levels_dbm, device=device)
        power_mw = torch.cat([db_to_linear(power_dbm), torch.zeros(1, device=device)])
        subchannel = actions // levels
        onehot = torch.nn.functional.one_hot(subchannel, radio.num_subchannels).float()
        return cls(subchannel, power_mw[actions % levels].float(), onehot)

    def numpy(self) -> ActionTables:
        return ActionTables(*(getattr(self, f.name).cpu().numpy() for f in fields(self)))


@dataclass(frozen=True)
class IntervalTables:
    """Linear radio quantities for every subframe of one control interval.

    Gains include antenna gains and the receiver's noise figure, so every SINR uses the same
    thermal noise power. Shapes: T subframes, B scenarios, L V2V links, M sub-channels.
    """

    own_gain: Array  # [T, B, L, M] V2V link l: its transmitter → its receiver, per sub-channel
    v2i_to_rx_mw: Array  # [T, B, L, M] power (mW) received at link l's receiver from V2I user m
    tx_to_bs_gain: Array  # [T, B, L, M] link l's transmitter → serving BS, per sub-channel
    cross_gain: Array  # [T, B, L, L] tx of link j (column) → rx of link i (row); diagonal 0
    v2i_signal_mw: Array  # [T, B, M] V2I user m's received power at the BS (mW)

    def numpy(self) -> IntervalTables:
        return IntervalTables(*(getattr(self, f.name).cpu().numpy() for f in fields(self)))


@dataclass
class LinkState:
    """CAM progress of each V2V link in the current interval (arrays of the kernel's backend)."""

    remaining_bits: Array  # [B, L] float32, ≤ 0 once delivered
    delay_subframes: (
        Array  # [B, L] int64: subframe (1..T) in which the last bit arrived; T+1 = not yet
    )
    occupancy: Array  # [B, M] float32: transmitting V2V links per sub-channel in the last subframe

    def numpy(self) -> LinkState:
        return LinkState(*(getattr(self, f.name).cpu().numpy() for f in fields(self)))

    def torch(self, device: torch.device) -> LinkState:
        return LinkState(
            *(torch.as_tensor(getattr(self, f.name), device=device) for f in fields(self))
        )


@dataclass
class SubframeOutcome:
    """What one subframe produced, per scenario (arrays of the kernel's backend)."""

    v2i_rate_bps: Array  # [B, M]
    v2v_bits: Array  # [B, L] bits delivered in this subframe
    v2v_power_mw: Array  # [B, L] transmit power actually used (0 when silent)
    delivered_now: Array  # [B, L] bool: the CAM's last bit arrived in this subframe
    was_pending: Array  # [B, L] bool: the CAM still had bits to send at the subframe start


def large_scale_gains_db(
    v2v_pathloss_db: torch.Tensor,
    v2v_shadow_db: torch.Tensor,
    v2i_pathloss_db: torch.Tensor,
    v2i_shadow_db: torch.Tensor,
    radio: RadioParams,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Vehicle→vehicle [B, N, N] and vehicle→BS [B, N] gains in dB, with antennas and NF."""
    v2v = (
        -v2v_pathloss_db
        - v2v_shadow_db
        + 2 * radio.vehicle_antenna_gain_db
        - radio.vehicle_noise_figure_db
    )
    v2i = (
        -v2i_pathloss_db
        - v2i_shadow_db
        + radio.vehicle_antenna_gain_db
        + radio.bs_antenna_gain_db
        - radio.bs_noise_figure_db
    )
    return v2v, v2i


@lru_cache(maxsize=32)
def _link_layout(topology: Topology, num_subchannels: int, device: torch.device | None):
    """Index constants of the topology's links: tx [L], rx [L], the V2I user of each
    sub-channel [M], and the off-diagonal mask [L, L] (docs/model.md §6).

    ``device=None``: NumPy arrays.
    """
    links = topology.num_links
    tx, rx = topology.link_tx, topology.link_rx
    v2i_user = topology.v2i_user(num_subchannels)
    if device is None:
        off_diagonal = (1.0 - np.eye(links)).astype(np.float32)
        return np.array(tx), np.array(rx), np.array(v2i_user), off_diagonal
    off_diagonal = 1.0 - torch.eye(links, device=device)
    tx, rx, v2i_user = (
        torch.tensor(rows, dtype=torch.long, device=device) for rows in (tx, rx, v2i_user)
    )
    return tx, rx, v2i_user, off_diagonal


def build_interval_tables(
    v2v_gain_db: torch.Tensor,
    v2i_gain_db: torch.Tensor,
    radio: RadioParams,
    num_subframes: int,
    generator: torch.Generator,
    topology: Topology,
) -> IntervalTables:
    """Draw the interval's Rayleigh fading and assemble the linear tables.

    ``v2v_gain_db`` [B, N, N] (tx row, rx column) and ``v2i_gain_db`` [B, N] come from
    :func:`large_scale_gains_db`. V2V link l runs from ``topology.link_tx[l]`` to
    ``topology.link_rx[l]``; sub-channel m carries the uplink of ``topology.v2i_user(M)[m]``
    (PF: link l from vehicle l to l+1, V2I user m = vehicle m mod N). Fading draws happen in a
    fixed order so that a seeded generator reproduces the same tables. With NumPy gains (the
    single-scenario fast path) the fading is drawn with the same torch generator and the
    tables are NumPy arrays.
    """
    b, n = v2i_gain_db.shape
    links, subch, t = topology.num_links, radio.num_subchannels, num_subframes
    numpy = isinstance(v2i_gain_db, np.ndarray)
    layout = _link_layout(topology, subch, None if numpy else v2i_gain_db.device)
    tx, rx, v2i_user, off_diagonal = layout
    v2i_power_mw = db_to_linear(radio.v2i_power_dbm)

    v2v_lin = db_to_linear(v2v_gain_db)  # [B, N, N]
    v2i_lin = db_to_linear(v2i_gain_db)  # [B, N]
    own_ls = v2v_lin[:, tx, rx]  # [B, L]
    v2i_to_rx_ls = v2v_lin[:, v2i_user][:, :, rx].swapaxes(1, 2)  # [B, L, M]
    tx_to_bs_ls = v2i_lin[:, tx]  # [B, L]
    cross_ls = v2v_lin[:, tx][:, :, rx].swapaxes(1, 2)  # [B, L_rx, L_tx]
    cross_ls = cross_ls * off_diagonal
    v2i_signal_ls = v2i_lin[:, v2i_user] * v2i_power_mw  # [B, M]

    fading = rayleigh_power_gain(
        (t, b, 3 * links * subch + links * links + subch), generator, numpy=numpy
    )
    block = links * subch
    cut = (0, block, 2 * block, 3 * block, 3 * block + links * links)
    own = fading[..., cut[0] : cut[1]].reshape(t, b, links, subch) * own_ls[None, :, :, None]
    v2i_rx = (
        fading[..., cut[1] : cut[2]].reshape(t, b, links, subch) * v2i_to_rx_ls[None] * v2i_power_mw
    )
    to_bs = fading[..., cut[2] : cut[3]].reshape(t, b, links, subch) * tx_to_bs_ls[None, :, :, None]
    cross = fading[..., cut[3] : cut[4]].reshape(t, b, links, links) * cross_ls[None]
    v2i_signal = fading[..., cut[4] :] * v2i_signal_ls[None]
    return IntervalTables(own, v2i_rx, to_bs, cross, v2i_signal)


def new_link_state(batch: int, links: int, subchannels: int, radio: RadioParams, t: int, device):
    """A fresh CAM of ``cam_size_bits`` on every link, nothing delivered yet.

    ``device=None``: NumPy arrays.
    """
    if device is None:
        return LinkState(
            remaining_bits=np.full((batch, links), float(radio.cam_size_bits), np.float32),
            delay_subframes=np.full((batch, links), t + 1, np.int64),
            occupancy=np.zeros((batch, subchannels), np.float32),
        )
    return LinkState(
        remaining_bits=torch.full((batch, links), float(radio.cam_size_bits), device=device),
        delay_subframes=torch.full((batch, links), t + 1, dtype=torch.long, device=device),
        occupancy=torch.zeros(batch, subchannels, device=device),
    )


@dataclass(frozen=True)
class KernelConstants:
    """Scalars and index grids the kernel needs, in its backend."""

    noise_mw: float
    bandwidth_hz: float
    subframe_s: float
    row_offset: Array  # [B, L] int64: flat index of (b, l, 0) in a contiguous [B, L, M] array

    @classmethod
    def build(cls, radio: RadioParams, subframe_s: float, batch: int, links: int, device):
        rows = torch.arange(batch * links, device=device).reshape(batch, links)
        return cls(
            noise_mw=float(db_to_linear(radio.noise_power_dbm)),
            bandwidth_hz=radio.subchannel_bandwidth_hz,
            subframe_s=subframe_s,
            row_offset=rows * radio.num_subchannels,
        )

    def numpy(self) -> KernelConstants:
        return replace(self, row_offset=self.row_offset.cpu().numpy())


def subframe_step(
    tables: IntervalTables,
    subframe: int,
    actions: Array,
    state: LinkState,
    decode: ActionTables,
    const: KernelConstants,
) -> SubframeOutcome:
    """Advance every V2V link by one 1 ms subframe (docs/model.md §4.4–4.5); updates ``state``.

    ``actions`` [B, L] are integer RRA actions. A link whose CAM is already delivered is silent.
    SINR_V2I[m] = P_I·G_m→BS / (σ² + Σ_{j on m} P_j·G_j→BS);
    SINR_V2V[i] = P_i·G_i / (σ² + P_I·G_{m→i} + Σ_{j≠i on m} P_j·G_{j→i}); rate = W·log2(1+SINR).
    """
    xp = _xp(actions)
    pending = state.remaining_bits > 0
    channel = decode.subchannel[actions]  # [B, L]
    power = decode.power_mw[actions] * pending  # [B, L]
    tx_onehot = decode.onehot[actions] * (power > 0)[..., None]  # [B, L, M]
    power_onehot = tx_onehot * power[..., None]

    # entry [b, l, channel[b, l]] of a contiguous [B, L, M] array, as one flat gather
    flat = const.row_offset + channel
    own = tables.own_gain[subframe].take(flat)
    from_v2i = tables.v2i_to_rx_mw[subframe].take(flat)
    # received V2V power at each receiver on each sub-channel, then the receiver's own channel
    rx_per_channel = xp.matmul(tables.cross_gain[subframe], power_onehot)  # [B, L, M]
    from_v2v = rx_per_channel.take(flat)
    v2v_sinr = power * own / (const.noise_mw + from_v2i + from_v2v)
    v2v_bits = xp.log1p(v2v_sinr) * (const.bandwidth_hz * const.subframe_s / math.log(2.0))

    bs_interference = sum_axis(power_onehot * tables.tx_to_bs_gain[subframe], 1)  # [B, M]
    v2i_sinr = tables.v2i_signal_mw[subframe] / (const.noise_mw + bs_interference)
    v2i_rate = xp.log1p(v2i_sinr) * (const.bandwidth_hz / math.log(2.0))

    state.remaining_bits = state.remaining_bits - v2v_bits
    delivered_now = pending & (state.remaining_bits <= 0)
    state.delay_subframes = xp.where(delivered_now, subframe + 1, state.delay_subframes)
    state.occupancy = sum_axis(tx_onehot, 1)
    return SubframeOutcome(v2i_rate, v2v_bits, power, delivered_now, pending)


def gain_feature(ratio: Array) -> Array:
    """A power ratio in dB, in units of ``RRA_OBS_GAIN_SCALE_DB``, clipped (observation scale)."""
    db = 10.0 * log10(clamp(ratio, 1e-30))
    return clamp(db / RRA_OBS_GAIN_SCALE_DB, *RRA_OBS_GAIN_CLIP)


def rra_static_observation(tables: IntervalTables, radio: RadioParams, noise_mw: float) -> Array:
    """Per-subframe CSI features of each link, [T, B, L, 3M] (docs/model.md §4.6).

    Blocks: own link SNR at maximum power; interference-to-noise it would cause at the BS at
    maximum power; interference-to-noise it suffers from each V2I user. All in units of 10 dB.
    Torch tables give a tensor, NumPy tables an array.
    """
    snr_at_max_power = float(db_to_linear(max(radio.v2v_power_levels_dbm))) / noise_mw
    ratios = cat(
        [
            tables.own_gain * snr_at_max_power,
            tables.tx_to_bs_gain * snr_at_max_power,
            tables.v2i_to_rx_mw * (1.0 / noise_mw),
        ],
        axis=-1,
    )
    return gain_feature(ratios)
