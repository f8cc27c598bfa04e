"""Discounted rollouts of a reference policy in copies of the twin's state (docs/model.md §5):
:func:`discounted_rollout`, :func:`bootstrapped_return` and :class:`RolloutValue`, which
the IVoI estimators and the value fit build on."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from vdtn_marl.sim.backend import as_float, repeat_rows, to_numpy, to_torch
from vdtn_marl.sim.cacc import CACCController
from vdtn_marl.sim.platoon import (
    GAP_ERROR_BOUND_M,
    SPEED_ERROR_BOUND_MPS,
    IntervalIntegrator,
    PlatoonState,
    control_reward,
    gaps_m,
    perfect_observation,
    spacing_errors,
)
from vdtn_marl.sim.twin import DigitalTwin

Policy = Callable[
    [torch.Tensor], torch.Tensor
]  # vehicle observations [..., F, 8] → commands [..., F]


def _is_linear_cacc(policy: Policy) -> bool:
    """The linear CACC law itself (also a subclass that keeps its ``__call__``)."""
    return isinstance(policy, CACCController) and type(policy).__call__ is CACCController.__call__


def _numpy_path(twin: DigitalTwin, policy: Policy) -> bool:
    """Run the rollouts on NumPy arrays: a NumPy twin and the linear CACC reference, which maps
    NumPy observations with the same float32 operations as torch. Same numbers, at a fraction
    of the per-operation cost on a few scenarios."""
    return twin.backend == "numpy" and _is_linear_cacc(policy)


def _check_rollout(horizon_intervals: int, discount: float) -> None:
    if horizon_intervals < 1:
        raise ValueError(f"horizon_intervals={horizon_intervals!r} must be >= 1")
    if not 0.0 <= discount <= 1.0:
        raise ValueError(f"discount={discount!r} is outside [0, 1]")


def discounted_rollout(
    twin: DigitalTwin,
    state: PlatoonState,
    interval: torch.Tensor,
    policy: Policy,
    horizon_intervals: int,
    discount: float,
    first_command: torch.Tensor | None = None,
    first_switch: torch.Tensor | None = None,
    stop_at_episode_end: bool = False,
) -> tuple[torch.Tensor, PlatoonState]:
    """Discounted control return [R, F] of ``policy`` on perfect observations from ``state``
    (R rows, e.g. branches × scenarios; ``interval`` [R] says where each row is on the twin's
    leader trace, rows r map to scenario r mod B). The first interval may use a given command
    and switch subframe. With ``stop_at_episode_end`` rewards after the episode's last
    interval count zero (finite-horizon value). A collision (any gap ≤ 0) ends a row's episode
    as it ends the environment's: the colliding interval's reward and penalty count, later
    intervals count zero. Returns (returns, final state).

    On a NumPy twin with the linear CACC as ``policy`` the rollout runs on NumPy arrays
    (:func:`_cacc_rollout_numpy`, the same numbers); inputs and results are torch tensors
    either way."""
    if not _numpy_path(twin, policy):
        returns, final, _ = _rollout(
            twin, state, interval, policy, horizon_intervals, discount,
            first_command, first_switch, stop_at_episode_end,
        )  # fmt: skip
        return returns, final
    returns, final, _ = _cacc_rollout_numpy(
        twin,
        state.numpy(),
        to_numpy(interval),
        policy,
        horizon_intervals,
        discount,
        None if first_command is None else to_numpy(first_command),
        None if first_switch is None else to_numpy(first_switch),
        stop_at_episode_end,
    )
    return to_torch(returns), final.torch()


def bootstrapped_return(
    twin: DigitalTwin,
    state: PlatoonState,
    interval: torch.Tensor,
    policy: Policy,
    horizon_intervals: int,
    discount: float,
    terminal_value: Policy | None = None,
) -> torch.Tensor:
    """``Σ_{j<H} γ^j r_j + γ^H·v(S_H)`` [R, F] of ``policy`` on perfect observations from
    ``state`` (torch tensors; rows as in :func:`discounted_rollout`), with ``terminal_value``
    (perfect observations [R, F, 8] → [R, F]) valuing the state reached; nothing counts after
    a collision ended a row. ``terminal_value=None``: the plain ``H``-interval return."""
    _check_rollout(horizon_intervals, discount)
    returns, final, alive = _rollout(twin, state, interval, policy, horizon_intervals, discount)
    if terminal_value is None:
        return returns
    value = terminal_value(perfect_observation(final, twin.params.platoon))
    return returns + discount**horizon_intervals * alive[:, None] * value


def _rollout(
    twin: DigitalTwin,
    state: PlatoonState,
    interval,
    policy: Policy,
    horizon_intervals: int,
    discount: float,
    first_command=None,
    first_switch=None,
    stop_at_episode_end: bool = False,
):
    """:func:`discounted_rollout` on torch tensors or NumPy arrays (all inputs alike); for the
    linear CACC on NumPy arrays, :func:`_cacc_rollout_numpy` computes the same faster.
    Returns (returns [R, F], final state, alive [R]: 1 where no collision ended the row)."""
    pp = twin.params.platoon
    integrator: IntervalIntegrator = twin.integrator
    rows = interval.shape[0]
    repeats = rows // twin.batch_size
    f = twin.num_followers
    if isinstance(interval, np.ndarray):
        steps = np.arange(horizon_intervals)
        returns = np.zeros((rows, f), np.float32)
        alive = np.ones(rows, np.float32)
        zero_switch = np.zeros((rows, f), np.int64)
    else:
        steps = torch.arange(horizon_intervals, device=interval.device)
        returns = torch.zeros(rows, f, device=interval.device)
        alive = torch.ones(rows, device=interval.device)
        zero_switch = torch.zeros(rows, f, dtype=torch.long, device=interval.device)
    leader = repeat_rows(
        twin.leader_accel_mps2(interval[: twin.batch_size, None] + steps), repeats
    )  # [R, H]
    # the linear CACC reads only part of the perfect observation: skip building the rest
    perfect_command = policy.perfect_command if _is_linear_cacc(policy) else None
    gap_error, speed_error = spacing_errors(state, pp)
    weight = 1.0
    for h in range(horizon_intervals):
        if h == 0 and first_command is not None:
            u = first_command
            switch = zero_switch if first_switch is None else first_switch
        elif perfect_command is not None:
            u = perfect_command(state, pp, gap_error, speed_error)
            switch = zero_switch
        else:
            u = policy(perfect_observation(state, pp))
            switch = zero_switch
        after = integrator.integrate(state, leader[:, h], u, switch)
        gap_error, speed_error = spacing_errors(after, pp)
        reward = control_reward(
            gap_error, speed_error, after.command_mps2[:, 1:], state.command_mps2[:, 1:], pp
        )
        collided = gaps_m(after.position_m, pp) <= 0
        reward = reward + as_float(collided) * pp.collision_penalty
        if stop_at_episode_end:
            inside = as_float(interval + h < twin.params.episode_intervals)[:, None]
            reward = reward * inside
        returns = returns + weight * (reward * alive[:, None])
        alive = alive * as_float(~collided.any(-1))
        weight *= discount
        state = after
    return returns, state, alive


def _cacc_rollout_numpy(
    twin: DigitalTwin,
    state: PlatoonState,
    interval: np.ndarray,
    policy: CACCController,
    horizon_intervals: int,
    discount: float,
    first_command: np.ndarray | None,
    first_switch: np.ndarray | None,
    stop_at_episode_end: bool,
) -> tuple[np.ndarray, PlatoonState]:
    """:func:`_rollout` of the linear CACC on NumPy arrays, in fewer NumPy calls.

    The generic loop composes :meth:`CACCController.perfect_command`,
    :meth:`~vdtn_marl.sim.platoon.IntervalIntegrator.integrate`, ``spacing_errors`` and
    ``control_reward``; on a few scenarios its cost is the number of NumPy calls. Here the
    state stays packed as one [R, N, 3] array of (p, v, a) updated in place, the four clipped
    CACC inputs and the four reward terms are each one [4, R, F] block, and the collision
    penalty is added only when a gap closed (adding 0·penalty = −0 changes no value). Every
    float32 operation of the generic loop is kept, in the same order, so the returns and the
    final state are the same numbers.
    """
    pp = twin.params.platoon
    f32 = np.float32
    t = pp.subframes_per_interval
    gain = twin.integrator._input_gain_np
    phi_0, phi_1, phi_2 = (np.ascontiguousarray(c) for c in twin.integrator._phi_t_np.T)
    rows, n = state.position_m.shape
    f = n - 1
    lo, hi = pp.accel_min_mps2, pp.accel_max_mps2
    dt, lead_gain, length = (
        pp.control_interval_s,
        twin.integrator.leader_pos_gain,
        pp.vehicle_length_m,
    )
    standstill, headway, penalty = pp.standstill_gap_m, pp.time_headway_s, pp.collision_penalty
    # CACC law (perfect observation features 0, 1, 4, 2 with their clips)
    law_lo = np.array([-GAP_ERROR_BOUND_M, -SPEED_ERROR_BOUND_MPS, lo, lo], f32)[:, None, None]
    law_hi = np.array([GAP_ERROR_BOUND_M, SPEED_ERROR_BOUND_MPS, hi, hi], f32)[:, None, None]
    # k_a enters negated: s + (−k_a)·x equals s − k_a·x exactly
    gains = [policy.gap_gain, policy.speed_gain, policy.feedforward_gain, -policy.accel_gain]
    law_gain = np.array(gains, f32)[:, None, None]
    u_lo, u_hi = policy.params.accel_min_mps2, policy.params.accel_max_mps2
    # the integrator clips u again; with the same bounds that is the identity, skip it
    clip_again = (u_lo, u_hi) != (lo, hi)
    # reward terms |e_p|/ê_p, α|e_v|/ê_v, β|u|/u_max, γ|jerk|/j_max (1·x is x exactly)
    weight_terms = [1.0, pp.weight_speed, pp.weight_accel, pp.weight_jerk]
    term_weight = np.array(weight_terms, f32)[:, None, None]
    scales = [pp.gap_error_scale_m, pp.speed_error_scale_mps, pp.accel_max_mps2, pp.jerk_max_mps3]
    term_scale = np.array(scales, f32)[:, None, None]

    steps = np.arange(horizon_intervals)
    leader = twin.leader_accel_mps2(interval[: twin.batch_size, None] + steps)
    leader = repeat_rows(leader, rows // twin.batch_size)  # [R, H]
    packed = np.empty((rows, n, 3), f32)  # (p, v, a) of every vehicle, leader first
    packed[..., 0], packed[..., 1], packed[..., 2] = (
        state.position_m,
        state.speed_mps,
        state.accel_mps2,
    )
    position, speed, z = packed[..., 0], packed[..., 1], packed[:, 1:]  # views
    command = state.command_mps2
    law = np.empty((4, rows, f), f32)  # clipped CACC inputs: e_p, e_v, û_{i−1}, a_i
    gap = position[:, :-1] - position[:, 1:] - length
    np.subtract(gap, standstill + headway * speed[:, 1:], out=law[0])
    np.subtract(speed[:, :-1], speed[:, 1:], out=law[1])
    law[2], law[3] = command[:, :-1], z[..., 2]
    u_old = command[:, 1:]
    terms = np.empty((4, rows, f), f32)
    returns = np.zeros((rows, f), f32)
    alive = np.ones(rows, f32)
    g_all = gain[t]
    weight = 1.0
    for h in range(horizon_intervals):
        if h == 0 and first_command is not None:
            u = first_command
            g_new = g_all if first_switch is None else gain[t - first_switch]
        else:
            np.minimum(np.maximum(law, law_lo, out=law), law_hi, out=law)
            law *= law_gain
            u = np.minimum(np.maximum(law[0] + law[1] + law[2] + law[3], u_lo), u_hi)
            g_new = g_all
        if h == 0 or clip_again:
            u = np.minimum(np.maximum(u, lo), hi)
        du = u - u_old
        la = leader[:, h]
        # leader: p + Δt·v + (its gain)·a, v + Δt·a clamped at 0 (read before overwriting)
        lead_v = packed[:, 0, 1]
        lead_p = packed[:, 0, 0] + dt * lead_v + lead_gain * la
        packed[:, 0, 1] = np.maximum(lead_v + dt * la, 0.0)
        packed[:, 0, 0], packed[:, 0, 2] = lead_p, la
        # followers: z ← z·Φᵀ (torch's summation order) + G_T·u_{k−1} + G_{T−d}·(u_k − u_{k−1})
        z_new = z[..., 0:1] * phi_0 + z[..., 1:2] * phi_1 + z[..., 2:3] * phi_2
        z[...] = z_new + g_all * u_old[..., None] + g_new * du[..., None]
        np.maximum(z[..., 1], 0.0, out=z[..., 1])
        # spacing errors after the interval: the reward's and the next CACC input
        gap = position[:, :-1] - position[:, 1:] - length
        np.subtract(gap, standstill + headway * speed[:, 1:], out=law[0])
        np.subtract(speed[:, :-1], speed[:, 1:], out=law[1])
        terms[:2] = law[:2]
        law[2, :, 0], law[2, :, 1:], law[3] = la, u[:, :-1], z[..., 2]
        terms[2] = u
        np.divide(du, dt, out=terms[3])
        np.abs(terms, out=terms)
        terms *= term_weight
        terms /= term_scale
        reward = -(terms[0] + terms[1] + terms[2] + terms[3])
        collided = gap <= 0
        if np.count_nonzero(collided):
            reward = reward + collided.astype(f32) * penalty
        if stop_at_episode_end:
            reward = reward * (interval + h < twin.params.episode_intervals).astype(f32)[:, None]
        returns = returns + weight * (reward * alive[:, None])
        alive = alive * (~collided.any(-1)).astype(f32)
        weight *= discount
        u_old = u
    command = np.empty((rows, n), f32)
    command[:, 0], command[:, 1:] = leader[:, -1], u
    final = PlatoonState(position.copy(), speed.copy(), packed[..., 2].copy(), command)
    return returns, final, alive


class RolloutValue:
    """Value v(S) of a reference policy on perfect observations, by a rollout in the twin over
    the known leader trace (platoon dynamics are deterministic given the trace, so one rollout
    is exact). With ``horizon_intervals`` at least the episode length this is the exact
    finite-horizon value of the episode; plug it into :class:`TDIVoIEstimator` as ``value`` for
    a critic-free reference."""

    def __init__(
        self,
        reference_policy: Policy | None = None,
        horizon_intervals: int = 10,
        discount: float = 0.99,
    ):
        _check_rollout(horizon_intervals, discount)
        self.reference_policy = reference_policy
        self.horizon_intervals = horizon_intervals
        self.discount = discount

    def state_value(
        self, twin: DigitalTwin, state: PlatoonState, interval: torch.Tensor
    ) -> torch.Tensor:
        """v(S) [B, F] of every follower at ``state`` at the start of interval ``interval``."""
        policy = self.reference_policy or CACCController(twin.params.platoon)
        returns, _ = discounted_rollout(
            twin, state, interval, policy, self.horizon_intervals, self.discount,
            stop_at_episode_end=True,
        )  # fmt: skip
        return returns
