"""Per-subframe SINR, rates and CAM transmission (docs/model.md §4.4–4.5).

The work is split by timescale. At the start of each control interval :func:`build_interval_tables`
draws the fast fading of all T subframes at once and folds powers, antenna gains and noise
figures into linear tables ``[T, B, ...]``. The per-subframe kernel :func:`subframe_step` then
only gathers and does a few arithmetic operations.

Two layouts of the same numbers. The torch path (batched, CPU or CUDA) stores every table
*link-major*, with the batch innermost (``[T, L, M, B]``, ``[T, L, L, B]``, ``[T, M, B]``; the
link state ``[L, B]``), so that each of the kernel's operations streams over B contiguous
values; :class:`IntervalTables` and :class:`LinkState` show them in the documented
``[T, B, ...]`` / ``[B, ...]`` shapes as views. Its buffers (the draws, the tables) are reused
from interval to interval (:class:`FadingWorkspace`), because a fresh multi-megabyte tensor
costs a page fault per 4 KiB on the CPU. The NumPy path (the single-scenario PettingZoo fast
path, where eager torch's per-operation overhead would dominate) keeps the plain
``[T, B, ...]`` arrays. Both perform the same float32 operations on every entry, in the same
order; all random draws happen in torch, so both paths see identical numbers (up to NumPy's
own matmul, see :func:`subframe_step`).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from functools import cache, lru_cache
from types import SimpleNamespace

import numpy as np
import torch

from vdtn_marl.sim.backend import Array, cat, clamp, float32_scalars, log10, sum_axis
from vdtn_marl.sim.channel import (
    FADING_DRAWS,
    db_to_linear,
    rayleigh_power_gain,
    rayleigh_power_gain_exponential,
)
from vdtn_marl.sim.layout import RRA_OBS_GAIN_CLIP, RRA_OBS_GAIN_SCALE_DB
from vdtn_marl.sim.params import RadioParams
from vdtn_marl.sim.topology import Topology


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
    thermal noise power. Shapes: T subframes, B scenarios, L V2V links, M sub-channels. On the
    torch path the fields are views of link-major storage (:meth:`link_major`).
    """

    own_gain: Array  # [T, B, L, M] V2V link l: its transmitter → its receiver, per sub-channel
    v2i_to_rx_mw: Array  # [T, B, L, M] power (mW) received at link l's receiver from V2I user m
    tx_to_bs_gain: Array  # [T, B, L, M] link l's transmitter → serving BS, per sub-channel
    cross_gain: Array  # [T, B, L, L] tx of link j (column) → rx of link i (row); diagonal 0
    v2i_signal_mw: Array  # [T, B, M] V2I user m's received power at the BS (mW)

    def numpy(self) -> IntervalTables:
        return IntervalTables(*(getattr(self, f.name).cpu().numpy() for f in fields(self)))

    def link_major(self) -> tuple[Array, ...]:
        """The fields with the batch axis moved last: ``[T, L, M, B]`` (three of them),
        ``[T, L_rx, L_tx, B]`` and ``[T, M, B]`` (views; contiguous for tables built by
        :func:`build_interval_tables` on torch)."""
        return tuple(_batch_last(getattr(self, f.name), 1) for f in fields(self))


def _batch_last(x: Array, axis: int) -> Array:
    """A view of ``x`` with axis ``axis`` moved to the end."""
    return x.movedim(axis, -1) if isinstance(x, torch.Tensor) else np.moveaxis(x, axis, -1)


def _batch_first(x: Array) -> Array:
    """A view of a batch-last ``x`` with its last axis moved to the front (the inverse for
    ``[L, B]``-like arrays)."""
    return x.movedim(-1, 0) if isinstance(x, torch.Tensor) else np.moveaxis(x, -1, 0)


@dataclass
class LinkState:
    """CAM progress of each V2V link in the current interval (arrays of the kernel's backend;
    on torch, views of link-major ``[L, B]`` / ``[M, B]`` storage)."""

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


def cam_delivered(delay_subframes: Array, subframes_per_interval: int) -> Array:
    """Whether each link's CAM arrived within its interval: its delivery subframe (1..T, T + 1
    while not delivered; :attr:`LinkState.delay_subframes`) is at most T, so a CAM whose last
    bit arrives in the deadline subframe T counts as delivered."""
    return delay_subframes <= subframes_per_interval


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


#: batch sizes from which the torch path works link-major (measured: below it the extra
#: operations of the link-major kernel cost more than its streaming saves, docs/profile.md)
LINK_MAJOR_MIN_BATCH = 256


def link_major(batch: int, numpy: bool = False) -> bool:
    """Whether a twin of ``batch`` scenarios holds its tables and link state link-major."""
    return not numpy and batch >= LINK_MAJOR_MIN_BATCH


#: values per array of a chunk of the interval's work on the torch path: a chunk of subframes
#: is worked through while its arrays are in the core's cache (L2: 0.5–2 MiB per core)
CHUNK_VALUES = 1 << 16


