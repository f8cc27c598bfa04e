"""Discounted rollouts of a reference policy in copies of the twin's state (docs/model.md §5):
:func:`discounted_rollout`, :func:`bootstrapped_return` and :class:`RolloutValue`, which
the IVoI estimators and the value fit build on."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.backend import as_float, repeat_rows, to_numpy, to_torch
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

    On a NumPy twin with the linear CACC as ``policy`` the rollout runs on NumPy arrays (the
    same numbers, fewer per-call costs on a few scenarios); inputs and results are torch
    tensors either way."""
    if not _numpy_path(twin, policy):
        returns, final, _ = _rollout(
            twin, state, interval, policy, horizon_intervals, discount,
            first_command, first_switch, stop_at_episode_end,
        )  # fmt: skip
        return returns, final
    returns, final, _ = _rollout(
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
    fused: bool = True,
):
    """:func:`discounted_rollout` on torch tensors or NumPy arrays (all inputs alike): the
    twin's own integrator, the CACC law and the control reward. Returns (returns [R, F],
    final state, alive [R]: 1 where no collision ended the row). NumPy arrays with the linear
    CACC take :func:`_cacc_rollout_numpy` (``fused``), the one written-out copy of these
    steps, tested bit for bit against this loop (``fused=False``)."""
    if fused and isinstance(interval, np.ndarray) and _is_linear_cacc(policy):
        return _cacc_rollout_numpy(
            twin, state, interval, policy, horizon_intervals, discount,
            first_command, first_switch, stop_at_episode_end,
        )  # fmt: skip
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
    )  # [R, H, Λ]
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
        follower = pp.topology.followers_of
        reward = control_reward(
            gap_error, speed_error, follower(after.command_mps2), follower(state.command_mps2), pp
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
    first_command=None,
    first_switch=None,
    stop_at_episode_end: bool = False,
):
    """:func:`_rollout` of the linear CACC on NumPy arrays, written out on the rows it reads:
    :meth:`CACCController.perfect_command`, :meth:`IntervalIntegrator.integrate`,
    :func:`spacing_errors`, :func:`control_reward` and the collision test with the same
    float32 operations in the same order, so the same numbers bit for bit (tested against
    the general loop, ``fused=False``). At B = 1 (4 rows of 3 followers on platoon4) the
    general loop's per-step wrappers (a ``PlatoonState`` per step, the topology's row
    lookups, the backend's dispatch) cost more than its arithmetic; the rollout IVoI runs
    this loop every interval of the PettingZoo environments."""
    pp = twin.params.platoon
    rows_of = pp.topology.row_indices()
    fi, pi, li = rows_of.follower_index, rows_of.predecessor_index, rows_of.leader_index
    phi, gain = twin.integrator.numpy_matrices()
    t = pp.subframes_per_interval
    lo, hi = pp.accel_min_mps2, pp.accel_max_mps2
    top_lo, top_hi = policy.params.accel_min_mps2, policy.params.accel_max_mps2
    length, standstill, headway = pp.vehicle_length_m, pp.standstill_gap_m, pp.time_headway_s
    interval_s = pp.control_interval_s
    leader_pos_gain = twin.integrator.leader_pos_gain
    maximum, minimum, absolute = np.maximum, np.minimum, np.absolute
    rows = interval.shape[0]
    f = twin.num_followers
    leader = repeat_rows(
        twin.leader_accel_mps2(interval[: twin.batch_size, None] + np.arange(horizon_intervals)),
        rows // twin.batch_size,
    )  # [R, H, Λ]
    position, speed, accel = state.position_m, state.speed_mps, state.accel_mps2
    command = state.command_mps2
    returns = np.zeros((rows, f), np.float32)
    alive = np.ones(rows, np.float32)
    g_all = gain[t]

    def errors(position, speed):  # gaps_m and spacing_errors
        follower_speed = speed[:, fi]
        gap = position[:, pi] - position[:, fi] - length
        gap_error = gap - (standstill + headway * follower_speed)
        return gap, gap_error, speed[:, pi] - follower_speed

    _, gap_error, speed_error = errors(position, speed)
    weight = 1.0
    for h in range(horizon_intervals):
        g_new = g_all
        if h == 0 and first_command is not None:
            u = first_command
            if first_switch is not None:
                g_new = gain[t - first_switch]
        else:  # CACCController.perfect_command
            u = (
                policy.gap_gain * minimum(maximum(gap_error, -GAP_ERROR_BOUND_M), GAP_ERROR_BOUND_M)
                + policy.speed_gain
                * minimum(maximum(speed_error, -SPEED_ERROR_BOUND_MPS), SPEED_ERROR_BOUND_MPS)
                + policy.feedforward_gain * minimum(maximum(command[:, pi], lo), hi)
                - policy.accel_gain * minimum(maximum(accel[:, fi], lo), hi)
            )
            u = minimum(maximum(u, top_lo), top_hi)
        # IntervalIntegrator.integrate
        u_new = minimum(maximum(u, lo), hi)
        u_old = command[:, fi]
        z = np.empty((rows, f, 3), np.float32)
        z[..., 0], z[..., 1], z[..., 2] = position[:, fi], speed[:, fi], accel[:, fi]
        z_phi = z[..., 0:1] * phi[:, 0] + z[..., 1:2] * phi[:, 1] + z[..., 2:3] * phi[:, 2]
        z = z_phi + g_all * u_old[..., None] + g_new * (u_new - u_old)[..., None]
        lead_accel = leader[:, h]
        lead_v = speed[:, li]
        lead_p = position[:, li] + interval_s * lead_v + leader_pos_gain * lead_accel
        lead_v = maximum(lead_v + interval_s * lead_accel, 0.0)
        position, speed = np.empty_like(position), np.empty_like(speed)
        accel, command = np.empty_like(accel), np.empty_like(command)
        position[:, li], position[:, fi] = lead_p, z[..., 0]
        speed[:, li], speed[:, fi] = lead_v, maximum(z[..., 1], 0.0)
        accel[:, li], accel[:, fi] = lead_accel, z[..., 2]
        command[:, li], command[:, fi] = lead_accel, u_new
        # control_reward, the collision and the discounted sum, as in _rollout
        gap, gap_error, speed_error = errors(position, speed)
        jerk = (u_new - u_old) / interval_s
        reward = -(
            absolute(gap_error) / pp.gap_error_scale_m
            + pp.weight_speed * absolute(speed_error) / pp.speed_error_scale_mps
            + pp.weight_accel * absolute(u_new) / pp.accel_max_mps2
            + pp.weight_jerk * absolute(jerk) / pp.jerk_max_mps3
        )
        collided = gap <= 0
        reward = reward + collided.astype(np.float32) * pp.collision_penalty
        if stop_at_episode_end:
            inside = (interval + h < twin.params.episode_intervals).astype(np.float32)[:, None]
            reward = reward * inside
        returns = returns + weight * (reward * alive[:, None])
        alive = alive * (~np.logical_or.reduce(collided, axis=-1)).astype(np.float32)
        weight *= discount
    return returns, PlatoonState(position, speed, accel, command), alive


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
