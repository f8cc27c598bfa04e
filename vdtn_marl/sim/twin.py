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

With ``backend="numpy"`` (CPU; the single-scenario path of the PettingZoo environments) the
per-subframe kernel and the per-interval work (channel update, tables, observations, platoon
integration) run on NumPy views of the twin's state, with the same float32 operations in the
same order as the torch path and the same draws from the same torch generator, so both
backends give the same numbers (:mod:`vdtn_marl.sim.backend`); a torch call per NumPy operation
would cost several times more at B = 1. Public state attributes and return values stay torch
tensors (CPU tensors sharing memory with those arrays); the interval tables, the link state and
the RRA observation are NumPy arrays on this backend. ``twin.ns``
(:class:`~vdtn_marl.sim.backend.ArrayNamespace`) makes, converts and masks the arrays of the
twin's backend, so the twin's code has few backend branches. The twin's own torch calls
(draws, a few transcendental functions) run on one intra-op thread there, see
:func:`~vdtn_marl.sim.backend.single_intra_op_thread`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch

from vdtn_marl.data.traces import TraceSource, get_trace_source
from vdtn_marl.errors import ConfigError
from vdtn_marl.sim import channel, link
from vdtn_marl.sim.backend import (
    ArrayNamespace,
    as_float,
    cat,
    clamp,
    mean_axis,
    stack,
    to_numpy,
    xp,
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
    control_reward,
    gaps_m,
    initial_state,
    perfect_observation,
    spacing_errors,
    vehicle_observation,
)


