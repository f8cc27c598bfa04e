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
    interval count zero (finite-horizon value). Returns (returns, final state)."""
    pp = twin.params.platoon
    integrator: IntervalIntegrator = twin.integrator
    rows = interval.shape[0]
    repeats = rows // twin.batch_size
    steps = torch.arange(horizon_intervals, device=interval.device)
    leader = twin.leader_accel_mps2(interval[: twin.batch_size, None] + steps).repeat(
        repeats, 1
    )  # [R, H]
    returns = torch.zeros(rows, twin.num_followers, device=interval.device)
    zero_switch = torch.zeros(rows, twin.num_followers, dtype=torch.long, device=interval.device)
    weight = 1.0
    for h in range(horizon_intervals):
        if h == 0 and first_command is not None:
            u = first_command
            switch = zero_switch if first_switch is None else first_switch
        else:
            u = policy(perfect_observation(state, pp))
            switch = zero_switch
        after = integrator.integrate(state, leader[:, h], u, switch)
        gap_error, speed_error = spacing_errors(after, pp)
        reward = control_reward(
            gap_error, speed_error, after.command_mps2[:, 1:], state.command_mps2[:, 1:], pp
        )
        reward = reward + (gaps_m(after.position_m, pp) <= 0).float() * pp.collision_penalty
        if stop_at_episode_end:
            inside = (interval + h < twin.params.episode_intervals).float()[:, None]
            reward = reward * inside
        returns = returns + weight * reward
        weight *= discount
        state = after
    return returns, state


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
        if horizon_intervals < 1:
            raise ValueError(f"horizon_intervals={horizon_intervals!r} must be >= 1")
        if not 0.0 <= discount <= 1.0:
            raise ValueError(f"discount={discount!r} is outside [0, 1]")
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

        interval = record.interval.repeat(branches)
        returns, state = discounted_rollout(
            twin, state, interval, policy, self.horizon_intervals, self.discount, u, switch
        )
        if self.terminal_value is not None:
            weight = self.discount**self.horizon_intervals
            returns = returns + weight * self.terminal_value(perfect_observation(state, pp))
        returns = returns.view(branches, b, f)
        actual = returns[1:].diagonal(dim1=0, dim2=2)  # [B, F]: branch i+1, follower i
        return actual - returns[0]


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


def make_ivoi_estimator(spec: str | IVoIEstimator | None, **kwargs) -> IVoIEstimator:
    """``"rollout"``, ``"td"`` (needs ``value=``), ``"none"`` or an estimator object."""
    if spec is None or spec == "none":
        return ZeroIVoIEstimator()
    if spec == "rollout":
        return RolloutIVoIEstimator(**kwargs)
    if spec == "td":
        if "value" not in kwargs:
            raise ValueError("ivoi_estimator='td' needs value=<critic of the optimal policy>")
        return TDIVoIEstimator(**kwargs)
    if isinstance(spec, str):
        raise ValueError(
            f"ivoi_estimator={spec!r} is not one of 'rollout', 'td', 'none' (or an object)"
        )
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
