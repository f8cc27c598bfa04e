"""Joint optimisation of communication and control (JOCC), and its single-stage variants.

One JOCC iteration runs four stages:

1. ``control_perfect``: train π* (MAPPO, group ``vehicle``) on perfect observations (with
   ``control.warm_start=causal_mpc``, π* first imitates the causal MPC, once, before its first
   stage: :mod:`vdtn_marl.algos.imitation`);
2. ``control_impaired``: train π̃ on impaired observations (CAM delay/age and the previous
   command in its state) under the current RRA policy: uniformly random in iteration 0, the
   learned RRA policy afterwards (or the configured RRA baseline);
3. ``rra``: hand the VoI estimator (``td`` with π*'s critic as v*, or ``rollout``) to the RRA
   environment, whose control module is π̃, and train the RRA agents (MAPPO, group ``rra``)
   with the configured reward (``jocc``: κ1·g + κ2·ξ; ``drra``; ``aoi``; ``throughput``);
4. ``evaluate``: π̃ with the RRA policy on impaired observations and π* on perfect ones, over
   the same held-out scenarios: control cost, gap/speed errors, CAM delivery and latency, Age
   of Information, V2I throughput per link, EVoI with its 95% CI (and the IVoI sum for
   comparison).

``vdtn-marl train`` runs a subset of the stages (see :data:`TASK_STAGES`). Baselines slot in
by configuration: ``control=cacc|oracle`` replaces π̃, ``rra=random|round_robin|greedy``
replaces the learned RRA policy (their training stages are skipped); so does a policy of the
user's own (``control=policy control.policy=...``, ``rra=policy rra.policy=...``:
:mod:`.user_policy`).

This module holds the stages and their order. Checkpoints (``checkpoints/last.pt``, written
every ``experiment.checkpoint_every`` PPO iterations and at the end of every stage; ``resume=true``
continues from the last one bit for bit) are :mod:`.checkpoint`'s; the ``evaluate`` stage, EVoI
and the run's summary are :mod:`.evaluate`'s; the files a run writes besides those are
:mod:`.outputs`'.

``python -m vdtn_marl.experiment.jocc`` runs one JOCC iteration with the default small budgets
(:func:`main`).
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import logging
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch

from vdtn_marl.algos.checkpoint import load_checkpoint, rng_state, set_rng_state
from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.imitation import distill_rra_teacher, distill_teacher, distillation_ticks
from vdtn_marl.algos.networks import AUGMENTATION_FEATURES
from vdtn_marl.algos.ppo import ActorPolicy, CriticValue
from vdtn_marl.algos.trainer import Trainer, trainer_class
from vdtn_marl.algos.value_fit import fit_value_on_acting_states
from vdtn_marl.core.reward import RRAReward, spread_scales
from vdtn_marl.data.selection import preprocessing_note
from vdtn_marl.data.traces import TraceSource
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment import checkpoint, outputs, warm_start
from vdtn_marl.experiment.config import RunConfig, to_dict, validate, validate_device
from vdtn_marl.experiment.evaluate import (
    EVAL_SEED_OFFSET,
    ActingSystem,
    evaluate_stage,
    perfect_returns,
    run_summary,
)
from vdtn_marl.experiment.reference import reference_check, scenarios_memo, scored_once
from vdtn_marl.io.files import (
    EVALUATION_FILE,
    SUMMARY_FILE,
    atomic_write_json,
    read_json,
    run_lock,
    run_outputs,
)
from vdtn_marl.io.interrupts import check_interrupt, interrupt_requested
from vdtn_marl.io.log import logged_stage, progress
from vdtn_marl.io.loggers import RunLoggers
from vdtn_marl.io.metrics import MetricsLog
from vdtn_marl.io.video import write_video
from vdtn_marl.policies import make_control_baseline, make_rra_baseline
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.reporting.tables import flatten
from vdtn_marl.sim.completion import make_completion
from vdtn_marl.voi import IVOI_ESTIMATORS, VoIReference, make_ivoi_estimator

STAGES = ("control_perfect", "control_impaired", "rra", "evaluate")
STAGE_POLICIES = {
    "control_perfect": "π*",
    "control_impaired": "π̃",
    "rra": "the RRA agents",
}
"""Who a training stage trains (for the run log)."""
TASK_STAGES = {
    "jocc": STAGES,
    "control": ("control_perfect", "evaluate"),
    "control_impaired": ("control_perfect", "control_impaired", "evaluate"),
    "rra": ("control_perfect", "rra", "evaluate"),
}
_log = logging.getLogger(__name__)

#: rra.term_scales=spread: scenarios and intervals per RRA policy whose terms are measured, and
#: the seed offset of those scenarios (apart from training's, evaluation's and the value fit's)
SCALE_SCENARIOS = 16
SCALE_INTERVALS = 100
SCALE_SEED_OFFSET = 1_500_000_000
#: rra.value_fit=acting: scenarios per RRA policy whose states v* is fitted on, and the seed
#: offset of those scenarios (apart from training's and evaluation's)
VALUE_FIT_SCENARIOS = 32
VALUE_FIT_SEED_OFFSET = 2_000_000_000


class SwitchablePolicy:
    """A policy slot an environment holds while the policy behind it changes (JOCC hands the
    learned RRA policy to the control environment after iteration 0)."""

    def __init__(self, policy):
        self.policy = policy

    def __call__(self, observation):
        return self.policy(observation)

    @property
    def rowwise(self) -> bool:
        """The current policy's ``rowwise`` (IntervalEngine.run_radio)."""
        return bool(getattr(self.policy, "rowwise", False))

    def bound(self):
        """The current policy's ``bound()`` (its weights read once, for one interval's radio:
        :meth:`~vdtn_marl.algos.ppo.ActorPolicy.bound`), or the current policy itself."""
        bind = getattr(self.policy, "bound", None)
        return bind() if bind is not None else self.policy

    def seed(self, seed: int | None) -> None:
        if hasattr(self.policy, "seed"):
            self.policy.seed(seed)


