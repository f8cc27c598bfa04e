"""The digital twin: B platoon scenarios with their radio links, stepped on two timescales.

Life cycle of one control interval k (docs/model.md §1, §4.5):

1. :meth:`DigitalTwin.begin_interval` — at kΔt the predecessor of every follower generates
   CAM_k (its acceleration and command), the large-scale channel is updated from the
   positions, and the fast fading of the interval's T subframes is drawn.
2. :meth:`DigitalTwin.step_subframe` × T — the RRA actions of every V2V link transmit the
   CAMs; V2I rates and CAM delivery subframes are recorded.
3. :meth:`DigitalTwin.vehicle_observation` — what each follower knows when it decides u_k.
4. :meth:`DigitalTwin.finish_interval` — the platoon is integrated over the interval with the
   command switching from u_{k−1} to u_k when CAM_k arrived, and the control reward is paid.

Who leads, whom each follower follows and hears its CAM from, the V2I users and the lanes come
from ``params.platoon.topology`` (:class:`~vdtn_marl.sim.topology.Topology`, built by a
scenario; by default one platoon with predecessor following), as index arrays. Each leader
drives its own window of the trace set: ``leader_speed_mps`` is [B, Λ, K].

The twin knows nothing of RL APIs. Every random number comes from one seeded
``torch.Generator`` on the twin's device.

The twin holds its state once, in the arrays of its backend (``twin.ns``, an
:class:`~vdtn_marl.sim.backend.ArrayNamespace`): NumPy arrays with ``backend="numpy"`` (CPU; the
single-scenario path of the PettingZoo environments, where a torch call per operation would
cost several times more at B = 1), torch tensors on the twin's device otherwise. The same code,
with the same float32 operations in the same order, runs on either, and the draws come from the
same torch generator, so both backends give the same numbers (:mod:`vdtn_marl.sim.backend`).
Torch is the edge: the public state attributes (``platoon``, ``interval``, ``cam_held``, …),
:meth:`~DigitalTwin.vehicle_observation`, :meth:`~DigitalTwin.switch_subframe` and the
:class:`IntervalRecord` are torch tensors (on the NumPy backend, CPU tensors sharing the arrays'
memory; assigning a tensor to a state attribute stores it as the backend's array). The
per-subframe interface (actions, :meth:`~DigitalTwin.rra_observation`, the subframe outcome,
``link_state`` and ``tables``) is in the backend's arrays. The twin's own torch calls on the
NumPy backend (draws, a few transcendental functions) run on one intra-op thread, see
:func:`~vdtn_marl.sim.backend.single_intra_op_thread`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import torch

from vdtn_marl.data.traces import TraceSource, get_trace_source
from vdtn_marl.errors import ConfigError
from vdtn_marl.sim import aoi, channel, link
from vdtn_marl.sim.backend import (
    ArrayNamespace,
    as_float,
    cat,
    clamp,
    float32_scalars,
    like,
    mean_axis,
    stack,
)
from vdtn_marl.sim.layout import (
    RRA_CAM_AGE_CLIP_INTERVALS,
    RRA_COMMAND_HISTORY,
    RRA_CONTROL_CLIP,
    RRA_DELAY_HISTORY,
    RRAFeatureLayout,
)
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.platoon import (
    IntervalIntegrator,
    PlatoonState,
    cam_snapshot,
    initial_state,
    interval_reward,
    perfect_observation,
    spacing_errors,
    vehicle_observation,
)


@dataclass
class IntervalRecord:
    """Everything that happened in one control interval, per scenario (torch tensors;
    ``state_after`` shares its memory with the twin's state on either backend: copy it before
    changing it).

    ``state_before``/``state_after`` are the perfect states S_k and S_{k+1}; ``interval`` [B]
    is k. ``switch_subframe`` [B, F] is when u_k took force. ``cam_delay_subframes`` [B, L]
    is the CAM delivery subframe (1..T, T+1 = lost); ``v2i_rate_bps`` [B, M] is the interval
    mean. ``command_if_lost_mps2`` [B, F], when the caller gave it, is the command each
    follower would have decided had this interval's CAM been lost (see
    :meth:`DigitalTwin.vehicle_observation` with ``cams_lost``).
    """

    interval: torch.Tensor
    state_before: PlatoonState
    state_after: PlatoonState
    command_mps2: torch.Tensor
    switch_subframe: torch.Tensor
    reward: torch.Tensor
    gap_error_m: torch.Tensor
    speed_error_mps: torch.Tensor
    collided: torch.Tensor
    truncated: torch.Tensor
    cam_delay_subframes: torch.Tensor
    v2i_rate_bps: torch.Tensor
    command_if_lost_mps2: torch.Tensor | None = None


def resolve_device(device: str | torch.device) -> torch.device:
    """The torch device of ``device`` if it can be used here (cpu, cuda, cuda:N); otherwise a
    :class:`ConfigError` naming the value and what is allowed on this machine."""
    if isinstance(device, torch.device):
        dev = device
    else:
        if not isinstance(device, str) or not device:
            raise ConfigError(f"device={device!r} is not allowed; use cpu, cuda or cuda:N")
        try:
            dev = torch.device(device)
        except (RuntimeError, ValueError):
            raise ConfigError(
                f"device={device!r} is not a torch device; use cpu, cuda or cuda:N"
            ) from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise ConfigError(
                f"device={device!r} is not available: torch.cuda.is_available() is False on "
                "this machine (a CPU-only torch build, or no GPU); allowed: cpu"
            )
        count = torch.cuda.device_count()
        if dev.index is not None and dev.index >= count:
            raise ConfigError(
                f"device={device!r} is not available: this machine has {count} CUDA "
                f"device(s); allowed: cpu, cuda, cuda:0..cuda:{count - 1}"
            )
    elif dev.type != "cpu":
        raise ConfigError(f"device={device!r} is not supported; use cpu, cuda or cuda:N")
    return dev


class _TorchState:
    """A public state attribute of :class:`DigitalTwin`, read and assigned as torch tensors.

    The twin holds the state once, as ``_<name>`` in its own namespace (``twin.ns``); reading
    gives torch tensors (on the NumPy backend, tensors sharing the arrays' memory, so in-place
    writes reach the state), assigning stores the backend's arrays.
    """

    def __init__(self, doc: str):
        self.__doc__ = doc

    def __set_name__(self, owner, name: str) -> None:
        self.held = "_" + name

    def __get__(self, twin, owner=None):
        if twin is None:
            return self
        return twin.ns.to_torch(getattr(twin, self.held))

    def __set__(self, twin, value) -> None:
        setattr(twin, self.held, twin.ns.from_torch(value))


def _replace_rows(state: link.LinkState, rows: torch.Tensor, part: link.LinkState):
    """``state`` with the scenarios ``rows`` [b] taken from ``part`` [b, ...]: new arrays
    (records may share the old ones)."""
    return link.LinkState(
        *(
            getattr(state, f.name).clone().index_copy_(0, rows, getattr(part, f.name))
            for f in dataclasses.fields(state)
        )
    )


class DigitalTwin:
    """B scenarios of the VDTN platoon model, batched in torch or NumPy.

    Args:
        params: model parameters (defaults: the case study).
        batch_size: B ≥ 1 independent scenarios.
        device: torch device of all tensors.
        seed: seed of the twin's generator (None: non-deterministic).
        trace_source: leader trace set, by name or instance (default ``params.traces``).
        radio: simulate the radio (False for the perfect-observation control env: faster,
            and CAMs are then exact and instantaneous).
        backend: ``"torch"`` or ``"numpy"``; ``"numpy"`` holds the state in NumPy arrays and
            runs the per-subframe kernel and the per-interval work on them (CPU,
            single-scenario fast path, same numbers). Draws stay in torch.
        lookahead_intervals: extra leader trace beyond the episode, for VoI rollouts.
        fading_draws: ``"normal"`` (default: two torch normal draws per fast-fading gain) or
            ``"exponential"`` (one Exp(1) draw per gain from NumPy's ziggurat seeded by the
            twin's generator: the same law, other numbers, the interval's draws in a fraction
            of the time; docs/profile.md). Both backends see the same numbers either way.
        draw_ahead: on the CPU from :data:`~vdtn_marl.sim.link.DRAW_AHEAD_MIN_BATCH`
            scenarios, make the next interval's draws on a second thread while this
            interval's subframes run (:class:`~vdtn_marl.sim.link.DrawAhead`): the same
            numbers, bit for bit, on a second core. False: draw at each interval's start.
    """

    # the state, held in the backend's arrays as ``_<name>``; torch tensors to callers
    leader_speed_mps = _TorchState("Every leader's speed trace (m/s), [B, Λ, K].")
    platoon = _TorchState("The perfect platoon state S_k (:class:`PlatoonState`, [B, N] each).")
    interval = _TorchState("The current control interval k, [B] int64.")
    v2v_shadow_db = _TorchState("V2V shadowing (dB), [B, N, N], symmetric.")
    v2i_shadow_db = _TorchState("V2I shadowing (dB), [B, N].")
    bs_offset_m = _TorchState("Along-road offset of the base-station grid (m), [B].")
    shadow_position_m = _TorchState("Positions at the last shadowing update (m), [B, N].")
    cam_snapshot = _TorchState("CAM_k: the predecessor's (accel, command), [B, F, 2].")
    cam_held = _TorchState("The last delivered CAM content of each follower, [B, F, 2].")
    cam_held_interval = _TorchState("Interval of the held CAM (−1: none yet), [B, F] int64.")
    cam_delay_history = _TorchState(
        "Each link's last CAM delivery subframes as fractions of T + 1, newest first, [B, L, H]."
    )
    command_history = _TorchState("Each follower's last commands (m/s²), newest first, [B, F, H].")

    def __init__(
        self,
        params: TwinParams | None = None,
        batch_size: int = 1,
        device: str | torch.device = "cpu",
        seed: int | None = None,
        trace_source: str | TraceSource | None = None,
        radio: bool = True,
        backend: str = "torch",
        lookahead_intervals: int = 200,
        fading_draws: str = "normal",
        draw_ahead: bool = True,
    ):
        self.params = (params or TwinParams()).validate()
        if (
            not isinstance(batch_size, int | np.integer)
            or isinstance(batch_size, bool)
            or batch_size < 1
        ):
            raise ConfigError(f"batch_size={batch_size!r} must be an integer >= 1")
        if backend not in ("torch", "numpy"):
            raise ConfigError(f"backend={backend!r} must be one of 'torch', 'numpy'")
        self.device = resolve_device(device)
        if backend == "numpy" and self.device.type != "cpu":
            raise ConfigError(f"backend='numpy' needs device='cpu', got device={device!r}")
        if fading_draws not in channel.FADING_DRAWS:
            raise ConfigError(
                f"fading_draws={fading_draws!r} must be one of {', '.join(channel.FADING_DRAWS)}"
            )
        #: "normal": |h|² = (x² + y²)/2 from two torch normal draws (the reference numbers);
        #: "exponential": one Exp(1) draw per gain, the same law in a fraction of the time
        #: (docs/profile.md), other numbers
        self.fading_draws = fading_draws
        if lookahead_intervals < 0:
            raise ConfigError(f"lookahead_intervals={lookahead_intervals!r} must be >= 0")
        self.batch_size = int(batch_size)
        if not isinstance(draw_ahead, bool):
            raise ConfigError(f"draw_ahead={draw_ahead!r} must be True or False")
        #: whether the next interval's draws are made on a second thread (see the class doc)
        self.draw_ahead = (
            draw_ahead
            and backend == "torch"
            and self.device.type == "cpu"
            and self.batch_size >= link.DRAW_AHEAD_MIN_BATCH
        )
        self.radio_enabled = radio
        self.backend = backend
        self.lookahead_intervals = lookahead_intervals
        self.trace_source = get_trace_source(trace_source or self.params.traces)
        self.generator = torch.Generator(device=self.device)
        #: the array type of the twin's state (NumPy arrays or torch tensors on the device)
        self.ns = ns = ArrayNamespace(backend == "numpy", self.device)

        pp, rp = self.params.platoon, self.params.radio
        #: who leads, who follows whom, links, V2I users, lanes (docs/model.md §6)
        self.topology = topology = pp.topology
        self.num_leaders = topology.num_leaders
        self.num_followers = topology.num_followers
        self.num_links = topology.num_links
        self.num_subchannels = rp.num_subchannels
        self.subframes_per_interval = pp.subframes_per_interval
        self.subframe_ms = pp.subframe_s * 1000.0
        self.interval_ms = pp.control_interval_s * 1000.0
        self.rra_layout = RRAFeatureLayout.from_radio(rp)
        self.rra_obs_dim = self.rra_layout.dim
        self.integrator = IntervalIntegrator(pp, self.device)
        t = pp.subframes_per_interval  # fraction of the interval left at each subframe, [T]
        self._time_left = ns.from_torch(
            1.0 - torch.arange(t, device=self.device, dtype=torch.float32) / t
        )
        # lane centres across the road [N] (m), None for one lane (docs/model.md §6)
        self._lateral_offset_m = None
        if not topology.single_lane:
            offsets = torch.tensor(topology.lateral_offset_m, device=self.device)
            self._lateral_offset_m = ns.from_torch(offsets)
        self._decode = ns.from_torch(link.ActionTables.build(rp, self.device))
        #: the torch path's draws and scratch, reused every interval (not state)
        self._workspace = link.FadingWorkspace()
        self.tables: link.IntervalTables | None = None
        self._const = ns.from_torch(
            link.KernelConstants.build(
                rp, pp.subframe_s, self.batch_size, self.num_links, self.device
            )
        )
        self.seed(seed)
        self.reset()

    # ------------------------------------------------------------------ set-up
    def seed(self, seed: int | None) -> None:
        """Re-seed the twin's generator (None: a non-deterministic seed)."""
        if seed is None:
            self.generator.seed()
        else:
            if not isinstance(seed, int | np.integer) or seed < 0:
                raise ConfigError(f"seed={seed!r} must be a non-negative integer or None")
            self.generator.manual_seed(int(seed))

    def _torch_calls(self):
        """Context of the twin's own torch calls: one intra-op thread on the NumPy backend."""
        return self.ns.own_threads()

    def reset(
        self, seed: int | None = None, mask: torch.Tensor | None = None, begin: bool = True
    ) -> None:
        """Start new episodes in all scenarios, or only where ``mask`` [B] is True.

        ``begin=False``: their first interval is not started; the caller starts it next with
        :meth:`begin_interval` of the whole batch (one interval start for the scenarios that
        go on and those that start anew; :meth:`restart` does both, the interval's draws
        first)."""
        with self._torch_calls():
            self._reset(seed, mask, begin)

    def _reset(self, seed: int | None, mask: torch.Tensor | None, begin: bool = True) -> None:
        if seed is not None:
            self.seed(seed)
        b, pp, rp = self.batch_size, self.params.platoon, self.params.radio
        dev, ns = self.device, self.ns
        num_points = self.params.episode_intervals + 1 + self.lookahead_intervals
        count = b if mask is None else int(mask.sum())
        if count == 0:
            return
        # one trace window per leader, leaders of a scenario consecutive: [B, Λ, K]
        leaders = self.num_leaders
        traces = self.trace_source.sample(
            count * leaders, num_points, pp.control_interval_s, self.generator
        )
        traces = traces.to(device=dev, dtype=torch.float32).reshape(count, leaders, num_points)
        if not torch.isfinite(traces).all() or (traces < 0).any():
            raise ValueError(
                f"trace source {self.trace_source.info.name!r} returned "
                "non-finite or negative speeds"
            )
        # the draws in torch, in a fixed order, then into the backend's arrays
        state = ns.from_torch(initial_state(traces[..., 0], pp, self.generator))
        v2v_shadow = rp.v2v_shadow_std_db * channel.symmetric_normal(
            (count, pp.num_vehicles, pp.num_vehicles), self.generator, numpy=ns.numpy
        )
        v2i_shadow = rp.v2i_shadow_std_db * ns.from_torch(
            torch.randn(count, pp.num_vehicles, generator=self.generator, device=dev)
        )
        bs_offset = rp.inter_site_distance_m * ns.from_torch(
            torch.rand(count, generator=self.generator, device=dev)
        )
        traces = ns.from_torch(traces)
        cam_held = cam_snapshot(state, pp)
        if mask is None:
            self._leader_speed_mps = traces
            self._platoon = state
            self._v2v_shadow_db, self._v2i_shadow_db = v2v_shadow, v2i_shadow
            self._bs_offset_m = bs_offset
            self._shadow_position_m = ns.copy(state.position_m)
            self._interval = ns.zeros((b,), "int64")
            self._cam_held = cam_held
            self._cam_held_interval = ns.full((b, self.num_followers), -1, "int64")
            self._cam_delay_history = ns.zeros((b, self.num_links, RRA_DELAY_HISTORY))
            self._command_history = ns.zeros((b, self.num_followers, RRA_COMMAND_HISTORY))
            if begin:
                self.begin_interval()
            return
        rows = ns.mask(mask)
        self._leader_speed_mps[rows] = traces
        # a new state, not written in place: records of earlier intervals share its arrays
        self._platoon = PlatoonState(
            *(
                self._scatter(getattr(self._platoon, f.name), rows, getattr(state, f.name))
                for f in dataclasses.fields(state)
            )
        )
        self._v2v_shadow_db[rows] = v2v_shadow
        self._v2i_shadow_db[rows] = v2i_shadow
        self._bs_offset_m[rows] = bs_offset
        self._shadow_position_m[rows] = state.position_m
        self._interval[rows] = 0
        self._cam_held[rows] = cam_held
        self._cam_held_interval[rows] = -1
        self._cam_delay_history[rows] = 0.0
        self._command_history[rows] = 0.0
        if begin:
            self.begin_interval(mask)

    def _scatter(self, base, rows, values):
        out = self.ns.copy(base)
        out[rows] = values
        return out

    # ------------------------------------------------------------------ interval start
    def begin_interval(self, mask: torch.Tensor | None = None) -> None:
        """Generate CAM_k, update the large-scale channel, draw the interval's fast fading.

        With ``mask`` only the masked scenarios start a new interval (after a partial reset);
        the others keep their current interval unchanged. The whole batch's draws are made
        either way (the generator's order); when the masked scenarios are at most half the
        batch, the interval's tables and observations are built for them alone.
        """
        with self._torch_calls():
            self._begin_interval(mask)

    def restart(self, mask: torch.Tensor) -> None:
        """New episodes in the scenarios ``mask`` [B] selects and the next interval of the
        others, in one interval start of the whole batch (``IntervalEngine.restart_ended`` of
        the core). The interval's draws come first, so those made ahead on the second thread
        are kept (NumPy backend: its shadowing innovations; the fading comes last), then the
        new episodes' (traces, initial state, shadowing); the next interval's draws are started
        after both. The same as :meth:`reset` ``(mask=mask, begin=False)`` with the generator
        moved past the interval's draws first and :meth:`begin_interval` from them."""
        with self._torch_calls():
            draws = self._interval_draws() if self.radio_enabled else None
            self._reset(None, mask, begin=False)
            self._begin_interval(None, draws)

    def _begin_interval(self, mask: torch.Tensor | None, draws=None) -> None:
        ns = self.ns
        keep = None if mask is None else ns.mask(mask)
        snapshot = cam_snapshot(self._platoon, self.params.platoon)
        if keep is not None:
            snapshot = ns.where(keep[:, None, None], snapshot, self._cam_snapshot)
        self._cam_snapshot = snapshot
        self.subframe = 0
        if not self.radio_enabled:
            return
        b, rp, t = self.batch_size, self.params.radio, self.subframes_per_interval
        rows = self.few_rows(keep)
        if rows is not None:
            self._begin_rows_interval(rows)
            return
        # all scenarios start over: the torch path overwrites the last interval's buffers
        reuse = keep is None and not ns.numpy
        tables = self._draw_interval_tables(reuse, draws=draws)
        link_state = link.new_link_state(
            b, self.num_links, self.num_subchannels, rp, t, ns.array_device
        )
        obs = self._rra_observation_buffer(tables, reuse)
        v2i_sum = ns.zeros((b, self.num_subchannels))
        if keep is not None:  # the others keep their interval: tables, CAM progress, ...

            def merge(new, old, batch_dim: int):
                shape = [1] * new.ndim
                shape[batch_dim] = b
                return ns.where(keep.reshape(shape), new, old)

            tables = link.IntervalTables(
                *(
                    merge(getattr(tables, f.name), getattr(self.tables, f.name), 1)
                    for f in dataclasses.fields(tables)
                )
            )
            link_state = link.LinkState(
                *(
                    merge(getattr(link_state, f.name), getattr(self.link_state, f.name), 0)
                    for f in dataclasses.fields(link_state)
                )
            )
            obs = merge(obs, self._rra_obs, 1)
            v2i_sum = merge(v2i_sum, self._v2i_rate_sum, 0)
        self.tables, self.link_state, self._rra_obs, self._v2i_rate_sum = (
            tables,
            link_state,
            obs,
            v2i_sum,
        )

    def few_rows(self, mask) -> torch.Tensor | None:
        """The indices of the scenarios ``mask`` [B] (bool) selects when they are at most half
        the batch on the torch backend (their interval is then built, and by
        :meth:`run_subframes` run, for them alone), else None."""
        if mask is None or self.ns.numpy:
            return None
        rows = torch.as_tensor(mask, device=self.device).nonzero().flatten()
        return rows if 2 * rows.numel() <= mask.numel() else None

    def _begin_rows_interval(self, rows: torch.Tensor) -> None:
        """:meth:`begin_interval` of the scenarios ``rows`` alone (the others keep their
        interval): the whole batch's draws, in their order, and large-scale update (as for any
        mask), then the tables, CAM progress and observation buffer of those rows only,
        written into the twin's (the same numbers as building them for all and keeping the
        rows: every entry's float32 operations are the same; tests/sim/test_twin_rows.py)."""
        rp, t = self.params.radio, self.subframes_per_interval
        tables = self._draw_interval_tables(False, rows)
        for f in dataclasses.fields(tables):  # the others' tables are this interval's: kept
            getattr(self.tables, f.name).index_copy_(1, rows, getattr(tables, f.name))
        fresh = link.new_link_state(
            rows.numel(), self.num_links, self.num_subchannels, rp, t, self.device
        )
        self.link_state = _replace_rows(self.link_state, rows, fresh)
        self._rra_obs.index_copy_(1, rows, self._rra_observation_buffer(tables, False, rows))
        self._v2i_rate_sum = self._v2i_rate_sum.clone().index_fill_(0, rows, 0.0)

    def _interval_draws(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """The interval's draws in their fixed order (V2V innovation, V2I innovation, fading)
        on both backends: made ahead on the second thread (started at the last interval's
        start) when the generator has not drawn since, or here. The next interval's are not
        started (:meth:`_draw_interval_tables` starts them)."""
        workspace = self._workspace
        ahead, workspace.ahead = workspace.ahead, None
        draws = None if ahead is None else ahead.take(self.generator)
        if draws is None:
            # NumPy: build_interval_tables draws the fading itself, as NumPy arrays
            buffers = (None, None) if self.ns.numpy else self._fading_buffers(workspace.turn)
            n = self._platoon.position_m.shape[1]
            draws = link.draw_interval(
                self.generator, self.batch_size, n, buffers[0], self.fading_draws, buffers[1]
            )
        return draws

    def _draw_interval_tables(
        self, reuse: bool, rows: torch.Tensor | None = None, draws=None
    ) -> link.IntervalTables:
        rp, ns = self.params.radio, self.ns
        x = self._platoon.position_m
        moved = abs(x - self._shadow_position_m)
        self._shadow_position_m = ns.copy(x)
        g = self.generator
        n = x.shape[1]
        workspace = self._workspace
        if draws is None:
            draws = self._interval_draws()
        v2v_innovation, v2i_innovation, drawn = draws
        if self.draw_ahead:
            # the next interval's draws from here on (nothing below draws), on a second
            # thread while this interval's start and subframes run, into the other buffer
            workspace.turn = 1 - workspace.turn
            fading, normals = self._fading_buffers(workspace.turn)
            workspace.ahead = link.DrawAhead(
                g, self.batch_size, n, fading, self.fading_draws, normals
            )
        self._v2v_shadow_db = v2v_shadow = channel.shadowing_update_db(
            self._v2v_shadow_db,
            moved[:, :, None] + moved[:, None, :],
            rp.v2v_shadow_std_db,
            rp.v2v_decorrelation_m,
            channel.symmetrize(v2v_innovation, numpy=ns.numpy),
        )
        self._v2i_shadow_db = v2i_shadow = channel.shadowing_update_db(
            self._v2i_shadow_db,
            moved,
            rp.v2i_shadow_std_db,
            rp.v2i_decorrelation_m,
            ns.from_torch(v2i_innovation),
        )
        bs_x = channel.serving_bs_x_m(mean_axis(x, 1), self._bs_offset_m, rp)
        lateral = self._lateral_offset_m
        v2v_db, v2i_db = link.large_scale_gains_db(
            channel.v2v_pathloss_db(channel.v2v_distance_m(x, lateral), rp),
            v2v_shadow,
            channel.v2i_pathloss_db(channel.v2i_distance_m(x, bs_x, rp, lateral)),
            v2i_shadow,
            rp,
        )
        workspace = self._workspace
        if rows is not None:  # the tables of these scenarios only, from the batch's draws
            drawn = drawn.index_select(-1, rows)  # [T, W, b]
            workspace = link.FadingWorkspace()  # not the batch's scratch
        return link.build_interval_tables(
            v2v_db,
            v2i_db,
            rp,
            self.subframes_per_interval,
            g,
            self.topology,
            workspace=workspace,
            out=self.tables if reuse else None,
            fading_draws=self.fading_draws,
            drawn=drawn,
            rows=rows,
        )

    def _fading_buffers(self, turn: int) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The workspace buffers an interval's fading is drawn into (torch backend): the
        power gains (buffer ``turn``) and, for normal draws, the normals' scratch."""
        width = link.fading_width(self.num_links, self.num_subchannels)
        sizes = (self._workspace, self.batch_size, width, self.subframes_per_interval)
        fading = link.fading_buffer(*sizes, self._time_left, turn)
        if self.fading_draws == "exponential":
            return fading, None
        return fading, link.normals_buffer(*sizes, self._time_left)

    def _rra_observation_buffer(
        self, tables: link.IntervalTables, reuse: bool, rows: torch.Tensor | None = None
    ):
        """[T, B, L, D] in the order of :data:`~vdtn_marl.sim.layout.RRA_OBS_FEATURES`: CSI,
        occupancy and bits left (filled per subframe), time left, the recipients' control
        state and the features that predict their IVoI (constant over the interval).

        In the backend's arrays; with ``reuse`` (torch) written over the last interval's. With
        ``rows`` [b] (torch) the buffer [T, b, L, D] of those scenarios, ``tables`` theirs.
        """
        t, n_l = self.subframes_per_interval, self.num_links
        b = self.batch_size if rows is None else rows.numel()
        pp, lay, platoon = self.params.platoon, self.rra_layout, self._platoon
        shape = (t, b, n_l, self.rra_obs_dim)
        old = getattr(self, "_rra_obs", None)
        if reuse and old is not None and tuple(old.shape) == shape and old.is_contiguous():
            obs = old
        else:
            obs = self.ns.empty(shape)
        gap_error, speed_error = spacing_errors(platoon, pp)
        control = clamp(
            stack(
                [
                    gap_error / pp.gap_error_scale_m,
                    speed_error / pp.speed_error_scale_mps,
                    self.topology.predecessors_of(platoon.accel_mps2) / pp.accel_max_mps2,
                    self.topology.followers_of(platoon.command_mps2) / pp.accel_max_mps2,
                ]
            ),
            -RRA_CONTROL_CLIP,
            RRA_CONTROL_CLIP,
        )
        age = as_float(self._interval[:, None] - self._cam_held_interval)
        history = clamp(
            self._command_history / pp.accel_max_mps2, -RRA_CONTROL_CLIP, RRA_CONTROL_CLIP
        )
        # one subframe's slot [B, L, D], copied to all T (one contiguous copy, not a strided
        # write per feature); the CSI and the time left are written over it
        slot = self.ns.empty((self.batch_size, n_l, self.rra_obs_dim))
        slot[..., lay.csi] = 0.0
        slot[..., lay.occupancy] = 0.0
        slot[..., lay.bits_left] = 1.0
        slot[..., lay.time_left] = 0.0
        slot[..., lay.control] = control
        slot[..., lay["cam_age"]] = clamp(age, 0.0, RRA_CAM_AGE_CLIP_INTERVALS)[..., None]
        slot[..., lay["cam_delay_history"]] = self._cam_delay_history
        slot[..., lay["command_history"]] = history
        if "cam_innovation" in lay.slices:  # RadioParams.rra_cam_innovation
            now = cam_snapshot(platoon, pp)  # [B, F, 2]: what a CAM sent now would carry
            slot[..., lay["cam_innovation"]] = clamp(
                (now - self._cam_held) / pp.accel_max_mps2, -RRA_CONTROL_CLIP, RRA_CONTROL_CLIP
            )
        if rows is not None:
            slot = slot.index_select(0, rows)
        time_left = self._time_left

        def fill(t0: int, t1: int) -> None:  # subframes t0..t1−1: all but the CSI
            part = obs[t0:t1]
            part[...] = slot
            part[..., lay.time_left] = time_left[t0:t1, None, None]

        if not link.link_major(b, self.ns.numpy):
            fill(0, t)
            obs[..., lay.csi] = link.rra_static_observation(
                tables, self.params.radio, self._const.noise_mw
            )
        else:  # a chunk of subframes at a time, all features while its slots are in cache
            link.fill_rra_static_observation(
                tables,
                self.params.radio,
                self._const.noise_mw,
                obs[..., lay.csi],
                self._workspace if rows is None else link.FadingWorkspace(),
                each_chunk=fill,
            )
        return obs

    # ------------------------------------------------------------------ subframes
    def step_subframe(
        self, actions, validated: bool = False, mask: torch.Tensor | None = None
    ) -> link.SubframeOutcome:
        """Transmit one 1 ms subframe with RRA ``actions`` [B, L] (ints in [0, M·P)).

        Arrays are torch tensors, or NumPy arrays with ``backend="numpy"``. ``validated=True``
        skips the range check for callers that have already checked every action. With
        ``mask`` [B] (bool tensor) only the masked scenarios' CAM progress and V2I totals
        advance: the others keep theirs (used to replay an interval after a partial reset).
        """
        if not self.radio_enabled:
            raise RuntimeError("this twin was built with radio=False; it has no subframes")
        t = self.subframe
        if t >= self.subframes_per_interval:
            raise RuntimeError(
                f"all {self.subframes_per_interval} subframes of the interval have run; "
                "call finish_interval() first"
            )
        if not validated:
            self._check_rra_actions(actions)
        before = self.link_state
        # the kernel rebinds the state's fields (never writes in place): a shallow copy keeps
        # `before` intact for the masked merge
        state = dataclasses.replace(before) if mask is not None else before
        outcome = link.subframe_step(self.tables, t, actions, state, self._decode, self._const)
        rate_sum = self._v2i_rate_sum + outcome.v2i_rate_bps
        if mask is not None:
            ns = self.ns
            keep = ns.mask(mask)[:, None]
            state = link.LinkState(
                *(
                    ns.where(keep, getattr(state, f.name), getattr(before, f.name))
                    for f in dataclasses.fields(state)
                )
            )
            rate_sum = ns.where(keep, rate_sum, self._v2i_rate_sum)
        self.link_state, self._v2i_rate_sum = state, rate_sum
        self.subframe = t + 1
        return outcome

    def run_subframes(self, rows: torch.Tensor, act: Callable, validated: bool = False) -> None:
        """Run the interval's remaining subframes for the scenarios ``rows`` [b] (indices)
        alone: each subframe ``act`` maps their RRA observations [b, L, D] to their actions
        [b, L]. The other scenarios keep their CAM progress and V2I totals, as with
        :meth:`step_subframe`'s ``mask``; the clock ends at the interval's end. Torch backend.

        The masked scenarios' numbers are :meth:`step_subframe`'s with ``mask`` (the kernel
        works each scenario on its own, draws nothing, and its one transcendental function,
        ``log1p``, rounds an entry alike wherever it sits in the array; tested in
        tests/sim/test_twin_rows.py), at the cost of b scenarios instead of B: the first
        interval of the few scenarios a partial reset starts. The other scenarios'
        observation slots are left as they were.
        """
        if not self.radio_enabled or self.ns.numpy:
            raise RuntimeError("run_subframes needs a torch twin with radio")
        rows = torch.as_tensor(rows, device=self.device)
        b, links, rp = rows.numel(), self.num_links, self.params.radio
        major = link.link_major(b)

        def part(full, batch_dim: int):  # the rows' copy, in the layout the kernel uses at b
            if not major:
                return full.index_select(batch_dim, rows)
            return full.movedim(batch_dim, -1).index_select(-1, rows).movedim(-1, batch_dim)

        tables = link.IntervalTables(
            *(part(getattr(self.tables, f.name), 1) for f in dataclasses.fields(self.tables))
        )
        before = self.link_state
        state = link.LinkState(
            *(part(getattr(before, f.name), 0) for f in dataclasses.fields(before))
        )
        const = link.KernelConstants.build(
            rp, self.params.platoon.subframe_s, b, links, self.device
        )
        obs = self._rra_obs.index_select(1, rows)
        rate_sum = self._v2i_rate_sum.index_select(0, rows)
        for t in range(self.subframe, self.subframes_per_interval):
            slot = obs[t]
            self._write_rra_progress(slot, state)
            actions = act(slot)
            if not validated:
                self._check_rra_actions(actions, b)
            outcome = link.subframe_step(tables, t, actions, state, self._decode, const)
            rate_sum = rate_sum + outcome.v2i_rate_bps
        self.link_state = _replace_rows(before, rows, state)
        self._v2i_rate_sum = self._v2i_rate_sum.clone().index_copy_(0, rows, rate_sum)
        self._rra_obs.index_copy_(1, rows, obs)
        self.subframe = self.subframes_per_interval

    def _check_rra_actions(self, actions, batch: int | None = None) -> None:
        expected = (self.batch_size if batch is None else batch, self.num_links)
        if tuple(actions.shape) != expected:
            raise ValueError(f"RRA actions have shape {tuple(actions.shape)}, expected {expected}")
        n_act = self.params.radio.num_actions
        bad = not self.ns.is_integer(actions)
        if not bad:
            low, high = self.ns.value_range(actions)
            bad = low < 0 or high >= n_act
        if bad:
            count = math.prod(expected)
            shown = actions.tolist() if count <= 16 else f"array of {count}"
            raise ValueError(
                f"RRA actions {shown} must be integers in [0, {n_act - 1}] "
                "(sub-channel × power level)"
            )

    def rra_observation(self):
        """RRA observations [B, L, D] for the next subframe (docs/model.md §4.6).

        The result is a view into the interval's observation buffer: each subframe has its own
        slot, but calling this again before the next subframe rewrites the same slot in place.
        Copy it if you keep it.
        """
        lay = self.rra_layout
        t = min(self.subframe, self.subframes_per_interval - 1)
        obs = self._rra_obs[t]
        state = self.link_state
        c = None
        if isinstance(obs, np.ndarray):
            c = _observation_float32(self.params.radio.cam_size_bits, self.num_links)
        if c is not None:  # the same numbers, written in place: fewer calls
            remaining = state.remaining_bits / c.cam_size_bits
            np.divide(state.occupancy[:, None, :], c.num_links, out=obs[..., lay.occupancy])
            np.minimum(np.maximum(remaining, c.zero), c.one, out=obs[..., lay.bits_left])
            return obs
        self._write_rra_progress(obs, state)
        return obs

    def _write_rra_progress(self, obs, state: link.LinkState) -> None:
        """Write a subframe's occupancy and bits left (from ``state``) into its slot ``obs``
        [B, L, D] (torch)."""
        lay = self.rra_layout
        remaining = state.remaining_bits / self.params.radio.cam_size_bits
        obs[..., lay.occupancy] = state.occupancy[:, None, :] / self.num_links
        obs[..., lay.bits_left] = clamp(remaining, 0.0, 1.0)

    def cam_age_ms(self):
        """Age of Information (ms) of the CAM content each recipient holds after the subframes
        run so far in this interval, [B, L] float32 in the backend's arrays (recipient i is at
        the end of link i; :mod:`vdtn_marl.sim.aoi`, docs/model.md §4.8). Read it between
        :meth:`begin_interval` and :meth:`finish_interval`."""
        held_age = self._interval[:, None] - self._cam_held_interval
        delay = self.link_state.delay_subframes
        return aoi.age_ms(held_age, delay, self.subframe, self.interval_ms, self.subframe_ms)

    # ------------------------------------------------------------------ interval end
    def drop_cams(self, mask: torch.Tensor) -> None:
        """Count the CAMs of the links in ``mask`` [B, L] (bool) as lost in this interval,
        whatever the radio did: for counterfactual experiments on a copy of the twin
        (``copy.deepcopy``). Call it after the interval's T subframes, before the vehicles
        observe and :meth:`finish_interval`."""
        expected = (self.batch_size, self.num_links)
        if tuple(mask.shape) != expected or mask.dtype != torch.bool:
            raise ValueError(
                f"mask has shape {tuple(mask.shape)} and dtype {mask.dtype}, "
                f"expected bool {expected}"
            )
        if self.subframe != self.subframes_per_interval:
            raise RuntimeError(
                f"drop_cams after {self.subframe} of {self.subframes_per_interval} subframes; "
                "run the whole interval first"
            )
        delay = self.link_state.delay_subframes
        lost = self.subframes_per_interval + 1
        self.link_state.delay_subframes = self.ns.where(self.ns.mask(mask), lost, delay)

    def switch_subframe(self, perfect: bool) -> torch.Tensor:
        """When u_k takes force in this interval, [B, F] int (docs/model.md §4.5).

        0 with perfect observation; otherwise the CAM's delivery subframe if it arrived in the
        first T−1 subframes, else T (the decision is taken at the deadline on an older CAM and
        its command takes force at the next interval).
        """
        return self.ns.to_torch(self._switch_subframe(perfect))

    def _switch_subframe(self, perfect: bool):
        t = self.subframes_per_interval
        if perfect:
            return self.ns.zeros((self.batch_size, self.num_followers), "int64")
        delay = self.link_state.delay_subframes
        return self.ns.where(delay <= t - 1, delay, t)

    def vehicle_observation(self, perfect: bool, cams_lost: bool = False) -> torch.Tensor:
        """What each follower knows when it decides u_k, [B, F, 8] (docs/model.md §2.4, §4.5).

        With ``cams_lost`` (impaired observation only): what it would know had this interval's
        CAM been lost, i.e. the content it held before the interval, at its age, and a command
        that takes force at the next interval (the counterfactual of a difference IVoI reward,
        the ``cam_lost`` baseline of :class:`~vdtn_marl.voi.RolloutIVoIEstimator`).
        """
        ns, pp, platoon = self.ns, self.params.platoon, self._platoon
        if perfect:
            return ns.to_torch(perfect_observation(platoon, pp))
        t = self.subframes_per_interval
        switch = self._switch_subframe(perfect=False)
        if cams_lost:
            switch = ns.full(switch.shape, t, "int64")
        usable = switch < t
        content = ns.where(usable[..., None], self._cam_snapshot, self._cam_held)
        age_intervals = as_float(self._interval[:, None] - self._cam_held_interval)
        age_ms = ns.where(usable, ns.zeros(age_intervals.shape), age_intervals * self.interval_ms)
        cam_delay_ms = as_float(switch) * self.subframe_ms
        return ns.to_torch(vehicle_observation(platoon, content, cam_delay_ms, age_ms, pp))

    def leader_accel_mps2(self, intervals: torch.Tensor) -> torch.Tensor:
        """Every leader's acceleration (m/s²) in intervals ``intervals`` [B, ...] →
        [B, ..., Λ] (Λ = ``num_leaders``; the leaders of ``topology.leaders`` in order).

        ``intervals`` may be a NumPy array (on a CPU twin): the result is one too.
        """
        return like(self._leader_accel_mps2(self.ns.asarray(intervals)), intervals)

    def _leader_accel_mps2(self, intervals):
        v = self._leader_speed_mps  # [B, Λ, K]
        k = clamp(intervals, 0, v.shape[-1] - 2).reshape(self.batch_size, 1, -1)
        take = self.ns.take_along_axis
        accel = (take(v, k + 1, 2) - take(v, k, 2)) / self.params.platoon.control_interval_s
        return accel.swapaxes(1, 2).reshape(*intervals.shape, self.num_leaders)

    def finish_interval(
        self,
        commands_mps2: torch.Tensor,
        perfect: bool,
        command_if_lost_mps2: torch.Tensor | None = None,
    ) -> IntervalRecord:
        """Integrate the platoon over the interval and pay the control reward.

        ``commands_mps2`` [B, F] are the followers' decisions u_k (clipped to the actuator
        bounds). With radio, all T subframes must have run. The twin does not start the next
        interval: call :meth:`begin_interval` (or :meth:`reset` for finished scenarios).
        ``command_if_lost_mps2`` [B, F] (optional, clipped alike) is only recorded, for IVoI
        estimators that compare with a lost CAM.
        """
        self._check_finish(commands_mps2, perfect, command_if_lost_mps2)
        ns, pp = self.ns, self.params.platoon
        # the platoon: u_k takes force at the switch subframe; the reward of where it ends
        switch = self._switch_subframe(perfect)
        before, interval = self._platoon, self._interval
        u = clamp(ns.float32(commands_mps2), pp.accel_min_mps2, pp.accel_max_mps2)
        after = self.integrator.integrate(before, self._leader_accel_mps2(interval), u, switch)
        reward, gap_error, speed_error, collided = interval_reward(before, after, u, pp)
        # the radio: which CAMs arrived (the recipients now hold them), the mean V2I rate
        delay, mean_rate = self._close_radio(interval, switch.shape)
        self._push_histories(delay, self.topology.followers_of(before.command_mps2))
        self._platoon, self._interval = after, interval + 1
        # the record is the edge: torch tensors (sharing the NumPy arrays' memory)
        out = ns.to_torch
        return IntervalRecord(
            interval=out(ns.copy(interval)),
            state_before=out(before),
            state_after=out(after),
            command_mps2=out(u),
            switch_subframe=out(switch),
            reward=out(reward),
            gap_error_m=out(gap_error),
            speed_error_mps=out(speed_error),
            collided=out(collided),
            truncated=out(interval + 1 >= self.params.episode_intervals),
            cam_delay_subframes=out(delay),
            v2i_rate_bps=out(mean_rate),
            command_if_lost_mps2=(
                None
                if command_if_lost_mps2 is None
                else out(
                    clamp(ns.float32(command_if_lost_mps2), pp.accel_min_mps2, pp.accel_max_mps2)
                )
            ),
        )

    def _check_finish(self, commands_mps2, perfect: bool, command_if_lost_mps2) -> None:
        """:meth:`finish_interval`'s preconditions: all T subframes ran (with radio), and the
        commands are [B, F]."""
        t = self.subframes_per_interval
        if self.radio_enabled and not perfect and self.subframe != t:
            raise RuntimeError(
                f"finish_interval after {self.subframe} of {t} subframes; run all {t} first"
            )
        expected = (self.batch_size, self.num_followers)
        if tuple(commands_mps2.shape) != expected:
            raise ValueError(
                f"commands have shape {tuple(commands_mps2.shape)}, expected {expected}"
            )
        if command_if_lost_mps2 is not None and tuple(command_if_lost_mps2.shape) != expected:
            raise ValueError(
                f"command_if_lost_mps2 has shape {tuple(command_if_lost_mps2.shape)}, "
                f"expected {expected}"
            )

    def _close_radio(self, interval, shape: tuple[int, ...]):
        """The interval's CAM delivery subframes [B, L] and mean V2I rate per sub-channel
        [B, M]; a CAM delivered within the interval becomes what its recipient holds. Without
        radio: every CAM on time (delay 0), no V2I traffic."""
        ns = self.ns
        if not self.radio_enabled:
            return ns.zeros(shape, "int64"), ns.zeros((self.batch_size, self.num_subchannels))
        delay = self.link_state.delay_subframes
        mean_rate = self._v2i_rate_sum / max(self.subframe, 1)
        delivered = link.cam_delivered(delay, self.subframes_per_interval)
        self._cam_held = ns.where(delivered[..., None], self._cam_snapshot, self._cam_held)
        self._cam_held_interval = ns.where(delivered, interval[:, None], self._cam_held_interval)
        return delay, mean_rate

    def _push_histories(self, delay, previous_command_mps2) -> None:
        """The recipients' histories the next interval's RRA observation reads: the CAM's
        delivery subframe d/(T+1) and the command u_{k−1}, newest first."""
        t = self.subframes_per_interval
        delay_fraction = clamp(as_float(delay) / (t + 1), 0.0, 1.0)
        self._cam_delay_history = cat(
            [delay_fraction[..., None], self._cam_delay_history[..., :-1]]
        )
        self._command_history = cat(
            [previous_command_mps2[..., None], self._command_history[..., :-1]]
        )


@functools.lru_cache(maxsize=16, typed=True)  # np.int64(x) and x apart
def _observation_float32(cam_size_bits: int, num_links: int) -> SimpleNamespace | None:
    """:meth:`DigitalTwin.rra_observation`'s numbers as read-only float32 0-d arrays: on its
    float32 arrays the same operations as with the Python numbers (NumPy casts a Python scalar
    to the array's dtype first), at a third of NumPy's cost per call."""
    return float32_scalars(cam_size_bits=cam_size_bits, num_links=num_links, zero=0.0, one=1.0)
