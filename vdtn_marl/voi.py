"""Value of Information estimators (docs/model.md §5).

IVoI ξ_k of follower i is the advantage, under the perfect-observation reference policy π*, of
what the acting system actually did in interval k (command u_k from the impaired observation,
taking force at its switch subframe) at the perfect state S_k:

    ξ_k = Q*(S_k, ũ_k) − V*(S_k)  ≤ 0 in expectation when π* is optimal.

An estimator is any callable ``estimator(twin, record) -> Tensor[B, F]`` called once per control
interval, right after the twin integrated it (``record`` is the
:class:`~vdtn_marl.sim.twin.IntervalRecord`). The environments add κ2·ξ_i to the reward of
``rra_i`` at the last subframe of the interval.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import torch

from vdtn_marl.sim.cacc import CACCController
from vdtn_marl.sim.platoon import (
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


class RolloutIVoIEstimator:
    """Counterfactual Monte-Carlo rollouts in the twin (the reference estimator).

    From the perfect state S_k, F + 1 branches are rolled out for ``horizon_intervals``
    intervals over the known leader trace: branch 0 lets every follower follow the reference
    policy on perfect observations; branch i replaces follower i's first command by what the
    acting system did (its u_k and switch subframe). ξ_i is the difference of follower i's
    discounted control return between branch i and branch 0. Platoon dynamics are
    deterministic given the trace, so one rollout per branch is exact for that reference and
    horizon; with ``terminal_value`` (a callable on perfect observations [.., F, 8] → [.., F])
    the tail beyond the horizon is bootstrapped.
    """

    def __init__(
        self,
        reference_policy: Policy | None = None,
        horizon_intervals: int = 10,
        discount: float = 0.99,
        terminal_value: Policy | None = None,
    ):
        if horizon_intervals < 1:
            raise ValueError(f"horizon_intervals={horizon_intervals!r} must be >= 1")
        if not 0.0 <= discount <= 1.0:
            raise ValueError(f"discount={discount!r} is outside [0, 1]")
        self.reference_policy = reference_policy
        self.horizon_intervals = horizon_intervals
        self.discount = discount
        self.terminal_value = terminal_value

    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        pp = twin.params.platoon
        policy = self.reference_policy or CACCController(pp)
        integrator: IntervalIntegrator = twin.integrator
        b, f = record.command_mps2.shape
        branches = f + 1
        dev = record.command_mps2.device

        state: PlatoonState = record.state_before.repeat(branches)
        reference_u = policy(perfect_observation(record.state_before, pp))  # [B, F]
        # deviates[j, :, i] is True when branch j replays follower i's actual interval
        branch = torch.arange(branches, device=dev)[:, None, None]
        follower = torch.arange(f, device=dev)[None, None, :]
        deviates = (branch == follower + 1).expand(branches, b, f)
        u = torch.where(deviates, record.command_mps2, reference_u).reshape(branches * b, f)
        switch = torch.where(
            deviates, record.switch_subframe, torch.zeros_like(record.switch_subframe)
        ).reshape(branches * b, f)

        steps = torch.arange(self.horizon_intervals, device=dev)
        leader = twin.leader_accel_mps2(record.interval[:, None] + steps).repeat(branches, 1)
        returns = torch.zeros(branches * b, f, device=dev)
        weight = 1.0
        zero_switch = torch.zeros_like(switch)
        for h in range(self.horizon_intervals):
            if h > 0:
                u = policy(perfect_observation(state, pp))
                switch = zero_switch
            after = integrator.integrate(state, leader[:, h], u, switch)
            gap_error, speed_error = spacing_errors(after, pp)
            reward = control_reward(
                gap_error, speed_error, after.command_mps2[:, 1:], state.command_mps2[:, 1:], pp
            )
            reward = reward + (gaps_m(after.position_m, pp) <= 0).float() * pp.collision_penalty
            returns = returns + weight * reward
            weight *= self.discount
            state = after
        if self.terminal_value is not None:
            returns = returns + weight * self.terminal_value(perfect_observation(state, pp))
        returns = returns.view(branches, b, f)
        actual = returns[1:].diagonal(dim1=0, dim2=2)  # [B, F]: branch i+1, follower i
        return actual - returns[0]


class ZeroIVoIEstimator:
    """ξ = 0: for rewards that do not use VoI (κ2 = 0, ``drra``, ``throughput``)."""

    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        return torch.zeros_like(record.reward)


def make_ivoi_estimator(spec: str | IVoIEstimator | None, **kwargs) -> IVoIEstimator:
    """``"rollout"``, ``"none"`` or an estimator object (passed through)."""
    if spec is None or spec == "none":
        return ZeroIVoIEstimator()
    if spec == "rollout":
        return RolloutIVoIEstimator(**kwargs)
    if isinstance(spec, str):
        raise ValueError(f"ivoi_estimator={spec!r} is not one of 'rollout', 'none' (or an object)")
    if not callable(spec):
        raise TypeError(f"ivoi_estimator={spec!r} must be callable as estimator(twin, record)")
    return spec
