"""Longitudinal platoon dynamics, spacing policy, errors and control reward (docs/model.md §2).

Leaders follow speed traces; followers have a first-order driveline lag and keep a gap to
their predecessor. Who leads and who follows whom is the scenario's topology
(``params.topology``, :class:`~vdtn_marl.sim.topology.Topology`; by default vehicle 0 leads and
vehicle i follows i−1). Every function is batched over B scenarios and pure: it takes a
:class:`PlatoonState` and returns a new one, so the twin and counterfactual VoI rollouts share
the same physics.

Integration is explicit Euler per 1 ms subframe with a zero-order hold on the command in
force. Within an interval the command switches once, from u_{k−1} to u_k at subframe d, so the
T-step recursion has the closed form z_T = Φ^T·z_0 + (G_T − G_{T−d})·u_{k−1} + G_{T−d}·u_k with
G_n = Σ_{j<n} Φ^j·Γ, which :class:`IntervalIntegrator` precomputes once.

Apart from :func:`initial_state` (which draws from the twin's generator) every function also
runs on NumPy arrays, with the same float32 operations in the same order
(:mod:`vdtn_marl.sim.backend`): that is the single-scenario fast path of the PettingZoo
environments and of the rollout VoI estimator.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from types import SimpleNamespace

import numpy as np
import torch

from vdtn_marl.sim.backend import (
    as_float,
    cast_like,
    clamp,
    repeat_rows,
    stack,
    to_numpy,
    to_torch,
    xp,
)
from vdtn_marl.sim.layout import VEHICLE_OBS_FEATURES  # noqa: F401 - re-exported; one definition, in layout
from vdtn_marl.sim.params import PlatoonParams

GAP_ERROR_BOUND_M = 200.0
SPEED_ERROR_BOUND_MPS = 50.0
CAM_AGE_BOUND_MS = 10_000.0


@dataclass
class PlatoonState:
    """Kinematic state of B scenarios' N vehicles at a control-interval boundary.

    ``command_mps2`` holds the command in force at the interval start (u_{k−1}) for every
    vehicle; for a leader it is its acceleration over the previous interval.
    """

    position_m: torch.Tensor  # [B, N], along the road; each vehicle ahead of its followers
    speed_mps: torch.Tensor  # [B, N]
    accel_mps2: torch.Tensor  # [B, N]
    command_mps2: torch.Tensor  # [B, N]

    def _map(self, fn) -> PlatoonState:
        """A state whose every field is ``fn(field)``."""
        return PlatoonState(*(fn(getattr(self, f.name)) for f in fields(self)))

    def clone(self) -> PlatoonState:
        return self._map(lambda field: field.clone())

    def where(self, mask: torch.Tensor, other: PlatoonState) -> PlatoonState:
        """Per scenario: ``other`` where ``mask`` [B] is True, else self."""
        m = mask[:, None]
        return PlatoonState(
            *(torch.where(m, getattr(other, f.name), getattr(self, f.name)) for f in fields(self))
        )

    def repeat(self, times: int) -> PlatoonState:
        """Repeat every scenario ``times`` times along the batch (branch-major: [times·B])."""
        return self._map(lambda field: repeat_rows(field, times))

    def numpy(self) -> PlatoonState:
        """The same state as NumPy arrays (views of CPU tensors, no copy)."""
        return self._map(to_numpy)

    def torch(self) -> PlatoonState:
        """The same state as torch tensors (NumPy arrays are shared, not copied)."""
        return self._map(to_torch)


def numbers(params: PlatoonParams, *arrays) -> SimpleNamespace:
    """``params.numbers`` as operations on ``arrays`` take them fastest: float32 0-d arrays
    where every one is a float32 NumPy array (the same results,
    :attr:`PlatoonParams.numbers_float32`), else the Python numbers."""
    for x in arrays:
        if type(x) is not np.ndarray or x.dtype != np.float32:
            return params.numbers
    f32 = params.numbers_float32
    return params.numbers if f32 is None else f32


def gaps_m(position_m: torch.Tensor, params: PlatoonParams) -> torch.Tensor:
    """Bumper-to-bumper gap g_i = p_pred(i) − p_i − L of each follower i to its predecessor,
    [B, N] → [B, F]."""
    topology = params.topology
    length = numbers(params, position_m).length
    return topology.predecessors_of(position_m) - topology.followers_of(position_m) - length


def desired_gaps_m(speed_mps: torch.Tensor, params: PlatoonParams) -> torch.Tensor:
    """Constant-time-headway desired gap d_i = r + h·v_i of each follower, [B, N] → [B, F]."""
    c = numbers(params, speed_mps)
    return c.standstill + c.headway * params.topology.followers_of(speed_mps)


def spacing_errors(state: PlatoonState, params: PlatoonParams) -> tuple[torch.Tensor, torch.Tensor]:
    """Gap error e_p = g − d (m) and speed error e_v = v_pred(i) − v_i (m/s), each [B, F]."""
    return _spacing(state, params)[1:]


def _spacing(state: PlatoonState, params: PlatoonParams):
    """(gap g, gap error e_p, speed error e_v), each [B, F]: :func:`gaps_m` and
    :func:`desired_gaps_m` in one pass (the same operations)."""
    topology = params.topology
    position, speed = state.position_m, state.speed_mps
    c = numbers(params, position, speed)
    gap = topology.predecessors_of(position) - topology.followers_of(position) - c.length
    follower_speed = topology.followers_of(speed)
    gap_error = gap - (c.standstill + c.headway * follower_speed)
    speed_error = topology.predecessors_of(speed) - follower_speed
    return gap, gap_error, speed_error


def initial_state(
    leader_speed_mps: torch.Tensor,
    params: PlatoonParams,
    generator: torch.Generator,
) -> PlatoonState:
    """Every follower at the desired gap behind its predecessor and at its leader's speed,
    a = 0 (plus optional noise).

    ``leader_speed_mps`` [B, Λ], one speed per leader of ``params.topology``; leader j starts
    at ``topology.leader_position_m[j]`` (default 0 m).
    """
    topology = params.topology
    b, n, f = leader_speed_mps.shape[0], params.num_vehicles, topology.num_followers
    dev = leader_speed_mps.device
    speed = leader_speed_mps[:, list(topology.leader_of)]  # [B, N]: each vehicle's leader's
    if params.initial_speed_noise_mps > 0:
        noise = torch.randn(b, f, generator=generator, device=dev)
        rows = list(topology.followers)
        speed[:, rows] = (speed[:, rows] + params.initial_speed_noise_mps * noise).clamp_min(0.0)
    spacing = params.vehicle_length_m + desired_gaps_m(speed, params)  # [B, F]
    if params.initial_gap_noise_m > 0:
        noise = torch.randn(b, f, generator=generator, device=dev)
        spacing = spacing + (params.initial_gap_noise_m * noise).clamp(
            -0.5 * params.standstill_gap_m, None
        )
    # distance behind the leader: the spacings along each chain, summed in float64 and rounded
    # once, as torch's CPU cumsum of float32 does (such sums are exact in float64, so the
    # order of the terms does not change a bit)
    chain = torch.as_tensor(topology.chain_matrix(), device=dev)
    behind = (spacing.double() @ chain.T).float()  # [B, F]
    start = torch.tensor(topology.leader_position_m or (0.0,) * topology.num_leaders, device=dev)
    leader_x = start.expand(b, -1)  # [B, Λ]
    position = topology.assemble(
        leader_x, topology.followers_of(leader_x[:, list(topology.leader_of)]) - behind
    )
    zeros = torch.zeros(b, n, device=dev)
    return PlatoonState(position, speed, zeros.clone(), zeros)


class IntervalIntegrator:
    """Exact composition of T explicit-Euler subframe steps with one command switch.

    Per subframe (dt = Δt/T), for a follower z = [p, v, a]:
    p' = p + dt·v,  v' = v + dt·a,  a' = a + (dt/τ)·(u − a).
    A leader's acceleration is set by its trace and constant within the interval.
    """

    def __init__(self, params: PlatoonParams, device: torch.device, dtype=torch.float32):
        self.params = params
        t, dt, tau = params.subframes_per_interval, params.subframe_s, params.driveline_lag_s
        phi = torch.tensor(
            [[1.0, dt, 0.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0 - dt / tau]], dtype=torch.float64
        )
        gamma = torch.tensor([0.0, 0.0, dt / tau], dtype=torch.float64)
        powers = [torch.eye(3, dtype=torch.float64)]
        for _ in range(t):
            powers.append(phi @ powers[-1])
        # G_n = Σ_{j<n} Φ^j Γ, n = 0..T
        g = torch.zeros(t + 1, 3, dtype=torch.float64)
        for n in range(1, t + 1):
            g[n] = g[n - 1] + powers[n - 1] @ gamma
        self.phi_t = powers[t].to(device=device, dtype=dtype)  # [3, 3]
        self.input_gain = g.to(device=device, dtype=dtype)  # [T+1, 3]
        self.leader_pos_gain = dt * dt * t * (t - 1) / 2.0  # p += T·dt·v + this·a
        self.leader_pos_gain_float32 = np.array(self.leader_pos_gain, np.float32)
        self.leader_pos_gain_float32.flags.writeable = False
        # the same matrices for NumPy states (the single-scenario fast path)
        self._phi_t_np = self.phi_t.cpu().numpy()
        self._input_gain_np = self.input_gain.cpu().numpy()

    def numpy_matrices(self) -> tuple[np.ndarray, np.ndarray]:
        """(Φ^T [3, 3], the input gains G_n [T+1, 3]) as the float32 NumPy arrays that
        :meth:`integrate` uses on NumPy states."""
        return self._phi_t_np, self._input_gain_np

    def integrate(
        self,
        state: PlatoonState,
        leader_accel_mps2: torch.Tensor,
        command_mps2: torch.Tensor,
        switch_subframe: torch.Tensor | None,
    ) -> PlatoonState:
        """State at the end of the interval.

        ``leader_accel_mps2`` [B, Λ] (one per leader of ``params.topology``);
        ``command_mps2`` [B, F] = u_k, clipped to the actuator bounds; ``switch_subframe``
        [B, F] int in 0..T: u_{k−1} is in force for subframes < d and u_k from d on (d = T:
        u_k takes force at the next interval; None: 0 for every follower). Torch tensors, or
        NumPy arrays for a NumPy state.
        """
        p = self.params
        t = p.subframes_per_interval
        topology = p.topology
        follower = topology.followers_of
        c = numbers(p, state.position_m, command_mps2, leader_accel_mps2)
        u_new = clamp(command_mps2, c.accel_min, c.accel_max)
        u_old = follower(state.command_mps2)
        position, speed, accel = (
            follower(state.position_m),
            follower(state.speed_mps),
            follower(state.accel_mps2),
        )
        if isinstance(position, np.ndarray):
            phi, gain = self._phi_t_np, self._input_gain_np
            # z @ Φᵀ as torch's small matmul computes it (products summed in order k = 0, 1, 2,
            # no fused multiply-add), so the two backends agree bitwise
            z_phi = (
                position[..., None] * phi[:, 0]
                + speed[..., None] * phi[:, 1]
                + accel[..., None] * phi[:, 2]
            )
        else:
            phi, gain = self.phi_t, self.input_gain
            z_phi = stack([position, speed, accel]) @ phi.T
        g_all = gain[t]  # [3]
        # [B, F, 3]; at switch 0 every follower's is G_T (the same numbers, no gather)
        g_new = g_all if switch_subframe is None else gain[t - switch_subframe]
        z = z_phi + g_all * u_old[..., None] + g_new * (u_new - u_old)[..., None]

        interval_s = c.interval_s
        lead_v = topology.leaders_of(state.speed_mps)  # [B, Λ]
        lead_p = (
            topology.leaders_of(state.position_m)
            + interval_s * lead_v
            + (self.leader_pos_gain if c is p.numbers else self.leader_pos_gain_float32)
            * leader_accel_mps2
        )
        lead_v = clamp(lead_v + interval_s * leader_accel_mps2, c.zero)

        position = topology.assemble(lead_p, z[..., 0])
        speed = topology.assemble(lead_v, clamp(z[..., 1], c.zero))
        accel = topology.assemble(leader_accel_mps2, z[..., 2])
        # u_k is in force at the start of the next interval, whatever its switch time was
        command = topology.assemble(leader_accel_mps2, u_new)
        return PlatoonState(position, speed, accel, command)


def control_reward(
    gap_error_m: torch.Tensor,
    speed_error_mps: torch.Tensor,
    command_mps2: torch.Tensor,
    prev_command_mps2: torch.Tensor,
    params: PlatoonParams,
) -> torch.Tensor:
    """r = −(|e_p|/ê_p + α|e_v|/ê_v + β|u|/u_max + γ_j|jerk|/j_max), [B, F] (docs §2.3).

    Errors are those at the end of the interval; jerk = (u_k − u_{k−1})/Δt.
    """
    c = numbers(params, gap_error_m, speed_error_mps, command_mps2, prev_command_mps2)
    return _control_reward(gap_error_m, speed_error_mps, command_mps2, prev_command_mps2, c)


def _control_reward(gap_error_m, speed_error_mps, command_mps2, prev_command_mps2, c):
    """:func:`control_reward` with the numbers ``c`` (:func:`numbers`)."""
    jerk = (command_mps2 - prev_command_mps2) / c.interval_s
    return -(
        abs(gap_error_m) / c.gap_scale
        + c.weight_speed * abs(speed_error_mps) / c.speed_scale
        + c.weight_accel * abs(command_mps2) / c.accel_max
        + c.weight_jerk * abs(jerk) / c.jerk_max
    )


def interval_reward(
    before: PlatoonState, after: PlatoonState, command_mps2: torch.Tensor, params: PlatoonParams
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """One interval's reward [B, F] from the states before and after it and the followers'
    commands u_k [B, F]: :func:`control_reward` of the errors at its end, plus
    ``collision_penalty`` for each follower where a gap closed (≤ 0). Returns (reward,
    gap error, speed error, collided [B, F]); the twin and the IVoI rollouts both pay this."""
    gap, gap_error, speed_error = _spacing(after, params)
    previous = params.topology.followers_of(before.command_mps2)
    c = numbers(params, gap_error, speed_error, command_mps2, previous)
    reward = _control_reward(gap_error, speed_error, command_mps2, previous, c)
    collided = gap <= c.zero
    reward = reward + as_float(collided) * c.collision_penalty
    return reward, gap_error, speed_error, collided


def vehicle_observation(
    state: PlatoonState,
    cam_content: torch.Tensor,
    cam_delay_ms: torch.Tensor,
    cam_age_ms: torch.Tensor,
    params: PlatoonParams,
) -> torch.Tensor:
    """Follower observations [B, F, 8] in the order of
    :data:`~vdtn_marl.sim.layout.VEHICLE_OBS_FEATURES`.

    Own gap/speed error and acceleration come from local sensing at the interval start;
    ``cam_content`` [B, F, 2] is the predecessor's (acceleration, command) from the CAM used
    for the decision; ``cam_delay_ms`` is when the decision's command takes force (0 = at the
    interval start, T = not in this interval) and ``cam_age_ms`` the age of the CAM content at
    the interval start. Values are clipped to the observation space bounds.
    """
    gap_error, speed_error = spacing_errors(state, params)
    follower = params.topology.followers_of
    lo, hi = params.accel_min_mps2, params.accel_max_mps2
    return stack(
        [
            clamp(gap_error, -GAP_ERROR_BOUND_M, GAP_ERROR_BOUND_M),
            clamp(speed_error, -SPEED_ERROR_BOUND_MPS, SPEED_ERROR_BOUND_MPS),
            clamp(follower(state.accel_mps2), lo, hi),
            clamp(cam_content[..., 0], lo, hi),
            clamp(cam_content[..., 1], lo, hi),
            cast_like(cam_delay_ms, gap_error),
            clamp(cast_like(cam_age_ms, gap_error), 0.0, CAM_AGE_BOUND_MS),
            clamp(follower(state.command_mps2), lo, hi),
        ]
    )


def cam_snapshot(state: PlatoonState, params: PlatoonParams) -> torch.Tensor:
    """CAM content each follower would receive from its predecessor now (the predecessor's
    acceleration and command): [B, F, 2]."""
    predecessor = params.topology.predecessors_of
    return stack([predecessor(state.accel_mps2), predecessor(state.command_mps2)])


def perfect_observation(state: PlatoonState, params: PlatoonParams) -> torch.Tensor:
    """Observation with an exact, instantaneous CAM (delay 0, age 0), [B, F, 8]."""
    zeros = xp(state.speed_mps).zeros_like(params.topology.followers_of(state.speed_mps))
    return vehicle_observation(state, cam_snapshot(state, params), zeros, zeros, params)


def vehicle_observation_bounds(params: PlatoonParams) -> tuple[list[float], list[float]]:
    """Lower and upper bounds of every vehicle observation feature."""
    lo, hi = params.accel_min_mps2, params.accel_max_mps2
    t_ms = params.subframes_per_interval * params.subframe_s * 1000.0
    low = [-GAP_ERROR_BOUND_M, -SPEED_ERROR_BOUND_MPS, lo, lo, lo, 0.0, 0.0, lo]
    high = [GAP_ERROR_BOUND_M, SPEED_ERROR_BOUND_MPS, hi, hi, hi, t_ms, CAM_AGE_BOUND_MS, hi]
    return low, high
