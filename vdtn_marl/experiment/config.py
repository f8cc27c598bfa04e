"""The experiment schema: one structured config shared by the CLI and the training code.

Dataclasses (Hydra's ConfigStore registers them, see :mod:`vdtn_marl.cli`) so every key has a
type and a default; :func:`validate` checks ranges and names the key, the value and what is
allowed. The training entry points (:mod:`vdtn_marl.experiment.api`) take a :class:`RunConfig`.

Groups: ``scenario`` (the model: platoon size, radio, episode, leader traces), ``algo`` (the
MARL learner), ``control`` (who drives the followers), ``rra`` (who allocates radio resources
and with which reward), ``experiment`` (budgets).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace
from typing import Any

from vdtn_marl.algos.params import ACTIVATIONS, MAX_COLLECTOR_WORKERS, AlgoConfig
from vdtn_marl.algos.trainer import ALGORITHMS
from vdtn_marl.core.reward import KAPPA_SUM_ABS_TOL, REWARD_KINDS, TERM_SCALES, RRAReward
from vdtn_marl.errors import ConfigError
from vdtn_marl.io.loggers import DEFAULT_LOGGERS, check_loggers
from vdtn_marl.io.video import VIDEO_FORMATS, VIDEO_SCENARIOS, check_video
from vdtn_marl.policies.registry import CONTROL_BASELINES, RRA_BASELINES
from vdtn_marl.scenarios import DEFAULT_SCENARIO, SCENARIOS, scenario_params
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.voi.registry import IVOI_BASELINES
from vdtn_marl.voi.registry import IVOI_ESTIMATORS as IVOI_ESTIMATOR_REGISTRY

ALGOS = tuple(ALGORITHMS)  # algo.name (vdtn_marl/algos/trainer.py)
# control.name: a learned policy or a baseline of the registry that may drive a run
# (or "policy": the user's own, control.policy; vdtn_marl/experiment/user_policy.py)
CONTROLS = ("learned", *(n for n, b in CONTROL_BASELINES.items() if b.in_runs), "policy")
RRA_CREDITS = ("interval", "subframe")  # values of algo.rra_credit
MPC_CONTROLS = tuple(n for n, b in CONTROL_BASELINES.items() if b.solver_steps)  # mpc_iterations
LEARNED_RRA = REWARD_KINDS  # an RRA policy is learned from one of these rewards ...
RRA_METHODS = LEARNED_RRA + tuple(RRA_BASELINES)  # ... or is a baseline of the registry
RRA_METHODS += ("policy",)  # ... or is the user's own (rra.policy; experiment/user_policy.py)
IVOI_ESTIMATORS = tuple(IVOI_ESTIMATOR_REGISTRY)  # rra.ivoi_estimator (vdtn_marl/voi/registry.py)
VALUE_FITS = ("none", "acting")  # rra.value_fit (vdtn_marl/algos/value_fit.py)
LR_SCHEDULES = ("constant", "linear")
TASKS = ("control", "control_impaired", "rra")
COMPLETIONS = ("none", "hold", "kalman", "learned")
WARM_STARTS = ("none", "causal_mpc")
#: rra.warm_start: none, or an RRA baseline the learned RRA agents imitate before PPO
RRA_WARM_STARTS = ("none", *(name for name in RRA_BASELINES if name not in ("random", "silent")))


@dataclass
class ScenarioConfig:
    """The simulated world. ``model`` holds any further :class:`TwinParams` override."""

    name: str = "platoon4"
    # the scenario class that arranges the vehicles: topology, lanes, agents
    # (vdtn_marl/scenarios/: platoon, two_platoons)
    kind: str = DEFAULT_SCENARIO
    num_vehicles: int = 4  # leader + followers (all platoons together)
    num_subchannels: int = 4  # M
    subchannel_bandwidth_hz: float = 180e3
    cam_size_bits: int = 14_400
    episode_intervals: int = 200  # 10 s at Δt = 50 ms
    # a registered leader trace set: cmap, 65 h of recorded drives of 22 vehicles, trained on
    # 17 and evaluated on 5 others (the EPA cycles udds/hwfet hold 13 and 7 disjoint windows
    # of episode + look-ahead in their held-out stretch: too few for a 16-scenario evaluation)
    traces: str = "cmap"
    trace_path: str | None = None  # a user's trace file (NGSIM, highD, time/speed CSV)
    # how evaluation cuts windows out of a recorded eval part: disjoint (non-overlapping, order
    # set by the seed; refused when there are too few) or random (independent, may overlap)
    eval_windows: str = "disjoint"
    # a trace file's acceleration: clipped by pre-processing to the followers' actuator limits
    # (actuator) or kept as recorded (none: the leader is not bound by those limits)
    trace_accel_clip: str = "actuator"
    model: dict[str, Any] = field(default_factory=dict)

    def model_kwargs(self) -> dict[str, Any]:
        """The scenario and its flat model overrides, as the environments and
        :func:`~vdtn_marl.scenarios.scenario_params` take them (``scenario=kind``, then
        :meth:`TwinParams.from_overrides` keywords)."""
        kw = {
            "num_vehicles": self.num_vehicles,
            "num_subchannels": self.num_subchannels,
            "subchannel_bandwidth_hz": self.subchannel_bandwidth_hz,
            "cam_size_bits": self.cam_size_bits,
            "episode_intervals": self.episode_intervals,
        }
        clash = sorted(set(kw) & set(self.model))
        if clash:
            raise ConfigError(
                f"scenario.model sets {clash[0]!r}, which is a scenario key itself; "
                f"set scenario.{clash[0]} instead"
            )
        return {"scenario": self.kind, **kw, **dict(self.model)}


@dataclass
class ControlConfig:
    """Who drives the followers: a learned policy, linear CACC, the oracle (MPC with the
    leader's future) or the causal MPC (without it)."""

    name: str = "learned"
    augmentation: bool = True  # π̃ sees CAM delay/age and its previous command
    completion: str = "none"  # data completion of late/lost CAMs
    completion_predictor: str | None = None  # completion=learned: path of a trained predictor
    # π* (learned control) before its first PPO stage: "causal_mpc" imitates the causal MPC
    # (DAgger, vdtn_marl.algos.imitation; a better reference: 6.9 % above the MPC oracle on
    # the held-out city cycle against 12.6 % from the prior, docs/control_vs_oracle.md);
    # "none" starts PPO from the CACC prior
    warm_start: str = "causal_mpc"
    # before π*'s first PPO update its critic alone is fitted to the start policy's returns on
    # this many training batches (PPOTrainer.fit_critic), so that PPO's first advantages are
    # measured; 0: none
    pi_star_critic_warmup: int = 10
    # algo.validate_every for π*: every N PPO iterations its deterministic policy is scored on
    # fixed validation scenarios and the best is kept, the stage's start a candidate (so π*
    # ends no worse than its start there); 0: π* keeps its last iterate
    pi_star_validate_every: int = 10
    # π*'s stage ends early once this many validations in a row did not beat its best (its
    # plateau; needs pi_star_validate_every); 0: it runs all experiment.control_iterations
    pi_star_patience: int = 0
    # a π* trained elsewhere (a run directory or checkpoint of a run that trained one, e.g.
    # `vdtn-marl train task=control`): it is loaded and not trained here, so methods can share
    # one π* per scenario and seed (`vdtn-marl bench` with benchmark.pi_star); None: train it
    pi_star: str | None = None
    # control=oracle|causal_mpc: Adam steps per control interval of the MPC's solver; None:
    # the controller's default (oracle 400, causal_mpc 200; see vdtn_marl.policies.mpc_oracle)
    mpc_iterations: int | None = None
    # control=policy: the user's control policy (π̃ is not trained; π* still is, as the
    # reference): module:factory, file.py:factory, or a TorchRL/BenchMARL checkpoint (.pt)
    policy: str | None = None


@dataclass
class RRAConfig:
    """Who allocates sub-channel × power for the V2V links, and the reward it learns from
    (the reward's defaults are those of :class:`~vdtn_marl.core.reward.RRAReward`)."""

    name: str = "jocc"
    kappa1: float = RRAReward.kappa1  # weight of V2I throughput
    kappa2: float | None = None  # weight of IVoI; None means 1 − κ1
    ivoi_estimator: str = "td"
    rollout_intervals: int = 10  # rollout estimator: intervals rolled out with π*
    rollout_bootstrap: bool = True  # rollout estimator: π*'s critic values the tail
    # rollout estimator: ξ compares the actual command with π*'s ("optimal", the paper's IVoI)
    # or with the one a lost CAM would have led to ("cam_lost", a difference reward)
    ivoi_baseline: str = "optimal"
    # td estimator: v* is π*'s critic (none) or a copy fitted, before each RRA stage, on the
    # states the acting system visits, to rollouts of π* (acting; vdtn_marl/algos/value_fit.py)
    value_fit: str = "none"
    value_fit_horizon: int = 100  # value_fit=acting: intervals of π* per target, then its critic
    throughput_scale: float = RRAReward.throughput_scale  # reward units per Mbps of summed V2I rate
    ivoi_scale: float = RRAReward.ivoi_scale  # multiplies ξ before κ2
    # jocc reward: "fixed" uses throughput_scale and ivoi_scale as given (the paper's reading);
    # "spread" sets both before each RRA stage so that each term's spread between the silent
    # and the greedy RRA policy, under the acting system, is 1 (vdtn_marl.core.reward)
    term_scales: str = "fixed"
    miss_penalty: float = RRAReward.miss_penalty  # drra: penalty of a CAM that misses its interval
    aoi_scale: float = RRAReward.aoi_scale  # aoi: reward units per ms of Age of Information
    # rra=policy: the user's RRA policy (no RRA agents are trained): module:factory,
    # file.py:factory, or a TorchRL/BenchMARL checkpoint (.pt)
    policy: str | None = None
    # learned RRA: before their first PPO update the RRA agents imitate this baseline (DAgger,
    # vdtn_marl.algos.imitation.distill_rra_teacher; e.g. opportunistic), as π* imitates the
    # causal MPC; none: PPO from the untrained policy
    warm_start: str = "none"
    # algo.validate_every for the RRA agents: every N PPO iterations their deterministic
    # policy is scored on fixed validation scenarios and the best is kept, the stage's start
    # a candidate (with a warm start: PPO must beat the imitated policy); 0: the last iterate
    validate_every: int = 0
    # learned RRA: the RRA agents also observe the CAM content's innovation (the model
    # parameter rra_cam_innovation; vdtn_marl.sim.layout.RRA_CAM_INNOVATION)
    cam_innovation: bool = False

    @property
    def learned(self) -> bool:
        return self.name in LEARNED_RRA

    @property
    def kappa2_value(self) -> float:
        return 1.0 - self.kappa1 if self.kappa2 is None else self.kappa2


@dataclass
class ExperimentConfig:
    """Budgets. ``*_iterations`` count PPO collect-and-update iterations."""

    name: str = "default"
    jocc_iterations: int = 1
    control_iterations: int = 60
    rra_iterations: int = 30
    eval_episodes: int = 16  # scenarios evaluated (one batch)
    eval_intervals: int = 200  # control intervals per evaluation episode
    checkpoint_every: int = 10  # iterations between checkpoints (0: only at the end)
    # where the metrics go besides metrics.csv and evaluation.csv (always written, the source
    # of plots): csv, tensorboard, wandb, mlflow (TorchRL's loggers; vdtn_marl/io/loggers.py)
    loggers: list[str] = field(default_factory=lambda: list(DEFAULT_LOGGERS))


@dataclass
class RunConfig:
    """Root config of every command."""

    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    rra: RRAConfig = field(default_factory=RRAConfig)
    experiment: ExperimentConfig = field(default_factory=ExperimentConfig)
    task: str = "control"  # for `train`: control (π*), control_impaired (π̃) or rra
    seed: int = 0
    device: str = "cpu"
    threads: int = 1  # torch CPU threads of this run (0: torch's default, one per core)
    resume: bool = False
    checkpoint: str | None = None  # for `eval` (and to start from trained policies)
    progress: bool = True
    # a directory where π*'s warm start is memoised and shared by the runs that would compute
    # the same one (vdtn_marl/experiment/warm_start.py); results do not depend on it
    warm_start_cache: str | None = None
    # each evaluation also writes held-out scenarios as videos, one frame per control
    # interval (<run>/episode.gif or .mp4; needs vdtn-marl[video]; vdtn_marl/io/video.py)
    video: bool = False
    video_format: str = "gif"  # gif or mp4
    # which held-out scenarios: first (episode.<format>) or best_worst (the highest and lowest
    # control return: episode_best and episode_worst, by a second run of the evaluation)
    video_scenarios: str = "first"

    def model_kwargs(self) -> dict[str, Any]:
        """The scenario's model keywords (:meth:`ScenarioConfig.model_kwargs`), with
        ``rra.cam_innovation`` as the model parameter ``rra_cam_innovation``: the one place
        the RRA config reaches into the model (the RRA agents' observation)."""
        kw = self.scenario.model_kwargs()
        if self.rra.cam_innovation:
            kw["rra_cam_innovation"] = True
        return kw

    def twin_params(self) -> TwinParams:
        """The model of the run, with its scenario's topology."""
        return scenario_params(**self.model_kwargs())


def _choice(key: str, value: Any, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ConfigError(f"{key}={value!r} is not allowed; choose one of {', '.join(allowed)}")


def _positive_int(key: str, value: Any, low: int = 1, high: int = 10**9) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise ConfigError(f"{key}={value!r} must be an integer in [{low}, {high}]")


def _real(key: str, value: Any, low: float, high: float, *, low_open: bool = False) -> None:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and value == value
    ok = ok and (value > low if low_open else value >= low) and value <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise ConfigError(f"{key}={value!r} is outside the allowed range {bracket}{low}, {high}]")


def _check_user_policies(control: ControlConfig, rra: RRAConfig) -> None:
    """``control.policy`` goes with ``control=policy`` and ``rra.policy`` with ``rra=policy``;
    each names a policy that resolves (experiment/user_policy.py)."""
    from vdtn_marl.experiment.user_policy import check_policy

    for group, section in (("control", control), ("rra", rra)):
        key = f"{group}.policy"
        if section.name == "policy":
            if section.policy is None:
                raise ConfigError(
                    f"{key}=None: {group}=policy needs {key}=<module:factory, file.py:factory "
                    "or a .pt checkpoint>"
                )
            check_policy(key, section.policy)
        elif section.policy is not None:
            raise ConfigError(
                f"{key}={section.policy!r} is set but {group}={section.name}; a policy of "
                f"your own needs {group}=policy (then {key} acts instead of {section.name})"
            )


def _check_task(cfg: RunConfig) -> None:
    """``task=rra`` (of ``vdtn-marl train``) needs RRA agents that learn."""
    if cfg.task == "rra" and not cfg.rra.learned:
        raise ConfigError(
            f"task=rra trains the RRA agents, but rra={cfg.rra.name} has nothing to learn; "
            f"choose rra={'|'.join(LEARNED_RRA)}"
        )


#: The policies ``eval`` scores without a checkpoint (nothing of theirs is trained): every
#: control but the learned one, every RRA policy but the learned ones.
FIXED_CONTROLS = tuple(name for name in CONTROLS if name != "learned")
FIXED_RRA = tuple(name for name in RRA_METHODS if name not in LEARNED_RRA)


def check_fixed_policies(cfg: RunConfig) -> None:
    """``eval`` without ``checkpoint``: the control and the RRA policy must both be fixed (a
    baseline or the user's), since no trained policy is loaded; :class:`ConfigError` names the
    learned ones and what is allowed."""
    learned = [
        f"{group}={name}"
        for group, name, fixed in (
            ("control", cfg.control.name, FIXED_CONTROLS),
            ("rra", cfg.rra.name, FIXED_RRA),
        )
        if name not in fixed
    ]
    if learned:
        raise ConfigError(
            f"checkpoint=None: eval without a checkpoint scores fixed policies, but "
            f"{' and '.join(learned)} {'is' if len(learned) == 1 else 'are'} learned; allowed: "
            f"checkpoint=<a run directory or checkpoint file>, or "
            f"control={'|'.join(FIXED_CONTROLS)} with rra={'|'.join(FIXED_RRA)}"
        )


def validate(cfg: RunConfig) -> RunConfig:
    """Check every key of ``cfg``; raise :class:`ConfigError` naming key, value and range."""
    _validate_control(cfg.control)
    _validate_rra(cfg)
    _choice("task", cfg.task, TASKS)
    _validate_algo(cfg)
    _validate_run(cfg)
    _validate_scenario(cfg)
    return cfg


def _validate_control(c: ControlConfig) -> None:
    """``control.*``: who drives the followers, and π*'s options."""
    _choice("control.name", c.name, CONTROLS)
    _choice("control.completion", c.completion, COMPLETIONS)
    _choice("control.warm_start", c.warm_start, WARM_STARTS)
    _positive_int("control.pi_star_critic_warmup", c.pi_star_critic_warmup, low=0)
    _positive_int("control.pi_star_validate_every", c.pi_star_validate_every, low=0)
    _positive_int("control.pi_star_patience", c.pi_star_patience, low=0)
    if c.pi_star_patience and not c.pi_star_validate_every:
        raise ConfigError(
            f"control.pi_star_patience={c.pi_star_patience} counts π*'s validations, but "
            "control.pi_star_validate_every=0 scores none; allowed: "
            "control.pi_star_validate_every >= 1, or control.pi_star_patience=0"
        )
    if c.mpc_iterations is not None:
        _positive_int("control.mpc_iterations", c.mpc_iterations, high=100_000)
        if c.name not in MPC_CONTROLS:
            raise ConfigError(
                f"control.mpc_iterations={c.mpc_iterations!r} is allowed only with control="
                f"{'|'.join(MPC_CONTROLS)}, not control={c.name}; leave it unset (null)"
            )
    if c.completion == "learned" and not c.completion_predictor:
        raise ConfigError(
            "control.completion_predictor=None: control.completion=learned needs the path of a "
            "predictor saved by vdtn_marl.algos.completion.train_completion_predictor"
        )


def _validate_rra(cfg: RunConfig) -> None:
    """``rra.*``: the RRA policy, its reward and the IVoI estimator."""
    c, r = cfg.control, cfg.rra
    _choice("rra.name", r.name, RRA_METHODS)
    _check_user_policies(c, r)
    _choice("rra.ivoi_estimator", r.ivoi_estimator, IVOI_ESTIMATORS)
    _choice("rra.warm_start", r.warm_start, RRA_WARM_STARTS)
    _choice("rra.term_scales", r.term_scales, TERM_SCALES)
    if r.term_scales != "fixed" and r.name != "jocc":
        raise ConfigError(
            f"rra.term_scales={r.term_scales!r} scales the jocc reward's two terms; it needs "
            f"rra=jocc, not rra={r.name!r} (allowed here: rra.term_scales=fixed)"
        )
    _positive_int("rra.validate_every", r.validate_every, low=0)
    if not isinstance(r.cam_innovation, bool):
        raise ConfigError(f"rra.cam_innovation={r.cam_innovation!r} must be true or false")
    if r.cam_innovation and cfg.scenario.model.get("rra_cam_innovation") is False:
        raise ConfigError(
            "rra.cam_innovation=true contradicts scenario.model.rra_cam_innovation=false; "
            "set one of them"
        )
    _choice("rra.value_fit", r.value_fit, VALUE_FITS)
    _positive_int("rra.value_fit_horizon", r.value_fit_horizon, high=100_000)
    if r.value_fit != "none" and r.ivoi_estimator != "td":
        raise ConfigError(
            f"rra.value_fit={r.value_fit!r} fits the v* of the td estimator; it needs "
            f"rra.ivoi_estimator=td, not {r.ivoi_estimator!r}"
        )
    _positive_int("rra.rollout_intervals", r.rollout_intervals, high=100_000)
    if not isinstance(r.rollout_bootstrap, bool):
        raise ConfigError(f"rra.rollout_bootstrap={r.rollout_bootstrap!r} must be true or false")
    _choice("rra.ivoi_baseline", r.ivoi_baseline, IVOI_BASELINES)
    if r.ivoi_baseline != "optimal" and r.ivoi_estimator != "rollout":
        raise ConfigError(
            f"rra.ivoi_baseline={r.ivoi_baseline!r} needs rra.ivoi_estimator=rollout "
            f"(got {r.ivoi_estimator!r}; td must compare with π*: rra.ivoi_baseline=optimal)"
        )
    _real("rra.kappa1", r.kappa1, 0.0, 1.0)
    if r.kappa2 is not None:
        _real("rra.kappa2", r.kappa2, 0.0, 1.0)
        if abs(r.kappa1 + r.kappa2 - 1.0) > KAPPA_SUM_ABS_TOL:
            raise ConfigError(
                f"rra.kappa1={r.kappa1!r} + rra.kappa2={r.kappa2!r} must sum to 1 "
                "(leave rra.kappa2 unset to derive it as 1 − κ1)"
            )
    _real("rra.throughput_scale", r.throughput_scale, 0.0, 1e6)
    _real("rra.ivoi_scale", r.ivoi_scale, 0.0, 1e6)
    _real("rra.miss_penalty", r.miss_penalty, 0.0, 1e6)
    _real("rra.aoi_scale", r.aoi_scale, 0.0, 1e6)


def _validate_algo(cfg: RunConfig) -> None:
    """``algo.*``: the learner's sizes, rates and switches."""
    a, s = cfg.algo, cfg.scenario
    _choice("algo.name", a.name, ALGOS)
    _choice("algo.lr_schedule", a.lr_schedule, LR_SCHEDULES)
    for key in (
        "depth",
        "num_cells",
        "epochs",
        "minibatch_size",
        "num_envs",
        "rollout_steps",
        "rra_num_envs",
        "rra_rollout_steps",
    ):
        _positive_int(f"algo.{key}", getattr(a, key))
    _positive_int("algo.validate_every", a.validate_every, low=0)
    _positive_int("algo.update_threads", a.update_threads, low=0, high=1024)
    _positive_int("algo.collector_workers", a.collector_workers, low=0, high=MAX_COLLECTOR_WORKERS)
    if a.collector_workers:
        if a.num_envs % a.collector_workers:
            raise ConfigError(
                f"algo.collector_workers={a.collector_workers} must divide "
                f"algo.num_envs={a.num_envs} (each worker collects an equal share)"
            )
        if str(cfg.device) != "cpu":
            raise ConfigError(
                f"algo.collector_workers={a.collector_workers} needs device=cpu (got "
                f"{cfg.device!r}; on a GPU one process collects the whole batch)"
            )
    # at least one interval of the episode is left after the burn-in
    _positive_int(
        "algo.rra_burn_in_intervals", a.rra_burn_in_intervals, low=0, high=s.episode_intervals - 1
    )
    _positive_int("algo.validation_scenarios", a.validation_scenarios)
    _real("algo.lr", a.lr, 0.0, 1.0, low_open=True)
    _real("algo.gamma", a.gamma, 0.0, 1.0)
    _real("algo.rra_gamma", a.rra_gamma, 0.0, 1.0)
    _real("algo.initial_log_scale", a.initial_log_scale, -10.0, 2.0)
    _real("algo.lmbda", a.lmbda, 0.0, 1.0)
    _real("algo.rra_lmbda", a.rra_lmbda, 0.0, 1.0)
    _choice("algo.rra_credit", a.rra_credit, RRA_CREDITS)
    _choice("algo.activation", a.activation, ACTIVATIONS)
    for key in ("rra_mask_silent", "persistent_envs"):
        if not isinstance(getattr(a, key), bool):
            raise ConfigError(f"algo.{key}={getattr(a, key)!r} must be true or false")
    _real("algo.clip_epsilon", a.clip_epsilon, 0.0, 1.0, low_open=True)
    _real("algo.entropy_coef", a.entropy_coef, 0.0, 1e3)
    _real("algo.critic_coef", a.critic_coef, 0.0, 1e3)
    _real("algo.max_grad_norm", a.max_grad_norm, 0.0, 1e6, low_open=True)


def _validate_run(cfg: RunConfig) -> None:
    """``experiment.*``, ``seed``, ``threads``, loggers and video."""
    e = cfg.experiment
    for key in ("jocc_iterations", "eval_episodes", "eval_intervals"):
        _positive_int(f"experiment.{key}", getattr(e, key))
    for key in ("control_iterations", "rra_iterations", "checkpoint_every"):
        _positive_int(f"experiment.{key}", getattr(e, key), low=0)
    _positive_int("seed", cfg.seed, low=0, high=2**63 - 1)
    _positive_int("threads", cfg.threads, low=0, high=1024)
    check_loggers(e.loggers, "experiment.loggers")  # names, and the extra of a missing one
    if not isinstance(cfg.video, bool):
        raise ConfigError(f"video={cfg.video!r} must be true or false")
    _choice("video_format", cfg.video_format, tuple(VIDEO_FORMATS))
    _choice("video_scenarios", cfg.video_scenarios, tuple(VIDEO_SCENARIOS))
    if cfg.video:
        check_video(cfg.video_format)  # imageio installed (vdtn-marl[video])


def _validate_scenario(cfg: RunConfig) -> None:
    """``scenario.*``: the model's ranges, the traces and the evaluation windows."""
    s, e = cfg.scenario, cfg.experiment
    _choice("scenario.kind", s.kind, tuple(SCENARIOS))
    cfg.twin_params()  # the model validates its own ranges (num_vehicles, bandwidth, ...)
    _check_task(cfg)
    from vdtn_marl.data.selection import (
        EVAL_WINDOWS,
        TRACE_ACCEL_CLIPS,
        check_eval_windows,
        check_trace_lengths,
        check_trace_settings,
    )

    check_trace_settings(s.traces, s.trace_path)
    _choice("scenario.eval_windows", s.eval_windows, EVAL_WINDOWS)
    _choice("scenario.trace_accel_clip", s.trace_accel_clip, TRACE_ACCEL_CLIPS)
    if s.trace_accel_clip != "actuator" and s.trace_path is None:
        raise ConfigError(
            f"scenario.trace_accel_clip={s.trace_accel_clip!r} applies to a trace file "
            "(scenario.trace_path); the shipped trace sets were pre-processed when extracted"
        )
    p = cfg.twin_params()
    check_trace_lengths(
        s.traces, s.trace_path,
        episode_intervals=p.episode_intervals, control_interval_s=p.platoon.control_interval_s,
    )  # fmt: skip
    check_eval_windows(
        s.traces, s.trace_path, s.eval_windows, episodes=e.eval_episodes,
        episode_intervals=p.episode_intervals, control_interval_s=p.platoon.control_interval_s,
        leaders=p.platoon.topology.num_leaders,
    )  # fmt: skip
    if e.eval_intervals > s.episode_intervals:
        raise ConfigError(
            f"experiment.eval_intervals={e.eval_intervals!r} must be <= "
            f"scenario.episode_intervals={s.episode_intervals!r}"
        )


def from_dict(data: dict[str, Any]) -> RunConfig:
    """Build a :class:`RunConfig` from nested plain data; unknown keys raise naming the key."""

    def build(cls, values: dict[str, Any], prefix: str):
        known = {f.name: f for f in fields(cls)}
        kwargs = {}
        for key, value in values.items():
            if key not in known:
                raise ConfigError(f"unknown key '{prefix}{key}'; known: {', '.join(sorted(known))}")
            sub = _NESTED.get((cls, key))
            kwargs[key] = build(sub, value, f"{prefix}{key}.") if sub else value
        return cls(**kwargs)

    return build(RunConfig, dict(data), "")


#: Keys added after checkpoints were first written, with the behaviour a checkpoint without
#: them was run with (not today's default): a loaded run's config means what it meant.
ABSENT_KEY_BEHAVIOUR: dict[tuple[str, str], Any] = {
    ("scenario", "eval_windows"): "random",
    ("algo", "rra_credit"): "subframe",
    ("algo", "rra_mask_silent"): False,
    ("algo", "persistent_envs"): False,
}


def from_saved_dict(data: dict[str, Any]) -> RunConfig:
    """:func:`from_dict` of a config saved with a run (a checkpoint's): keys of
    :data:`ABSENT_KEY_BEHAVIOUR` that it lacks take the behaviour it was run with."""
    data = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items()}
    for (group, key), value in ABSENT_KEY_BEHAVIOUR.items():
        if isinstance(data.get(group), dict):
            data[group].setdefault(key, value)
    return from_dict(data)


def to_dict(cfg: RunConfig) -> dict[str, Any]:
    """Plain nested data (JSON/YAML-safe) of ``cfg``."""
    assert is_dataclass(cfg)
    return asdict(cfg)


_NESTED = {
    (RunConfig, "scenario"): ScenarioConfig,
    (RunConfig, "algo"): AlgoConfig,
    (RunConfig, "control"): ControlConfig,
    (RunConfig, "rra"): RRAConfig,
    (RunConfig, "experiment"): ExperimentConfig,
}


def validate_device(device: str) -> str:
    """Check that torch can use ``device`` here; raise :class:`ConfigError` naming ``device``
    (:func:`vdtn_marl.sim.twin.resolve_device`)."""
    from vdtn_marl.sim.twin import resolve_device

    resolve_device(device)
    return device


# --- benchmarks (`vdtn-marl bench`) ---------------------------------------------------------

#: ``benchmark.interval``: how the leaderboard's confidence intervals across seeds are computed
#: (Student-t, BCa bootstrap, percentile bootstrap; vdtn_marl.leaderboard.stats).
BENCHMARK_INTERVALS = ("t", "bca", "percentile")


@dataclass
class BenchmarkTargetConfig:
    """The benchmark's headline claim, checked by the report (``benchmark.target``).

    On each of ``scenarios``, ``method`` against ``reference``, paired by seed (the seeds both
    have; the target is met when it is met on every scenario):
    for each of ``error_metrics`` the ratio of means method/reference must stay at or below
    ``max_error_ratio`` (its interval: Fieller's, the ratios ρ for which the t interval of the
    per-seed differences method − ρ·reference holds 0), and ``gain_metric`` must be above the
    reference's (the t interval of the paired differences above 0). A criterion is decided
    only from ``min_seeds`` paired seeds on (vdtn_marl.leaderboard.target).
    """

    scenarios: list[str] = field(default_factory=lambda: ["platoon4"])
    method: str = ""
    reference: str = ""
    max_error_ratio: float = 1.25
    error_metrics: list[str] = field(default_factory=list)
    gain_metric: str | None = None
    min_seeds: int = 10


@dataclass
class BenchmarkConfig:
    """A benchmark: ``scenarios`` × ``methods`` × ``seeds``, every run with ``experiment``.

    A method is the list of command-line overrides that selects it, e.g.
    ``["rra=jocc", "rra.kappa1=0.25"]``. Every run (a *cell*) composes, in this order:
    ``scenario=S``, ``experiment=E``, ``overrides`` (budgets shared by every cell), the
    method's overrides, ``budgets[method]`` (the method's own budgets), ``seed=K``. Cells of
    one scenario must evaluate on the same held-out scenarios (same ``experiment.eval_*`` and
    seeds), so that methods are compared scenario by scenario.

    ``version`` names the benchmark's definition in published results (it is written into
    every result file); bump it whenever scenarios, methods, seeds or budgets change.

    ``interval`` chooses the confidence interval of means and paired differences across seeds:
    ``t`` (Student-t, the default), ``bca`` or ``percentile`` (bootstrap with
    ``bootstrap_resamples`` resamples). The IQM's interval is always a bootstrap: BCa under
    ``t`` and ``bca``, percentile under ``percentile``.

    ``extra_seeds`` (``{scenario: {method: [seeds]}}``) runs those cells for these seeds too,
    after the cells of ``seeds`` (e.g. more seeds for the headline comparison only); methods
    then differ in n, and paired differences use the seeds both methods have. ``target``
    (:class:`BenchmarkTargetConfig`, optional) adds the check of the headline claim to the
    report.
    """

    name: str = "smoke"
    version: str = "0.1"
    description: str = ""
    experiment: str = "smoke"
    overrides: list[str] = field(default_factory=list)
    scenarios: list[str] = field(default_factory=lambda: ["platoon4"])
    methods: dict[str, list[str]] = field(default_factory=dict)
    budgets: dict[str, list[str]] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=lambda: [0])
    # {scenario: {method: [seeds]}}: cells run for these seeds in addition to `seeds`
    extra_seeds: dict[str, dict[str, list[int]]] = field(default_factory=dict)
    # the two methods whose gap/speed error traces are compared (same scenario and seed)
    trace_methods: list[str] = field(default_factory=list)
    interval: str = "t"  # one of BENCHMARK_INTERVALS
    bootstrap_resamples: int = 10_000  # resamples of the bootstrap CIs (bca/percentile, IQM)
    confidence: float = 0.95
    target: BenchmarkTargetConfig | None = None  # the headline claim the report checks
    # the π* the cells share, one per scenario and seed: the overrides of its `train
    # task=control` run after `experiment` and `overrides` (e.g. its budget and plateau);
    # null: every cell trains its own π* (vdtn_marl/leaderboard/pi_star.py)
    pi_star: list[str] | None = None


