"""MAPPO / IPPO for one agent group of a batched TorchRL environment.

Built from TorchRL parts: :func:`~vdtn_marl.algos.networks.make_actor` /
:func:`~vdtn_marl.algos.networks.make_critic` (MultiAgentMLP, ProbabilisticActor),
:class:`~torchrl.objectives.ClipPPOLoss` and its GAE value estimator. Rollouts come from the
environment's own ``rollout`` (the batched face is already vectorised over B scenarios, so a
collector would add nothing but a copy).

Training stages (:meth:`PPOTrainer.begin_stage` … :meth:`PPOTrainer.finish_stage`) add two
switches of :class:`~vdtn_marl.algos.params.AlgoConfig`: ``lr_schedule="linear"`` anneals the
learning rate linearly to zero over the stage, and ``validate_every=N`` scores the
deterministic policy at the stage's start, every N iterations and at the stage's last on fixed
validation scenarios (``validation_scenarios`` of them, seeded apart from the training and
evaluation ones), and hands back the best-scoring actor and critic at the end of the stage
(model selection; the last iterate of PPO can be much worse than an earlier one, and a
warm-started policy is kept unless PPO beats it).

Training window (``algo.persistent_envs``, default): the environment's scenarios persist
across PPO iterations and are reset only where an episode ends, so batches sample every part
of the episode (not only the intervals after a reset, where the platoon is at its desired
gaps); the first iteration starts from scenarios reset with ``seed_for(k)``. With
``persistent_envs=false`` every iteration ``k`` collects from freshly reset scenarios seeded
with ``seed_for(k)``. With ``algo.collector_workers=N`` and an ``env_factory``, N worker
processes hold the persisting scenarios, ``B / N`` each, and collect them together
(:mod:`~vdtn_marl.algos.shards`).

Credit (``active``): a callable that marks, from the observations, the agent-steps whose action
has an effect (an RRA link with a CAM to send). The others' advantages are set to zero after
GAE, and advantages are standardised over the active agent-steps only, per agent, so steps
whose action changes nothing do not train the policy (the critic still learns their values).

Reproducibility: action sampling and minibatch shuffles use the global torch RNG, whose state
goes into :meth:`PPOTrainer.state_dict`, and so do the persisting scenarios (the environment's
state and the step to continue from, :meth:`VDTNTorchRLEnv.state_dict`). A run resumed from a
checkpoint therefore continues bit for bit on the same device.
"""

from __future__ import annotations

import contextlib
import copy
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import InteractionType, set_interaction_type
from torchrl.envs import EnvBase
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from vdtn_marl.algos.networks import CategoricalMode, make_actor, make_critic, scalers
from vdtn_marl.algos.params import AlgoConfig
from vdtn_marl.algos.shards import ShardedCollector, continue_rollout

#: Iteration seeds are spread so that no two iterations (or two runs with nearby seeds) share
#: scenarios: seed_for(k) = seed · SEED_STRIDE + k.
SEED_STRIDE = 1_000_003
#: ``seed_for`` offsets of the scaling-fit rollout and of the validation scenarios: never a
#: training iteration's.
SCALING_ITERATION = SEED_STRIDE - 1
VALIDATION_ITERATION = SEED_STRIDE - 2
SCALING_MID_EPISODE_ITERATION = SEED_STRIDE - 4  # -3: imitation's DISTILLATION_ITERATION


#: fit_critic: the critic's own Adam step size, and its passes per batch in units of algo.epochs
CRITIC_FIT_LR = 1e-3
CRITIC_FIT_EPOCHS = 2

#: The terms of the clipped loss that are optimised, and the diagnostics it returns beside them.
LOSS_KEYS = ("loss_objective", "loss_critic", "loss_entropy")
HEALTH_KEYS = ("kl_approx", "clip_fraction", "explained_variance")


