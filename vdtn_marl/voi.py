"""Value of Information estimators (docs/model.md §5).

IVoI ξ_k of follower i is the advantage, under the perfect-observation reference policy π*, of
what the acting system actually did in interval k (command u_k from the impaired observation,
taking force at its switch subframe) at the perfect state S_k:

    ξ_k = Q*(S_k, ũ_k) − V*(S_k)  ≤ 0 in expectation when π* is optimal.

An estimator is any callable ``estimator(twin, record) -> Tensor[B, F]`` called once per control
interval, right after the twin integrated it (``record`` is the
:class:`~vdtn_marl.sim.twin.IntervalRecord`). The environments add κ2·ξ_i to the reward of
``rra_i`` at the last subframe of the interval.

The named estimators are :data:`IVOI_ESTIMATORS` (``rra.ivoi_estimator=<name>``), each built
from the :class:`VoIReference` it measures against (π*'s policy, its value v*, the discount)
by its ``from_reference``. A new estimator is its class with ``from_reference``, one line in
the registry, and nothing else: the config's choices, the environments and the JOCC loop read
the registry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import torch

from vdtn_marl.errors import ConfigError
from vdtn_marl.sim.backend import as_float, repeat_rows, to_numpy, to_torch, xp
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
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord

Policy = Callable[
    [torch.Tensor], torch.Tensor
]  # vehicle observations [..., F, 8] → commands [..., F]


class IVoIEstimator(Protocol):
    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        """IVoI ξ of every follower for the interval in ``record``, [B, F]."""
        ...


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


#: what ξ compares the acting system's command with (:class:`RolloutIVoIEstimator`)
IVOI_BASELINES = ("optimal", "cam_lost")


@dataclass(frozen=True)
class VoIReference:
    """What an IVoI estimator measures against: the reference policy π* (perfect observations
    [.., F, 8] → commands [.., F]; ``None``: the linear CACC), its value v* (observations →
    [.., F], or an object with ``state_value``; ``None``: none available) and the discount γ
    per control interval."""

    policy: Policy | None = None
    value: Any = None
    discount: float = 0.99


class RolloutIVoIEstimator:
    """Counterfactual Monte-Carlo rollouts in the twin (the reference estimator).

    From the perfect state S_k, branches are rolled out for ``horizon_intervals`` intervals over
    the known leader trace. In a branch that tests follower i's command, follower i plays that
    command (with its switch subframe) in the first interval while every other follower
    follows the reference policy on perfect observations; afterwards everyone does. A
    collision ends a branch's episode (its penalty counts once, as in the environment). With
    ``terminal_value`` (a callable on perfect observations [.., F, 8] → [.., F]) the tail
    beyond the horizon is bootstrapped. Platoon dynamics are deterministic given the trace, so
    one rollout per branch is exact for that reference and horizon.

    ``baseline`` says what follower i's actual command is compared with:

    - ``"optimal"`` (the paper's IVoI, docs/model.md §5): the reference policy's own command;
      ξ_i = Q*(S_k, ũ_k) − V*(S_k), F + 1 branches;
    - ``"cam_lost"`` (a difference reward): the command follower i would have taken had its
      CAM of interval k been lost (``record.command_if_lost_mps2``, taking force at the next
      interval); ξ_i = Q*(S_k, ũ_k) − Q*(S_k, ũ_k^lost) = IVoI(delivered) − IVoI(had it been
      lost), the value of this interval's delivery, with the same leader trace on both sides
      (common random numbers), and exactly 0 where the CAM was not in time. 2F branches.
    """

    def __init__(
        self,
        reference_policy: Policy | None = None,
        horizon_intervals: int = 10,
        discount: float = 0.99,
        terminal_value: Policy | None = None,
        baseline: str = "optimal",
    ):
        _check_rollout(horizon_intervals, discount)
        if baseline not in IVOI_BASELINES:
            raise ValueError(f"baseline={baseline!r} is not one of {', '.join(IVOI_BASELINES)}")
        self.reference_policy = reference_policy
        self.horizon_intervals = horizon_intervals
        self.discount = discount
        self.terminal_value = terminal_value
        self.baseline = baseline

    @classmethod
    def from_reference(
        cls,
        reference: VoIReference,
        *,
        horizon_intervals: int = 10,
        bootstrap: bool = True,
        baseline: str = "optimal",
    ) -> RolloutIVoIEstimator:
        """Rollouts of ``reference.policy`` for ``horizon_intervals``; with ``bootstrap`` (and
        a ``reference.value``) v* values the state each branch ends in."""
        terminal = reference.value if bootstrap else None
        return cls(reference.policy, horizon_intervals, reference.discount, terminal, baseline)

    @property
    def needs_command_if_lost(self) -> bool:
        """True when the environment must record ``command_if_lost_mps2``."""
        return self.baseline == "cam_lost"

    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        policy = self.reference_policy or CACCController(twin.params.platoon)
        inputs = [record.command_mps2, record.switch_subframe]
        if self.needs_command_if_lost:
            if record.command_if_lost_mps2 is None:
                raise ValueError(
                    "the cam_lost IVoI baseline needs record.command_if_lost_mps2, the command "
                    "each follower would have taken had its CAM been lost; pass "
                    "command_if_lost_mps2= to DigitalTwin.finish_interval"
                )
            inputs.append(record.command_if_lost_mps2)
        if not _numpy_path(twin, policy):
            return self._estimate(twin, policy, record.state_before, record.interval, *inputs)
        xi = self._estimate(
            twin,
            policy,
            record.state_before.numpy(),
            to_numpy(record.interval),
            *(to_numpy(x) for x in inputs),
        )
        return to_torch(xi)

    def _estimate(
        self, twin, policy, state_before, interval, command, switch, command_if_lost=None
    ):
        """ξ [B, F] on torch tensors or NumPy arrays (all inputs alike)."""
        lib = xp(command)
        if command_if_lost is None:
            reference, (actual,) = self._branch_returns(
                twin, policy, state_before, interval, [(command, switch)], reference=True
            )
            return actual - reference
        t = twin.subframes_per_interval
        _, (actual, lost) = self._branch_returns(
            twin, policy, state_before, interval,
            [(command, switch), (command_if_lost, lib.full_like(switch, t))], reference=False,
        )  # fmt: skip
        in_time = switch < t  # otherwise both branches are the same interval
        return lib.where(in_time, actual - lost, lib.zeros_like(actual))

    def _branch_returns(self, twin, policy, state_before, interval, alternatives, reference):
        """Follower i's discounted return when it plays each alternative (command [B, F],
        switch [B, F]) in the first interval and the others play the reference policy: one
        [B, F] per alternative; with ``reference``, first the return when everyone plays it
        (else None). One batched rollout of 1 + F·A (or F·A) branches."""
        pp = twin.params.platoon
        b, f = alternatives[0][0].shape
        lib = xp(alternatives[0][0])
        offset = 1 if reference else 0
        branches = offset + f * len(alternatives)

        state: PlatoonState = state_before.repeat(branches)
        if _is_linear_cacc(policy):  # same numbers, fewer operations
            reference_u = policy.perfect_command(state_before, pp)  # [B, F]
        else:
            reference_u = policy(perfect_observation(state_before, pp))
        # deviates[j, :, i]: branch j tests follower i (alternative (j - offset) // F)
        if lib is np:
            branch, follower = np.arange(branches), np.arange(f)
        else:
            device = reference_u.device
            branch = torch.arange(branches, device=device)
            follower = torch.arange(f, device=device)
        tested = (branch - offset) % f
        deviates = (branch[:, None] >= offset) & (tested[:, None] == follower[None, :])
        deviates = deviates[:, None, :]  # [branches, 1, F]
        if lib is np:
            u = np.repeat(reference_u[None], branches, axis=0)
            switch = np.zeros((branches, b, f), np.int64)
        else:
            u = reference_u[None].expand(branches, b, f)
            switch = torch.zeros(branches, b, f, dtype=torch.long, device=reference_u.device)
        for a, (command, first_switch) in enumerate(alternatives):
            block = deviates & ((branch - offset) // f == a)[:, None, None]
            u = lib.where(block, command[None], u)
            switch = lib.where(block, first_switch[None], switch)
        u = u.reshape(branches * b, f)
        switch = switch.reshape(branches * b, f)

        rollout = _cacc_rollout_numpy if lib is np else _rollout
        returns, state, alive = rollout(
            twin, state, repeat_rows(interval, branches), policy,
            self.horizon_intervals, self.discount, u, switch, False,
        )  # fmt: skip
        if self.terminal_value is not None:  # nothing after a collision ended the episode
            weight = self.discount**self.horizon_intervals * alive[:, None]
            observation = perfect_observation(state, pp)
            if lib is np:
                value = to_numpy(self.terminal_value(to_torch(observation)))
            else:
                value = self.terminal_value(observation)
            returns = returns + weight * value
        returns = returns.reshape(branches, b, f)
        per_alternative = [  # [B, F]: branch offset + a·F + i, follower i
            returns[offset + a * f : offset + (a + 1) * f].diagonal(0, 0, 2)
            for a in range(len(alternatives))
        ]
        return (returns[0] if reference else None), per_alternative


class TDIVoIEstimator:
    """One-step TD error of the perfect-observation value function (docs/model.md §5):

        ξ_k = R_k + γ·(1 − terminal)·v*(S_{k+1}) − v*(S_k),

    with S_k, S_{k+1} the perfect states before and after the interval, R_k the control reward
    the acting system obtained, and ``value`` π*'s critic: a callable on perfect vehicle
    observations [.., F, 8] → [.., F], or an object with ``state_value(twin, state, interval)``
    such as :class:`RolloutValue`. Given (S_k, ũ_k) its expectation is the
    advantage A*(S_k, ũ_k). It costs two critic calls per interval, against
    ``horizon × (F + 1)`` integrations for :class:`RolloutIVoIEstimator`.
    """

    def __init__(self, value: Policy, discount: float = 0.99):
        if not (callable(value) or hasattr(value, "state_value")):
            raise TypeError(
                f"value={value!r} must be callable (observations [B, F, 8] -> [B, F]) "
                "or have state_value(twin, state, interval)"
            )
        if not 0.0 <= discount <= 1.0:
            raise ValueError(f"discount={discount!r} is outside [0, 1]")
        self.value = value
        self.discount = discount

    @classmethod
    def from_reference(
        cls, reference: VoIReference, *, baseline: str = "optimal", **_: Any
    ) -> TDIVoIEstimator:
        """The TD error of ``reference.value`` (required); the rollout options do not apply,
        and ξ can only compare with π* (``baseline="optimal"``)."""
        if reference.value is None:
            raise ValueError("ivoi_estimator='td' needs value=<critic of the optimal policy>")
        if baseline != "optimal":
            raise ConfigError(
                f"baseline={baseline!r} needs the rollout estimator (td compares with π*)"
            )
        return cls(reference.value, reference.discount)

    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        pp = twin.params.platoon
        if hasattr(self.value, "state_value"):  # e.g. RolloutValue: needs the twin's trace
            value_before = self.value.state_value(twin, record.state_before, record.interval)
            value_after = self.value.state_value(twin, record.state_after, record.interval + 1)
        else:
            before = perfect_observation(record.state_before, pp)
            after = perfect_observation(record.state_after, pp)
            value_before, value_after = self.value(torch.stack([before, after]))  # one call
        terminal = record.collided.any(-1, keepdim=True).float()
        return record.reward + self.discount * (1.0 - terminal) * value_after - value_before


class ZeroIVoIEstimator:
    """ξ = 0: for rewards that do not use VoI (κ2 = 0, ``drra``, ``throughput``)."""

    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        return torch.zeros_like(record.reward)


def close_interval(
    twin: DigitalTwin,
    estimator: IVoIEstimator | None,
    decide: Callable[[bool], torch.Tensor] | None,
    perfect: bool = False,
    commands: torch.Tensor | None = None,
) -> IntervalRecord:
    """Finish the twin's interval for ``estimator``: the followers' commands are ``commands``
    or ``decide(False)`` (the acting policy on the observation of the actual CAMs); when the
    estimator compares with a lost CAM (``needs_command_if_lost``), ``decide(True)`` (the same
    policy on the observation had the CAMs been lost) is recorded too, and called first, so
    that a stateful completer ends on the actual CAMs."""
    command_if_lost = None
    if not perfect and getattr(estimator, "needs_command_if_lost", False):
        if decide is None:
            raise ValueError(
                "this IVoI estimator needs the command each follower would have taken had its "
                "CAM been lost, which only a control module can give: the followers' commands "
                "here come from the vehicle agents"
            )
        command_if_lost = decide(True)
    if commands is None:
        commands = decide(False)
    return twin.finish_interval(commands, perfect, command_if_lost_mps2=command_if_lost)


#: The named IVoI estimators, name → class with ``from_reference(reference, **options)``.
IVOI_ESTIMATORS: dict[str, type] = {
    "td": TDIVoIEstimator,
    "rollout": RolloutIVoIEstimator,
}


def make_ivoi_estimator(
    spec: str | IVoIEstimator | None, reference: VoIReference | None = None, **options
) -> IVoIEstimator:
    """A name of :data:`IVOI_ESTIMATORS` built on ``reference`` with ``options``, ``"none"``
    (ξ = 0) or an estimator object. Without ``reference`` one is made of the options
    ``reference_policy``, ``value``, ``terminal_value`` and ``discount`` (the constructors'
    keywords), so ``make_ivoi_estimator("td", value=critic)`` and
    ``make_ivoi_estimator("rollout", horizon_intervals=5)`` work as before."""
    if spec is None or spec == "none":
        return ZeroIVoIEstimator()
    if isinstance(spec, str):
        if spec not in IVOI_ESTIMATORS:
            raise ValueError(
                f"ivoi_estimator={spec!r} is not one of "
                f"{', '.join(repr(k) for k in (*IVOI_ESTIMATORS, 'none'))} (or an object)"
            )
        if reference is None:
            value = options.pop("value", None)
            terminal = options.pop("terminal_value", None)
            reference = VoIReference(
                policy=options.pop("reference_policy", None),
                value=value if value is not None else terminal,
                discount=options.pop("discount", 0.99),
            )
            if spec == "rollout":  # the constructor's default: no bootstrap without a value
                options.setdefault("bootstrap", terminal is not None)
        return IVOI_ESTIMATORS[spec].from_reference(reference, **options)
    if not callable(spec):
        raise TypeError(f"ivoi_estimator={spec!r} must be callable as estimator(twin, record)")
    return spec


def mean_ci(samples: torch.Tensor, confidence: float = 0.95) -> tuple[float, float, float]:
    """Mean and Student-t confidence interval (low, high) of i.i.d. per-scenario samples."""
    from scipy import stats

    x = torch.as_tensor(samples, dtype=torch.float64).reshape(-1)
    n = x.numel()
    if n == 0:
        raise ValueError("mean_ci needs at least one sample")
    mean = float(x.mean())
    if n == 1:
        return mean, float("nan"), float("nan")
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * float(x.std(unbiased=True)) / n**0.5
    return mean, mean - half, mean + half


def expected_voi(
    impaired_returns: torch.Tensor, perfect_returns: torch.Tensor, confidence: float = 0.95
) -> tuple[float, float, float]:
    """EVoI = J̃ − J* with its CI, from per-scenario returns of the acting policy on impaired
    observations and of the optimal policy on perfect ones, paired by scenario (same seeds and
    leader traces)."""
    impaired = torch.as_tensor(impaired_returns, dtype=torch.float64).reshape(-1)
    perfect = torch.as_tensor(perfect_returns, dtype=torch.float64).reshape(-1)
    if impaired.shape != perfect.shape:
        raise ValueError(
            f"EVoI pairs scenarios: got {impaired.numel()} impaired and {perfect.numel()} perfect"
        )
    return mean_ci(impaired - perfect, confidence)