@dataclass
class BenchConfig:
    """Root config of ``vdtn-marl bench``.

    ``out_dir`` holds one run directory per cell (``<scenario>/<method>/seed<k>/``); a cell
    with a complete ``summary.json`` is skipped, so rerunning the command resumes the grid.
    ``report_dir`` receives LEADERBOARD.md, the JSON and CSV exports and the plots (default:
    ``out_dir``). ``shard``/``num_shards`` split the grid between the jobs of a Hydra sweep
    (``-m bench shard=0,1 num_shards=2 hydra/launcher=joblib``). ``cells`` (glob patterns over
    ``<scenario>/<method>/seed<k>``, e.g. ``[platoon4/greedy/*]``; empty: all) runs only the
    matching cells, shards splitting those; the report still covers every complete cell. With
    ``benchmark.pi_star`` the patterns may name the shared π* runs too
    (``<scenario>/pi_star/seed<k>``; ``[*/pi_star/*]`` trains only those).
    ``run=false`` runs no cell and only writes the report of the complete ones.
    ``share_warm_starts`` lets the cells that would compute the same warm start of π* share it
    through ``<out_dir>/warm_starts`` (``warm_start_cache``; the results do not change).
    ``video`` adds videos of the two ``trace_methods`` on their best and worst held-out scenario
    to the report (:mod:`vdtn_marl.leaderboard.videos`).
    """

    benchmark: BenchmarkConfig = field(default_factory=BenchmarkConfig)
    out_dir: str = "outputs/bench/${benchmark.name}-v${benchmark.version}"
    report_dir: str | None = None
    shard: int = 0
    num_shards: int = 1
    cells: list[str] = field(default_factory=list)
    run: bool = True  # false: run no cell, only write the report of the complete ones
    report: bool = True  # write the report once every cell is complete
    device: str = "cpu"
    progress: bool = True
    share_warm_starts: bool = True
    # the report also writes videos of the trace methods on their best and worst held-out
    # scenario (vdtn_marl/leaderboard/videos.py; needs vdtn-marl[video])
    video: bool = False
    # methods of the user's own, {name: [overrides]} like benchmark.methods (e.g. [rra=policy,
    # rra.policy=my_rra.py:make_policy]): run on every scenario and seed of the benchmark,
    # reported beside its methods, not part of its definition (docs/leaderboard.md)
    submissions: dict[str, list[str]] = field(default_factory=dict)
    video_format: str = "gif"  # gif or mp4


