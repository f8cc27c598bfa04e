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
    IntervalIntegrator,
    PlatoonState,
    interval_reward,
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
    if (
        fused
        and isinstance(interval, np.ndarray)
        and _is_linear_cacc(policy)
        and state.position_m.dtype == np.float32  # the written-out copy's arrays
        and (first_command is None or first_command.dtype == np.float32)
    ):
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
    else:
        steps = torch.arange(horizon_intervals, device=interval.device)
        returns = torch.zeros(rows, f, device=interval.device)
        alive = torch.ones(rows, device=interval.device)
    leader = repeat_rows(
        twin.leader_accel_mps2(interval[: twin.batch_size, None] + steps), repeats
    )  # [R, H, Λ]
    # the linear CACC reads only part of the perfect observation: skip building the rest
    perfect_command = policy.perfect_command if _is_linear_cacc(policy) else None
    gap_error, speed_error = spacing_errors(state, pp)
    weight = 1.0
    for h in range(horizon_intervals):
        switch = None  # perfect observations: each command takes force at once
        if h == 0 and first_command is not None:
            u = first_command
            switch = first_switch
        elif perfect_command is not None:
            u = perfect_command(state, pp, gap_error, speed_error)
        else:
            u = policy(perfect_observation(state, pp))
        after = integrator.integrate(state, leader[:, h], u, switch)
        command = pp.topology.followers_of(after.command_mps2)
        reward, gap_error, speed_error, collided = interval_reward(state, after, command, pp)
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
    # every constant as a float32 0-d array (PlatoonParams.numbers_float32): on float32 arrays
    # the same operation as with the Python number, at a fraction of NumPy's cost per call
    c, g = pp.numbers_float32, policy.numbers_float32
    if c is None or g is None:  # constants that are not Python numbers: the general loop
        return _rollout(
            twin, state, interval, policy, horizon_intervals, discount,
            first_command, first_switch, stop_at_episode_end, fused=False,
        )  # fmt: skip
    leader_pos_gain = twin.integrator.leader_pos_gain_float32
    lo, hi, top_lo, top_hi = c.accel_min, c.accel_max, g.lo, g.hi
    length, standstill, headway, interval_s = c.length, c.standstill, c.headway, c.interval_s
    zero = c.zero
    maximum, minimum, absolute = np.maximum, np.minimum, np.absolute
    rows = interval.shape[0]
    f, n = twin.num_followers, state.position_m.shape[1]
    leader = repeat_rows(
        twin.leader_accel_mps2(interval[: twin.batch_size, None] + np.arange(horizon_intervals)),
        rows // twin.batch_size,
    )  # [R, H, Λ]
    # the state as one float32 array [R, N, 4] (position, speed, acceleration, command): a
    # follower's integrator state z [R, F, 3] is a view of it, the next state one array
    s = np.empty((rows, n, 4), np.float32)
    s[..., 0], s[..., 1] = state.position_m, state.speed_mps
    s[..., 2], s[..., 3] = state.accel_mps2, state.command_mps2
    returns = np.zeros((rows, f), np.float32)
    alive = np.ones(rows, np.float32)
    g_all = gain[t]
    phi_p, phi_v, phi_a = phi[:, 0], phi[:, 1], phi[:, 2]

    def errors(s):  # gaps_m and spacing_errors, on the follower and predecessor rows
        ahead, behind = s[:, pi], s[:, fi]
        follower_speed = behind[..., 1]
        gap = ahead[..., 0] - behind[..., 0] - length
        gap_error = gap - (standstill + headway * follower_speed)
        return ahead, behind, gap, gap_error, ahead[..., 1] - follower_speed

    ahead, behind, _, gap_error, speed_error = errors(s)
    weight = 1.0
    for h in range(horizon_intervals):
        g_new = g_all
        if h == 0 and first_command is not None:
            u = first_command
            if first_switch is not None:
                g_new = gain[t - first_switch]
        else:  # CACCController.perfect_command
            u = (
                g.gap_gain * minimum(maximum(gap_error, g.gap_lo), g.gap_hi)
                + g.speed_gain * minimum(maximum(speed_error, g.speed_lo), g.speed_hi)
                + g.feedforward_gain * minimum(maximum(ahead[..., 3], lo), hi)
                - g.accel_gain * minimum(maximum(behind[..., 2], lo), hi)
            )
            u = minimum(maximum(u, top_lo), top_hi)
        # IntervalIntegrator.integrate
        u_new = minimum(maximum(u, lo), hi)
        u_old = behind[..., 3]
        step = u_new - u_old
        z = behind[..., 0:1] * phi_p + behind[..., 1:2] * phi_v + behind[..., 2:3] * phi_a
        z = z + g_all * u_old[..., None] + g_new * step[..., None]
        lead_accel = leader[:, h]
        lead = s[:, li]
        lead_v = lead[..., 1]
        lead_p = lead[..., 0] + interval_s * lead_v + leader_pos_gain * lead_accel
        lead_v = maximum(lead_v + interval_s * lead_accel, zero)
        s = np.empty((rows, n, 4), np.float32)
        s[:, fi, :3] = z
        s[:, fi, 1] = maximum(z[..., 1], zero)
        s[:, fi, 3] = u_new
        s[:, li, 0], s[:, li, 1] = lead_p, lead_v
        s[:, li, 2:] = lead_accel[..., None]  # the leader's acceleration and command
        # control_reward, the collision and the discounted sum, as in _rollout
        ahead, behind, gap, gap_error, speed_error = errors(s)
        jerk = step / interval_s
        reward = -(
            absolute(gap_error) / c.gap_scale
            + c.weight_speed * absolute(speed_error) / c.speed_scale
            + c.weight_accel * absolute(u_new) / c.accel_max
            + c.weight_jerk * absolute(jerk) / c.jerk_max
        )
        collided = gap <= zero
        reward = reward + collided.astype(np.float32) * c.collision_penalty
        if stop_at_episode_end:
            inside = (interval + h < twin.params.episode_intervals).astype(np.float32)[:, None]
            reward = reward * inside
        returns = returns + np.float32(weight) * (reward * alive[:, None])
        alive = alive * (~np.logical_or.reduce(collided, axis=-1)).astype(np.float32)
        weight *= discount
    final = PlatoonState(*(np.ascontiguousarray(s[..., k]) for k in range(4)))
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
