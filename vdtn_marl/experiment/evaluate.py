"""The JOCC loop's ``evaluate`` stage, EVoI, and the metrics of a run's summary.

:func:`evaluate_stage` scores the acting system (π̃ or a control baseline, with the current RRA
policy, on impaired observations) and π* (on perfect ones) over the same held-out scenarios,
seeded apart from every training scenario (:data:`EVAL_SEED_OFFSET`): control cost, gap/speed
errors, CAM delivery and latency, V2I throughput per link, EVoI = J̃ − J* with its 95% CI
(:func:`~vdtn_marl.voi.expected_voi`) and, for comparison, the sum of the IVoI the estimator
paid. A ``task=control`` run scores π* against the CACC instead, and ``eval`` of fixed
policies (no checkpoint, so no trained π*) scores the acting system alone: no EVoI, no IVoI.

:func:`run_summary` is the run's ``summary.json``: what ran (the user's policies first, by
their spec: :func:`user_policy_specs`), the last evaluation's metrics, and the evaluation after
each JOCC iteration (:data:`PER_ITERATION_METRICS`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch

from vdtn_marl import __version__
from vdtn_marl.algos.evaluate import EvalResult, evaluate_system
from vdtn_marl.data.traces import TraceSource
from vdtn_marl.experiment.config import RunConfig, to_dict
from vdtn_marl.io.video import VIDEO_SCENARIOS
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.voi import expected_voi, mean_ci

#: Evaluation scenarios are seeded apart from every training scenario.
EVAL_SEED_OFFSET = 1_000_000_000
#: Metrics of each JOCC iteration's evaluation in the run summary (``per_iteration``).
PER_ITERATION_METRICS = (
    "jocc_iteration",
    "cam_delivery_rate",
    "v2i_throughput_mbps_per_link",
    "gap_error_abs_m",
    "speed_error_abs_mps",
    "control_cost",
    "collision_rate",
    "evoi",
)


@dataclass
class ActingSystem:
    """What acts on impaired observations: the control policy (π̃ or a baseline, obs →
    commands), the RRA policy, the IVoI estimator whose ξ is summed, and the completion of
    late or lost CAM content."""

    control: Callable
    rra: Callable
    ivoi_estimator: Any
    completion: Any


@dataclass
class Evaluation:
    """One ``evaluate`` stage: the row of ``evaluation.csv`` and the results behind it
    (``acting`` is None when π* was scored against the CACC, ``optimal`` None when no π* was
    scored), and with a ``video`` the frames
    of the scenarios it drew, one per control interval, by video stem (the acting system's;
    π*'s when there is none); ``drawn`` the scenario index of each stem."""

    row: dict[str, Any]
    optimal: EvalResult | None
    acting: EvalResult | None
    frames: dict[str, list] = field(default_factory=dict)
    drawn: dict[str, int] = field(default_factory=dict)


class ScenarioView:
    """Scenario ``index`` of a batched twin (or interval record) seen as scenario 0 of a batch
    of one, which is what :func:`~vdtn_marl.envs.render.render_twin` draws: the attributes
    named in ``sliced`` (all, for ``sliced=None``) that are tensors or arrays with the batch
    ``[B, ...]`` first come back as ``[index:index+1]``, and those in ``nested`` as views
    themselves (the twin's state objects); everything else as it is."""

    def __init__(self, obj, index: int, batch: int, sliced=None, nested=()):
        self._obj, self._index, self._batch = obj, index, batch
        self._sliced, self._nested = sliced, nested

    def __getattr__(self, name: str):
        value = getattr(self._obj, name)
        if name in self._nested:
            return ScenarioView(value, self._index, self._batch)
        if self._sliced is not None and name not in self._sliced:
            return value
        shape = getattr(value, "shape", ())
        if hasattr(value, "__getitem__") and len(shape) > 0 and shape[0] == self._batch:
            return value[self._index : self._index + 1]
        return value


#: The twin's attributes with a batch dimension that the renderer reads, and its state objects.
_TWIN_SLICED = ("interval", "last_subchannel", "last_rra_actions", "_v2i_rate_sum")
_TWIN_NESTED = ("platoon", "link_state")


def _render(twin, record, index: int, batch: int):
    from vdtn_marl.envs.render import render_twin  # matplotlib, only for a video

    if index == 0:
        return render_twin(twin, record)
    view = ScenarioView(twin, index, batch, sliced=_TWIN_SLICED, nested=_TWIN_NESTED)
    return render_twin(view, None if record is None else ScenarioView(record, index, batch))


def evaluate_stage(
    cfg: RunConfig,
    params: TwinParams,
    optimal_policy: Callable | None,
    acting: ActingSystem | None,
    *,
    trace_source: str | TraceSource,
    device: torch.device,
    jocc_iteration: int,
    video: str | None = None,
) -> Evaluation:
    """Evaluate π* (``optimal_policy``, perfect observations) and the ``acting`` system over
    ``cfg.experiment.eval_episodes`` held-out scenarios of ``eval_intervals`` intervals; with
    ``acting=None`` (a ``task=control`` run) π* is scored against the CACC instead; with
    ``optimal_policy=None`` (no trained π*: ``eval`` of fixed policies) the acting system is
    scored alone, and the row has no EVoI, IVoI or π* entries.

    ``video`` (a key of :data:`VIDEO_SCENARIOS`) draws scenarios after every interval
    (:func:`~vdtn_marl.envs.render.render_twin`): ``first`` the first scenario during the
    evaluation; ``best_worst`` the scenarios of the highest and the lowest control return,
    by running the same (seeded, deterministic) evaluation once more. Drawing reads the twin
    and changes no result, and the second run leaves the global RNG as it found it."""
    if video is not None and video not in VIDEO_SCENARIOS:
        raise ValueError(f"video={video!r} is not one of {', '.join(VIDEO_SCENARIOS)}")
    if optimal_policy is None and acting is None:
        raise ValueError("evaluate_stage needs π* (optimal_policy), an acting system, or both")
    episodes = cfg.experiment.eval_episodes
    frames: dict[str, list] = {}
    drawn: dict[str, int] = {}

    def draw(twin, record) -> None:
        for stem, index in drawn.items():
            frames.setdefault(stem, []).append(_render(twin, record, index, episodes))

    if video == "first":
        drawn["episode"] = 0
    common = evaluation_scenarios(cfg, trace_source, device)
    began = time.perf_counter()
    optimal = None
    if optimal_policy is not None:
        optimal = evaluate_system(
            params, optimal_policy, None, perfect=True,
            on_interval=draw if drawn and acting is None else None, **common,
        )  # fmt: skip
    row: dict[str, Any] = {"jocc_iteration": jocc_iteration}
    result = None
    acting_args: dict[str, Any] = {}
    if acting is None:
        cacc = evaluate_system(params, CACCController(params.platoon), None, perfect=True, **common)
        row.update(optimal.metrics)
        row["cacc_control_cost"] = cacc.metrics["control_cost"]
    else:
        acting_args = dict(
            perfect=False, ivoi_estimator=acting.ivoi_estimator, record_traces=True,
            completion=acting.completion,
        )  # fmt: skip
        result = evaluate_system(
            params, acting.control, acting.rra, on_interval=draw if drawn else None,
            **acting_args, **common,
        )  # fmt: skip
        row.update(result.metrics)
        if optimal is not None:
            evoi, low, high = expected_voi(result.returns, optimal.returns)
            row.update(
                optimal_control_cost=optimal.metrics["control_cost"],
                evoi=evoi, evoi_ci_low=low, evoi_ci_high=high,
            )  # fmt: skip
        if result.ivoi_sums is not None:
            ivoi, ivoi_low, ivoi_high = mean_ci(result.ivoi_sums)
            row.update(ivoi_sum=ivoi, ivoi_sum_ci_low=ivoi_low, ivoi_sum_ci_high=ivoi_high)
    row["eval_seconds"] = time.perf_counter() - began
    if video == "best_worst":
        returns = (optimal if result is None else result).returns
        drawn.update(episode_best=int(returns.argmax()), episode_worst=int(returns.argmin()))
        with torch.random.fork_rng(devices=[]):
            if result is None:
                evaluate_system(params, optimal_policy, None, perfect=True, on_interval=draw,
                                **common)  # fmt: skip
            else:
                evaluate_system(params, acting.control, acting.rra, on_interval=draw,
                                **acting_args, **common)  # fmt: skip
    return Evaluation(row, optimal, result, frames, drawn)


def evaluation_scenarios(
    cfg: RunConfig, trace_source: str | TraceSource, device: torch.device
) -> dict[str, Any]:
    """The keyword arguments of :func:`~vdtn_marl.algos.evaluate.evaluate_system` that fix a
    run's held-out evaluation scenarios (the same at every evaluation of the run)."""
    return dict(
        episodes=cfg.experiment.eval_episodes, intervals=cfg.experiment.eval_intervals,
        seed=EVAL_SEED_OFFSET + cfg.seed, gamma=cfg.algo.gamma, device=device,
        trace_source=trace_source,
    )  # fmt: skip


def perfect_returns(
    cfg: RunConfig,
    params: TwinParams,
    policy: Callable,
    *,
    trace_source: str | TraceSource,
    device: torch.device,
) -> torch.Tensor:
    """Per-scenario discounted control returns [E] of ``policy`` on perfect observations over
    the run's held-out evaluation scenarios (paired with every evaluation's)."""
    scenarios = evaluation_scenarios(cfg, trace_source, device)
    return evaluate_system(params, policy, None, perfect=True, **scenarios).returns


def run_summary(
    cfg: RunConfig,
    task: str,
    stages: Sequence[str],
    *,
    position: Mapping[str, Any],
    trainer_iterations: Mapping[str, int],
    trace_preprocessing: Any,
    evaluation: Mapping[str, Any],
    eval_rows: Sequence[Mapping[str, Any]],
    seconds: float,
    resumed: bool,
    videos: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The summary of a run of ``task`` (its ``stages``) at ``position``: ``evaluation`` is the
    last evaluation's row, ``eval_rows`` every evaluation's (``evaluation.csv``)."""
    return {
        "vdtn_marl_version": __version__,
        "task": task,
        # rra=policy, control=policy: the user's policies as given (module:factory,
        # file.py:factory or a checkpoint's path), by key
        **({"user_policies": specs} if (specs := user_policy_specs(cfg)) else {}),
        "seed": cfg.seed,
        # the RRA reward weights, where this task trains RRA agents
        **({"kappa1": cfg.rra.kappa1, "kappa2": cfg.rra.kappa2_value} if "rra" in stages else {}),
        "rra": cfg.rra.name,
        "control": cfg.control.name,
        "scenario": cfg.scenario.name,
        "traces": cfg.scenario.traces,
        "trace_path": cfg.scenario.trace_path,
        # what pre-processing changed in a trace file (samples clipped, accelerations)
        "trace_preprocessing": trace_preprocessing,
        "iterations": position["iteration"],
        "trainer_iterations": dict(trainer_iterations),
        # with algo.validate_every: the trainer iteration whose weights each stage kept
        "selected_iterations": dict(position.get("selected_iterations", {})),
        "warm_start": position.get("warm_start"),
        # control.pi_star: the run π* was loaded from (not trained here), and what it holds
        "pi_star_source": position.get("shared_pi_star"),
        # control.pi_star_patience: the stages that ended at their plateau, where
        "plateaus": position.get("plateaus"),
        # control.pi_star_critic_warmup: π*'s critic fitted before its first update
        "critic_warmup": position.get("critic_warmup"),
        # rra.warm_start: the RRA agents' imitation of a baseline
        "rra_warm_start": position.get("rra_warm_start"),
        # rra.term_scales=spread: the jocc reward's scales set before each RRA stage
        "term_scales": position.get("term_scales"),
        # rra.value_fit=acting: each fit of v* (MSE of π*'s critic and of the fitted copy)
        "value_fit": position.get("value_fit"),
        "seconds": seconds,
        "resumed": resumed,
        **{k: v for k, v in evaluation.items() if k != "jocc_iteration"},
        # the evaluation after each JOCC iteration: does the loop improve across them?
        "per_iteration": [
            {k: row.get(k) for k in PER_ITERATION_METRICS if k in row} for row in eval_rows
        ],
        # video=true: the last evaluation's videos by stem (episode, episode_best, ...)
        **({"videos": {k: str(v) for k, v in videos.items()}} if videos else {}),
        "config": summary_config(cfg, task),
    }


def user_policy_specs(cfg: RunConfig) -> dict[str, str]:
    """``{"control.policy": spec, "rra.policy": spec}`` for the groups set to ``policy`` (the
    user's own policy); empty where none is."""
    sections = (("control.policy", cfg.control), ("rra.policy", cfg.rra))
    return {key: str(s.policy) for key, s in sections if s.name == "policy" and s.policy}


def summary_config(cfg: RunConfig, task: str) -> dict[str, Any]:
    """The run's config for its summary: ``task`` (a key of ``vdtn-marl train``, which
    picks one stage) only where the run is one stage; a jocc run's task is the summary's."""
    config = to_dict(cfg)
    if task == "jocc":
        config.pop("task", None)
    return config