#: Keys a benchmark sets itself in every cell; a method or budget may not set them.
BENCHMARK_RESERVED_KEYS = (
    "scenario",
    "seed",
    "device",
    "resume",
    "progress",
    "checkpoint",
    "task",
    "warm_start_cache",
)
_NAME_PATTERN = r"[A-Za-z0-9][A-Za-z0-9_.+-]*"


def validate_benchmark(cfg: BenchConfig) -> BenchConfig:
    """Check the shape of a benchmark (the runs themselves are checked by :func:`validate`)."""
    import re

    b = cfg.benchmark
    if not b.version:
        raise ConfigError("benchmark.version='' must name the benchmark's version, e.g. '0.1'")
    if not isinstance(cfg.video, bool):
        raise ConfigError(f"video={cfg.video!r} must be true or false")
    _choice("video_format", cfg.video_format, tuple(VIDEO_FORMATS))
    if cfg.video:
        check_video(cfg.video_format)  # imageio installed (vdtn-marl[video])
    if not re.fullmatch(_NAME_PATTERN, b.name):
        raise ConfigError(
            f"benchmark.name={b.name!r} must be a plain name (letters, digits, _ . + -)"
        )
    for key in ("scenarios", "methods", "seeds"):
        if not getattr(b, key):
            raise ConfigError(f"benchmark.{key}=[] is empty; list at least one")
    for seed in b.seeds:
        _positive_int("benchmark.seeds", seed, low=0, high=2**63 - 1)
    for key in ("scenarios", "seeds"):
        values = list(getattr(b, key))
        if len(set(values)) != len(values):
            raise ConfigError(f"benchmark.{key}={values} lists a value twice")
    for method in b.methods:
        if not re.fullmatch(_NAME_PATTERN, str(method)):
            raise ConfigError(
                f"benchmark.methods.{method} is not a plain name (letters, digits, _ . + -); "
                "it names the method's directory"
            )
    for name in cfg.submissions:
        if not re.fullmatch(_NAME_PATTERN, str(name)):
            raise ConfigError(
                f"submissions.{name} is not a plain name (letters, digits, _ . + -); it names "
                "the method's directory"
            )
        if name in b.methods:
            raise ConfigError(
                f"submissions.{name} has the name of a method of benchmark {b.name!r}; "
                f"allowed: a name other than {', '.join(b.methods)}"
            )
    if b.pi_star is not None:
        _validate_pi_star(cfg)
    for where, overrides in [
        ("benchmark.overrides", b.overrides),
        *((("benchmark.pi_star", b.pi_star),) if b.pi_star is not None else ()),
        *((f"benchmark.methods.{m}", o) for m, o in b.methods.items()),
        *((f"benchmark.budgets.{m}", o) for m, o in b.budgets.items()),
        *((f"submissions.{m}", o) for m, o in cfg.submissions.items()),
    ]:
        if isinstance(overrides, str) or not isinstance(overrides, Sequence):
            raise ConfigError(f"{where}={overrides!r} must be a list of overrides")
        for item in overrides:
            key = str(item).partition("=")[0].lstrip("+~")
            if key.split(".")[0].split("/")[0] in BENCHMARK_RESERVED_KEYS or key == "experiment":
                raise ConfigError(
                    f"{where} sets {item!r}; the benchmark sets scenario, experiment, seed and "
                    "device itself (use benchmark.scenarios, benchmark.experiment, "
                    "benchmark.seeds, device=); allowed: any other KEY=VALUE or GROUP=OPTION"
                )
    unknown = sorted(set(b.budgets) - set(b.methods))
    if unknown:
        raise ConfigError(
            f"benchmark.budgets.{unknown[0]} names no method; allowed: {', '.join(b.methods)}"
        )
    for method in b.trace_methods:
        if method not in b.methods:
            raise ConfigError(
                f"benchmark.trace_methods={list(b.trace_methods)} names {method!r}, which is not "
                f"a method; allowed: {', '.join(b.methods)}"
            )
    _validate_extra_seeds(b)
    _validate_target(b)
    _choice("benchmark.interval", b.interval, BENCHMARK_INTERVALS)
    _positive_int("benchmark.bootstrap_resamples", b.bootstrap_resamples, low=100, high=10**7)
    _real("benchmark.confidence", b.confidence, 0.5, 1.0, low_open=True)
    if b.confidence >= 1.0:
        raise ConfigError(f"benchmark.confidence={b.confidence!r} must be below 1")
    _positive_int("num_shards", cfg.num_shards, low=1, high=10**6)
    _positive_int("shard", cfg.shard, low=0, high=cfg.num_shards - 1)
    if not cfg.out_dir:
        raise ConfigError("out_dir='' must name the directory of the benchmark's runs")
    _validate_cell_patterns(cfg)
    return cfg


