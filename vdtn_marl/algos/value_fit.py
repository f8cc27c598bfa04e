"""v* fitted where the acting system goes (``rra.value_fit=acting``).

The ``td`` IVoI estimator values states with π*'s critic (docs/model.md §5). That critic is
trained on the states π* itself visits, with perfect observations; the states the acting
system (π̃ on impaired observations, under the current RRA policy) visits lie elsewhere, where
nothing trains the critic. This module fits a copy of the critic on those states:

1. **States.** The acting system runs ``episodes`` scenarios of the training traces for
   ``intervals`` intervals (:func:`~vdtn_marl.algos.evaluate.evaluate_system`), once under the
   current RRA policy and once under the greedy RRA (so that the states a better RRA policy
   leads to are covered too). Every interval's state before the commands is kept, up to a
   collision.
2. **Targets.** From each state, π* drives the twin on perfect observations for ``horizon``
   intervals along the scenario's own leader trace (the twin knows it), and π*'s critic values
   the state reached, where π* has brought the platoon back to its own distribution:
   ``Σ_{j<H} γ^j r_j + γ^H·v*(S_H)`` (0 after a collision).
3. **Fit.** The copy starts from π*'s critic and is fitted by mean squared error (Adam).

The fitted copy replaces π*'s critic in the ``td`` estimator only; π* and its own critic are
not changed.
"""

from __future__ import annotations

import copy
import time
from dataclasses import asdict, dataclass
from typing import Any

import torch

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.ppo import CriticValue
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.platoon import perfect_observation
from vdtn_marl.voi import bootstrapped_return


@dataclass
class ValueFitStats:
    samples: int  # (state, follower) pairs fitted
    target_mean: float
    target_std: float
    mse_before: float  # of π*'s critic on the targets
    mse_after: float  # of the fitted copy (on the same samples)
    held_out_mse_before: float  # on a held-out 20 % of the scenarios
    held_out_mse_after: float
    seconds: float

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class _TargetRecorder:
    """An IVoI estimator in form only: it records each interval's perfect observation and its
    target value (module doc, step 2) and returns ξ = 0."""

    needs_command_if_lost = False

    def __init__(self, reference_policy, critic_value, horizon: int, discount: float) -> None:
        self.reference_policy = reference_policy
        self.critic_value = critic_value
        self.horizon = horizon
        self.discount = discount
        self.observations: list[torch.Tensor] = []
        self.targets: list[torch.Tensor] = []
        self.scenario: list[torch.Tensor] = []
        self._alive: torch.Tensor | None = None

    def __call__(self, twin, record) -> torch.Tensor:
        b = record.reward.shape[0]
        if self._alive is None or self._alive.shape[0] != b:
            self._alive = torch.ones(b, dtype=torch.bool, device=record.reward.device)
        keep = self._alive.clone()
        target = bootstrapped_return(
            twin, record.state_before, record.interval, self.reference_policy,
            self.horizon, self.discount, self.critic_value,
        )  # fmt: skip
        observation = perfect_observation(record.state_before, twin.params.platoon)
        self.observations.append(observation[keep].float())
        self.targets.append(target[keep].float())
        self.scenario.append(torch.arange(b, device=keep.device)[keep])
        self._alive &= ~record.collided.any(-1)
        return torch.zeros_like(record.reward)


def acting_value_samples(
    params: TwinParams,
    control,
    rra_policies: list,
    reference_policy,
    critic_value,
    *,
    episodes: int,
    intervals: int,
    seed: int,
    horizon: int,
    discount: float,
    trace_source,
    device: str | torch.device = "cpu",
    completion=None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(observations [N, F, 8], targets [N, F], scenario ids [N]) of the states the acting
    system visits under each of ``rra_policies`` (module doc, steps 1 and 2); scenario ids are
    distinct across policies."""
    observations, targets, scenarios = [], [], []
    for k, rra in enumerate(rra_policies):
        recorder = _TargetRecorder(reference_policy, critic_value, horizon, discount)
        evaluate_system(
            params, control, rra, perfect=False, episodes=episodes, intervals=intervals,
            seed=seed + k, gamma=discount, device=device, trace_source=trace_source,
            ivoi_estimator=recorder, completion=completion,
        )  # fmt: skip
        observations.append(torch.cat(recorder.observations))
        targets.append(torch.cat(recorder.targets))
        scenarios.append(torch.cat(recorder.scenario) + k * episodes)
    return torch.cat(observations), torch.cat(targets), torch.cat(scenarios)


def fit_critic(
    critic,
    group: str,
    observations: torch.Tensor,
    targets: torch.Tensor,
    scenarios: torch.Tensor,
    *,
    epochs: int = 30,
    lr: float = 1e-3,
    minibatch: int = 256,
    seed: int = 0,
) -> tuple[float, float, float, float]:
    """Fit ``critic`` (a TensorDict module: ``(group, "observation")`` → ``(group,
    "state_value")``) to ``targets`` by MSE, in place, on 80 % of the scenarios; returns the
    MSE before and after on those and on the held-out 20 %."""
    value = CriticValue(critic, group).with_grad
    generator = torch.Generator().manual_seed(seed)
    ids = torch.unique(scenarios)
    held = ids[torch.randperm(len(ids), generator=generator)[: max(1, len(ids) // 5)]]
    test = torch.isin(scenarios, held)
    train = ~test if (~test).any() else test

    def mse(mask: torch.Tensor) -> float:
        with torch.no_grad():
            return float(((value(observations[mask]) - targets[mask]) ** 2).mean())

    before, held_before = mse(train), mse(test)
    x, y = observations[train], targets[train]
    optimiser = torch.optim.Adam(critic.parameters(), lr=lr)
    for _ in range(epochs):
        order = torch.randperm(len(x), generator=generator)
        for start in range(0, len(x), minibatch):
            batch = order[start : start + minibatch]
            loss = ((value(x[batch]) - y[batch]) ** 2).mean()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    return before, mse(train), held_before, mse(test)


def fit_value_on_acting_states(
    target_critic,
    reference_critic,
    group: str,
    params: TwinParams,
    control,
    rra_policies: list,
    reference_policy,
    *,
    epochs: int = 30,
    **sampling: Any,
) -> ValueFitStats:
    """The whole procedure of the module doc: ``target_critic`` takes ``reference_critic``'s
    weights, then is fitted on the acting system's states (``sampling``: the keywords of
    :func:`acting_value_samples`; ``reference_critic`` values the targets' tails); returns
    what was measured."""
    began = time.perf_counter()
    target_critic.load_state_dict(copy.deepcopy(reference_critic.state_dict()))
    observations, targets, scenarios = acting_value_samples(
        params, control, rra_policies, reference_policy, CriticValue(reference_critic, group),
        **sampling,
    )  # fmt: skip
    seed = sampling["seed"]
    before, after, held_before, held_after = fit_critic(
        target_critic, group, observations, targets, scenarios, epochs=epochs, seed=seed
    )
    return ValueFitStats(
        samples=int(targets.numel()),
        target_mean=float(targets.mean()),
        target_std=float(targets.std()),
        mse_before=before,
        mse_after=after,
        held_out_mse_before=held_before,
        held_out_mse_after=held_after,
        seconds=time.perf_counter() - began,
    )
