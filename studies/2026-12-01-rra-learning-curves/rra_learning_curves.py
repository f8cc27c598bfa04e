"""Learning curves of the JOCC and DRRA RRA agents: how many RRA iterations to a plateau?

For each method (``--methods``) × RRA learning problem (``--credits``) × seed, a JOCC iteration
is run stage by stage with :class:`~vdtn_marl.experiment.jocc.JointOptimisation`'s own stages:
π* (perfect observation; warm-started from the causal MPC unless ``--no-warm-start``) and π̃
(impaired observations under random RRA) for ``--control-iterations`` PPO iterations each, as
JOCC's iteration 0 does; then the RRA agents train for ``--rra-iterations`` PPO iterations
(``loop.rra.train_iteration()``). At RRA iteration 0 and every ``--eval-every`` iterations the
acting system (π̃ with the deterministic RRA actor) is evaluated as JOCC's ``evaluate`` stage
evaluates it (same evaluation seed, held-out traces, completion and IVoI estimator) on
``--eval-episodes`` scenarios × ``--eval-intervals`` control intervals: CAM delivery rate, V2I
throughput per link (Mbps), mean |gap error| (m), mean |speed error| (m/s), control cost,
collision rate; with the RRA training reward of the last iteration. Random, round-robin and
greedy RRA are evaluated once per run on the same scenarios with the same π̃ (reference lines).

Methods: ``jocc_k050`` (``rra=jocc rra.kappa1=0.5``), ``drra`` (``rra=drra``), and
``jocc_k025``/``jocc_k075``/``throughput``. Credits (:data:`CREDITS`, as in
``studies/2026-12-01-rra-positive-control/ivoi_noise.py``): ``paper`` is the default RRA learning problem (γ = 0.99 per
control interval, i.e. γ^(1/T) per subframe, GAE λ = 0.95 per subframe step, silent subframes
masked, scenarios persisting across PPO iterations, 32 scenarios × 250 subframes per batch),
``legacy`` the setting before it (γ = 0.99 and λ = 0.95 per subframe, every subframe trains,
fresh resets, 64 scenarios × 100 subframes). The JSON records both as resolved.

Per method × credit: the curve of the seed means with 95 % Student-t intervals over seeds, and
the plateau budget (:func:`plateau`): the first evaluation point from which the seed-mean CAM
delivery and V2I throughput per link both stay within a tolerance of their mean over the last
``PLATEAU_WINDOW`` points, with fixed tolerances (:data:`PLATEAU_TOLERANCES`: 2 percentage
points of delivery, 0.02 Mbps of V2I per link). A curve counts as plateaued only if its stable
stretch holds at least ``PLATEAU_MIN_POINTS`` points (one more than the window), so a curve
still moving at the end of the budget is reported as not plateaued. The seed intervals are not
the tolerance: with 3 seeds the 95 % t factor is 4.30, and the half-widths (tens of
percentage points where seeds disagree) would call such a curve flat from its first point.

Writes ``studies/2026-12-01-rra-learning-curves/rra_learning_curves.json`` (after every run, atomically) and the
PNG next to it. ``--merge`` adds the runs of an earlier JSON (same evaluation settings) so a
measurement may be split into invocations; ``--report-only`` only merges. The committed
measurement ran as two invocations side by side (about 55 minutes of wall time on a shared
2-core machine at a load average of 3-7), then a merge; the budget is reduced from the default
200 RRA iterations (evaluated every 10, 16 scenarios) to 40 (every 5, 8 scenarios) to fit it:

    OMP_NUM_THREADS=1 python studies/2026-12-01-rra-learning-curves/rra_learning_curves.py --methods jocc_k050,drra \\
        --credits paper --seeds 0,1,2 --rra-iterations 40 --eval-every 5 --eval-episodes 8 \\
        --output studies/2026-12-01-rra-learning-curves/rra_learning_curves_paper.json
    OMP_NUM_THREADS=1 python studies/2026-12-01-rra-learning-curves/rra_learning_curves.py --methods jocc_k050 \\
        --credits legacy --seeds 0,1,2 --rra-iterations 40 --eval-every 5 --eval-episodes 8 \\
        --output studies/2026-12-01-rra-learning-curves/rra_learning_curves_legacy.json
    python studies/2026-12-01-rra-learning-curves/rra_learning_curves.py --seeds 0,1,2 --rra-iterations 40 --eval-every 5 \\
        --eval-episodes 8 --report-only --merge studies/2026-12-01-rra-learning-curves/rra_learning_curves_paper.json \\
        --merge studies/2026-12-01-rra-learning-curves/rra_learning_curves_legacy.json

On the recorded drives (``cmap``, the default traces of runs; random windows of the held-out
vehicles), 15 minutes on a quiet machine:

    OMP_NUM_THREADS=1 python studies/2026-12-01-rra-learning-curves/rra_learning_curves.py --methods jocc_k050,drra \\
        --credits paper --seeds 0,1,2 --rra-iterations 40 --eval-every 10 --eval-episodes 8 \\
        --traces cmap --output studies/2026-12-01-rra-learning-curves/rra_learning_curves_cmap.json

The merged ``rra_learning_curves.json`` keeps every run and every invocation (command, date,
load averages, seconds); the two partial files are not kept. Most of the time goes to the
control stages (π*'s causal-MPC warm start: 7-12 minutes per seed at a quarter of a core);
one RRA iteration took 1-2.5 s and one evaluation of 8 scenarios 10-20 s, so a longer RRA
budget costs little once π̃ is trained.

A tiny timing run: ``--seeds 0 --rra-iterations 4 --eval-every 2 --eval-episodes 2
--control-iterations 1 --output x.json``.
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import importlib.util
import math
import os
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch
from rich.table import Table

from vdtn_marl.algos.checkpoint import rng_state, set_rng_state
from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.ppo import ActorPolicy
from vdtn_marl.data import trace_source_names
from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RRAConfig,
    RunConfig,
    ScenarioConfig,
    validate,
)
from vdtn_marl.experiment.evaluate import EVAL_SEED_OFFSET
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import atomic_write_json, read_json
from vdtn_marl.policies import make_rra_baseline
from vdtn_marl.reporting.benchmarking import parse_names, parse_seeds, provenance, table_console
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.voi import mean_ci

RESULTS = Path(__file__).parent / "rra_learning_curves.json"

#: ``--methods``: the RRA configuration of each method (control learned: π̃).
METHODS = {
    "jocc_k025": dict(name="jocc", kappa1=0.25),
    "jocc_k050": dict(name="jocc", kappa1=0.5),
    "jocc_k075": dict(name="jocc", kappa1=0.75),
    "drra": dict(name="drra"),
    "throughput": dict(name="throughput"),
}


def _ivoi_noise():
    """studies/2026-12-01-rra-positive-control/ivoi_noise.py, whose ``CREDITS`` name the RRA learning problems."""
    spec = importlib.util.spec_from_file_location(
        "ivoi_noise",
        Path(__file__).resolve().parents[1] / "2026-12-01-rra-positive-control" / "ivoi_noise.py",
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


#: ``--credits``: the RRA learning problem (AlgoConfig overrides, ``CREDITS`` of
#: ``studies/2026-12-01-rra-positive-control/ivoi_noise.py``). ``paper``: the defaults; ``legacy``: the setting before them.
CREDITS = {name: _ivoi_noise().CREDITS[name] for name in ("paper", "legacy")}
BASELINES = ("random", "round_robin", "greedy")
#: the evaluation figures of a curve point (keys of ``evaluate_system``'s metrics)
METRICS = (
    "cam_delivery_rate",
    "v2i_throughput_mbps_per_link",
    "gap_error_abs_m",
    "speed_error_abs_mps",
    "control_cost",
    "collision_rate",
)
LABELS = {
    "cam_delivery_rate": "CAM delivery rate",
    "v2i_throughput_mbps_per_link": "V2I throughput per link (Mbps)",
    "gap_error_abs_m": "mean |gap error| (m)",
    "speed_error_abs_mps": "mean |speed error| (m/s)",
}
#: the plateau rule: reference window (last points), tolerances of the seed means, and the
#: shortest stable stretch that counts as a plateau
PLATEAU_WINDOW = 3
PLATEAU_TOLERANCES = {"cam_delivery_rate": 0.02, "v2i_throughput_mbps_per_link": 0.02}
PLATEAU_MIN_POINTS = PLATEAU_WINDOW + 1


# ---------------------------------------------------------------------- statistics
def interval(samples) -> dict[str, float | int]:
    """Mean with its 95 % Student-t interval over the finite samples (NaN bounds for one)."""
    finite = [float(x) for x in samples if x is not None and math.isfinite(float(x))]
    if not finite:
        return {"mean": float("nan"), "low": float("nan"), "high": float("nan"), "n": 0}
    mean, low, high = mean_ci(torch.tensor(finite, dtype=torch.float64))
    return {"mean": mean, "low": low, "high": high, "n": len(finite)}


def stable_from(means, tolerance: float, window: int = PLATEAU_WINDOW) -> int:
    """The first index from which every value of ``means`` lies within ``tolerance`` of the
    mean of its last ``window`` values."""
    if len(means) < window:
        raise ValueError(f"a plateau needs at least window={window} points, got {len(means)}")
    reference = statistics.fmean(means[-window:])
    start = len(means)
    for index in range(len(means) - 1, -1, -1):
        if abs(means[index] - reference) > tolerance:
            break
        start = index
    return start


def plateau(
    iterations,
    means: dict[str, list[float]],
    tolerances: dict[str, float] = PLATEAU_TOLERANCES,
    window: int = PLATEAU_WINDOW,
    min_points: int = PLATEAU_MIN_POINTS,
) -> dict[str, Any]:
    """The plateau budget of seed-mean curves evaluated at RRA ``iterations``.

    For each metric of ``tolerances``: the first point from which the curve stays within its
    tolerance of the mean of the last ``window`` points (:func:`stable_from`). The budget is
    the later of the metrics' first points; ``plateaued`` is whether at least ``min_points``
    points (``min_points`` > ``window``) lie in the stable stretch of every metric."""
    iterations = list(iterations)
    if min_points <= window:
        raise ValueError(f"min_points={min_points} must exceed window={window}")
    per_metric = {}
    for metric, tolerance in tolerances.items():
        curve = list(means[metric])
        if len(curve) != len(iterations):
            raise ValueError(f"{metric}: {len(curve)} points for {len(iterations)} iterations")
        start = stable_from(curve, tolerance, window)
        per_metric[metric] = {
            "tolerance": tolerance,
            "reference": statistics.fmean(curve[-window:]),
            "stable_from_iteration": iterations[start] if start < len(curve) else None,
            "stable_points": len(curve) - start,
        }
    stable_points = min(entry["stable_points"] for entry in per_metric.values())
    start = len(iterations) - stable_points
    plateaued = stable_points >= min_points
    return {
        "plateaued": plateaued,
        "budget_iterations": iterations[start] if plateaued else None,
        "stable_points": stable_points,
        "metrics": per_metric,
    }


# ---------------------------------------------------------------------- runs
def run_config(
    method: str,
    credit: str,
    seed: int,
    control_iterations: int = 8,
    rra_iterations: int = 200,
    eval_episodes: int = 16,
    eval_intervals: int = 200,
    warm_start: bool = True,
    traces: str = "udds",
) -> RunConfig:
    """The run's config: the defaults (platoon4, learned control) on the leader trace set
    ``traces`` with the method's RRA config, the credit's RRA learning problem and these
    budgets."""
    experiment = replace(
        ExperimentConfig(),
        control_iterations=control_iterations,
        rra_iterations=rra_iterations,
        eval_episodes=eval_episodes,
        eval_intervals=eval_intervals,
        checkpoint_every=0,
    )
    control = ControlConfig() if warm_start else ControlConfig(warm_start="none")
    return validate(
        RunConfig(
            # evaluation windows drawn at random out of the held-out part (the behaviour the
            # committed figures were measured with; 16 disjoint ones do not fit in udds's)
            scenario=ScenarioConfig(traces=traces, eval_windows="random"),
            rra=RRAConfig(**METHODS[method]),
            control=control,
            algo=replace(AlgoConfig(), **CREDITS[credit]),
            experiment=experiment,
            seed=seed,
            progress=False,
        )
    )


class _SilentBar:
    """The progress bar a JOCC stage updates, doing nothing."""

    def update(self, n: int = 1) -> None:
        pass

    def set_postfix(self, **kwargs) -> None:
        pass


def train_control(loop: JointOptimisation, cache: dict | None = None) -> bool:
    """π* then π̃ as JOCC's iteration 0 trains them (its own stage methods, in order).

    The control stages do not depend on the RRA reward: loops that differ only in it train
    bit-identical π* and π̃ and leave the torch RNG in the same state. With ``cache`` the
    first such loop's trainers, RNG state and position are kept (keyed by the seed and the
    algorithm and control configs) and loaded into the next; returns whether it was."""
    cfg = loop.cfg
    key = repr((cfg.seed, cfg.algo, cfg.control, cfg.experiment.control_iterations))
    if cache is not None and key in cache:
        kept = cache[key]
        loop.pi_star.load_state_dict(copy.deepcopy(kept["pi_star"]))
        loop.pi_tilde.load_state_dict(copy.deepcopy(kept["pi_tilde"]))
        loop.position = copy.deepcopy(kept["position"])
        set_rng_state(kept["rng"])
        return True
    for stage in ("control_perfect", "control_impaired"):
        loop._train_stage(stage, _SilentBar())
        loop._advance()
    if cache is not None:
        cache[key] = copy.deepcopy(
            {
                "pi_star": loop.pi_star.state_dict(),
                "pi_tilde": loop.pi_tilde.state_dict(),
                "position": loop.position,
                "rng": rng_state(),
            }
        )
    return False


def evaluate_acting(loop: JointOptimisation, rra_policy) -> dict[str, float]:
    """The metrics of π̃ with ``rra_policy`` as JOCC's ``evaluate`` stage measures the acting
    system (its evaluation seed, held-out traces, completion and IVoI estimator)."""
    cfg = loop.cfg
    acting = evaluate_system(
        loop.params,
        loop.control_policy(),
        rra_policy,
        perfect=False,
        episodes=cfg.experiment.eval_episodes,
        intervals=cfg.experiment.eval_intervals,
        seed=EVAL_SEED_OFFSET + cfg.seed,
        gamma=loop.gamma,
        device=loop.device,
        trace_source=loop.eval_traces,
        ivoi_estimator=loop.estimator,
        completion=loop.completion,
    )
    return {key: acting.metrics.get(key, float("nan")) for key in METRICS}


def _weights_key(module: torch.nn.Module) -> str:
    digest = hashlib.sha256()
    for name, tensor in sorted(module.state_dict().items()):
        digest.update(name.encode())
        digest.update(tensor.detach().cpu().numpy().tobytes())
    return digest.hexdigest()


def learning_curve(cfg: RunConfig, eval_every: int, cache: dict | None = None, log=print) -> dict:
    """One run: control stages, baselines, then the RRA curve (see the module doc).
    ``cache`` (a dict kept across runs) shares the control stages (:func:`train_control`)
    and the baselines' figures of identical π̃ weights."""
    began = time.perf_counter()
    cache = {} if cache is None else cache
    with tempfile.TemporaryDirectory(prefix="rra_curves_") as run_dir:
        loop = JointOptimisation(cfg, run_dir)
        reused = train_control(loop, cache.setdefault("control", {}))
        control_seconds = time.perf_counter() - began
        # the baselines see the same π̃ and scenarios; identical π̃ weights give identical figures
        key = (cfg.seed, _weights_key(loop.pi_tilde.actor), cfg.experiment.eval_episodes)
        figures = cache.setdefault("baselines", {})
        if key not in figures:
            figures[key] = {
                name: evaluate_acting(loop, make_rra_baseline(name, loop.params, cfg.seed))
                for name in BASELINES
            }
        baselines = figures[key]
        policy = ActorPolicy(loop.rra.actor, "rra")
        budget = cfg.experiment.rra_iterations
        curve = [{"rra_iteration": 0, **evaluate_acting(loop, policy), "rra_reward_mean": None}]
        log(f"  RRA it 0: delivery {curve[-1]['cam_delivery_rate']:.3f}")
        loop.rra.begin_stage(budget)
        train_seconds = 0.0
        while loop.rra.iteration < budget:
            stats = loop.rra.train_iteration()
            train_seconds += stats.seconds
            done = loop.rra.iteration
            if done % eval_every == 0 or done == budget:
                point = evaluate_acting(loop, policy)
                curve.append({"rra_iteration": done, **point, "rra_reward_mean": stats.reward_mean})
                log(
                    f"  RRA it {done}: delivery {point['cam_delivery_rate']:.3f}, V2I "
                    f"{point['v2i_throughput_mbps_per_link']:.3f} Mbps, reward "
                    f"{stats.reward_mean:.4f} ({time.perf_counter() - began:.0f} s)"
                )
        loop.rra.finish_stage()
        loop.loggers.close()
    return {
        "warm_start": loop.position.get("warm_start"),
        "control_stages_shared": reused,
        "pi_tilde_sha256": key[1],
        "baselines": baselines,
        "curve": curve,
        "seconds": time.perf_counter() - began,
        "control_seconds": control_seconds,
        "rra_train_seconds": train_seconds,
    }