#: The directory name of the shared π* runs (benchmark.pi_star), beside the methods'.
PI_STAR_NAME = "pi_star"


def _validate_pi_star(cfg: BenchConfig) -> None:
    """``benchmark.pi_star``: no method is named like its runs, and none sets π* itself."""
    b = cfg.benchmark
    if isinstance(b.pi_star, str) or not isinstance(b.pi_star, Sequence):
        raise ConfigError(f"benchmark.pi_star={b.pi_star!r} must be a list of overrides or null")
    methods = {**b.methods, **cfg.submissions}
    if PI_STAR_NAME in methods:
        raise ConfigError(
            f"benchmark.methods.{PI_STAR_NAME} names the shared π* runs' directory "
            f"(benchmark.pi_star); allowed: another method name"
        )
    for method, overrides in methods.items():
        for item in overrides:
            key = str(item).partition("=")[0].lstrip("+~")
            if key.startswith("control.pi_star") or key.startswith("control.warm_start"):
                raise ConfigError(
                    f"benchmark.methods.{method} sets {item!r}, but benchmark.pi_star shares "
                    "one π* per scenario and seed across the methods; allowed: set π*'s "
                    "options in benchmark.pi_star"
                )


def selected_cells(patterns: Sequence[str], names: Sequence[str]) -> list[str]:
    """The cell names (``<scenario>/<method>/seed<k>``) matched by any glob pattern of
    ``cells`` (all of them when there is none)."""
    from fnmatch import fnmatchcase

    if not patterns:
        return list(names)
    return [n for n in names if any(fnmatchcase(n, p) for p in patterns)]