@dataclass
class IntervalRecord:
    """Everything that happened in one control interval, per scenario (torch tensors).

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


class DigitalTwin:
    """B scenarios of the VDTN platoon model, batched in torch.

    Args:
        params: model parameters (defaults: the case study).
        batch_size: B ≥ 1 independent scenarios.
        device: torch device of all tensors.
        seed: seed of the twin's generator (None: non-deterministic).
        trace_source: leader trace set, by name or instance (default ``params.traces``).
        radio: simulate the radio (False for the perfect-observation control env: faster,
            and CAMs are then exact and instantaneous).
        backend: ``"torch"`` or ``"numpy"``; ``"numpy"`` runs the per-subframe kernel and the
            per-interval work on NumPy arrays (CPU, single-scenario fast path, same numbers).
            Draws stay in torch.
        lookahead_intervals: extra leader trace beyond the episode, for VoI rollouts.
    """

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
        if lookahead_intervals < 0:
            raise ConfigError(f"lookahead_intervals={lookahead_intervals!r} must be >= 0")
        self.batch_size = int(batch_size)
        self.radio_enabled = radio
        self.backend = backend
        self.lookahead_intervals = lookahead_intervals
        self.trace_source = get_trace_source(trace_source or self.params.traces)
        self.generator = torch.Generator(device=self.device)

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
        self._time_left = 1.0 - torch.arange(t, device=self.device, dtype=torch.float32) / t
        #: the array type of the twin's state (NumPy arrays or torch tensors on the device)
        self.ns = ns = ArrayNamespace(backend == "numpy", self.device)
        self._numpy = ns.numpy
        self._time_left = ns.native(self._time_left)
        # lane centres across the road [N] (m), None for one lane (docs/model.md §6)
        self._lateral_offset_m = None
        if not topology.single_lane:
            offsets = torch.tensor(topology.lateral_offset_m, device=self.device)
            self._lateral_offset_m = ns.native(offsets)
        self._decode_torch = link.ActionTables.build(rp, self.device)
        self._const_torch = link.KernelConstants.build(
            rp, pp.subframe_s, self.batch_size, self.num_links, self.device
        )
        self._decode = self._decode_torch.numpy() if ns.numpy else self._decode_torch
        self._const = self._const_torch.numpy() if ns.numpy else self._const_torch
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

    def reset(self, seed: int | None = None, mask: torch.Tensor | None = None) -> None:
        """Start new episodes in all scenarios, or only where ``mask`` [B] is True."""
        with self._torch_calls():
            self._reset(seed, mask)

    def _reset(self, seed: int | None, mask: torch.Tensor | None) -> None:
        if seed is not None:
            self.seed(seed)
        b, pp, rp = self.batch_size, self.params.platoon, self.params.radio
        dev = self.device
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
        state = initial_state(traces[..., 0], pp, self.generator)
        v2v_shadow = rp.v2v_shadow_std_db * channel.symmetric_normal(
            (count, pp.num_vehicles, pp.num_vehicles), self.generator
        )
        v2i_shadow = rp.v2i_shadow_std_db * torch.randn(
            count, pp.num_vehicles, generator=self.generator, device=dev
        )
        bs_offset = rp.inter_site_distance_m * torch.rand(
            count, generator=self.generator, device=dev
        )
        cam_held = cam_snapshot(state, pp)
        if mask is None:
            self.leader_speed_mps = traces
            self.platoon = state
            self.v2v_shadow_db, self.v2i_shadow_db = v2v_shadow, v2i_shadow
            self.bs_offset_m = bs_offset
            self.shadow_position_m = state.position_m.clone()
            self.interval = torch.zeros(b, dtype=torch.long, device=dev)
            self.cam_held = cam_held
            self.cam_held_interval = torch.full((b, self.num_followers), -1, device=dev)
            self.cam_delay_history = torch.zeros(b, self.num_links, RRA_DELAY_HISTORY, device=dev)
            self.command_history = torch.zeros(
                b, self.num_followers, RRA_COMMAND_HISTORY, device=dev
            )
            self.begin_interval()
            return
        idx = mask.nonzero().squeeze(-1)
        self.leader_speed_mps[idx] = traces
        self.platoon = PlatoonState(
            *(
                self._scatter(getattr(self.platoon, k), idx, getattr(state, k))
                for k in ("position_m", "speed_mps", "accel_mps2", "command_mps2")
            )
        )
        self.v2v_shadow_db[idx] = v2v_shadow
        self.v2i_shadow_db[idx] = v2i_shadow
        self.bs_offset_m[idx] = bs_offset
        self.shadow_position_m[idx] = state.position_m
        self.interval[idx] = 0
        self.cam_held[idx] = cam_held
        self.cam_held_interval[idx] = -1
        self.cam_delay_history[idx] = 0.0
        self.command_history[idx] = 0.0
        self.begin_interval(mask)

    @staticmethod
    def _scatter(base: torch.Tensor, idx: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
        out = base.clone()
        out[idx] = values
        return out

    def _native(self, x):
        """A state tensor in the backend's array type (a NumPy view on the NumPy backend)."""
        return self.ns.native(x)

    def _public(self, x) -> torch.Tensor:
        """A backend array as a torch tensor (shares the NumPy array's memory)."""
        return self.ns.public(x)

    def _native_platoon(self) -> PlatoonState:
        return self.platoon.numpy() if self._numpy else self.platoon

    # ------------------------------------------------------------------ interval start
    def begin_interval(self, mask: torch.Tensor | None = None) -> None:
        """Generate CAM_k, update the large-scale channel, draw the interval's fast fading.

        With ``mask`` only the masked scenarios start a new interval (after a partial reset);
        the others keep their current interval unchanged.
        """
        with self._torch_calls():
            self._begin_interval(mask)

    def _begin_interval(self, mask: torch.Tensor | None) -> None:
        snapshot = self._public(cam_snapshot(self._native_platoon(), self.params.platoon))
        self.cam_snapshot = (
            snapshot
            if mask is None
            else torch.where(mask[:, None, None], snapshot, self.cam_snapshot)
        )
        self.subframe = 0
        if not self.radio_enabled:
            return
        rp, t = self.params.radio, self.subframes_per_interval
        tables = self._draw_interval_tables()
        link_state = link.new_link_state(
            self.batch_size,
            self.num_links,
            self.num_subchannels,
            rp,
            t,
            None if self._numpy else self.device,
        )
        obs = self._rra_observation_buffer(tables)
        v2i_sum = self.ns.zeros((self.batch_size, self.num_subchannels))
        if mask is not None:
            tables, link_state, obs, v2i_sum = self._merge_interval(
                mask, tables, link_state, obs, v2i_sum
            )
            if self._numpy:
                tables, link_state = tables.numpy(), link_state.numpy()
                obs, v2i_sum = obs.numpy(), v2i_sum.numpy()
        self.tables, self.link_state, self._rra_obs, self._v2i_rate_sum = (
            tables,
            link_state,
            obs,
            v2i_sum,
        )

    def _merge_interval(self, mask, tables, link_state, obs, v2i_sum):
        def merge(new, old, batch_dim):
            new = torch.as_tensor(new, device=self.device)
            old = torch.as_tensor(old, device=self.device)
            shape = [1] * new.dim()
            shape[batch_dim] = -1
            return torch.where(mask.view(shape), new, old)

        tables = link.IntervalTables(
            *(
                merge(getattr(tables, k), getattr(self.tables, k), 1)
                for k in (
                    "own_gain",
                    "v2i_to_rx_mw",
                    "tx_to_bs_gain",
                    "cross_gain",
                    "v2i_signal_mw",
                )
            )
        )
        link_state = link.LinkState(
            *(
                merge(getattr(link_state, k), getattr(self.link_state, k), 0)
                for k in ("remaining_bits", "delay_subframes", "occupancy")
            )
        )
        return (
            tables,
            link_state,
            merge(obs, self._rra_obs, 1),
            merge(v2i_sum, self._v2i_rate_sum, 0),
        )

    def _draw_interval_tables(self) -> link.IntervalTables:
        rp = self.params.radio
        native = self._native
        x = native(self.platoon.position_m)
        moved = abs(x - native(self.shadow_position_m))
        self.shadow_position_m = self._public(self.ns.copy(x))
        g = self.generator
        n = x.shape[1]
        # draws in a fixed order (V2V innovation, V2I innovation, fading) on both backends
        v2v_shadow = channel.shadowing_update_db(
            native(self.v2v_shadow_db),
            moved[:, :, None] + moved[:, None, :],
            rp.v2v_shadow_std_db,
            rp.v2v_decorrelation_m,
            channel.symmetric_normal((self.batch_size, n, n), g, numpy=self._numpy),
        )
        v2i_shadow = channel.shadowing_update_db(
            native(self.v2i_shadow_db),
            moved,
            rp.v2i_shadow_std_db,
            rp.v2i_decorrelation_m,
            native(torch.randn(self.batch_size, n, generator=g, device=self.device)),
        )
        self.v2v_shadow_db = self._public(v2v_shadow)
        self.v2i_shadow_db = self._public(v2i_shadow)
        bs_x = channel.serving_bs_x_m(mean_axis(x, 1), native(self.bs_offset_m), rp)
        lateral = self._lateral_offset_m
        v2v_db, v2i_db = link.large_scale_gains_db(
            channel.v2v_pathloss_db(channel.v2v_distance_m(x, lateral), rp),
            v2v_shadow,
            channel.v2i_pathloss_db(channel.v2i_distance_m(x, bs_x, rp, lateral)),
            v2i_shadow,
            rp,
        )
        return link.build_interval_tables(
            v2v_db, v2i_db, rp, self.subframes_per_interval, g, self.topology
        )

    def _rra_observation_buffer(self, tables: link.IntervalTables):
        """[T, B, L, D] in the order of :data:`~vdtn_marl.sim.layout.RRA_OBS_FEATURES`: CSI,
        occupancy and bits left (filled per subframe), time left, the recipients' control
        state and the features that predict their IVoI (constant over the interval).

        A tensor, or a NumPy array on the NumPy backend.
        """
        t, b, n_l = self.subframes_per_interval, self.batch_size, self.num_links
        pp, lay, native = self.params.platoon, self.rra_layout, self._native
        platoon = self._native_platoon()
        csi = link.rra_static_observation(tables, self.params.radio, self._const_torch.noise_mw)
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
        age = as_float(native(self.interval)[:, None] - native(self.cam_held_interval))
        history = clamp(
            native(self.command_history) / pp.accel_max_mps2, -RRA_CONTROL_CLIP, RRA_CONTROL_CLIP
        )
        obs = self.ns.empty((t, b, n_l, self.rra_obs_dim))
        obs[..., lay.csi] = csi
        obs[..., lay.occupancy] = 0.0
        obs[..., lay.bits_left] = 1.0
        obs[..., lay.time_left] = self._time_left[:, None, None]
        obs[..., lay.control] = control
        obs[..., lay["cam_age"]] = clamp(age, 0.0, RRA_CAM_AGE_CLIP_INTERVALS)[..., None]
        obs[..., lay["cam_delay_history"]] = native(self.cam_delay_history)
        obs[..., lay["command_history"]] = history
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
            lib, keep = self.ns.lib, self.ns.mask(mask)
            state = link.LinkState(
                *(
                    lib.where(keep[:, None], getattr(state, f.name), getattr(before, f.name))
                    for f in dataclasses.fields(state)
                )
            )
            rate_sum = lib.where(keep[:, None], rate_sum, self._v2i_rate_sum)
        self.link_state, self._v2i_rate_sum = state, rate_sum
        self.subframe = t + 1
        return outcome

    def _check_rra_actions(self, actions) -> None:
        expected = (self.batch_size, self.num_links)
        if tuple(actions.shape) != expected:
            raise ValueError(f"RRA actions have shape {tuple(actions.shape)}, expected {expected}")
        n_act = self.params.radio.num_actions
        if self.backend == "numpy":
            bad = actions.dtype.kind not in "iu" or actions.min() < 0 or actions.max() >= n_act
        else:
            bad = actions.dtype.is_floating_point or bool(
                ((actions < 0) | (actions >= n_act)).any()
            )
        if bad:
            count = actions.size if self.backend == "numpy" else actions.numel()
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
        obs[..., lay.occupancy] = self.link_state.occupancy[:, None, :] / self.num_links
        remaining = self.link_state.remaining_bits / self.params.radio.cam_size_bits
        obs[..., lay.bits_left] = clamp(remaining, 0.0, 1.0)
        return obs

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
        self.link_state.delay_subframes = self.ns.lib.where(self.ns.mask(mask), lost, delay)

    def _delivery_subframes(self):
        """CAM delivery subframes [B, L] in the backend's array type."""
        return self.link_state.delay_subframes

    def switch_subframe(self, perfect: bool) -> torch.Tensor:
        """When u_k takes force in this interval, [B, F] int (docs/model.md §4.5).

        0 with perfect observation; otherwise the CAM's delivery subframe if it arrived in the
        first T−1 subframes, else T (the decision is taken at the deadline on an older CAM and
        its command takes force at the next interval).
        """
        return self._public(self._switch_subframe(perfect))

    def _switch_subframe(self, perfect: bool):
        t = self.subframes_per_interval
        if perfect:
            return self.ns.zeros((self.batch_size, self.num_followers), "int64")
        delay = self._delivery_subframes()
        return self.ns.lib.where(delay <= t - 1, delay, t)

    def vehicle_observation(self, perfect: bool, cams_lost: bool = False) -> torch.Tensor:
        """What each follower knows when it decides u_k, [B, F, 8] (docs/model.md §2.4, §4.5).

        With ``cams_lost`` (impaired observation only): what it would know had this interval's
        CAM been lost, i.e. the content it held before the interval, at its age, and a command
        that takes force at the next interval (the counterfactual of a difference IVoI reward,
        the ``cam_lost`` baseline of :class:`~vdtn_marl.voi.RolloutIVoIEstimator`).
        """
        platoon = self._native_platoon()
        if perfect:
            return self._public(perfect_observation(platoon, self.params.platoon))
        native = self._native
        switch = self._switch_subframe(perfect=False)
        lib = xp(switch)
        if cams_lost:
            switch = lib.full_like(switch, self.subframes_per_interval)
        usable = switch < self.subframes_per_interval
        content = lib.where(usable[..., None], native(self.cam_snapshot), native(self.cam_held))
        age_intervals = as_float(native(self.interval)[:, None] - native(self.cam_held_interval))
        age_ms = lib.where(usable, lib.zeros_like(age_intervals), age_intervals * self.interval_ms)
        return self._public(
            vehicle_observation(
                platoon, content, as_float(switch) * self.subframe_ms, age_ms, self.params.platoon
            )
        )

    def leader_accel_mps2(self, intervals: torch.Tensor) -> torch.Tensor:
        """Every leader's acceleration (m/s²) in intervals ``intervals`` [B, ...] →
        [B, ..., Λ] (Λ = ``num_leaders``; the leaders of ``topology.leaders`` in order).

        ``intervals`` may be a NumPy array (on a CPU twin): the result is one too.
        """
        b, leaders = self.batch_size, self.num_leaders
        last = self.leader_speed_mps.shape[-1] - 2
        k = clamp(intervals, 0, last)
        flat = k.reshape(b, 1, -1)
        dt = self.params.platoon.control_interval_s
        if isinstance(flat, np.ndarray):
            v = to_numpy(self.leader_speed_mps)
            rows = np.arange(b)[:, None, None]
            lead = np.arange(leaders)[None, :, None]
            accel = (v[rows, lead, flat + 1] - v[rows, lead, flat]) / dt
        else:
            v = self.leader_speed_mps
            flat = flat.expand(b, leaders, flat.shape[-1])
            accel = (v.gather(2, flat + 1) - v.gather(2, flat)) / dt
        return accel.swapaxes(1, 2).reshape(*intervals.shape, leaders)

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
        pp = self.params.platoon
        native, public = self._native, self._public
        switch = self._switch_subframe(perfect)
        before = self._native_platoon()
        u = clamp(self.ns.float32(commands_mps2), pp.accel_min_mps2, pp.accel_max_mps2)
        if command_if_lost_mps2 is not None:
            if tuple(command_if_lost_mps2.shape) != expected:
                raise ValueError(
                    f"command_if_lost_mps2 has shape {tuple(command_if_lost_mps2.shape)}, "
                    f"expected {expected}"
                )
            command_if_lost_mps2 = torch.as_tensor(
                command_if_lost_mps2, dtype=torch.float32, device=self.device
            ).clamp(pp.accel_min_mps2, pp.accel_max_mps2)
        interval = native(self.interval)
        after = self.integrator.integrate(before, self.leader_accel_mps2(interval), u, switch)
        gap_error, speed_error = spacing_errors(after, pp)
        follower = self.topology.followers_of
        reward = control_reward(gap_error, speed_error, u, follower(before.command_mps2), pp)
        collided = gaps_m(after.position_m, pp) <= 0
        reward = reward + as_float(collided) * pp.collision_penalty

        lib = xp(u)
        if self.radio_enabled:
            delay = self._delivery_subframes()
            mean_rate = native(self._v2i_rate_sum) / max(self.subframe, 1)
            delivered = delay <= t
            self.cam_held = public(
                lib.where(delivered[..., None], native(self.cam_snapshot), native(self.cam_held))
            )
            self.cam_held_interval = public(
                lib.where(delivered, interval[:, None], native(self.cam_held_interval))
            )
        else:
            delay = lib.zeros_like(switch)
            mean_rate = self.ns.zeros((self.batch_size, self.num_subchannels))
        # the recipients' histories the next interval's RRA observation reads
        delay_fraction = clamp(as_float(delay) / (t + 1), 0.0, 1.0)
        self.cam_delay_history = public(
            cat([delay_fraction[..., None], native(self.cam_delay_history)[..., :-1]])
        )
        self.command_history = public(
            cat(
                [
                    follower(before.command_mps2)[..., None],
                    native(self.command_history)[..., :-1],
                ]
            )
        )
        record = IntervalRecord(
            interval=public(self.ns.copy(interval)),
            state_before=self.platoon,
            state_after=after.torch() if self._numpy else after,
            command_mps2=public(u),
            switch_subframe=public(switch),
            reward=public(reward),
            gap_error_m=public(gap_error),
            speed_error_mps=public(speed_error),
            collided=public(collided),
            truncated=public(interval + 1 >= self.params.episode_intervals),
            cam_delay_subframes=public(delay),
            v2i_rate_bps=public(mean_rate),
            command_if_lost_mps2=command_if_lost_mps2,
        )
        self.platoon = record.state_after
        self.interval = public(interval + 1)
        return record
