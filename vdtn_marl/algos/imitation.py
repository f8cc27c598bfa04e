"""Warm start of the acceleration policy by imitating a model-predictive teacher (DAgger).

PPO from the CACC prior improves on CACC by 7–8 % within the default budgets; the
causal MPC (:class:`~vdtn_marl.policies.mpc_oracle.OracleController` with
``preview_intervals=0``) is 8–16 % better than CACC, and it is causal: it plans from the
present state only. :func:`distill_teacher` copies such a teacher into the actor of a
:class:`~vdtn_marl.algos.ppo.PPOTrainer` before PPO fine-tunes it (``control.warm_start`` in
the run config), in the manner of DAgger (Ross, Gordon and Bagnell, AISTATS 2011):

- round 0 drives the twin with the teacher's commands plus Gaussian exploration noise
  (``exploration_std_mps2``); every later round drives it with the current student, so the
  data covers the states the student itself visits;
- in every round the teacher labels each visited state with its command u (m/s²), on perfect
  observations, and the aggregated data set grows;
- after each round the actor's deterministic command (the mode of its TanhNormal,
  ``center + half_range · tanh(loc)``) is fitted to the labels by mean squared error with Adam.

Only the actor's location network changes (its observation scaling is fitted first, from the
trainer's own scaling rollout, so PPO continues from the same input statistics); the
exploration scale and the critic are PPO's to learn. The scenarios of round r are seeded with
``trainer.seed_for(DISTILLATION_ITERATION − r)``, apart from every training, scaling and
validation batch, and the noise and minibatches draw from a generator seeded with the trainer's
seed, so a warm start is repeatable and leaves the global torch RNG alone (except for the
trainer's observation-scaling rollout, when it has not run yet).

What it costs and gives: docs/training.md.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import torch
from tensordict import TensorDict

from vdtn_marl.algos.ppo import SEED_STRIDE, ActorPolicy, PPOTrainer
from vdtn_marl.core.interval import IntervalEngine
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin

#: ``seed_for`` offset of the first distillation round's scenarios (later rounds count down).
DISTILLATION_ITERATION = SEED_STRIDE - 3
#: Most rounds a distillation may run (keeps its seeds clear of the training iterations').
MAX_ROUNDS = 64


@dataclass
class DistillationStats:
    """What a warm start did."""

    rounds: int
    samples: int  # (state, command) pairs: scenario-intervals × followers
    rms_error_mps2: float  # root mean squared error of the student on all the data, m/s²
    seconds: float


def distillation_ticks(rounds: int = 3, intervals: int = 200, fit_steps: int = 3000) -> int:
    """How many times :func:`distill_teacher` calls ``progress`` (for a progress bar)."""
    return rounds * (intervals + fit_steps // 100)


def _check(name: str, value, low, kind=int) -> None:
    if isinstance(value, bool) or not isinstance(value, kind) or not value >= low:
        what = "an integer" if kind is int else "a number"
        raise ValueError(f"{name}={value!r} must be {what} >= {low}")


def _check_distillation(
    params: TwinParams, rounds, scenarios, intervals, fit_steps, minibatch_size, lr
) -> None:
    """The sizes and step size of a distillation (either group's), each named when bad."""
    _check("rounds", rounds, 1)
    if rounds > MAX_ROUNDS:
        raise ValueError(f"rounds={rounds!r} must be <= {MAX_ROUNDS}")
    _check("scenarios", scenarios, 1)
    _check("intervals", intervals, 1)
    _check("fit_steps", fit_steps, 0)
    _check("minibatch_size", minibatch_size, 1)
    if intervals > params.episode_intervals:
        raise ValueError(
            f"intervals={intervals} must be <= the model's episode_intervals="
            f"{params.episode_intervals}"
        )
    if not lr > 0:
        raise ValueError(f"lr={lr!r} must be > 0")


def distill_teacher(
    trainer: PPOTrainer,
    teacher: Callable[[DigitalTwin], torch.Tensor],
    params: TwinParams,
    *,
    rounds: int = 3,
    scenarios: int = 32,
    intervals: int = 200,
    fit_steps: int = 3000,
    minibatch_size: int = 1024,
    lr: float = 1e-3,
    exploration_std_mps2: float = 0.1,
    trace_source=None,
    progress: Callable[[int], None] | None = None,
    state: dict | None = None,
    on_state: Callable[[dict], None] | None = None,
) -> DistillationStats:
    """Fit ``trainer``'s vehicle actor to ``teacher`` on perfect observations (see module doc).

    Args:
        trainer: a PPOTrainer of the ``vehicle`` group with a continuous (TanhNormal) actor.
        teacher: twin → commands [B, F] (m/s²) from the twin's current state, e.g. an unbound
            :class:`~vdtn_marl.policies.mpc_oracle.OracleController` (causal:
            ``preview_intervals=0``). Its ``reset()``, if any, is called at the start of each
            round.
        params: the twin model the scenarios run on (the trainer's environment's).
        rounds: DAgger rounds (round 0: teacher + noise drives; later: the student).
        scenarios: scenarios B per round; ``intervals`` control intervals each (≤ the episode).
        fit_steps, minibatch_size, lr: Adam steps, minibatch and step size after each round.
        exploration_std_mps2: std (m/s²) of the noise on the teacher's commands in round 0.
        trace_source: the leader traces (default: the model's).
        progress: called with 1 after every simulated interval and every 100 fit steps.
        on_state: called after each round's rollouts and after its fit with the distillation's
            state so far (samples, optimiser, random generator; ``trainer`` holds the actor):
            a caller keeps it with the trainer's state, in a checkpoint.
        state: such a state, with ``trainer`` restored to the same moment: the distillation
            goes on from there, as if it had not stopped.
    """
    if trainer.group != "vehicle":
        raise ValueError(f"distillation trains the 'vehicle' group, not {trainer.group!r}")
    _check_distillation(params, rounds, scenarios, intervals, fit_steps, minibatch_size, lr)
    if not exploration_std_mps2 >= 0:
        raise ValueError(f"exploration_std_mps2={exploration_std_mps2!r} must be >= 0 m/s²")
    began = time.perf_counter()
    tick = progress or (lambda n: None)
    if not trainer.scaling_fitted:
        trainer.fit_observation_scaling()
    device = trainer.device
    student = ActorPolicy(trainer.actor, "vehicle")
    generator = torch.Generator(device=device).manual_seed(trainer.seed)
    # only the location network has a gradient: the mode does not depend on the scale
    optimizer = torch.optim.Adam(trainer.actor.parameters(), lr=lr)
    observations: list[torch.Tensor] = []
    labels: list[torch.Tensor] = []
    first_round, collected = 0, False
    if state is not None:
        optimizer.load_state_dict(state["optimizer"])
        generator.set_state(state["generator"])
        observations, labels = [state["observations"]], [state["labels"]]
        first_round = state["round"] + int(state["fitted"])
        collected = not state["fitted"]
        began -= state["seconds"]

    def keep(r: int, fitted: bool) -> None:
        if on_state is not None:
            on_state({
                "round": r, "fitted": fitted, "seconds": time.perf_counter() - began,
                "observations": torch.cat(observations), "labels": torch.cat(labels),
                "optimizer": optimizer.state_dict(), "generator": generator.get_state(),
            })  # fmt: skip

    for r in range(first_round, rounds):
        if collected and r == first_round:
            data_x, data_y = observations[0], labels[0]
        else:
            data_x, data_y = _collect_round(
                trainer, teacher, params, r, scenarios, intervals, exploration_std_mps2,
                trace_source, generator, student, observations, labels, tick,
            )  # fmt: skip
            keep(r, fitted=False)
        for step in range(fit_steps):
            index = torch.randint(
                0, data_x.shape[0], (min(minibatch_size, data_x.shape[0]),),
                generator=generator, device=device,
            )  # fmt: skip
            loss = (student.action(data_x[index]) - data_y[index]).pow(2).mean()
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            if (step + 1) % 100 == 0:
                tick(1)
        if r + 1 < rounds:
            keep(r, fitted=True)
    with torch.no_grad():
        rms = float((student(data_x) - data_y).pow(2).mean().sqrt())
    return DistillationStats(
        rounds=rounds,
        samples=int(data_y.numel()),
        rms_error_mps2=rms,
        seconds=time.perf_counter() - began,
    )


def _collect_round(
    trainer, teacher, params, r, scenarios, intervals, exploration_std_mps2, trace_source,
    generator, student, observations, labels, tick,
) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """Round ``r`` of :func:`distill_teacher`: its scenarios' observations and the teacher's
    labels, appended to ``observations`` and ``labels``; returns all of them so far."""
    pp = params.platoon
    low, high = pp.accel_min_mps2, pp.accel_max_mps2
    device = trainer.device
    seed = trainer.seed_for(DISTILLATION_ITERATION - r)
    twin = DigitalTwin(
        params, batch_size=scenarios, device=device, seed=seed, radio=False,
        trace_source=trace_source, backend="torch",
    )  # fmt: skip
    twin.reset(seed=seed)
    if hasattr(teacher, "reset"):
        teacher.reset()
    engine = IntervalEngine(twin, perfect=True)
    alive = torch.ones(scenarios, dtype=torch.bool, device=device)
    for k in range(intervals):
        if k > 0:
            engine.advance()
        observation = engine.observe()
        with torch.no_grad():
            label = teacher(twin).to(observation.dtype)
            if r == 0:
                noise = torch.randn(
                    label.shape, generator=generator, device=device, dtype=label.dtype
                )
                act = label + exploration_std_mps2 * noise
            else:
                act = student(observation).to(label.dtype)
        observations.append(observation[alive])  # a collided scenario teaches nothing
        labels.append(label[alive])
        alive &= ~engine.close(act.clamp(low, high)).terminated
        tick(1)
    return torch.cat(observations), torch.cat(labels)


#: ``seed_for`` offset of the first RRA distillation round's scenarios (later rounds count down
#: from it): apart from the vehicle distillation's and every training batch's.
RRA_DISTILLATION_ITERATION = SEED_STRIDE - 3 - MAX_ROUNDS


class _LabelledRadio:
    """An RRA policy for :meth:`IntervalEngine.run_radio` that asks the ``teacher`` for its
    actions in every subframe (a stateful teacher sees every observation), keeps the subframes
    in which some link has a CAM pending, and acts with the ``driver`` (the teacher itself when
    None)."""

    def __init__(self, teacher, driver, bits_left: int):
        self.teacher, self.driver, self.bits_left = teacher, driver, bits_left
        self.observations: list[torch.Tensor] = []
        self.labels: list[torch.Tensor] = []
        self.pending: list[torch.Tensor] = []

    def __call__(self, observation: torch.Tensor) -> torch.Tensor:
        label = torch.as_tensor(self.teacher(observation), device=observation.device).long()
        pending = observation[..., self.bits_left] > 0  # [B, L]: the action has an effect
        rows = pending.any(-1)
        if bool(rows.any()):
            self.observations.append(observation[rows].clone())
            self.labels.append(label[rows])
            self.pending.append(pending[rows])
        return label if self.driver is None else self.driver(observation)


@dataclass
class RRADistillationStats:
    """What an RRA warm start did."""

    rounds: int
    samples: int  # (link, subframe) pairs with a CAM pending
    agreement: float  # share of them on which the student's action is the teacher's
    seconds: float


def distill_rra_teacher(
    trainer: PPOTrainer,
    teacher: Callable[[torch.Tensor], torch.Tensor],
    params: TwinParams,
    control: Callable[[torch.Tensor], torch.Tensor],
    *,
    rounds: int = 3,
    scenarios: int = 16,
    intervals: int = 40,
    fit_steps: int = 1500,
    minibatch_size: int = 1024,
    lr: float = 1e-3,
    trace_source=None,
    completion=None,
    progress: Callable[[int], None] | None = None,
) -> RRADistillationStats:
    """Fit ``trainer``'s RRA actor (a Categorical over sub-channel × power) to an RRA
    ``teacher`` (RRA observations [B, L, D] → actions [B, L], e.g. the opportunistic
    baseline), DAgger as :func:`distill_teacher` does for the vehicles: round 0 runs the radio
    with the teacher, later rounds with the student's deterministic action; the teacher labels
    every subframe and the actor's logits are fitted to its actions by cross-entropy over the
    (link, subframe) pairs with a CAM pending (elsewhere the action has no effect). The
    followers act with ``control`` (the acting control module, on impaired observations, with
    ``completion``); ``scenarios`` of ``intervals`` control intervals per round, seeded with
    ``trainer.seed_for(RRA_DISTILLATION_ITERATION − r)``. The teacher's ``reset()``, if any,
    is called at every round's start. ``progress`` is called with 1 after every interval and
    every 100 fit steps."""
    if trainer.group != "rra":
        raise ValueError(f"RRA distillation trains the 'rra' group, not {trainer.group!r}")
    _check_distillation(params, rounds, scenarios, intervals, fit_steps, minibatch_size, lr)
    began = time.perf_counter()
    tick = progress or (lambda n: None)
    if not trainer.scaling_fitted:
        trainer.fit_observation_scaling()
    device = trainer.device
    student = ActorPolicy(trainer.actor, "rra")
    logits_of = trainer.actor.module[0]  # the TensorDictModule writing (rra, logits)
    generator = torch.Generator(device=device).manual_seed(trainer.seed)
    optimizer = torch.optim.Adam(trainer.actor.parameters(), lr=lr)
    observations: list[torch.Tensor] = []
    labels: list[torch.Tensor] = []
    pending: list[torch.Tensor] = []

    def logits(x: torch.Tensor) -> torch.Tensor:
        td = TensorDict({("rra", "observation"): x}, batch_size=x.shape[:-2], device=device)
        return logits_of(td).get(("rra", "logits"))

    for r in range(rounds):
        seed = trainer.seed_for(RRA_DISTILLATION_ITERATION - r)
        twin = DigitalTwin(
            params, batch_size=scenarios, device=device, seed=seed, radio=True,
            trace_source=trace_source, backend="torch",
        )  # fmt: skip
        twin.reset(seed=seed)
        if hasattr(teacher, "reset"):
            teacher.reset()
        if completion is not None:
            completion.reset()
        radio = _LabelledRadio(teacher, None if r == 0 else student, twin.rra_layout.bits_left)
        engine = IntervalEngine(
            twin, perfect=False, rra_policy=radio, control=control, completion=completion
        )
        engine.run_radio()
        for k in range(intervals):
            if k > 0:
                engine.advance()
            engine.close()
            tick(1)
        observations += radio.observations
        labels += radio.labels
        pending += radio.pending
        data_x, data_y, data_m = torch.cat(observations), torch.cat(labels), torch.cat(pending)
        for step in range(fit_steps):
            index = torch.randint(
                0, data_x.shape[0], (min(minibatch_size, data_x.shape[0]),),
                generator=generator, device=device,
            )  # fmt: skip
            mask = data_m[index]
            loss = torch.nn.functional.cross_entropy(
                logits(data_x[index])[mask], data_y[index][mask]
            )
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            if (step + 1) % 100 == 0:
                tick(1)
    with torch.no_grad():
        agreement = float((student(data_x) == data_y)[data_m].double().mean())
    return RRADistillationStats(
        rounds=rounds,
        samples=int(data_m.sum()),
        agreement=agreement,
        seconds=time.perf_counter() - began,
    )