def with_submissions(cfg: BenchConfig) -> BenchConfig:
    """``cfg`` with its ``submissions`` as methods of the benchmark after the built-in ones,
    each run on the benchmark's ``seeds`` and, per scenario, on every extra seed any method
    has there (so that it pairs with every method). The definition itself is ``cfg``'s: this
    is what runs and what the report covers."""
    if not cfg.submissions:
        return cfg
    b = cfg.benchmark
    extra = {scenario: dict(by_method) for scenario, by_method in (b.extra_seeds or {}).items()}
    for by_method in extra.values():
        seeds = sorted({int(s) for method_seeds in by_method.values() for s in method_seeds})
        for name in cfg.submissions:
            by_method[name] = seeds
    methods = {**b.methods, **{k: list(v) for k, v in cfg.submissions.items()}}
    return replace(cfg, benchmark=replace(b, methods=methods, extra_seeds=extra))


def _validate_cell_patterns(cfg: BenchConfig) -> None:
    """``cells``: a list of glob patterns, each matching at least one cell of the grid."""
    b = with_submissions(cfg).benchmark
    patterns = cfg.cells if cfg.cells is not None else []
    if isinstance(patterns, str) or not isinstance(patterns, Sequence):
        raise ConfigError(
            f"cells={patterns!r} must be a list of patterns over <scenario>/<method>/seed<k>, "
            "e.g. [platoon4/greedy/*]"
        )
    names = [
        f"{scenario}/{method}/seed{seed}"
        for scenario in b.scenarios
        for method in b.methods
        for seed in benchmark_seeds(b, scenario, method)
    ]
    if b.pi_star is not None:  # the shared π* runs are selectable too
        names += sorted({f"{n.split('/')[0]}/{PI_STAR_NAME}/{n.split('/')[2]}" for n in names})
    for pattern in patterns:
        if not isinstance(pattern, str) or not selected_cells([pattern], names):
            raise ConfigError(
                f"cells: {pattern!r} matches no cell of benchmark {b.name!r}; patterns are "
                f"globs over <scenario>/<method>/seed<k>, e.g. {names[0]!r} or "
                f"'{b.scenarios[0]}/*'"
            )