@dataclass
class TrainingEnvFactory:
    """Builds a vehicle stage's training environment (``mode``: ``control`` for π*,
    ``control_impaired`` for π̃) in a collector worker (``algo.collector_workers``,
    :mod:`vdtn_marl.algos.shards`), with the arguments of the trainer's own but the batch.
    π̃'s holds an RRA slot; the workers' slots get the trainer's policy whenever JOCC swaps it
    (:meth:`policy_of`, :meth:`install`)."""

    mode: str
    kwargs: dict[str, Any] = field(default_factory=dict)
    params: Any = None  # TwinParams: the slot's placeholder until the first policy arrives
    seed: int = 0

    def __call__(self, batch_size: int) -> VDTNTorchRLEnv:
        kwargs = dict(self.kwargs, batch_size=batch_size)
        if self.mode == "control_impaired":
            placeholder = make_rra_baseline("random", self.params, self.seed)
            kwargs["rra_policy"] = SwitchablePolicy(placeholder)
        return VDTNTorchRLEnv(self.mode, **kwargs)

    def policy_of(self, env: VDTNTorchRLEnv):
        """The policy in ``env``'s RRA slot (None without one)."""
        slot = env.rra_policy
        return slot.policy if isinstance(slot, SwitchablePolicy) else None

    def install(self, env: VDTNTorchRLEnv, policy) -> None:
        env.rra_policy.policy = policy


def trace_sources(cfg: RunConfig) -> tuple[str | TraceSource, str | TraceSource]:
    """The scenario's leader traces for training and for evaluation: a named trace set
    (:func:`~vdtn_marl.data.selection.named_sources`: a recorded one split in time) or a
    user's file divided into a train and an eval part
    (:func:`~vdtn_marl.data.selection.file_sources`)."""
    from vdtn_marl.data.selection import accel_band, file_sources, named_sources

    scenario = cfg.scenario
    if scenario.trace_path is None:
        return named_sources(scenario.traces, scenario.eval_windows)
    platoon = cfg.twin_params().platoon
    band = accel_band(scenario.trace_accel_clip, platoon.accel_min_mps2, platoon.accel_max_mps2)
    return file_sources(scenario.traces, scenario.trace_path, scenario.eval_windows, band)


