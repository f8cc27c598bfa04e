"""The IVoI estimators (docs/model.md §5), named in the registry
:data:`~vdtn_marl.voi.registry.IVOI_ESTIMATORS`: the one-step TD error of v*
(:class:`TDIVoIEstimator`), counterfactual rollouts (:class:`RolloutIVoIEstimator`) and ξ = 0
(:class:`ZeroIVoIEstimator`). :func:`close_interval`, which finishes a twin interval with what an
estimator needs, lives in :mod:`vdtn_marl.core.interval` and is re-exported here."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import torch

from vdtn_marl.core.interval import close_interval  # noqa: F401 - re-exported; lives in core
from vdtn_marl.errors import ConfigError
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.backend import repeat_rows, to_numpy, to_torch, xp
from vdtn_marl.sim.platoon import (
    PlatoonState,
    perfect_observation,
)
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord
from vdtn_marl.voi.registry import IVOI_BASELINES, ivoi_estimator_class
from vdtn_marl.voi.rollout import (
    Policy,
    _check_rollout,
    _is_linear_cacc,
    _numpy_path,
    _rollout,
)


class IVoIEstimator(Protocol):
    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        """IVoI ξ of every follower for the interval in ``record``, [B, F]."""
        ...


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

        returns, state, alive = _rollout(
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
        cls,
        reference: VoIReference,
        *,
        baseline: str = "optimal",
        horizon_intervals: int | None = None,
        bootstrap: bool | None = None,
    ) -> TDIVoIEstimator:
        """The TD error of ``reference.value`` (required). The rollout options
        (``horizon_intervals``, ``bootstrap``) are accepted, so one set of options builds any
        registered estimator, and do not apply; ξ can only compare with π*
        (``baseline="optimal"``). Any other option is a ``TypeError``."""
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


def make_ivoi_estimator(
    spec: str | IVoIEstimator | None, reference: VoIReference | None = None, **options
) -> IVoIEstimator:
    """A name of :data:`~vdtn_marl.voi.registry.IVOI_ESTIMATORS` built on ``reference`` with
    ``options``, ``"none"`` (ξ = 0) or an estimator object. Without ``reference`` one is made
    of the options ``reference_policy``, ``value``, ``terminal_value`` and ``discount`` (the
    constructors' keywords), so ``make_ivoi_estimator("td", value=critic)`` and
    ``make_ivoi_estimator("rollout", horizon_intervals=5)`` work as before."""
    if spec is None or spec == "none":
        return ZeroIVoIEstimator()
    if isinstance(spec, str):
        estimator_class = ivoi_estimator_class(spec)
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
        return estimator_class.from_reference(reference, **options)
    if not callable(spec):
        raise TypeError(f"ivoi_estimator={spec!r} must be callable as estimator(twin, record)")
    return spec