def benchmark_seeds(b: BenchmarkConfig, scenario: str, method: str) -> list[int]:
    """The seeds a benchmark runs for one scenario × method: ``seeds``, then its
    ``extra_seeds``."""
    extra = (b.extra_seeds or {}).get(scenario, {}).get(method, [])
    return [int(s) for s in b.seeds] + [int(s) for s in extra]


def _validate_extra_seeds(b: BenchmarkConfig) -> None:
    """``benchmark.extra_seeds``: known scenarios and methods, integer seeds listed once and
    not already in ``benchmark.seeds``."""
    from collections.abc import Mapping

    extra = b.extra_seeds if b.extra_seeds is not None else {}
    if not isinstance(extra, Mapping):
        raise ConfigError(
            f"benchmark.extra_seeds={extra!r} must map scenario → method → [seeds], "
            "e.g. {platoon4: {drra: [5, 6]}}"
        )
    for scenario, by_method in extra.items():
        where = f"benchmark.extra_seeds.{scenario}"
        if scenario not in b.scenarios:
            raise ConfigError(
                f"{where} names no scenario of the benchmark; allowed: {', '.join(b.scenarios)}"
            )
        if not isinstance(by_method, Mapping):
            raise ConfigError(f"{where}={by_method!r} must map method → [seeds]")
        for method, seeds in by_method.items():
            key = f"{where}.{method}"
            if method not in b.methods:
                raise ConfigError(f"{key} names no method; allowed: {', '.join(b.methods)}")
            if isinstance(seeds, str | bytes) or not hasattr(seeds, "__iter__"):
                raise ConfigError(f"{key}={seeds!r} must be a list of integer seeds")
            values = list(seeds)
            for seed in values:
                if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
                    raise ConfigError(
                        f"{key}={values} lists {seed!r}, which is not an integer seed in "
                        f"[0, {2**63 - 1}]"
                    )
            twice = sorted({s for s in values if values.count(s) > 1})
            if twice:
                raise ConfigError(f"{key}={values} lists {twice[0]} twice")
            again = [s for s in values if s in set(b.seeds)]
            if again:
                raise ConfigError(
                    f"{key}={values} lists {again[0]}, which benchmark.seeds={list(b.seeds)} "
                    "already runs; allowed: seeds outside benchmark.seeds"
                )