class JointOptimisation:
    """The JOCC loop (see the module doc). ``task`` picks the stages (:data:`TASK_STAGES`)."""

    def __init__(self, cfg: RunConfig, run_dir: str | Path, task: str = "jocc"):
        if task not in TASK_STAGES:
            raise ConfigError(f"task={task!r} is not one of {', '.join(TASK_STAGES)}")
        self.cfg = validate(cfg)
        self.task = task
        self.stages = TASK_STAGES[task]
        self.run_dir = Path(run_dir)
        self.params = cfg.twin_params()
        self.device = torch.device(cfg.device)
        if cfg.threads:
            # small per-step tensors: one thread avoids oversubscription, and parallel sweep
            # jobs on one machine do not fight over cores
            torch.set_num_threads(cfg.threads)
        torch.manual_seed(cfg.seed)  # the trainers below draw their weights in this order
        self.control_learned = cfg.control.name == "learned"
        self.rra_learned = cfg.rra.learned
        self.gamma = cfg.algo.gamma
        self.train_traces, self.eval_traces = trace_sources(cfg)
        note = preprocessing_note(self.train_traces, cfg.scenario.trace_path)
        if note:
            _log.warning(note)
        env_kw: dict[str, Any] = dict(
            batch_size=cfg.algo.num_envs, device=self.device, seed=cfg.seed,
            trace_source=self.train_traces, **cfg.model_kwargs(),
        )  # fmt: skip
        self._user_policies: dict[str, Any] = {}  # rra=policy, control=policy: built once
        # 1. π*, the reference: the controller on perfect observations
        self.pi_star = self._make_pi_star(env_kw)
        # 2. π̃, the acting controller, on what the RRA policy in the slot delivers
        self.rra_slot = SwitchablePolicy(self.rra_policy(untrained=True))
        self.completion = make_completion(
            cfg.control.completion, cfg.control.completion_predictor, self.params.platoon
        )
        self.pi_tilde = self._make_pi_tilde(env_kw)
        # 3. the IVoI estimator on π*; rra.value_fit=acting: the td estimator's v* is a copy of
        # π*'s critic fitted on the acting system's states before each RRA stage
        # (value_fit.py), π*'s own is unchanged
        self.v_fit = copy.deepcopy(self.pi_star.critic) if cfg.rra.value_fit == "acting" else None
        self.estimator = self.ivoi_estimator(cfg.rra.ivoi_estimator, baseline=cfg.rra.ivoi_baseline)
        # 4. the RRA agents: κ1·g per subframe, κ2·ξ at the interval's end
        self.rra = self._make_rra(env_kw) if self.rra_learned else None
        # 5. where the loop stands, and its logs
        self.position = {"iteration": 0, "stage": 0, "stage_start": None}
        self._open_logs()
        self.last_evaluation: dict[str, Any] | None = None
        self.videos: dict[str, Path] = {}  # the last evaluation's, by stem (video=true)
        self.video_indices: dict[str, int] = {}  # and the held-out scenario each shows

    def _completion_kwargs(self) -> dict[str, Any]:
        control = self.cfg.control
        return dict(
            completion=control.completion, completion_predictor=control.completion_predictor
        )

    def _make_pi_star(self, env_kw: dict[str, Any]) -> Trainer:
        """π*: PPO on perfect observations, keeping its best policy by validation
        (``control.pi_star_validate_every``)."""
        cfg = self.cfg
        return trainer_class(cfg.algo.name)(  # vdtn_marl/algos/trainer.py: ALGORITHMS
            VDTNTorchRLEnv("control", **env_kw),
            "vehicle",
            dataclasses.replace(cfg.algo, validate_every=cfg.control.pi_star_validate_every),
            seed=cfg.seed * 8,
            prior=CACCController(self.params.platoon),
            env_factory=TrainingEnvFactory("control", env_kw),
        )

    def _make_pi_tilde(self, env_kw: dict[str, Any]) -> Trainer:
        """π̃: PPO on the observations the RRA policy in :attr:`rra_slot` delivers, completed
        by ``control.completion``; without ``control.augmentation`` it does not see the CAM's
        delay and age."""
        cfg = self.cfg
        completion_kw = self._completion_kwargs()
        return trainer_class(cfg.algo.name)(
            VDTNTorchRLEnv("control_impaired", rra_policy=self.rra_slot, **completion_kw, **env_kw),
            "vehicle",
            cfg.algo,
            seed=cfg.seed * 8 + 1,
            drop_features=() if cfg.control.augmentation else AUGMENTATION_FEATURES,
            prior=CACCController(self.params.platoon),
            env_factory=TrainingEnvFactory(
                "control_impaired", {**completion_kw, **env_kw}, self.params, cfg.seed
            ),
        )

    def _make_rra(self, env_kw: dict[str, Any]) -> Trainer:
        """The RRA agents: PPO per subframe under the acting control policy, rewarded by
        ``rra.name``'s reward (:mod:`vdtn_marl.core.reward`) with the IVoI of
        :attr:`estimator`."""
        cfg = self.cfg
        algo, rra = cfg.algo, cfg.rra
        rra_env = VDTNTorchRLEnv(
            "rra",
            **{**env_kw, "batch_size": algo.rra_num_envs},
            control_module=SwitchablePolicy(self.control_policy()),
            reward=rra.name,
            kappa1=rra.kappa1,
            kappa2=rra.kappa2_value,
            ivoi_estimator=self.estimator,
            throughput_scale=rra.throughput_scale,
            ivoi_scale=rra.ivoi_scale,
            miss_penalty=rra.miss_penalty,
            aoi_scale=rra.aoi_scale,
            burn_in_intervals=algo.rra_burn_in_intervals,
            **self._completion_kwargs(),
        )
        policy = rra_env.control_module.policy
        if hasattr(policy, "bind"):  # oracle, causal_mpc: they read the twin's true state
            rra_env.control_module.policy = policy.bind(rra_env.twin)
        gamma, lmbda = algo.rra_subframe_discounts(self.params.platoon.subframes_per_interval)
        bits_left = rra_env.twin.rra_layout.bits_left
        return trainer_class(algo.name)(
            rra_env,
            "rra",
            dataclasses.replace(algo, validate_every=rra.validate_every),
            seed=cfg.seed * 8 + 2,
            rollout_steps=algo.rra_rollout_steps,
            gamma=gamma,
            lmbda=lmbda,
            # a link whose CAM is delivered is silent: its action has no effect
            active=(lambda obs: obs[..., bits_left] > 0) if algo.rra_mask_silent else None,
        )

    def _open_logs(self) -> None:
        """The CSV tables, and TensorBoard, W&B, MLflow beside them (``experiment.loggers``),
        opened on the first row; the two logs share them."""
        self.loggers = RunLoggers(
            self.cfg.experiment.loggers,
            self.run_dir,
            run_name=f"{self.task} {self.run_dir.resolve().parent.name}/{self.run_dir.name}",
            hparams=flatten(to_dict(self.cfg)),
        )
        self.train_log = MetricsLog(self.run_dir, loggers=self.loggers)
        self.eval_log = MetricsLog(self.run_dir, filename=EVALUATION_FILE, loggers=self.loggers)

    # ------------------------------------------------------------------ policies
    def control_policy(self):
        """The acting control policy (π̃ or a control baseline) as obs → commands."""
        if self.control_learned:
            return ActorPolicy(self.pi_tilde.actor, "vehicle")
        control = self.cfg.control
        if control.name == "policy":
            return self.user_policy("control.policy", control.policy)
        solver = {} if control.mpc_iterations is None else {"iterations": control.mpc_iterations}
        return make_control_baseline(control.name, self.params, **solver)

    def rra_policy(self, untrained: bool = False):
        """The current RRA policy: the learned one once trained (uniformly random before, and
        with ``untrained``), the user's (``rra=policy``) or a baseline."""
        if self.rra_learned:
            if untrained or self.rra.iteration == 0:
                return make_rra_baseline("random", self.params, self.cfg.seed)
            return ActorPolicy(self.rra.actor, "rra")
        if self.cfg.rra.name == "policy":
            return self.user_policy("rra.policy", self.cfg.rra.policy)
        return make_rra_baseline(self.cfg.rra.name, self.params, self.cfg.seed)

    def user_policy(self, key: str, spec: str):
        """The user's policy ``spec`` for ``key`` (``rra.policy``, ``control.policy``), built
        once per run (:func:`~vdtn_marl.experiment.user_policy.load_policy`)."""
        if key not in self._user_policies:
            from vdtn_marl.experiment.user_policy import load_policy

            self._user_policies[key] = load_policy(
                key, spec, self.params, self.cfg.seed, self.device
            )
        return self._user_policies[key]

    def trainers(self) -> dict[str, Trainer]:
        out = {"pi_star": self.pi_star, "pi_tilde": self.pi_tilde}
        if self.rra is not None:
            out["rra"] = self.rra
        return out

    @classmethod
    def from_checkpoint(
        cls, path: str | Path, run_dir: str | Path, needs_pi_tilde: bool = False
    ) -> JointOptimisation:
        """The loop of a checkpoint's run (config from the checkpoint) with every trainer's
        weights loaded, writing nothing next to the checkpoint (``run_dir`` is its run
        directory; torch threads are left as the caller set them). ``needs_pi_tilde``
        refuses a checkpoint of a run with learned control that trained no π̃."""
        cfg, saved = checkpoint.run_config(path, needs_pi_tilde)
        cfg.threads = 0
        loop = cls(cfg, run_dir, task="jocc")
        loop.load_policies(saved)
        loop.position["reference"] = saved.get("position", {}).get("reference")
        return loop

    def ivoi_estimator(
        self,
        name: str,
        rollout_intervals: int | None = None,
        bootstrap: bool | None = None,
        baseline: str = "optimal",
    ):
        """The IVoI estimator ``name`` on π*: ``td`` (π*'s critic as v*) or ``rollout`` (π*
        for ``rollout_intervals`` intervals, then, with ``bootstrap``, its critic; defaults:
        ``rra.rollout_intervals`` and ``rra.rollout_bootstrap``; ``baseline``: see
        :class:`~vdtn_marl.voi.RolloutIVoIEstimator`). It reads the trainers' current
        weights."""
        if name not in IVOI_ESTIMATORS:
            raise ConfigError(f"ivoi_estimator={name!r} is not one of {', '.join(IVOI_ESTIMATORS)}")
        rra = self.cfg.rra
        critic = self.pi_star.critic
        if name == "td" and self.v_fit is not None:  # rra.value_fit=acting: td reads the fit
            critic = self.v_fit
        reference = VoIReference(
            policy=ActorPolicy(self.pi_star.actor, "vehicle"),
            value=CriticValue(critic, "vehicle"),
            discount=self.gamma,
        )
        options = {
            "horizon_intervals": (
                rra.rollout_intervals if rollout_intervals is None else rollout_intervals
            ),
            "bootstrap": rra.rollout_bootstrap if bootstrap is None else bootstrap,
            "baseline": baseline,
        }
        return make_ivoi_estimator(name, reference, **options)

    # ------------------------------------------------------------------ checkpoints
    @property
    def checkpoint_path(self) -> Path:
        return checkpoint.checkpoint_path(self.run_dir)

    def save(self, path: Path | None = None) -> Path:
        """Write the loop's checkpoint (:func:`.checkpoint.save`)."""
        return checkpoint.save(self, path)

    def load_policies(self, payload: dict[str, Any]) -> None:
        """Load every trainer state a checkpoint holds (policies, critics, optimisers)."""
        checkpoint.load_policies(self, payload)

    def resume(self) -> bool:
        """Continue from ``checkpoints/last.pt`` if it exists; returns whether it did."""
        return checkpoint.resume(self)

    def prepare_load(self, position: dict[str, Any]) -> None:
        """Put in π̃'s RRA slot the policy it held at ``position`` (a checkpoint's), so that the
        checkpoint's state of π̃'s environment, which holds that policy's state, loads into a
        policy of its kind. π̃'s stage of each JOCC iteration sets the slot when it begins
        (:meth:`_train_stage`): at ``position`` it holds that of its iteration once that
        stage has begun, else that of the iteration before, else the untrained policy the
        loop was built with."""
        if "control_impaired" not in self.stages:
            return
        index = self.stages.index("control_impaired")
        begun = position["stage"] > index or (
            position["stage"] == index and position["stage_start"] is not None
        )
        iteration = position["iteration"] - (0 if begun else 1)
        if iteration < 0:
            return
        # the RRA agents had trained `iteration` stages when the slot was set
        trained = "rra" in self.stages and iteration * self.cfg.experiment.rra_iterations > 0
        if self.rra_learned and trained:  # the RRA trainer's weights load after this
            self.rra_slot.policy = ActorPolicy(self.rra.actor, "rra")
        else:
            self.rra_slot.policy = self.rra_policy(untrained=True)

    # ------------------------------------------------------------------ stages
    def _stage_budget(self, stage: str) -> tuple[Trainer | None, int]:
        e = self.cfg.experiment
        if stage == "control_perfect":  # control.pi_star: loaded, not trained here
            return (None, 0) if self.cfg.control.pi_star else (self.pi_star, e.control_iterations)
        if stage == "control_impaired":
            return (self.pi_tilde, e.control_iterations) if self.control_learned else (None, 0)
        if stage == "rra":
            return (self.rra, e.rra_iterations) if self.rra_learned else (None, 0)
        return None, 0

    def total_steps(self) -> int:
        per_iteration = sum(self._stage_budget(s)[1] for s in self.stages) + (
            1 if "evaluate" in self.stages else 0
        )
        return per_iteration * self.cfg.experiment.jocc_iterations

    def _train_stage(self, stage: str, bar) -> None:
        trainer, budget = self._stage_budget(stage)
        if trainer is None or budget == 0:
            return
        if self.position["stage_start"] is None:
            if stage == "control_impaired":  # π̃ trains under the RRA policy of this iteration
                self.rra_slot.policy = self.rra_policy()
            if stage == "control_perfect" and trainer.iteration == 0:
                self._warm_start_pi_star()
                self._score_reference("start", ActorPolicy(self.pi_star.actor, "vehicle"))
                self._fit_pi_star_critic()
            if stage == "rra" and self.v_fit is not None:
                self._fit_value()
            if stage == "rra" and trainer.iteration == 0:
                self._warm_start_rra()
            if stage == "rra" and self.cfg.rra.term_scales == "spread":
                self._scale_rra_terms()
            self.position["stage_start"] = trainer.iteration
            trainer.begin_stage(budget)
        end = self.position["stage_start"] + budget
        every = self.cfg.experiment.checkpoint_every
        what = f"{STAGE_POLICIES[stage]} for {end - trainer.iteration} PPO iterations"
        patience = self.cfg.control.pi_star_patience if stage == "control_perfect" else 0
        with logged_stage(stage, what, self.position["iteration"]):
            while trainer.iteration < end and not trainer.plateaued(patience):
                stats = trainer.train_iteration()
                row = {"jocc_iteration": self.position["iteration"], "stage": stage}
                row.update(stats.__dict__)
                self.train_log.log(row, step=stats.iteration, prefix=stage, step_key="iteration")
                bar.update(1)
                bar.set_postfix(stage=stage, reward=f"{stats.reward_mean:.4f}")
                if interrupt_requested() and trainer.iteration < end:
                    self.save()  # Ctrl-C: keep this iteration, then stop (io/interrupts.py)
                    check_interrupt()
                if every and trainer.iteration < end and trainer.iteration % every == 0:
                    self.save()
        if trainer.iteration < end:  # control.pi_star_patience: π* reached its plateau
            self._record_plateau(stage, trainer, end, patience)
            bar.update(end - trainer.iteration)
        selected = trainer.finish_stage()["best_iteration"]
        if selected is not None:  # algo.validate_every: the stage kept this iteration's weights
            self.position.setdefault("selected_iterations", {})[stage] = selected

    def _record_plateau(self, stage: str, trainer: Trainer, end: int, patience: int) -> None:
        """The stage ended ``end − iteration`` PPO iterations early: its last ``patience``
        validations did not beat its best."""
        record = {"stopped_at": trainer.iteration, "budget_end": end, "patience": patience}
        self.position.setdefault("plateaus", {})[stage] = record
        _log.info(
            "%s reached its plateau at PPO iteration %d (%d validations without a gain); "
            "%d of the stage's iterations left unused",
            STAGE_POLICIES[stage], trainer.iteration, patience, end - trainer.iteration,
        )  # fmt: skip

    def _load_shared_pi_star(self) -> None:
        """``control.pi_star``: π* (actor, critic, observation scaling) is that of another
        run's checkpoint, and is not trained here. Its start's score on this run's
        evaluation scenarios comes with it where that run scored it on the same ones."""
        path = self.cfg.control.pi_star
        saved = load_checkpoint(path)  # its networks fit (compose.check_pi_star)
        self.pi_star.load_state_dict(saved["trainers"]["pi_star"])
        position = saved.get("position", {})
        memo = self.reference_memo()
        theirs = position.get("reference", {})
        if theirs.get("scenarios") == memo["scenarios"] and "start" in theirs:
            memo.setdefault("start", list(theirs["start"]))
        self.position["shared_pi_star"] = {
            "checkpoint": str(path),
            "sha256": warm_start.file_digest(path),
            "seed": saved.get("config", {}).get("seed"),
            "ppo_iterations": self.pi_star.iteration,
            "selected_iteration": position.get("selected_iterations", {}).get("control_perfect"),
            "plateau": position.get("plateaus", {}).get("control_perfect"),
            "warm_start": position.get("warm_start"),
        }
        _log.info(
            "π* loaded from %s (%d PPO iterations), not trained here", path, self.pi_star.iteration
        )

    def _fit_pi_star_critic(self) -> None:
        """``control.pi_star_critic_warmup``: π*'s critic alone learns its start policy's
        returns before PPO's first update (:meth:`~vdtn_marl.algos.ppo.PPOTrainer.fit_critic`)."""
        batches = self.cfg.control.pi_star_critic_warmup
        if not batches:
            return
        what = f"π*'s critic on {batches} batches of its start policy"
        with logged_stage("critic_warmup", what, self.position["iteration"]):
            stats = self.pi_star.fit_critic(batches)
        self.position["critic_warmup"] = {"batches": batches, **stats}

    def _warm_start_rra(self) -> None:
        """``rra.warm_start=<baseline>``: the RRA agents imitate the baseline before their first
        PPO stage, the acting control driving the followers
        (:func:`~vdtn_marl.algos.imitation.distill_rra_teacher`, on the training traces)."""
        cfg = self.cfg
        if cfg.rra.warm_start == "none":
            return
        teacher = make_rra_baseline(cfg.rra.warm_start, self.params, cfg.seed)
        what = f"the RRA agents imitating rra={cfg.rra.warm_start}"
        with logged_stage("rra_warm_start", what, self.position["iteration"]):
            stats = distill_rra_teacher(
                self.rra, teacher, self.params, self.control_policy(),
                trace_source=self.train_traces, completion=self.completion,
                progress=lambda n: check_interrupt(),
            )  # fmt: skip
        self.position["rra_warm_start"] = {"teacher": cfg.rra.warm_start, **asdict(stats)}

    def _scale_rra_terms(self) -> None:
        """``rra.term_scales=spread``: the jocc reward's s_g and s_ξ from the spreads of its
        two terms between the silent and the greedy RRA policy, under the acting system and
        the IVoI estimator the RRA agents are paid with, on calibration scenarios of the
        training traces (:func:`~vdtn_marl.core.reward.spread_scales`)."""
        cfg, params = self.cfg, self.params
        subframes = params.platoon.subframes_per_interval
        measured = {}
        what = f"the RRA reward's terms under silent and greedy RRA ({SCALE_SCENARIOS} scenarios)"
        with logged_stage("term_scales", what, self.position["iteration"]):
            for name in ("silent", "greedy"):
                with torch.random.fork_rng(devices=[]):
                    metrics = evaluate_system(
                        params, self.control_policy(), make_rra_baseline(name, params, cfg.seed),
                        perfect=False, episodes=SCALE_SCENARIOS,
                        intervals=min(SCALE_INTERVALS, params.episode_intervals),
                        seed=SCALE_SEED_OFFSET + cfg.seed * 100 + self.position["iteration"],
                        gamma=self.gamma, device=self.device, trace_source=self.train_traces,
                        ivoi_estimator=self.estimator, completion=self.completion,
                    ).metrics  # fmt: skip
                links = params.radio.num_subchannels  # one V2I uplink per sub-channel
                interval_mbps = metrics["v2i_throughput_mbps_per_link"] * links * subframes
                measured[name] = (interval_mbps, metrics["ivoi_mean"])
        throughput_scale, ivoi_scale = spread_scales(
            (measured["silent"][0], measured["greedy"][0]),
            (measured["silent"][1], measured["greedy"][1]),
        )
        entry = {
            "jocc_iteration": self.position["iteration"],
            "throughput_scale": throughput_scale, "ivoi_scale": ivoi_scale,
            "interval_throughput_mbps_silent": measured["silent"][0],
            "interval_throughput_mbps_greedy": measured["greedy"][0],
            "ivoi_mean_silent": measured["silent"][1], "ivoi_mean_greedy": measured["greedy"][1],
        }  # fmt: skip
        _log.info("RRA term scales: %s", entry)
        kept = [
            e
            for e in self.position.get("term_scales", [])
            if e["jocc_iteration"] != entry["jocc_iteration"]
        ]
        self.position["term_scales"] = [*kept, entry]
        self._apply_term_scales()

    def _apply_term_scales(self) -> None:
        """Pay the RRA agents with the last scales ``rra.term_scales=spread`` measured (after
        a resume too: the environment's state does not hold its reward)."""
        scales = self.position.get("term_scales")
        if not scales or self.rra is None:
            return
        env = self.rra.env
        env.reward_fn = dataclasses.replace(
            env.reward_fn,
            throughput_scale=scales[-1]["throughput_scale"],
            ivoi_scale=scales[-1]["ivoi_scale"],
        )

    def _fit_value(self) -> None:
        """``rra.value_fit=acting``: fit the td estimator's v* on the states the acting system
        visits under the current RRA policy and under the greedy one (value_fit.py)."""
        cfg = self.cfg
        what = f"v* on the acting system's states ({cfg.rra.value_fit_horizon}-interval targets)"
        with logged_stage("value_fit", what, self.position["iteration"]):
            stats = fit_value_on_acting_states(
                self.v_fit,
                self.pi_star.critic,
                "vehicle",
                self.params,
                self.control_policy(),
                [self.rra_policy(), make_rra_baseline("greedy", self.params, cfg.seed)],
                ActorPolicy(self.pi_star.actor, "vehicle"),
                episodes=VALUE_FIT_SCENARIOS,
                intervals=self.params.episode_intervals,
                seed=VALUE_FIT_SEED_OFFSET + cfg.seed * 100 + self.position["iteration"],
                horizon=cfg.rra.value_fit_horizon,
                discount=self.gamma,
                trace_source=self.train_traces,
                device=self.device,
                completion=self.completion,
            )
        _log.info("value fit: %s", stats.as_dict())
        self.position.setdefault("value_fit", []).append(
            {"jocc_iteration": self.position["iteration"], **stats.as_dict()}
        )

    def _warm_start_pi_star(self) -> None:
        """``control.warm_start=causal_mpc``: π* imitates the causal MPC before its first PPO
        stage (:func:`~vdtn_marl.algos.imitation.distill_teacher`, on the training traces).
        With ``warm_start_cache`` a run that would compute the same warm start as an earlier
        one loads it (:mod:`.warm_start`)."""
        cfg = self.cfg
        if cfg.control.warm_start == "none":
            return
        intervals = min(200, self.params.episode_intervals)
        memo_dir, key = cfg.warm_start_cache, None
        # an interrupted warm start's state, from the checkpoint written after each of its
        # rounds' rollouts and fits: it goes on from there
        partial = self.position.pop("warm_start_partial", None)
        if partial is not None:
            key = partial.pop("memo_key")
        elif memo_dir:
            key = warm_start.memo_key(
                trainer=self.pi_star.state_dict(),
                trainer_seed=self.pi_star.seed,
                rng=rng_state(),
                scenario=to_dict(cfg)["scenario"],
                algo=to_dict(cfg)["algo"],
                teacher=cfg.control.warm_start,
                intervals=intervals,
                device=str(self.device),
                trace_file=warm_start.file_digest(cfg.scenario.trace_path),
            )
            entry = warm_start.load(memo_dir, key)
            if entry is not None:
                self.pi_star.load_state_dict(entry["trainer"])
                set_rng_state(entry["rng"])
                self.position["warm_start"] = {**entry["stats"], "memo": "loaded"}
                _log.info("π*'s warm start loaded from %s", warm_start.memo_path(memo_dir, key))
                return
        teacher = make_control_baseline("causal_mpc", self.params)
        ticks = distillation_ticks(intervals=intervals)

        def keep(state: dict) -> None:
            self.position["warm_start_partial"] = {**state, "memo_key": key}
            self.save()

        with progress(ticks, "π* imitating the causal MPC", cfg.progress) as bar:
            stats = distill_teacher(
                self.pi_star,
                teacher,
                self.params,
                intervals=intervals,
                trace_source=self.train_traces,
                progress=lambda n: (check_interrupt(), bar.update(n)),
                state=partial,
                on_state=keep,
            )
        self.position.pop("warm_start_partial", None)
        self.position["warm_start"] = {"teacher": cfg.control.warm_start, **asdict(stats)}
        if key is not None and memo_dir:
            warm_start.store(
                memo_dir, key, self.pi_star.state_dict(), rng_state(), self.position["warm_start"]
            )
            self.position["warm_start"]["memo"] = "stored"

    def _score_reference(self, name: str, policy) -> torch.Tensor | None:
        """Per-scenario returns of a reference comparator on perfect observations over the
        evaluation scenarios, scored once per run and kept in the loop's position (so in its
        checkpoints): :mod:`.reference`. None in a run without an ``evaluate`` stage."""
        if "evaluate" not in self.stages:
            return None
        memo = self.reference_memo()

        def score() -> torch.Tensor:
            with torch.random.fork_rng(devices=[]):  # scoring leaves training's RNG alone
                return perfect_returns(
                    self.cfg, self.params, policy, trace_source=self.eval_traces,
                    device=self.device,
                )  # fmt: skip

        return scored_once(memo, name, score)

    def reference_memo(self) -> dict[str, Any]:
        """The reference comparators scored so far on this run's evaluation scenarios."""
        e, scenario = self.cfg.experiment, self.cfg.scenario
        scenarios = {
            "seed": self.cfg.seed, "episodes": e.eval_episodes, "intervals": e.eval_intervals,
            "gamma": self.gamma, "scenario": scenario.name, "traces": scenario.traces,
            "trace_path": scenario.trace_path, "eval_windows": scenario.eval_windows,
        }  # fmt: skip
        return scenarios_memo(self.position, scenarios)

    def reference_row(self, optimal, acting) -> dict[str, Any]:
        """The reference check's entries of an evaluation row (:mod:`.reference`): π*
        against its start, the causal MPC, the CACC and the acting system."""
        scored = self.reference_memo()
        oracle_acts = self.cfg.control.name == "oracle"  # it knows the leader's future
        comparators = {
            # π*'s start is scored before its first update; a run without one (no PPO
            # iterations, or resumed from a checkpoint written before the check) has none
            "start": torch.tensor(scored["start"]) if "start" in scored else None,
            "causal_mpc": self._score_reference(
                "causal_mpc", make_control_baseline("causal_mpc", self.params)
            ),
            "cacc": self._score_reference("cacc", CACCController(self.params.platoon)),
            "acting": None if acting is None or oracle_acts else acting.returns,
        }
        row = reference_check(optimal.returns, comparators)
        if not row["reference_ok"]:
            _log.warning("reference check failed: %s", row["reference_problems"])
        return row

    def evaluate(self, pi_star: bool = True) -> dict[str, Any]:
        """The ``evaluate`` stage (:func:`.evaluate.evaluate_stage`): metrics of the acting
        system, EVoI against π*; the row is logged to ``evaluation.csv`` and returned. Without
        ``pi_star`` (``eval`` of fixed policies: no π* was trained) the acting system is
        scored alone: no EVoI, no IVoI, no reference check."""
        acting = None
        if self.stages != TASK_STAGES["control"]:  # task=control scores π* against the CACC
            estimator = self.estimator if pi_star else None  # ξ is read off π*
            acting = ActingSystem(
                self.control_policy(), self.rra_policy(), estimator, self.completion
            )
        result = evaluate_stage(
            self.cfg,
            self.params,
            ActorPolicy(self.pi_star.actor, "vehicle") if pi_star else None,
            acting,
            trace_source=self.eval_traces,
            device=self.device,
            jocc_iteration=self.position["iteration"],
            video=self.cfg.video_scenarios if self.cfg.video else None,
        )
        self._last_results = (result.optimal, result.acting)
        if pi_star:
            result.row.update(self.reference_row(result.optimal, result.acting))
        fps = 1.0 / self.params.platoon.control_interval_s  # one frame per interval: real time
        for stem, frames in result.frames.items():
            path = write_video(self.run_dir, frames, fps, self.cfg.video_format, stem=stem)
            self.videos[stem], self.video_indices[stem] = path, result.drawn[stem]
            _log.info("video of evaluation scenario %d: %s", result.drawn[stem], path)
        self.eval_log.log(
            result.row, step=self.position["iteration"], prefix="eval", step_key="jocc_iteration"
        )
        self.last_evaluation = result.row
        return result.row

    # ------------------------------------------------------------------ loop
    def run(self) -> dict[str, Any]:
        """Run (or continue) every iteration and stage; write and return the summary."""
        with run_lock(self.run_dir):  # a second process in this folder is refused
            return self._run()

    def _run(self) -> dict[str, Any]:
        try:
            return self._run_stages()
        finally:
            self.close()

    def close(self) -> None:
        """Stop the trainers' collector workers (``algo.collector_workers``)."""
        for trainer in self.trainers().values():
            close = getattr(trainer, "close", None)
            if close is not None:
                close()

    def _run_stages(self) -> dict[str, Any]:
        cfg = self.cfg
        resumed = cfg.resume and self.resume()
        ended = self.run_dir / SUMMARY_FILE
        if resumed and self.position["iteration"] >= cfg.experiment.jocc_iterations:
            if ended.is_file():  # resume=true on a run that had ended: its results stay as they are
                _log.info("the run had ended; %s is kept as it was", ended)
                return read_json(ended)
        if resumed:
            self._apply_term_scales()
        elif cfg.control.pi_star and not cfg.checkpoint:
            self._load_shared_pi_star()
        began = time.perf_counter()
        done_steps = 0
        if resumed:
            done_steps = self._steps_before(self.position)
        with progress(self.total_steps(), f"{self.task} seed={cfg.seed}", cfg.progress) as bar:
            bar.update(done_steps)
            while self.position["iteration"] < cfg.experiment.jocc_iterations:
                stage = self.stages[self.position["stage"]]
                if stage == "evaluate":
                    e = cfg.experiment
                    what = f"{e.eval_episodes} episodes of {e.eval_intervals} intervals"
                    with logged_stage(stage, what, self.position["iteration"]):
                        self.evaluate()
                    bar.update(1)
                else:
                    self._train_stage(stage, bar)
                self._advance()
                self.save()
                check_interrupt()
        summary = self.summary(time.perf_counter() - began, resumed)
        self.write_raw_evaluation()
        summary["plots"] = self.write_plots()
        atomic_write_json(self.run_dir / SUMMARY_FILE, summary)
        self.loggers.close()
        return summary

    def write_raw_evaluation(self) -> None:
        """The last evaluation's arrays as ``evaluation_raw.npz`` (:mod:`.outputs`)."""
        optimal, acting = getattr(self, "_last_results", (None, None))
        if acting is not None:
            seed = EVAL_SEED_OFFSET + self.cfg.seed  # the held-out scenarios' (.evaluate)
            outputs.write_raw_evaluation(self.run_dir, self.params, optimal, acting, seed)

    def write_plots(self) -> list[str]:
        """Training curves, and error traces and CAM latency CDF of the last evaluation."""
        acting = getattr(self, "_last_results", (None, None))[1]
        label = f"{self.cfg.rra.name} RRA, {self.cfg.control.name} control"
        train_log = self.train_log.path if self.train_log.rows else None
        return outputs.write_run_plots(self.run_dir, self.params, train_log, acting, label)

    def _advance(self) -> None:
        self.position["stage"] += 1
        self.position["stage_start"] = None
        if self.position["stage"] == len(self.stages):
            self.position["stage"] = 0
            self.position["iteration"] += 1

    def _steps_before(self, position: dict[str, Any]) -> int:
        per_stage = [
            self._stage_budget(s)[1] if s != "evaluate" else 1 for s in self.stages
        ]  # fmt: skip
        steps = position["iteration"] * sum(per_stage) + sum(per_stage[: position["stage"]])
        if position["stage_start"] is not None:
            trainer, _ = self._stage_budget(self.stages[position["stage"]])
            steps += trainer.iteration - position["stage_start"]
        return steps

    def summary(self, seconds: float, resumed: bool) -> dict[str, Any]:
        """The run's summary (:func:`.evaluate.run_summary`) with the last evaluation."""
        evaluation = dict(self.last_evaluation or {})
        if not evaluation and self.eval_log.rows:
            evaluation = dict(self.eval_log.rows[-1])
        return run_summary(
            self.cfg,
            self.task,
            self.stages,
            position=self.position,
            trainer_iterations={n: t.iteration for n, t in self.trainers().items()},
            trace_preprocessing=getattr(self.train_traces, "preprocessing", None),
            evaluation=evaluation,
            eval_rows=self.eval_log.rows,
            seconds=seconds,
            resumed=resumed,
            videos=self.videos,
        )