@dataclass
class IterationStats:
    """What one collect-and-update iteration did (rewards per agent per step of its clock)."""

    iteration: int
    frames: int  # scenario-steps collected
    reward_mean: float
    episodes_done: int
    loss_objective: float
    loss_critic: float
    loss_entropy: float
    # PPO health, means over the iteration's minibatches (as ClipPPOLoss returns them):
    kl_approx: float  # approximate KL of the updated policy from the collecting one
    clip_fraction: float  # share of samples whose probability ratio was clipped
    explained_variance: float  # of the value targets by the critic
    lr: float  # learning rate of the iteration's update
    validation_return: float  # of the deterministic policy after the update (NaN: not scored)
    seconds: float

    def row(self, prefix: str) -> dict:
        return {f"{prefix}/{k}": v for k, v in self.__dict__.items()}


class PPOTrainer:
    """Clipped PPO with GAE for ``group`` of ``env`` (MAPPO with a centralised critic or IPPO).

    Args:
        env: a batched TorchRL environment with the group's nested keys (e.g.
            :class:`~vdtn_marl.envs.torchrl.VDTNTorchRLEnv`, or a ``PettingZooWrapper``).
        group: ``"vehicle"`` or ``"rra"``.
        algo: hyper-parameters (:class:`~vdtn_marl.algos.params.AlgoConfig`);
            ``algo.name == "mappo"`` gives the critic the whole group's observations.
        seed: seeds the scenarios of every iteration (see the module doc).
        drop_features: observation features the actor must not see (the critic sees all).
        prior: controller the continuous policy starts from (see
            :mod:`~vdtn_marl.algos.networks`), e.g. the linear CACC controller.
        rollout_steps: steps per scenario per batch (default ``algo.rollout_steps``).
        gamma: discount per step of the group's clock (default ``algo.gamma``).
        lmbda: GAE λ per step of the group's clock (default ``algo.lmbda``).
        env_factory: a picklable callable ``batch_size → environment`` that builds ``env``'s
            like in a worker process: with ``algo.collector_workers=N`` (and persisting
            scenarios) N workers collect the training batches
            (:class:`~vdtn_marl.algos.shards.ShardedCollector`); without it, this process.
    """

    def __init__(
        self,
        env: EnvBase,
        group: str,
        algo: AlgoConfig,
        seed: int = 0,
        drop_features: Sequence[int] = (),
        prior=None,
        rollout_steps: int | None = None,
        gamma: float | None = None,
        lmbda: float | None = None,
        active=None,
        env_factory=None,
    ):
        self.env = env
        self.active = active
        self.persistent = bool(algo.persistent_envs)
        self._carry: TensorDictBase | None = None  # where persisting scenarios continue
        self.group = group
        self.algo = algo
        self.seed = int(seed)
        self.rollout_steps = int(rollout_steps or algo.rollout_steps)
        self.device = env.device
        obs_spec = env.observation_spec
        self.actor = make_actor(
            obs_spec,
            env.full_action_spec,
            group,
            share_params=algo.share_params,
            depth=algo.depth,
            num_cells=algo.num_cells,
            drop_features=drop_features,
            prior=prior,
            initial_log_scale=algo.initial_log_scale,
            device=self.device,
            activation=algo.activation,
        )
        self.critic = make_critic(
            obs_spec,
            group,
            centralised=algo.centralised_critic,
            share_params=algo.share_params,
            depth=algo.depth,
            num_cells=algo.num_cells,
            device=self.device,
            activation=algo.activation,
        )
        self.loss = ClipPPOLoss(
            actor_network=self.actor,
            critic_network=self.critic,
            clip_epsilon=algo.clip_epsilon,
            entropy_coeff=algo.entropy_coef,
            critic_coeff=algo.critic_coef,
            # with `active`, update() standardises over the active agent-steps itself
            normalize_advantage=active is None,
            normalize_advantage_exclude_dims=(-2,),  # the agent dimension
        )
        self.loss.set_keys(
            reward=(group, "reward"),
            action=(group, "action"),
            sample_log_prob=(group, "action_log_prob"),
            value=(group, "state_value"),
            done=(group, "done"),
            terminated=(group, "terminated"),
        )
        self.gamma = algo.gamma if gamma is None else gamma
        self.lmbda = algo.lmbda if lmbda is None else lmbda
        self.loss.make_value_estimator(ValueEstimators.GAE, gamma=self.gamma, lmbda=self.lmbda)
        self.optimizer = torch.optim.Adam(self.loss.parameters(), lr=algo.lr)
        self.iteration = 0
        self.scaling_fitted = False
        self.stage: dict | None = None  # see begin_stage
        self.shards: ShardedCollector | None = None
        workers = int(getattr(algo, "collector_workers", 0) or 0)
        if workers and env_factory is not None and self.persistent:
            self.shards = ShardedCollector(
                env_factory, int(env.batch_size.numel()), workers, self.actor
            )

    # ------------------------------------------------------------------ data
    def seed_for(self, iteration: int) -> int:
        return self.seed * SEED_STRIDE + iteration

    def collect(self, iteration: int | None = None) -> TensorDictBase:
        """Roll out ``rollout_steps`` steps of every scenario with the stochastic actor.

        The training batch (``iteration`` None) continues the persisting scenarios
        (``algo.persistent_envs``); an explicit ``iteration`` always collects from scenarios
        freshly reset with ``seed_for(iteration)`` (scaling fits, tests)."""
        k = self.iteration if iteration is None else iteration
        with torch.no_grad(), set_interaction_type(InteractionType.RANDOM):
            if not (self.persistent and iteration is None):
                self.env.set_seed(self.seed_for(k))
                return self.env.rollout(
                    self.rollout_steps,
                    policy=self.actor,
                    tensordict=self.env.reset(),
                    auto_reset=False,
                    break_when_any_done=False,
                )
            if self.shards is not None:
                return self.shards.collect(self.env, self.seed_for(k), self.rollout_steps)
            if self._carry is None:
                self.env.set_seed(self.seed_for(k))
                self._carry = self.env.reset()
            data, self._carry = continue_rollout(
                self.env, self.actor, self._carry, self.rollout_steps
            )
            return data

    def close(self) -> None:
        """Stop the collector's worker processes, if any (``algo.collector_workers``)."""
        if self.shards is not None:
            self.shards.close()

    @contextlib.contextmanager
    def _env_kept(self):
        """Inside the block the environment may be reset and stepped (validation); the
        persisting scenarios continue afterwards as if it had not been used."""
        if not (self.persistent and self._carry is not None):
            yield
            return
        saved = self.env.state_dict()
        try:
            yield
        finally:
            self.env.load_state_dict(saved)

    def fit_observation_scaling(self) -> None:
        """Standardise observations with statistics of one rollout of the initial policy
        (scenarios seeded apart from the training iterations).

        An RRA rollout is a few subframes long: from a reset alone its followers' control
        errors are near zero, and scaling by that spread would blow them up ~30× on the
        mid-episode states of evaluation. So RRA statistics also take a rollout from
        mid-episode (:meth:`VDTNTorchRLEnv.burned_in`).
        """
        observations = self.collect(iteration=SCALING_ITERATION).get((self.group, "observation"))
        if getattr(self.env, "mode", None) == "rra":
            with self.env.burned_in(self.env.twin.params.episode_intervals // 2):
                later = self.collect(iteration=SCALING_MID_EPISODE_ITERATION)
            observations = torch.cat([observations, later.get((self.group, "observation"))])
        for scaler in scalers(self.actor) + scalers(self.critic):
            scaler.fit_(observations)
        self.scaling_fitted = True

    # ------------------------------------------------------------------ update
    def update(self, data: TensorDictBase) -> dict[str, float]:
        """GAE, then ``algo.epochs`` passes of shuffled minibatches of the clipped loss, on
        ``algo.update_threads`` torch threads where that is set (the caller's restored)."""
        threads = self.algo.update_threads
        before = torch.get_num_threads()
        if not threads or threads == before:
            return self._update(data)
        torch.set_num_threads(threads)
        try:
            return self._update(data)
        finally:
            torch.set_num_threads(before)

    def _update(self, data: TensorDictBase) -> dict[str, float]:
        with torch.no_grad():
            self._value_targets(data)
            if self.active is not None:
                self._mask_advantage(data)
        # minibatches gather only what the loss reads once GAE is done (not the next step's
        # observations, rewards and flags, nor the collecting policy's loc and scale)
        flat = data.reshape(-1).select(*self._minibatch_keys(), strict=False)
        n = flat.shape[0]
        size = min(self.algo.minibatch_size, n)
        sums = dict.fromkeys(LOSS_KEYS + HEALTH_KEYS, 0.0)
        steps = 0
        for _ in range(self.algo.epochs):
            order = torch.randperm(n, device=self.device)
            for start in range(0, n - size + 1, size):
                batch = flat[order[start : start + size]]
                losses = self.loss(batch)
                total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
                self.optimizer.zero_grad(set_to_none=True)
                total.backward()
                torch.nn.utils.clip_grad_norm_(self.loss.parameters(), self.algo.max_grad_norm)
                self.optimizer.step()
                for key in sums:
                    value = losses.get(key, None)
                    sums[key] += math.nan if value is None else float(value.detach().mean())
                steps += 1
        return {key: value / max(steps, 1) for key, value in sums.items()}

    def fit_critic(self, iterations: int) -> dict[str, float]:
        """Fit the critic alone to the current actor's returns before the actor's first update
        (a warm-started actor's first advantages are then measured, not read off an untrained
        critic whose values are far from the returns): ``iterations`` batches collected as
        training collects them; on each, GAE's TD(λ) targets with the current critic, the
        critic's output shifted by the mean target error (its values start near 0, the
        returns of a whole horizon do not), then ``algo.epochs`` ×
        :data:`CRITIC_FIT_EPOCHS` passes of shuffled minibatches of the critic loss with an
        Adam of its own at :data:`CRITIC_FIT_LR`. The actor, PPO's optimiser, the iteration
        count and the stage do not change. Returns the last batch's mean critic loss and
        explained variance."""
        if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 0:
            raise ValueError(f"critic fit iterations={iterations!r} must be an integer >= 0")
        if not self.scaling_fitted:
            self.fit_observation_scaling()
        optimizer = torch.optim.Adam(self.critic.parameters(), lr=CRITIC_FIT_LR)
        *_, output_bias = (p for n, p in self.critic.named_parameters() if n.endswith("bias"))
        keys = self.loss.tensor_keys
        loss_sum = variance_sum = 0.0
        steps = 0
        for _ in range(iterations):
            data = self.collect()
            with torch.no_grad():
                self._value_targets(data)
                output_bias.add_((data.get(keys.value_target) - data.get(keys.value)).mean())
                self._value_targets(data)
            flat = data.reshape(-1).select(*self._minibatch_keys(), strict=False)
            n = flat.shape[0]
            size = min(self.algo.minibatch_size, n)
            loss_sum = variance_sum = 0.0  # the last batch's
            steps = 0
            for _ in range(self.algo.epochs * CRITIC_FIT_EPOCHS):
                order = torch.randperm(n, device=self.device)
                for start in range(0, n - size + 1, size):
                    loss, _, explained = self.loss.loss_critic(flat[order[start : start + size]])
                    loss = loss.mean()
                    optimizer.zero_grad(set_to_none=True)
                    loss.backward()
                    torch.nn.utils.clip_grad_norm_(
                        self.critic.parameters(), self.algo.max_grad_norm
                    )
                    optimizer.step()
                    loss_sum += float(loss.detach())
                    variance_sum += math.nan if explained is None else float(explained.mean())
                    steps += 1
        return {
            "loss_critic": loss_sum / steps if steps else math.nan,
            "explained_variance": variance_sum / steps if steps else math.nan,
        }

    def _value_targets(self, data: TensorDictBase) -> None:
        """GAE's advantage and value target into ``data``, with the current critic."""
        self.loss.value_estimator(
            data,
            params=self.loss.critic_network_params,
            target_params=self.loss.target_critic_network_params,
        )

    def _minibatch_keys(self) -> list:
        """The keys the clipped loss reads from a minibatch: its inputs at the current step
        (observation, action, the collecting policy's log-probability) and GAE's outputs."""
        keys = self.loss.tensor_keys
        now = [k for k in self.loss.in_keys if not (isinstance(k, tuple) and k[0] == "next")]
        return list(dict.fromkeys([*now, keys.advantage, keys.value_target, keys.value]))

    def _mask_advantage(self, data: TensorDictBase) -> None:
        """Standardise the advantage [..., n, 1] over the active agent-steps of each agent and
        zero it elsewhere (see the module doc)."""
        key = self.loss.tensor_keys.advantage
        advantage = data.get(key)
        active = self.active(data.get((self.group, "observation")))[..., None].to(advantage)
        dims = tuple(d for d in range(advantage.dim()) if d != advantage.dim() - 2)
        count = active.sum(dims, keepdim=True)
        mean = (advantage * active).sum(dims, keepdim=True) / count.clamp_min(1.0)
        var = ((advantage - mean) ** 2 * active).sum(dims, keepdim=True) / (count - 1).clamp_min(
            1.0
        )
        standard = (advantage - mean) / var.sqrt().clamp_min(1e-6)
        data.set(key, torch.where(active > 0, standard, torch.zeros_like(advantage)))

    def validation_return(self) -> float:
        """Mean reward (per agent and step) of the deterministic policy on the validation
        scenarios: ``rollout_steps`` steps of at least ``algo.validation_scenarios``
        scenarios (whole batches of the environment's B), drawn after seeding the environment
        with ``seed_for(VALIDATION_ITERATION)``, the same at every call."""
        batches = -(-self.algo.validation_scenarios // self.env.batch_size.numel())
        with self._env_kept():
            return self._validation_return(batches)

    def _validation_return(self, batches: int) -> float:
        self.env.set_seed(self.seed_for(VALIDATION_ITERATION))
        total = 0.0
        with torch.no_grad(), set_interaction_type(InteractionType.DETERMINISTIC):
            for _ in range(batches):
                data = self.env.rollout(
                    self.rollout_steps,
                    policy=self.actor,
                    tensordict=self.env.reset(),
                    auto_reset=False,
                    break_when_any_done=False,
                )
                total += float(data.get(("next", self.group, "reward")).mean())
        return total / batches

    # ------------------------------------------------------------------ stages
    def begin_stage(self, iterations: int) -> None:
        """Start a training stage of ``iterations`` iterations from the current one (for the
        learning-rate schedule and the validation of ``algo.lr_schedule``/``validate_every``)."""
        if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
            raise ValueError(f"stage iterations={iterations!r} must be an integer >= 1")
        self.stage = {
            "start": self.iteration,
            "end": self.iteration + iterations,
            "best_return": None,
            "best_iteration": None,
            "best_state": None,
            "since_best": 0,  # validations since the best one (plateaued)
        }
        if self.algo.validate_every:
            # the weights the stage starts from are a candidate too (iteration start − 1):
            # PPO must beat them on the validation scenarios to replace them
            if not self.scaling_fitted:
                self.fit_observation_scaling()
            self._keep_if_best(self.validation_return(), self.iteration - 1)

    def _keep_if_best(self, validation: float, iteration: int) -> None:
        best = self.stage["best_return"]
        if best is None or validation > best:
            self.stage.update(
                best_return=validation,
                best_iteration=iteration,
                best_state={
                    "actor": copy.deepcopy(self.actor.state_dict()),
                    "critic": copy.deepcopy(self.critic.state_dict()),
                },
                since_best=0,
            )
        else:
            self.stage["since_best"] = self.stage.get("since_best", 0) + 1

    def plateaued(self, patience: int) -> bool:
        """Whether the stage's last ``patience`` validations in a row did not beat its best
        (``patience`` 0, or a stage without validation: never)."""
        if not patience or self.stage is None or not self.algo.validate_every:
            return False
        return self.stage.get("since_best", 0) >= patience

    def learning_rate(self) -> float:
        """Learning rate of the current iteration's update: ``algo.lr``, or with
        ``lr_schedule="linear"`` inside a stage, ``algo.lr · (end − k) / (end − start)``."""
        if self.algo.lr_schedule == "constant" or self.stage is None:
            return self.algo.lr
        start, end = self.stage["start"], self.stage["end"]
        return self.algo.lr * max(end - self.iteration, 1) / (end - start)

    def _validate_now(self) -> bool:
        every = self.algo.validate_every
        if not every or self.stage is None:
            return False
        done = self.iteration + 1 - self.stage["start"]  # iterations of the stage after this one
        return done % every == 0 or self.iteration + 1 >= self.stage["end"]

    def finish_stage(self) -> dict:
        """End the stage; with validation, load the best-scoring actor and critic (the
        optimiser state stays that of the last iterate). Returns ``{"best_iteration",
        "best_return"}`` (None without validation). Calling it again is a no-op."""
        stage, self.stage = self.stage, None
        if stage is None or stage["best_state"] is None:
            return {"best_iteration": None, "best_return": None}
        self.actor.load_state_dict(stage["best_state"]["actor"])
        self.critic.load_state_dict(stage["best_state"]["critic"])
        return {"best_iteration": stage["best_iteration"], "best_return": stage["best_return"]}

    def train_iteration(self) -> IterationStats:
        """Collect one batch and update on it; returns the iteration's statistics."""
        if not self.scaling_fitted:
            self.fit_observation_scaling()
        began = time.perf_counter()
        data = self.collect()
        reward = data.get(("next", self.group, "reward"))
        done = data.get(("next", "done"))
        lr = self.learning_rate()
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        losses = self.update(data)
        validation = float("nan")
        if self._validate_now():
            validation = self.validation_return()
            self._keep_if_best(validation, self.iteration)
        stats = IterationStats(
            iteration=self.iteration,
            frames=int(data.numel()),
            reward_mean=float(reward.mean()),
            episodes_done=int(done.sum()),
            seconds=time.perf_counter() - began,
            lr=lr,
            validation_return=validation,
            **losses,
        )
        self.iteration += 1
        return stats

    # ------------------------------------------------------------------ state
    def state_dict(self) -> dict:
        shards = self.shards.state() if self.shards is not None else None
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "optimizer": self.optimizer.state_dict(),
            "iteration": self.iteration,
            "scaling_fitted": self.scaling_fitted,
            "stage": copy.deepcopy(self.stage),
            **(
                {"env": self.env.state_dict(), "carry": self._carry.to_dict()}
                if self._carry is not None
                else {}
            ),
            **({"shards": shards} if shards is not None else {}),
        }

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.iteration = int(state["iteration"])
        self.scaling_fitted = bool(state["scaling_fitted"])
        self.stage = copy.deepcopy(state.get("stage"))
        self._carry = None
        shards = state.get("shards")
        if shards is not None and self.shards is None:
            raise ValueError(
                f"algo.collector_workers=0 cannot continue a checkpoint whose scenarios "
                f"{len(shards)} worker processes collected; set algo.collector_workers="
                f"{len(shards)}"
            )
        if self.shards is not None:
            if "carry" in state:
                raise ValueError(
                    f"algo.collector_workers={self.shards.workers} cannot continue a checkpoint "
                    "whose scenarios the trainer's process collected; set "
                    "algo.collector_workers=0"
                )
            self.shards.load(shards, self.env)
        if "carry" in state:
            carry = self.env.reset()  # a tensordict of the right structure (nested batch sizes)
            self.env.load_state_dict(state["env"])
            carry.update(state["carry"])
            self._carry = carry


class ActorPolicy:
    """A trained actor as a plain callable: observations [B, n, D] → actions [B, n].

    Deterministic by default (the mode of the action distribution); continuous actions come
    back as float m/s², discrete ones as long indices. This is how a learned policy is handed
    to an environment as ``rra_policy`` or ``control_module``. A deterministic discrete actor
    with shared parameters (the RRA policy, called every subframe) is evaluated straight from
    its layers (:class:`~vdtn_marl.algos.networks.CategoricalMode`, the same actions bit for
    bit).
    """

    def __init__(self, actor, group: str, deterministic: bool = True):
        self.actor = actor
        self.group = group
        self.interaction = (
            InteractionType.DETERMINISTIC if deterministic else InteractionType.RANDOM
        )
        self.mode = CategoricalMode.of(actor) if deterministic else None

    @property
    def rowwise(self) -> bool:
        """Whether each scenario's actions depend on its own observation only and a call
        draws no random numbers, so that a caller may ask for some scenarios alone
        (:meth:`~vdtn_marl.core.interval.IntervalEngine.run_radio`): the deterministic fast
        path. On the CPU its actions on a subset of the batch are bit for bit those of the
        whole batch (tests/algos/test_networks.py); elsewhere a BLAS that picks its kernel by
        shape may round a subset's products differently, which stays reproducible by seed."""
        return self.mode is not None

    def __call__(self, observation: torch.Tensor) -> torch.Tensor:
        return self._act(observation, self.mode)

    def bound(self) -> Callable[[torch.Tensor], torch.Tensor]:
        """This policy with its weights read once, now: the same actions as :meth:`__call__`
        for a run of calls during which the weights do not change (the 50 subframes of one
        interval's radio, :meth:`~vdtn_marl.core.interval.IntervalEngine.run_radio`), without
        reading the parameters' TensorDict at every call. Without the fast path, the policy
        itself."""
        if self.mode is None:
            return self
        mode = self.mode.bound()
        return lambda observation: self._act(observation, mode)

    @torch.no_grad()
    def _act(self, observation: torch.Tensor, mode) -> torch.Tensor:
        """The fast path ``mode`` (the CategoricalMode or its binding) where it applies."""
        if mode is not None:
            observation = torch.as_tensor(observation, dtype=torch.float32)
            if self.mode.accepts(observation):
                return mode(observation)
        return self.action(observation)

    def action(self, observation: torch.Tensor) -> torch.Tensor:
        """The actions as :meth:`__call__` gives them, differentiable in the actor's
        parameters (deterministic continuous actions; used to fit the actor by imitation)."""
        observation = torch.as_tensor(observation, dtype=torch.float32)
        td = TensorDict(
            {(self.group, "observation"): observation},
            batch_size=observation.shape[:-2],
            device=observation.device,
        )
        with set_interaction_type(self.interaction):
            action = self.actor(td).get((self.group, "action"))
        return action.squeeze(-1) if action.dim() == observation.dim() else action


class CriticValue:
    """A group critic as a value function: observations [B, n, D] → values [B, n]."""

    def __init__(self, critic, group: str):
        self.critic = critic
        self.group = group

    @torch.no_grad()
    def __call__(self, observation: torch.Tensor) -> torch.Tensor:
        return self.with_grad(observation)

    def with_grad(self, observation: torch.Tensor) -> torch.Tensor:
        """The values, differentiable in the critic's weights (for fitting it)."""
        td = TensorDict(
            {(self.group, "observation"): observation.float()},
            batch_size=observation.shape[:-2],
            device=observation.device,
        )
        return self.critic(td).get((self.group, "state_value")).squeeze(-1)