# ---------------------------------------------------------------------- summary
def summarise(runs: list[dict]) -> dict[str, dict]:
    """Per method × credit: the curve of seed means with t intervals, the final point, the
    baselines and the plateau (:func:`plateau`)."""
    groups: dict[str, list[dict]] = {}
    for run in runs:
        groups.setdefault(f"{run['method']}/{run['credit']}", []).append(run)
    out = {}
    for label, members in groups.items():
        iterations = [p["rra_iteration"] for p in members[0]["curve"]]
        if any([p["rra_iteration"] for p in m["curve"]] != iterations for m in members):
            raise SystemExit(f"{label}: the runs were evaluated at different RRA iterations")
        curve = []
        for index, iteration in enumerate(iterations):
            point: dict[str, Any] = {"rra_iteration": iteration}
            for key in (*METRICS, "rra_reward_mean"):
                point[key] = interval(m["curve"][index][key] for m in members)
            curve.append(point)
        means = {k: [p[k]["mean"] for p in curve] for k in PLATEAU_TOLERANCES}
        found = (
            plateau(iterations, means)
            if len(iterations) >= PLATEAU_WINDOW
            else {"plateaued": False, "budget_iterations": None, "note": "too few points"}
        )
        out[label] = {
            "method": members[0]["method"],
            "credit": members[0]["credit"],
            "seeds": [m["seed"] for m in members],
            "curve": curve,
            "final": curve[-1],
            "baselines": {
                name: {k: interval(m["baselines"][name][k] for m in members) for k in METRICS}
                for name in BASELINES
            },
            "plateau": found,
        }
    return out