class FadingWorkspace:
    """Buffers the torch path reuses from interval to interval: the interval's fading draws
    and the scratch of a chunk, and the next interval's draws when a :class:`DrawAhead` is
    making them (``ahead``, into the other of the two fading buffers: ``turn`` is the one
    this interval's are in). Never state (each interval overwrites them): it has no
    ``__dict__``, so snapshots (:mod:`vdtn_marl.sim.snapshot`) skip it, and a deep copy of a
    twin gets a fresh one."""

    __slots__ = ("_buffers", "ahead", "turn")

    def __init__(self):
        self._buffers: dict[str, torch.Tensor] = {}
        self.ahead: DrawAhead | None = None
        self.turn = 0

    def get(self, name: str, shape: tuple[int, ...], like: torch.Tensor) -> torch.Tensor:
        """The buffer ``name`` of ``shape`` in ``like``'s dtype and device (kept, or new)."""
        buffer = self._buffers.get(name)
        if (
            buffer is None
            or tuple(buffer.shape) != tuple(shape)
            or buffer.dtype != like.dtype
            or buffer.device != like.device
        ):
            buffer = self._buffers[name] = torch.empty(shape, dtype=like.dtype, device=like.device)
        return buffer

    def __deepcopy__(self, memo) -> FadingWorkspace:
        return FadingWorkspace()  # scratch: nothing to copy


def fading_width(links: int, subchannels: int) -> int:
    """W = 3LM + L² + M fast-fading gains per scenario and subframe."""
    return 3 * links * subchannels + links * links + subchannels


def fading_buffer(
    workspace: FadingWorkspace, batch: int, width: int, subframes: int, like: torch.Tensor,
    turn: int = 0,
) -> torch.Tensor:  # fmt: skip
    """The buffer ``[T, W, B]`` that holds an interval's fast-fading power gains |h|²,
    link-major (:func:`draw_fading`). ``turn`` (0 or 1) picks one of two: the next
    interval's gains are drawn into one (:class:`DrawAhead`) while this interval's are read
    from the other."""
    return workspace.get(f"fading{turn}", (subframes, width, batch), like)


def normals_buffer(
    workspace: FadingWorkspace, batch: int, width: int, subframes: int, like: torch.Tensor
) -> torch.Tensor:
    """Scratch ``[2, T, B, W]`` for the normal draws of ``fading_draws="normal"``."""
    return workspace.get("normals", (2, subframes, batch, width), like)


def draw_fading(
    buffer: torch.Tensor, generator: torch.Generator, fading_draws: str,
    normals: torch.Tensor | None = None,
) -> None:  # fmt: skip
    """Fill :func:`fading_buffer`'s ``buffer`` with the interval's fast-fading power gains.

    ``"normal"``: one call draws the normals ``[2, T, B, W]`` into ``normals`` (a
    :func:`normals_buffer`; the same numbers as
    :func:`~vdtn_marl.sim.channel.rayleigh_power_gain`'s randn), then |h|² = (x² + y²)/2 is
    written link-major into ``buffer``: in place in the draws, then one transposing copy
    (elementwise operations that transpose as they go cost torch several times more). Whole
    arrays, not chunks: on the :class:`DrawAhead` thread each call is a turn at the GIL the
    main thread waits for (measured: chunks cost the twin at B = 256 about 7 %, and gained
    nothing at B = 4,096). ``"exponential"``: one Exp(1) draw per gain, straight into
    ``buffer``."""
    if fading_draws != "exponential":
        normals.normal_(generator=generator)
        x, y = normals
        x.mul_(x).add_(y.mul_(y)).mul_(0.5)
        buffer.copy_(x.transpose(1, 2))
    elif buffer.device.type == "cpu":
        rayleigh_power_gain_exponential(buffer.shape, generator, out=buffer.numpy())
    else:
        buffer.exponential_(generator=generator)


