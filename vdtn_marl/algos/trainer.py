"""The trainer protocol and the registry of training algorithms.

A trainer learns one group's policy (``"vehicle"``: π* or π̃; ``"rra"``: the RRA agents) on a
batched TorchRL face of the twin, collect-and-update iteration by iteration. The JOCC loop
(:mod:`vdtn_marl.experiment.jocc`) drives every trainer through :class:`Trainer` only: it
begins a stage with a budget, calls :meth:`~Trainer.train_iteration` until it is spent,
finishes the stage, and saves and restores the trainer's state in checkpoints.

A new algorithm is its trainer class (in a file of its own, with the members of
:class:`Trainer` and the constructor of :class:`~vdtn_marl.algos.ppo.PPOTrainer`), one line in
:data:`ALGORITHMS`, and ``conf/algo/<name>.yaml``; config validation, the JOCC loop and the
tests read the registry. The constructor's ``env_factory`` (for ``algo.collector_workers``,
:mod:`~vdtn_marl.algos.shards`) may be ignored, and a ``close()`` that stops worker
processes is optional (the JOCC loop calls it at the end of a run where it exists). Entries
are ``"module:Class"`` strings, imported when first used, so reading the registry (the CLI's
config checks) does not import TorchRL.
"""

from __future__ import annotations

import importlib
from typing import Any, Protocol, runtime_checkable

from vdtn_marl.errors import ConfigError


@runtime_checkable
class Trainer(Protocol):
    """What the JOCC loop uses of a trainer."""

    group: str  # the TorchRL group it trains ("vehicle" or "rra")
    seed: int
    iteration: int  # PPO (or other) iterations done, over every stage
    scaling_fitted: bool  # observation scaling fitted (before the first iteration)
    actor: Any  # the policy module (TensorDict in → action out)
    critic: Any  # the value module

    def seed_for(self, iteration: int) -> int:
        """The seed of the scenarios an iteration collects."""

    def fit_observation_scaling(self) -> None:
        """Fit the observation scaling of actor and critic on collected observations."""

    def begin_stage(self, iterations: int) -> None:
        """Start a training stage of ``iterations`` iterations."""

    def train_iteration(self) -> Any:
        """Collect one batch and update on it; an :class:`~vdtn_marl.algos.ppo.IterationStats`."""

    def plateaued(self, patience: int) -> bool:
        """Whether the stage's last ``patience`` validations did not beat its best (the loop
        then ends the stage early: ``control.pi_star_patience``)."""

    def finish_stage(self) -> dict:
        """End the stage (e.g. restore its best validated iterate); what it did, as a dict."""

    def state_dict(self) -> dict:
        """Everything needed to continue bit for bit (weights, optimiser, iteration, ...)."""

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict`."""


#: Training algorithms, ``algo.name`` → ``"module:Class"`` of the trainer. MAPPO and IPPO are
#: one trainer: ``AlgoConfig.centralised_critic`` (MAPPO) gives the critic the whole group's
#: observations, IPPO's critics see their own agent's.
ALGORITHMS: dict[str, str] = {
    "mappo": "vdtn_marl.algos.ppo:PPOTrainer",
    "ippo": "vdtn_marl.algos.ppo:PPOTrainer",
}


def trainer_class(name: str) -> type:
    """The trainer class of the algorithm ``name`` (imported on first use)."""
    if name not in ALGORITHMS:
        raise ConfigError(f"algo.name={name!r} is not one of {', '.join(ALGORITHMS)}")
    module, _, attribute = ALGORITHMS[name].partition(":")
    return getattr(importlib.import_module(module), attribute)