def _ci(entry: dict, digits: int = 3) -> str:
    mean, low, high = entry["mean"], entry["low"], entry["high"]
    if not math.isfinite(low):
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {(high - low) / 2:.{digits}f}"


def results_table(summary: dict[str, dict], baselines: dict[str, dict]) -> Table:
    table = Table(title="Final evaluation point (mean ± 95 % t half-width over seeds)")
    columns = (
        "method/credit", "seeds", "RRA it", "CAM delivery", "V2I/link (Mbps)", "|gap| (m)",
        "|speed| (m/s)", "control cost", "collisions", "plateau at",
    )  # fmt: skip
    for column in columns:
        table.add_column(column, justify="right")
    for label, group in summary.items():
        final = group["final"]
        found = group["plateau"]
        table.add_row(
            label,
            str(len(group["seeds"])),
            str(final["rra_iteration"]),
            _ci(final["cam_delivery_rate"]),
            _ci(final["v2i_throughput_mbps_per_link"]),
            _ci(final["gap_error_abs_m"]),
            _ci(final["speed_error_abs_mps"]),
            _ci(final["control_cost"], 4),
            _ci(final["collision_rate"], 2),
            str(found["budget_iterations"]) if found["plateaued"] else "not reached",
        )
    for name, figures in baselines.items():
        table.add_row(
            f"{name} RRA",
            f"{figures['pi_tilde']} π̃",
            "-",
            *(
                _ci(figures[k], 4 if k == "control_cost" else 2 if k == "collision_rate" else 3)
                for k in METRICS
            ),
            "-",
        )
    return table