# --- python -m vdtn_marl.experiment.jocc ---------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    """``python -m vdtn_marl.experiment.jocc``: one JOCC iteration with the default small
    budgets, a few flags instead of the CLI's keys; prints the metrics."""
    parser = argparse.ArgumentParser(
        prog="python -m vdtn_marl.experiment.jocc",
        description="One JOCC iteration with the default small budgets; prints the metrics.",
    )
    parser.add_argument(
        "--run-dir",
        default="runs/jocc",
        help="output directory; one that already holds a run is refused unless --resume",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--kappa1", type=float, default=RRAReward.kappa1)
    parser.add_argument("--device", default="cpu")
    parser.add_argument(
        "--resume", action="store_true", help="continue the run in --run-dir from its checkpoint"
    )
    args = parser.parse_args(argv)
    cfg = RunConfig(seed=args.seed, device=args.device, resume=args.resume)
    cfg.rra.kappa1 = args.kappa1
    try:
        validate(cfg)
        validate_device(cfg.device)
    except ConfigError as exc:
        parser.error(str(exc))
    found = run_outputs(args.run_dir)
    if found and not args.resume:
        # training afresh would overwrite its checkpoints and metrics (as the CLI refuses to)
        print(
            f"error: --run-dir={args.run_dir} already holds a run ({', '.join(found)}); "
            "allowed: --resume to continue it, or another --run-dir",
            file=sys.stderr,
        )
        return 2
    summary = JointOptimisation(cfg, args.run_dir).run()
    print(outputs.format_table(summary))
    print(f"outputs: {Path(args.run_dir).resolve()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