def draw_interval(
    generator: torch.Generator, batch: int, vehicles: int, fading: torch.Tensor | None,
    fading_draws: str, normals: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:  # fmt: skip
    """An interval's random draws in their fixed order: the V2V shadowing innovation
    ``[B, N, N]`` (before :func:`~vdtn_marl.sim.channel.symmetrize`), the V2I innovation
    ``[B, N]``, then the fast fading into ``fading`` (a :func:`fading_buffer`, with
    ``normals`` a :func:`normals_buffer` for ``"normal"`` draws; None: the caller's
    :func:`build_interval_tables` draws it next). The only copy of this order: the twin draws
    with it, and :class:`DrawAhead` with a copy of the twin's generator."""
    device = generator.device
    v2v = torch.randn((batch, vehicles, vehicles), generator=generator, device=device)
    v2i = torch.randn(batch, vehicles, generator=generator, device=device)
    if fading is not None:
        draw_fading(fading, generator, fading_draws, normals)
    return v2v, v2i, fading


#: from this many scenarios the CPU twin makes the next interval's draws on a second thread
#: while the subframes run (:class:`DrawAhead`); below it a thread costs about what the draws
#: do (at B = 4,096 they are more than half of the interval's work, docs/profile.md)
DRAW_AHEAD_MIN_BATCH = 128


class DrawAhead:
    """The next interval's :func:`draw_interval`, made on a second thread from a copy of the
    twin's generator while this interval's subframes run (torch releases the GIL in its
    kernels, so a second core draws while the first steps the radio).

    :meth:`take` hands the draws over, and moves the twin's generator to where the copy
    ended, only if the twin's generator has not drawn since the copy was taken (a reset, a
    burn-in, a restored snapshot draw or set it): otherwise it returns None and the twin draws
    again itself, in order. Either way the numbers are those of drawing in place, bit for bit;
    the generator itself is never touched by the thread, so snapshots and deep copies of the
    twin see it as if nothing were pending."""

    __slots__ = ("_start", "_result", "_thread")

    def __init__(
        self, generator: torch.Generator, batch: int, vehicles: int, fading: torch.Tensor,
        fading_draws: str, normals: torch.Tensor | None = None,
    ):  # fmt: skip
        self._start = generator.get_state()
        copy = torch.Generator(device=generator.device)
        copy.set_state(self._start)
        self._result: dict = {}

        def job() -> None:
            try:
                draws = draw_interval(copy, batch, vehicles, fading, fading_draws, normals)
                self._result["done"] = (draws, copy.get_state())  # one store: all or nothing
            except BaseException as error:  # re-raised by take()
                self._result["error"] = error

        # not a daemon: the interpreter waits for it at exit instead of finalizing under a
        # running torch kernel (which aborts the process)
        self._thread = threading.Thread(target=job, name="vdtn-draw-ahead", daemon=False)
        self._thread.start()

    def wait(self) -> None:
        """Block until the draws are made (:meth:`take` waits too; profiling times this)."""
        self._thread.join()

    def take(self, generator: torch.Generator):
        """The draws ``(v2v, v2i, fading)``, ``generator`` advanced past them, or None when
        ``generator`` has drawn (or been set) since: then the caller draws them itself."""
        self._thread.join()  # also after a fork: the copied thread counts as stopped
        if "error" in self._result:
            raise self._result["error"]
        done = self._result.get("done")
        if done is None or not torch.equal(generator.get_state(), self._start):
            return None
        draws, end = done
        generator.set_state(end)
        return draws


def _chunk_subframes(batch: int, width: int, subframes: int) -> int:
    """Subframes per chunk: ``width`` values per scenario and subframe, ≈ CHUNK_VALUES per
    array, at least one subframe and at most all of them."""
    return max(1, min(subframes, CHUNK_VALUES // max(1, batch * width)))


def build_interval_tables(
    v2v_gain_db: torch.Tensor,
    v2i_gain_db: torch.Tensor,
    radio: RadioParams,
    num_subframes: int,
    generator: torch.Generator,
    topology: Topology,
    workspace: FadingWorkspace | None = None,
    out: IntervalTables | None = None,
    fading_draws: str = "normal",
    drawn: torch.Tensor | None = None,
    rows: torch.Tensor | None = None,
) -> IntervalTables:
    """Draw the interval's Rayleigh fading and assemble the linear tables.

    ``v2v_gain_db`` [B, N, N] (tx row, rx column) and ``v2i_gain_db`` [B, N] come from
    :func:`large_scale_gains_db`. V2V link l runs from ``topology.link_tx[l]`` to
    ``topology.link_rx[l]``; sub-channel m carries the uplink of ``topology.v2i_user(M)[m]``
    (PF: link l from vehicle l to l+1, V2I user m = vehicle m mod N). Fading draws happen in a
    fixed order, one call for the whole interval (:func:`rayleigh_power_gain`: [2, T, B, W]
    normals, W = 3LM + L² + M gains per scenario and subframe), so that a seeded generator
    reproduces the same tables. With NumPy gains (the single-scenario fast path) the fading is
    drawn with the same torch generator and the tables are NumPy arrays.

    ``fading_draws="exponential"`` draws each gain as one Exp(1) number
    (:func:`~vdtn_marl.sim.channel.rayleigh_power_gain_exponential`, laid out [T, W, B]): the
    same law, other numbers, in a fraction of the time; on CUDA with torch's
    ``exponential_`` on the device.

    On torch the draws land in ``workspace``'s buffer and the tables are built link-major,
    a chunk of subframes at a time (:data:`CHUNK_VALUES`), into ``out``'s storage when it has
    the right shapes and is link-major (the previous interval's tables, overwritten), else
    into new tensors. ``drawn`` (torch): a :func:`fading_buffer` that already holds the
    interval's fading power gains (:func:`draw_interval`), which are then not drawn again.

    ``rows`` [b] (torch, with ``drawn`` [T, W, b] those scenarios' gains): the tables of the
    scenarios ``rows`` of the batch alone. The gains in dB are made linear for the whole batch
    first: ``torch.pow`` on the CPU can round an entry in the last bit differently by its
    place in the array (measured), which these rows' own call would change.
    """
    b, n = v2i_gain_db.shape
    links, subch, t = topology.num_links, radio.num_subchannels, num_subframes
    numpy = isinstance(v2i_gain_db, np.ndarray)
    layout = _link_layout(topology, subch, None if numpy else v2i_gain_db.device)
    tx, rx, v2i_user, off_diagonal = layout
    v2i_power_mw = db_to_linear(radio.v2i_power_dbm)

    v2v_lin = db_to_linear(v2v_gain_db)  # [B, N, N]
    v2i_lin = db_to_linear(v2i_gain_db)  # [B, N]
    if rows is not None:
        if drawn is None:
            raise ValueError("build_interval_tables(rows=...) needs the batch's drawn fading")
        v2v_lin, v2i_lin, b = (
            v2v_lin.index_select(0, rows),
            v2i_lin.index_select(0, rows),
            len(rows),
        )
    own_ls = v2v_lin[:, tx, rx]  # [B, L]
    v2i_to_rx_ls = v2v_lin[:, v2i_user][:, :, rx].swapaxes(1, 2)  # [B, L, M]
    tx_to_bs_ls = v2i_lin[:, tx]  # [B, L]
    cross_ls = v2v_lin[:, tx][:, :, rx].swapaxes(1, 2)  # [B, L_rx, L_tx]
    cross_ls = cross_ls * off_diagonal
    v2i_signal_ls = v2i_lin[:, v2i_user] * v2i_power_mw  # [B, M]
    width = fading_width(links, subch)
    if fading_draws not in FADING_DRAWS:
        raise ValueError(f"fading_draws={fading_draws!r} must be one of {FADING_DRAWS}")
    if link_major(b, numpy):
        return _build_tables_link_major(
            (own_ls, v2i_to_rx_ls, tx_to_bs_ls, cross_ls, v2i_signal_ls),
            v2i_power_mw,
            t,
            width,
            generator,
            workspace or FadingWorkspace(),
            out,
            fading_draws,
            drawn,
        )

    if drawn is not None:  # [T, W, B] seen as [T, B, W]: the same numbers as the draws below
        fading = drawn.transpose(1, 2)
    elif fading_draws == "exponential":  # [T, W, B] as link-major, seen as [T, B, W]
        fading = rayleigh_power_gain_exponential((t, width, b), generator).transpose(0, 2, 1)
        if not numpy:
            fading = torch.from_numpy(fading).to(v2i_gain_db.device)
    else:
        fading = rayleigh_power_gain((t, b, width), generator, numpy=numpy)
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


def _gain_stack(tables: IntervalTables) -> torch.Tensor | None:
    """The link-major storage [T, 3, L, M, B] that ``own_gain``, ``v2i_to_rx_mw`` and
    ``tx_to_bs_gain`` are views of, in this order (tables built by
    :func:`build_interval_tables` on torch); None when they are not (e.g. after a snapshot
    restored them as separate tensors)."""
    own, v2i_rx, to_bs, _, _ = tables.link_major()
    if not all(isinstance(x, torch.Tensor) for x in (own, v2i_rx, to_bs)):
        return None
    t, links, subch, batch = own.shape
    block = links * subch * batch
    strides = (3 * block, subch * batch, batch, 1)
    base = own.data_ptr()
    for i, array in enumerate((own, v2i_rx, to_bs)):
        if (
            tuple(array.shape) != (t, links, subch, batch)
            or array.stride() != strides
            or array.untyped_storage().data_ptr() != own.untyped_storage().data_ptr()
            or array.data_ptr() != base + i * block * own.element_size()
        ):
            return None
    return own.as_strided((t, 3, links, subch, batch), (3 * block, block, subch * batch, batch, 1))


def _reusable(out: IntervalTables | None, shapes: list[tuple[int, ...]], like: torch.Tensor):
    """``out``'s link-major storage (the gain stack, cross gains, V2I signals) when it has
    these shapes, is contiguous, and in ``like``'s dtype and device; else None."""
    if out is None:
        return None
    _, _, _, cross, v2i_signal = out.link_major()
    arrays = (_gain_stack(out), cross, v2i_signal)
    for array, shape in zip(arrays, shapes, strict=True):
        if (
            not isinstance(array, torch.Tensor)
            or tuple(array.shape) != shape
            or not array.is_contiguous()
            or array.dtype != like.dtype
            or array.device != like.device
        ):
            return None
    return arrays


def _build_tables_link_major(
    large_scale, v2i_power_mw: float, t: int, width: int, generator, workspace, out, fading_draws,
    drawn=None,
) -> IntervalTables:  # fmt: skip
    """The torch path of :func:`build_interval_tables`: the same float32 operations on every
    entry as the NumPy path, written link-major a chunk of subframes at a time. The own,
    V2I→rx and tx→BS gains share one storage [T, 3, L, M, B] (one multiplication builds the
    three, one more starts their CSI features)."""
    own_ls, v2i_to_rx_ls, tx_to_bs_ls, cross_ls, v2i_signal_ls = large_scale
    b, links, subch = v2i_to_rx_ls.shape
    # the large-scale factors with the batch last, broadcasting against [C, ·, ·, B]
    gain_f = torch.stack(
        [
            own_ls.T[:, None, :].expand(links, subch, b),
            v2i_to_rx_ls.permute(1, 2, 0),
            tx_to_bs_ls.T[:, None, :].expand(links, subch, b),
        ]
    )  # [3, L, M, B]
    cross_f = cross_ls.permute(1, 2, 0).contiguous()  # [L_rx, L_tx, B]
    v2i_signal_f = v2i_signal_ls.T.contiguous()  # [M, B]
    shapes = [(t, 3, links, subch, b), (t, links, links, b), (t, subch, b)]
    gains, cross, v2i_signal = _reusable(out, shapes, own_ls) or tuple(
        torch.empty(shape, dtype=own_ls.dtype, device=own_ls.device) for shape in shapes
    )

    chunk = _chunk_subframes(b, width, t)
    block = links * subch
    # |h|² link-major [T, W, B] (draw_fading)
    if drawn is None:
        drawn = fading_buffer(workspace, b, width, t, own_ls)
        normals = normals_buffer(workspace, b, width, t, own_ls)
        draw_fading(drawn, generator, fading_draws, normals)
    for t0 in range(0, t, chunk):
        t1 = min(t, t0 + chunk)
        c = t1 - t0
        fading = drawn[t0:t1]
        torch.mul(fading[:, : 3 * block].view(c, 3, links, subch, b), gain_f, out=gains[t0:t1])
        gains[t0:t1, 1].mul_(v2i_power_mw)
        cut = 3 * block + links * links
        torch.mul(fading[:, 3 * block : cut].view(c, links, links, b), cross_f, out=cross[t0:t1])
        torch.mul(fading[:, cut:], v2i_signal_f, out=v2i_signal[t0:t1])
    return IntervalTables(
        gains[:, 0].permute(0, 3, 1, 2),
        gains[:, 1].permute(0, 3, 1, 2),
        gains[:, 2].permute(0, 3, 1, 2),
        cross.permute(0, 3, 1, 2),
        v2i_signal.permute(0, 2, 1),
    )


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
    if not link_major(batch):
        return LinkState(
            remaining_bits=torch.full((batch, links), float(radio.cam_size_bits), device=device),
            delay_subframes=torch.full((batch, links), t + 1, dtype=torch.long, device=device),
            occupancy=torch.zeros(batch, subchannels, device=device),
        )
    # link-major storage, shown [B, ...]
    return LinkState(
        remaining_bits=torch.full((links, batch), float(radio.cam_size_bits), device=device).T,
        delay_subframes=torch.full((links, batch), t + 1, dtype=torch.long, device=device).T,
        occupancy=torch.zeros(subchannels, batch, device=device).T,
    )


@dataclass(frozen=True)
class KernelConstants:
    """Scalars and index grids the kernel needs, in its backend."""

    noise_mw: float
    bandwidth_hz: float
    subframe_s: float
    row_offset: Array  # [B, L] int64: flat index of (b, l, 0) in a contiguous [B, L, M] array
    link_offset: Array  # [L, B] int64: flat index of (l, 0, b) in a contiguous [L, M, B] array
    channel_offset: Array  # [A] int64: each action's sub-channel × B
    subchannels: Array  # [M, 1] int64: 0..M−1

    @classmethod
    def build(cls, radio: RadioParams, subframe_s: float, batch: int, links: int, device):
        rows = torch.arange(batch * links, device=device).reshape(batch, links)
        per_link = torch.arange(links, device=device)[:, None] * (radio.num_subchannels * batch)
        actions = torch.arange(radio.num_actions, device=device)
        return cls(
            noise_mw=float(db_to_linear(radio.noise_power_dbm)),
            bandwidth_hz=radio.subchannel_bandwidth_hz,
            subframe_s=subframe_s,
            row_offset=rows * radio.num_subchannels,
            link_offset=per_link + torch.arange(batch, device=device),
            channel_offset=actions // radio.num_power_levels * batch,
            subchannels=torch.arange(radio.num_subchannels, device=device)[:, None],
        )

    @property
    def float32(self) -> SimpleNamespace | None:
        """The NumPy kernel's scalars as read-only float32 0-d arrays: on float32 arrays the
        same operations as with the Python numbers (NumPy casts a Python scalar to the
        array's dtype first), at a third of NumPy's cost per call."""
        return _kernel_float32(self.noise_mw, self.bandwidth_hz, self.subframe_s)

    def numpy(self) -> KernelConstants:
        arrays = {
            f.name: getattr(self, f.name).cpu().numpy()
            for f in fields(self)
            if isinstance(getattr(self, f.name), torch.Tensor)
        }
        return replace(self, **arrays)


@lru_cache(maxsize=16, typed=True)  # np.float64(x) and x apart
def _kernel_float32(
    noise_mw: float, bandwidth_hz: float, subframe_s: float
) -> SimpleNamespace | None:
    # positive numbers: the cache's key (equal values share an entry) loses no zero's sign
    return float32_scalars(
        zero=0.0,
        noise_mw=noise_mw,
        v2v_bits_per_nat=bandwidth_hz * subframe_s / math.log(2.0),
        v2i_bps_per_nat=bandwidth_hz / math.log(2.0),
    )


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

    On torch the sums over links add in the order of the ``[B, L, M]`` formulation's batched
    matmul and sum over the link axis: in link order, 0 + x_0 + x_1 + …, each term rounded to
    float32 before it is added, where that is their order on this machine
    (:func:`_torch_adds_in_link_order`, measured once per shape), else by calling them on
    ``[B, ...]`` copies (tested against that formulation, tests/sim/test_physics.py). On
    NumPy arrays the V2V interference is NumPy's matmul, whose order is BLAS's (the
    single-scenario path's own numbers: in about 0.4 % of the subframes in which two
    interferers share a receiver's sub-channel it differs from torch's in the last bit). On
    torch from :data:`LINK_MAJOR_MIN_BATCH` scenarios on the work is link-major
    (:func:`_subframe_step_link_major`; the results are ``[B, ...]`` views), below it the
    ``[B, L, M]`` code (:func:`_subframe_step_dense`); on NumPy arrays that code with fewer
    calls (:func:`_subframe_step_numpy`, bit for bit the same). The three share the SINR
    equations and the CAM's progress (:func:`sinr_rates_and_progress`); they differ only in
    the layout, the gathers and the order of the interference sums.
    """
    if isinstance(actions, np.ndarray):
        return _subframe_step_numpy(tables, subframe, actions, state, decode, const)
    if link_major(actions.shape[0]):
        return _subframe_step_link_major(tables, subframe, actions, state, decode, const)
    return _subframe_step_dense(tables, subframe, actions, state, decode, const)


def sinr_rates_and_progress(
    power: Array, own: Array, from_v2i: Array, from_v2v: Array, v2i_signal: Array,
    bs_interference: Array, remaining_bits: Array, pending: Array, log1p: Callable,
    noise_mw, bits_per_nat, bps_per_nat, zero,
) -> tuple[Array, Array, Array, Array]:  # fmt: skip
    """The SINR equations of docs/model.md §4.4 and the CAM's progress, once for every kernel.

    Each kernel gathers, in its own layout, every V2V link's transmit power ``power`` (0 when
    silent), own gain ``own``, the power it receives from its sub-channel's V2I user
    ``from_v2i`` and from the other V2V transmitters there ``from_v2v`` (all ``[B, L]``, or
    ``[L, B]`` link-major), and every sub-channel's V2I signal ``v2i_signal`` and V2V power at
    the BS ``bs_interference`` (``[B, M]`` or ``[M, B]``); ``log1p`` and the scalars are the
    backend's (``zero`` too: the NumPy kernel's are float32 0-d arrays). Returns the V2I rates
    (bit/s), the V2V bits of this subframe, the bits left and whether the CAM's last bit
    arrived in this subframe."""
    v2v_sinr = power * own / (noise_mw + from_v2i + from_v2v)
    v2v_bits = log1p(v2v_sinr) * bits_per_nat
    v2i_sinr = v2i_signal / (noise_mw + bs_interference)
    v2i_rate = log1p(v2i_sinr) * bps_per_nat
    remaining = remaining_bits - v2v_bits
    delivered_now = pending & (remaining <= zero)
    return v2i_rate, v2v_bits, remaining, delivered_now


def _subframe_step_dense(tables, subframe, actions, state, decode, const) -> SubframeOutcome:
    """:func:`subframe_step` in the ``[B, L, M]`` formulation, on either backend (torch
    below :data:`LINK_MAJOR_MIN_BATCH` scenarios; the reference of the NumPy kernel)."""
    xp = np if isinstance(actions, np.ndarray) else torch
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
    bs_interference = sum_axis(power_onehot * tables.tx_to_bs_gain[subframe], 1)  # [B, M]
    v2i_rate, v2v_bits, remaining, delivered_now = sinr_rates_and_progress(
        power, own, from_v2i, from_v2v, tables.v2i_signal_mw[subframe], bs_interference,
        state.remaining_bits, pending, xp.log1p, const.noise_mw,
        const.bandwidth_hz * const.subframe_s / math.log(2.0),
        const.bandwidth_hz / math.log(2.0), 0,
    )  # fmt: skip
    state.remaining_bits = remaining
    state.delay_subframes = xp.where(delivered_now, subframe + 1, state.delay_subframes)
    state.occupancy = sum_axis(tx_onehot, 1)
    return SubframeOutcome(v2i_rate, v2v_bits, power, delivered_now, pending)


def _subframe_step_numpy(tables, subframe, actions, state, decode, const) -> SubframeOutcome:
    """:func:`subframe_step` on NumPy arrays: the ``[B, L, M]`` code with fewer NumPy calls
    (at B = 1 the cost of each call, not its arithmetic, is the kernel's time), the same
    float32 operations on the same operands, so the same numbers bit for bit (tested against
    the ``[B, L, M]`` code, tests/sim/test_physics.py). The sender's power on its sub-channel
    is ``onehot · power`` (``power`` is 0 for a silent link, so the ``(power > 0)`` mask of
    the general code multiplies by 1 or meets a 0 already there); occupancy counts its
    non-zero entries; the scalars are float32 0-d arrays (:attr:`KernelConstants.float32`)."""
    c = const.float32
    if c is None:  # constants that are not Python numbers
        return _subframe_step_dense(tables, subframe, actions, state, decode, const)
    pending = state.remaining_bits > c.zero
    channel = decode.subchannel.take(actions)  # [B, L]
    power = decode.power_mw.take(actions) * pending  # [B, L]
    power_onehot = decode.onehot.take(actions, 0) * power[..., None]  # [B, L, M]
    flat = const.row_offset + channel
    own = tables.own_gain[subframe].take(flat)
    from_v2i = tables.v2i_to_rx_mw[subframe].take(flat)
    from_v2v = np.matmul(tables.cross_gain[subframe], power_onehot).take(flat)
    bs_interference = _add_reduce(power_onehot * tables.tx_to_bs_gain[subframe], 1)  # [B, M]
    v2i_rate, v2v_bits, remaining, delivered_now = sinr_rates_and_progress(
        power, own, from_v2i, from_v2v, tables.v2i_signal_mw[subframe], bs_interference,
        state.remaining_bits, pending, np.log1p, c.noise_mw, c.v2v_bits_per_nat,
        c.v2i_bps_per_nat, c.zero,
    )  # fmt: skip
    state.remaining_bits = remaining
    state.delay_subframes = np.where(delivered_now, subframe + 1, state.delay_subframes)
    state.occupancy = _add_reduce(power_onehot > c.zero, 1, dtype=np.float32)
    return SubframeOutcome(v2i_rate, v2v_bits, power, delivered_now, pending)


_add_reduce = np.add.reduce


def _subframe_step_link_major(tables, subframe, actions, state, decode, const) -> SubframeOutcome:
    """:func:`subframe_step` on torch tensors, link-major: every array is ``[L, B]``,
    ``[L, M, B]``, ``[L, L, B]`` or ``[M, B]``, so that each operation streams over the batch
    (broadcasts over a trailing axis of 3 or 4 entries cost torch several times more). The
    arithmetic is :func:`link_major_arithmetic`; this wrapper slices the subframe's tables and
    rebinds the state."""
    own_gain, v2i_to_rx, tx_to_bs, cross_gain, v2i_signal = (
        table[subframe] for table in tables.link_major()
    )
    v2i_rate, v2v_bits, power, delivered_now, pending, remaining, occupancy = (
        link_major_arithmetic(
            own_gain, v2i_to_rx, tx_to_bs, cross_gain, v2i_signal, actions,
            state.remaining_bits, *link_major_constants(decode, const, own_gain),
        )
    )  # fmt: skip
    delay = torch.where(delivered_now, subframe + 1, state.delay_subframes.T)
    state.remaining_bits, state.delay_subframes, state.occupancy = (
        remaining.T,
        delay.T,
        occupancy.T,
    )
    return SubframeOutcome(v2i_rate.T, v2v_bits.T, power.T, delivered_now.T, pending.T)


def link_major_constants(decode: ActionTables, const: KernelConstants, own_gain: torch.Tensor):
    """The arguments of :func:`link_major_arithmetic` after the remaining bits: the action
    decoding, the index constants and the scalars (``own_gain`` [L, M, B]: one subframe's
    table, for the shapes and the device)."""
    links, subch, _ = own_gain.shape
    return (
        decode.subchannel,
        decode.power_mw,
        const.link_offset,
        const.channel_offset,
        const.subchannels,
        const.noise_mw,
        const.bandwidth_hz * const.subframe_s / math.log(2.0),
        const.bandwidth_hz / math.log(2.0),
        _torch_adds_in_link_order(links, subch, own_gain.device),
    )


def link_major_arithmetic(
    own_gain: torch.Tensor, v2i_to_rx: torch.Tensor, tx_to_bs: torch.Tensor,
    cross_gain: torch.Tensor, v2i_signal: torch.Tensor, actions: torch.Tensor,
    remaining_bits: torch.Tensor, subchannel_of: torch.Tensor, power_of: torch.Tensor,
    link_offset: torch.Tensor, channel_offset: torch.Tensor, subchannels: torch.Tensor,
    noise_mw: float, bits_per_log1p: float, rate_per_log1p: float, in_link_order: bool,
) -> tuple[torch.Tensor, ...]:  # fmt: skip
    """The arithmetic of one link-major subframe: tensors in, tensors out, no Python state (so
    that it can also be handed to ``torch.compile``; ``benchmarks/compile_kernel.py``).

    One subframe's tables (``[L, M, B]`` ×3, ``[L_rx, L_tx, B]``, ``[M, B]``), the actions and
    the remaining bits ``[B, L]``, then :func:`link_major_constants`. Returns link-major
    ``v2i_rate [M, B]``, ``v2v_bits``, ``power``, ``delivered_now``, ``pending``, the new
    remaining bits ``[L, B]`` and the occupancy ``[M, B]``."""
    links = own_gain.shape[0]
    act = actions.T.contiguous()  # [L, B]: one copy, read by three gathers
    pending = remaining_bits.T > 0
    channel = subchannel_of.take(act)
    power = torch.where(pending, power_of.take(act), 0.0)

    # entry [l, channel[l, b], b] of a contiguous [L, M, B] array, as one flat gather
    flat = link_offset + channel_offset.take(act)
    own = own_gain.take(flat)
    from_v2i = v2i_to_rx.take(flat)
    # interference at receiver i from every transmitter j on i's sub-channel
    on_channel = channel[:, None, :] == subchannels  # [L, M, B]
    if in_link_order:
        same = channel[:, None, :] == channel[None, :, :]  # [L_rx, L_tx, B]
        terms = cross_gain * torch.where(same, power[None, :, :], 0.0)
        from_v2v = terms[:, 0]
        for j in range(1, links):
            from_v2v = from_v2v + terms[:, j]
    else:  # the [B, L, M] path's matmul itself, on [B, ...] copies
        power_onehot = torch.where(on_channel, power[:, None, :], 0.0).permute(2, 0, 1)
        rx_per_channel = torch.matmul(
            cross_gain.permute(2, 0, 1).contiguous(), power_onehot.contiguous()
        )  # [B, L_rx, M]
        from_v2v = rx_per_channel.permute(1, 2, 0).take(flat)
    # each link's power at the BS on its sub-channel, summed per sub-channel in link order
    to_bs = torch.where(on_channel, (power * tx_to_bs.take(flat))[:, None, :], 0.0)
    bs_interference = _sum_links_link_major(to_bs, in_link_order)  # [M, B]
    v2i_rate, v2v_bits, remaining, delivered_now = sinr_rates_and_progress(
        power, own, from_v2i, from_v2v, v2i_signal, bs_interference, remaining_bits.T,
        pending, torch.log1p, noise_mw, bits_per_log1p, rate_per_log1p, 0,
    )  # fmt: skip
    occupancy = (on_channel & (power > 0)[:, None, :]).sum(0, dtype=torch.float32)
    return v2i_rate, v2v_bits, power, delivered_now, pending, remaining, occupancy


def _torch_adds_in_link_order(links: int, subchannels: int, device: torch.device) -> bool:
    """Whether torch's batched matmul ``[B, L, L] @ [B, L, M]`` and its sum of a ``[B, L, M]``
    array over the links both add in link order, 0 + x_0 + x_1 + …, each term rounded to
    float32 first, on this machine (:func:`_probe_link_order`, once per shape). The order is
    BLAS's and torch's choice and depends on the CPU (L = 15, M = 4 is in order on the
    machine where the link-major layout was first measured, not on an AVX-512 x86-64 CPU);
    it is always False on CUDA."""
    if device.type != "cpu":
        return False
    return _probe_link_order(links, subchannels)


#: scenarios of the probe: any other order shows in the last bits of some of its sums
_PROBE_BATCH = 64


@cache
def _probe_link_order(links: int, subchannels: int) -> bool:
    """Measure whether the matmul and the sum of :func:`_torch_adds_in_link_order` add in link
    order for ``links`` × ``subchannels``: both on heavy-tailed float32 data (log-normal, as
    path gains are), compared bit for bit with the sums written out in link order."""
    generator = torch.Generator().manual_seed(links * 1000 + subchannels)
    shape = (_PROBE_BATCH, links)
    cross = torch.exp(3.0 * torch.randn(*shape, links, generator=generator))
    onehot = torch.exp(3.0 * torch.randn(*shape, subchannels, generator=generator))
    in_order = cross[:, :, 0, None] * onehot[:, None, 0, :]
    summed = onehot[:, 0]
    for j in range(1, links):
        in_order = in_order + cross[:, :, j, None] * onehot[:, None, j, :]
        summed = summed + onehot[:, j]
    return bool(
        torch.equal(torch.matmul(cross, onehot), in_order) and torch.equal(onehot.sum(1), summed)
    )


def _sum_links_link_major(terms: torch.Tensor, in_link_order: bool) -> torch.Tensor:
    """``terms`` [L, M, B] summed over the links, [M, B], with the rounding of the [B, L, M]
    formulation's ``sum(1)``: link by link where that is its order, else that very call on a
    [B, L, M] copy."""
    if not in_link_order:
        return terms.permute(2, 0, 1).contiguous().sum(1).T
    total = terms[0]
    for j in range(1, terms.shape[0]):
        total = total + terms[j]
    return total


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
    snr_at_max_power = _snr_at_max_power(radio, noise_mw)
    ratios = cat(
        [
            tables.own_gain * snr_at_max_power,
            tables.tx_to_bs_gain * snr_at_max_power,
            tables.v2i_to_rx_mw * (1.0 / noise_mw),
        ],
        axis=-1,
    )
    return gain_feature(ratios)


def _snr_at_max_power(radio: RadioParams, noise_mw: float) -> float:
    return float(db_to_linear(max(radio.v2v_power_levels_dbm))) / noise_mw


def fill_rra_static_observation(
    tables: IntervalTables,
    radio: RadioParams,
    noise_mw: float,
    out: torch.Tensor,
    workspace: FadingWorkspace,
    each_chunk: Callable[[int, int], None] | None = None,
) -> None:
    """:func:`rra_static_observation` of torch tables written into ``out`` [T, B, L, 3M] (the
    CSI block of the observation buffer), a chunk of subframes at a time: the same float32
    operations on every entry, computed link-major in ``workspace``'s scratch. The clamp of
    :func:`gain_feature` at 1e-30 is left out: it changes only ratios below 1e-5, which end at
    the lower clip either way (the ratios are never negative)."""
    own_gain, v2i_to_rx, tx_to_bs, _, _ = tables.link_major()
    t, links, subch, batch = own_gain.shape
    snr_at_max_power = _snr_at_max_power(radio, noise_mw)
    stack = _gain_stack(tables)
    # the stack's order (own, V2I→rx, tx→BS): each block's factor, and its block in `out`
    factor = torch.tensor(
        [snr_at_max_power, 1.0 / noise_mw, snr_at_max_power], dtype=own_gain.dtype
    ).to(own_gain.device)[:, None, None, None]
    position = (0, 2, 1)
    chunk = _chunk_subframes(batch, 3 * links * subch, t)
    for t0 in range(0, t, chunk):
        t1 = min(t, t0 + chunk)
        c = t1 - t0
        ratios = workspace.get("csi", (chunk, 3, links, subch, batch), own_gain)[:c]
        if stack is not None:
            torch.mul(stack[t0:t1], factor, out=ratios)
        else:
            for i, gain in enumerate((own_gain, v2i_to_rx, tx_to_bs)):
                torch.mul(gain[t0:t1], factor[i], out=ratios[:, i])
        ratios.log10_().mul_(10.0).div_(RRA_OBS_GAIN_SCALE_DB).clamp_(*RRA_OBS_GAIN_CLIP)
        if each_chunk is not None:
            each_chunk(t0, t1)
        blocks = out[t0:t1].view(c, batch, links, 3, subch)
        for i, j in enumerate(position):
            blocks[:, :, :, j].copy_(ratios[:, i].permute(0, 3, 1, 2))