def pooled_baselines(runs: list[dict]) -> dict[str, dict]:
    """The RRA baselines' figures over every distinct π̃ of ``runs`` (runs that share their
    control stages share π̃ and count once): mean with its 95 % t interval per metric."""
    distinct = {run["pi_tilde_sha256"]: run["baselines"] for run in runs}
    return {
        name: {
            **{k: interval(b[name][k] for b in distinct.values()) for k in METRICS},
            "pi_tilde": len(distinct),
        }
        for name in BASELINES
    }


def plot(
    summary: dict[str, dict],
    baselines: dict[str, dict],
    path: Path,
    settings: dict[str, Any],
    note: str | None = None,
) -> Path:
    """One panel per metric of :data:`LABELS`: one line per method × credit (seed mean, 95 %
    t band, clipped to the metric's range) and the RRA baselines as horizontal lines."""
    from vdtn_marl.reporting.plots import pyplot_agg, save_figure

    plt = pyplot_agg()
    fig, axes = plt.subplots(2, 2, figsize=(12, 8), dpi=120)
    styles = {"random": ":", "round_robin": "-.", "greedy": "--"}
    for ax, (metric, label) in zip(axes.flat, LABELS.items(), strict=True):
        top = 1.0 if metric == "cam_delivery_rate" else float("inf")
        shown = []
        for name, group in summary.items():
            xs = [p["rra_iteration"] for p in group["curve"]]
            mean = [p[metric]["mean"] for p in group["curve"]]
            low = [max(p[metric]["low"], 0.0) for p in group["curve"]]
            high = [min(p[metric]["high"], top) for p in group["curve"]]
            seeds = len(group["seeds"])
            (line,) = ax.plot(xs, mean, marker=".", linewidth=1.5, label=f"{name} ({seeds} seeds)")
            shown += mean
            if all(math.isfinite(v) for v in low + high):
                ax.fill_between(xs, low, high, color=line.get_color(), alpha=0.15, linewidth=0)
            found = group["plateau"]
            if metric in PLATEAU_TOLERANCES and found.get("plateaued"):
                ax.axvline(found["budget_iterations"], color=line.get_color(), alpha=0.5, lw=0.8)
        for name, figures in baselines.items():
            value = figures[metric]["mean"]
            if math.isfinite(value):
                shown.append(value)
                ax.axhline(
                    value, color="0.3", linestyle=styles[name], linewidth=1, label=f"{name} RRA"
                )
        finite = [v for v in shown if math.isfinite(v)]
        if metric == "cam_delivery_rate":
            ax.set_ylim(-0.02, 1.02)
        elif finite:
            ax.set_ylim(0.0, 1.25 * max(finite))  # the bands may leave the panel
        ax.set_xlabel("RRA PPO iterations")
        ax.set_ylabel(label)
        ax.set_title(label)
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7, loc="center right")
    control = settings["control_iterations"]
    fig.suptitle(
        f"RRA learning curves: {settings['eval_episodes']} held-out scenarios × "
        f"{settings['eval_intervals']} intervals ({settings['scenario']}, "
        f"{settings['traces']}); π̃ fixed after {control}+{control} control iterations "
        f"(warm start: {settings['warm_start']})\nlines: seed mean; bands: 95 % Student-t "
        "over seeds (clipped to the panel); grey: RRA baselines with the same π̃; "
        "vertical: plateau budget",
        fontsize=9,
    )
    return save_figure(fig, path, note)