def _validate_target(b: BenchmarkConfig) -> None:
    """``benchmark.target``: a scenario and two methods of the benchmark, known metrics, a
    positive bound, and enough seeds planned to decide it (``min_seeds``)."""
    from collections.abc import Mapping

    if b.target is None:
        return
    if isinstance(b.target, Mapping):
        names = {f.name for f in fields(BenchmarkTargetConfig)}
        unknown = sorted(set(map(str, b.target)) - names)
        if unknown:
            raise ConfigError(
                f"benchmark.target.{unknown[0]} is not a known key; allowed keys of "
                f"benchmark.target: {', '.join(sorted(names))}"
            )
        b.target = BenchmarkTargetConfig(**dict(b.target))
    t = b.target
    from vdtn_marl.experiment.metrics import METRIC_KEYS

    if not t.scenarios:
        raise ConfigError(
            f"benchmark.target.scenarios is empty; allowed: some of {', '.join(b.scenarios)}"
        )
    for scenario in t.scenarios:
        if scenario not in b.scenarios:
            raise ConfigError(
                f"benchmark.target.scenarios names {scenario!r}, which is not a scenario of the "
                f"benchmark; allowed: {', '.join(b.scenarios)}"
            )
    for key in ("method", "reference"):
        value = getattr(t, key)
        if value not in b.methods:
            raise ConfigError(
                f"benchmark.target.{key}={value!r} is not a method of the benchmark; "
                f"allowed: {', '.join(b.methods)}"
            )
    if t.method == t.reference:
        raise ConfigError(
            f"benchmark.target.reference={t.reference!r} is benchmark.target.method too; "
            "allowed: another method"
        )
    metrics = list(t.error_metrics or [])
    for metric in [*metrics, *([t.gain_metric] if t.gain_metric is not None else [])]:
        if metric not in METRIC_KEYS:
            raise ConfigError(
                f"benchmark.target names the metric {metric!r}, which the leaderboard does not "
                f"report; allowed: {', '.join(METRIC_KEYS)}"
            )
    if len(set(metrics)) != len(metrics):
        raise ConfigError(f"benchmark.target.error_metrics={metrics} lists a metric twice")
    if not metrics and t.gain_metric is None:
        raise ConfigError(
            "benchmark.target sets neither error_metrics nor gain_metric; allowed: at least one"
        )
    _real("benchmark.target.max_error_ratio", t.max_error_ratio, 0.0, 1e9, low_open=True)
    _positive_int("benchmark.target.min_seeds", t.min_seeds, low=2, high=10**9)
    for scenario in t.scenarios:
        paired = set(benchmark_seeds(b, scenario, t.method)) & set(
            benchmark_seeds(b, scenario, t.reference)
        )
        if len(paired) < t.min_seeds:
            raise ConfigError(
                f"benchmark.target.min_seeds={t.min_seeds} but the benchmark runs {t.method} and "
                f"{t.reference} on {scenario} for {len(paired)} common seed(s), so the target "
                "could never be decided; allowed: more benchmark.seeds or benchmark.extra_seeds, "
                "or a smaller min_seeds"
            )


def register_configs() -> None:
    """Register the schemas in Hydra's ConfigStore (``run_schema``, ``bench_schema``).

    ``conf/config.yaml`` and ``conf/bench.yaml`` list them first in their defaults, so every
    composed config is typed by these dataclasses: an unknown key or a value of the wrong type
    fails at composition. Ranges are checked afterwards by :func:`validate`.
    """
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance()
    store.store(name="run_schema", node=RunConfig)
    store.store(name="bench_schema", node=BenchConfig)