def learning_problem(credit: str) -> dict[str, Any]:
    """The RRA learning problem of ``credit`` as it resolves from the defaults."""
    algo = replace(AlgoConfig(), **CREDITS[credit])
    gamma, lmbda = algo.rra_subframe_discounts(TwinParams().platoon.subframes_per_interval)
    keys = (
        "rra_credit", "rra_gamma", "rra_lmbda", "rra_mask_silent", "persistent_envs",
        "rra_num_envs", "rra_rollout_steps",
    )  # fmt: skip
    return {
        "overrides": CREDITS[credit],
        **{key: getattr(algo, key) for key in keys},
        "per_subframe_gamma": gamma,
        "per_subframe_lambda": lmbda,
    }


# ---------------------------------------------------------------------- command line
def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--methods", default="jocc_k050,drra", help=f"of {', '.join(METHODS)}")
    p.add_argument("--credits", default="paper", help=f"of {', '.join(CREDITS)}")
    p.add_argument("--seeds", default="0,1,2", help="run seeds")
    p.add_argument("--control-iterations", type=int, default=8, help="PPO iterations, π* and π̃")
    p.add_argument("--rra-iterations", type=int, default=200, help="RRA PPO iterations")
    p.add_argument("--eval-every", type=int, default=10, help="RRA iterations between evaluations")
    p.add_argument("--eval-episodes", type=int, default=16, help="held-out scenarios")
    p.add_argument("--eval-intervals", type=int, default=200, help="control intervals each")
    p.add_argument("--no-warm-start", action="store_true", help="π* without the causal MPC")
    p.add_argument(
        "--traces",
        default="udds",
        help="leader trace set (default udds, the EPA city cycle: trains on its first 80 %%, "
        "evaluates on its last 20 %%, the set the committed figures were measured on)",
    )
    p.add_argument(
        "--merge",
        type=Path,
        action="append",
        default=[],
        help="add the runs of this results JSON (same settings; repeatable)",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="run nothing: the table, JSON and PNG of the --merge files",
    )
    p.add_argument("--output", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    args.method_list = parse_names("--methods", args.methods, tuple(METHODS))
    args.credit_list = parse_names("--credits", args.credits, tuple(CREDITS))
    args.seed_list = parse_seeds("--seeds", args.seeds)
    if args.traces not in trace_source_names():
        raise SystemExit(
            f"--traces {args.traces!r} is not a known trace set; known here: "
            f"{', '.join(trace_source_names())}"
        )
    for flag, value, minimum in (
        ("--control-iterations", args.control_iterations, 1),
        ("--rra-iterations", args.rra_iterations, 1),
        ("--eval-every", args.eval_every, 1),
        ("--eval-episodes", args.eval_episodes, 1),
        ("--eval-intervals", args.eval_intervals, 1),
    ):
        if value < minimum:
            raise SystemExit(f"{flag} {value!r} must be >= {minimum}")
    if args.eval_intervals > ScenarioConfig().episode_intervals:
        raise SystemExit(
            f"--eval-intervals {args.eval_intervals} exceeds the episode "
            f"({ScenarioConfig().episode_intervals} intervals)"
        )
    if args.report_only and not args.merge:
        raise SystemExit("--report-only needs at least one --merge file")
    return args


def settings(args: argparse.Namespace) -> dict[str, Any]:
    """What every merged run must share."""
    return {
        "scenario": ScenarioConfig().name,
        "traces": args.traces,
        "control_iterations": args.control_iterations,
        "rra_iterations": args.rra_iterations,
        "eval_every": args.eval_every,
        "eval_episodes": args.eval_episodes,
        "eval_intervals": args.eval_intervals,
        "warm_start": "none" if args.no_warm_start else ControlConfig().warm_start,
    }


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    config = settings(args)
    previous: list[dict] = []
    history: list[dict] = []
    for path in args.merge:
        try:
            earlier = read_json(path)
        except (OSError, ValueError) as err:
            raise SystemExit(f"--merge {str(path)!r} cannot be read ({err})") from err
        if earlier.get("settings") != config:
            raise SystemExit(
                f"--merge {str(path)!r} was measured with other settings "
                f"({earlier.get('settings')}, here {config})"
            )
        previous += earlier["runs"]
        history += earlier.get("invocations", [])
    torch.set_num_threads(1)
    console = table_console(160)
    began = time.perf_counter()
    load_before = os.getloadavg()
    new_runs: list[dict] = []
    cache: dict = {}
    this = {**provenance("rra_learning_curves"), "load_average_before": list(load_before)}

    def write() -> tuple[dict[str, dict], dict[str, dict]]:
        fresh = {(r["method"], r["credit"], r["seed"]) for r in new_runs}
        runs = [r for r in previous if (r["method"], r["credit"], r["seed"]) not in fresh]
        runs += new_runs
        summary, baselines = summarise(runs), pooled_baselines(runs)
        invocation = {
            **this,
            "load_average_after": list(os.getloadavg()),
            "seconds": time.perf_counter() - began,
            "runs": [f"{r['method']}/{r['credit']}/seed{r['seed']}" for r in new_runs],
        }
        atomic_write_json(
            args.output,
            {
                **provenance("rra_learning_curves"),
                "settings": config,
                "credits": {c: learning_problem(c) for c in CREDITS},
                "methods": {m: METHODS[m] for m in METHODS},
                "plateau_rule": {
                    "window": PLATEAU_WINDOW,
                    "tolerances": PLATEAU_TOLERANCES,
                    "min_points": PLATEAU_MIN_POINTS,
                    "rule": "first evaluation point from which the seed-mean CAM delivery and "
                    "V2I per link stay within their tolerances of their mean over the last "
                    "window points; plateaued only if the stable stretch holds at least "
                    "min_points points",
                },
                "invocations": [*history, invocation],
                "summary": summary,
                "baselines": baselines,
                "runs": runs,
            },
        )
        return summary, baselines

    summary, baselines = write() if args.report_only else ({}, {})
    for method in [] if args.report_only else args.method_list:
        for credit in args.credit_list:
            for seed in args.seed_list:
                console.print(f"[bold]{method}, credit {credit}, seed {seed}[/]")
                cfg = run_config(
                    method, credit, seed, args.control_iterations, args.rra_iterations,
                    args.eval_episodes, args.eval_intervals, warm_start=not args.no_warm_start,
                    traces=args.traces,
                )  # fmt: skip
                result = learning_curve(cfg, args.eval_every, cache, log=console.print)
                new_runs.append({"method": method, "credit": credit, "seed": seed, **result})
                console.print(f"  done in {result['seconds']:.0f} s")
                summary, baselines = write()
    console.print(results_table(summary, baselines))
    png = plot(summary, baselines, args.output.with_suffix(".png"), config, this["command"][:200])
    console.print(f"wrote {args.output} and {png} in {time.perf_counter() - began:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
