"""Training benchmark: MAPPO frames/s, and the control cost of learned π* against the oracle.

    python benchmarks/training.py                      # full run, writes results/training.json
    python benchmarks/training.py --traces synthetic --output results/training_synthetic.json
    python benchmarks/training.py --iterations 5 --quick
    python benchmarks/training.py --warm-starts '' --preview-s '' --fps-iterations 0 \
        --output baselines.json  # baselines only: no π*, no frames/s

Figures:
- MAPPO frames/s (collection + PPO update) on the batched TorchRL face at B scenarios
  (default 256; one frame = one scenario-step, i.e. F vehicle-agent steps), and through
  TorchRL's ``PettingZooWrapper`` around the registered ``vdtn/platoon-control-v0`` (B = 1);
- control cost (−mean reward per follower and interval, perfect observation, held-out
  scenarios of ``--traces``, by default the held-out end of the EPA city cycle) of π* after
  ``--iterations`` MAPPO iterations (one run per ``--pi-seeds`` seed, all evaluated on the
  same scenarios; mean, best and worst), of linear
  CACC, of the exact oracle (the minimum of the evaluated cost over the known leader trace, a
  linear program per scenario, planned 6 s beyond the evaluated intervals: the lower bound),
  of the MPC oracle (``control=oracle``: receding 6 s horizon over the known leader trace,
  ``ORACLE_MPC_ITERATIONS`` = 400 solver steps per interval; leaderboard 1.0 ran 60) and of
  the causal MPC (``control=causal_mpc``: the same MPC without the leader's future, 200 solver
  steps); every row's gap to the exact oracle, and π*'s gaps to the MPC oracle (target:
  within 10 %) and to the causal MPC. π* observes only the present, so what previewing the leader
  trace is worth is out of its reach;
- the value of preview: the control cost of the causal MPC's solver when it knows the next
  ``--preview-s`` seconds of the leader trace (0 s is the causal MPC).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import asdict, replace
from pathlib import Path

import torch

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.imitation import distill_teacher, distillation_ticks
from vdtn_marl.algos.ppo import ActorPolicy, PPOTrainer
from vdtn_marl.data import trace_source_names
from vdtn_marl.data.selection import named_sources
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.experiment.config import AlgoConfig, ScenarioConfig
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.io.log import progress
from vdtn_marl.policies import CAUSAL_MPC_ITERATIONS, make_control_baseline
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.policies.exact_oracle import ORACLE_HORIZON_INTERVALS
from vdtn_marl.reporting.benchmarking import parse_names, parse_seeds, provenance
from vdtn_marl.sim.params import TwinParams

RESULTS = Path(__file__).parent / "results" / "training.json"


def frames_per_second(trainer: PPOTrainer, iterations: int) -> dict[str, float]:
    """Frames/s of ``iterations`` MAPPO iterations (collection + update, and collection
    alone) after one warm-up iteration, with the 1-minute load average before and after
    (other processes on the cores slow every figure)."""
    trainer.train_iteration()  # warm-up (also fits the observation scaling)
    load_before = os.getloadavg()[0]
    collect_s, total_s, frames = 0.0, 0.0, 0
    for _ in range(iterations):
        began = time.perf_counter()
        data = trainer.collect()
        collected = time.perf_counter()
        trainer.update(data)
        trainer.iteration += 1
        collect_s += collected - began
        total_s += time.perf_counter() - began
        frames += data.numel()
    return {
        "frames_per_s": frames / total_s,
        "collect_frames_per_s": frames / collect_s,
        "load_average_1min_before": load_before,
        "load_average_1min_after": os.getloadavg()[0],
    }


def mappo_frames_per_second(args: argparse.Namespace) -> dict[str, dict]:
    """MAPPO frames/s on the batched face (B = ``--batch``) and through ``PettingZooWrapper``."""
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    import vdtn_marl

    algo = AlgoConfig(num_envs=args.batch, rollout_steps=50, minibatch_size=4096, epochs=4)
    env = VDTNTorchRLEnv(
        "control", batch_size=args.batch, device=args.device, seed=args.seed, traces=args.traces
    )
    trainer = PPOTrainer(env, "vehicle", algo, seed=args.seed, prior=CACCController())
    batched = {
        "B": args.batch,
        "traces": args.traces,
        **frames_per_second(trainer, args.fps_iterations),
    }
    wrapped = PettingZooWrapper(
        vdtn_marl.make("vdtn/platoon-control-v0", traces=args.traces),
        return_state=False,
        use_mask=False,
    )
    wrapped_trainer = PPOTrainer(
        wrapped, "vehicle", replace(algo, minibatch_size=256, rollout_steps=200), seed=args.seed
    )
    return {
        "mappo_batched": batched,
        "mappo_pettingzoo_wrapper": {"B": 1, **frames_per_second(wrapped_trainer, 2)},
    }


def _preview_intervals(text: str, interval_s: float) -> dict[float, int]:
    """Parse ``--preview-s`` ("0.25,0.5") into {preview s: whole control intervals}."""
    previews = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        preview_s = float(item)
        intervals = round(preview_s / interval_s)
        horizon_s = ORACLE_HORIZON_INTERVALS * interval_s
        if (
            not 0 < intervals < ORACLE_HORIZON_INTERVALS
            or abs(intervals * interval_s - preview_s) > 1e-9
        ):
            raise SystemExit(
                f"--preview-s {item!r} must be a multiple of {interval_s * 1000:g} ms "
                f"in (0, {horizon_s:g}) s (the oracle's horizon)"
            )
        previews[preview_s] = intervals
    return previews


def _costs(result) -> dict[str, float]:
    """The control-cost figures of one evaluation."""
    keys = ("control_cost", "gap_error_abs_m", "speed_error_abs_mps", "collision_rate")
    return {key: result.metrics[key] for key in keys}


WARM_STARTS = ("none", "causal_mpc")


def train_pi_star(args: argparse.Namespace, seed: int, warm_start: str, params: TwinParams, traces):
    """Train π* with the training defaults of ``vdtn-marl jocc`` (AlgoConfig(), CACC prior),
    the model-selection switches of the command line and ``warm_start`` ("none", or
    "causal_mpc": DAgger imitation of the causal MPC first, as ``control.warm_start``) on the
    training part ``traces`` of ``--traces``; returns (actor, training figures)."""
    algo = replace(
        AlgoConfig(),
        validate_every=args.validate_every,
        lr_schedule=args.lr_schedule,
        **({"lmbda": args.lmbda} if args.lmbda is not None else {}),
    )
    learner = PPOTrainer(
        VDTNTorchRLEnv(
            "control",
            batch_size=algo.num_envs,
            device=args.device,
            seed=seed,
            episode_intervals=ScenarioConfig().episode_intervals,
            trace_source=traces,
        ),
        "vehicle",
        algo,
        seed=seed,
        prior=CACCController(),
    )
    began = time.perf_counter()
    distilled = None
    if warm_start == "causal_mpc":
        teacher = make_control_baseline("causal_mpc", params)
        with progress(distillation_ticks(), f"imitating the causal MPC (seed {seed})") as bar:
            stats = distill_teacher(
                learner,
                teacher,
                params,
                trace_source=traces,
                progress=bar.update,
            )
            distilled = asdict(stats)
    learner.begin_stage(args.iterations)  # for --lr-schedule and --validate-every
    with progress(args.iterations, f"training π* (seed {seed}, {warm_start})") as bar:
        for _ in range(args.iterations):
            stats = learner.train_iteration()
            bar.update(1)
            bar.set_postfix(reward=f"{stats.reward_mean:.4f}")
    selected = learner.finish_stage()["best_iteration"]
    return learner.actor, {
        "seed": seed,
        "warm_start": warm_start,
        "distillation": distilled,
        "iterations": args.iterations,
        "seconds": time.perf_counter() - began,
        "lr_schedule": algo.lr_schedule,
        "validate_every": algo.validate_every,
        "lmbda": algo.lmbda,
        "selected_iteration": selected,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=256, help="scenarios B of the batched face")
    parser.add_argument("--iterations", type=int, default=60, help="MAPPO iterations for π*")
    parser.add_argument("--pi-seeds", default="0,1,2", help="training seeds of π* (one run each)")
    parser.add_argument(
        "--warm-starts",
        default="none,causal_mpc",
        help="π* variants: none (PPO from the CACC prior), causal_mpc (DAgger, then PPO); "
        "'' for none (only the baselines' rows)",
    )
    parser.add_argument("--lmbda", type=float, default=None, help="GAE λ of π* (default: config)")
    parser.add_argument(
        "--validate-every",
        type=int,
        default=5,
        help="π*: keep the best of the iterates validated every N iterations (0: the last)",
    )
    parser.add_argument("--lr-schedule", choices=("constant", "linear"), default="constant")
    parser.add_argument(
        "--preview-s",
        default="0.25,0.5,1,2",
        help="comma-separated leader preview times (s) of the MPC rows ('' for none)",
    )
    parser.add_argument(
        "--traces",
        default=ScenarioConfig().traces,
        help="leader trace set of π*'s training and of the evaluation (default: the scenarios' "
        "default, udds; hwfet, synthetic, ...; udds and hwfet are the bundled EPA cycles, which "
        "train on the first 80 %% of the drive and evaluate on its last 20 %%)",
    )
    parser.add_argument(
        "--fps-iterations", type=int, default=5, help="MAPPO iterations timed (0: no frames/s)"
    )
    parser.add_argument("--episodes", type=int, default=128, help="evaluation scenarios")
    parser.add_argument("--intervals", type=int, default=200, help="evaluation intervals")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (0: default)")
    parser.add_argument("--quick", action="store_true", help="small figures, no JSON written")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if args.traces not in trace_source_names():
        raise SystemExit(
            f"--traces {args.traces!r} is not a known trace set; known here: "
            f"{', '.join(trace_source_names())}"
        )
    torch.manual_seed(args.seed)
    if args.threads:
        torch.set_num_threads(args.threads)
    rows: dict[str, object] = {}
    previews = _preview_intervals(args.preview_s, TwinParams().platoon.control_interval_s)

    if args.fps_iterations < 0:
        raise SystemExit(f"--fps-iterations {args.fps_iterations} must be >= 0")
    if args.fps_iterations:
        rows.update(mappo_frames_per_second(args))

    # π* (one per training seed) against CACC and the MPCs on held-out scenarios (perfect
    # observation), all on the same scenarios
    params = TwinParams.from_overrides(episode_intervals=max(args.intervals, 200))
    train_traces, eval_traces = named_sources(args.traces)  # a recorded set split in time
    common = dict(
        perfect=True, episodes=args.episodes, intervals=args.intervals, seed=10**9 + args.seed,
        device=args.device, trace_source=eval_traces,
    )  # fmt: skip
    # the exact oracle optimises exactly the evaluated intervals
    exact_horizon = {"horizon_intervals": args.intervals}
    costs: dict[str, dict] = {}
    training = []
    variants = parse_names("--warm-starts", args.warm_starts, WARM_STARTS, allow_empty=True)
    per_seed: dict[str, list[float]] = {}
    for warm_start in variants:
        name = f"pi_star_{warm_start}"
        for seed in parse_seeds("--pi-seeds", args.pi_seeds):
            actor, trained = train_pi_star(args, seed, warm_start, params, train_traces)
            training.append(trained)
            result = evaluate_system(params, ActorPolicy(actor, "vehicle"), None, **common)
            costs[f"{name}_seed{seed}"] = _costs(result)
            per_seed.setdefault(name, []).append(costs[f"{name}_seed{seed}"]["control_cost"])
        costs[name] = {
            "control_cost": statistics.fmean(per_seed[name]),
            "min": min(per_seed[name]),
            "max": max(per_seed[name]),
            "seeds": len(per_seed[name]),
        }
    for name, policy in (
        ("cacc", CACCController(params.platoon)),
        ("exact_oracle", make_control_baseline("exact_oracle", params, **exact_horizon)),
        ("oracle", make_control_baseline("oracle", params)),
        ("causal_mpc", make_control_baseline("causal_mpc", params)),
    ):
        began_eval = time.perf_counter()
        result = evaluate_system(params, policy, None, **common)
        costs[name] = {**_costs(result), "eval_seconds": time.perf_counter() - began_eval}
    for preview_s, intervals in previews.items():  # the causal MPC's solver, with preview
        mpc = make_control_baseline(
            "oracle", params, preview_intervals=intervals, iterations=CAUSAL_MPC_ITERATIONS
        )
        costs[f"mpc_preview_{preview_s:g}s"] = {
            "preview_s": preview_s,
            **_costs(evaluate_system(params, mpc, None, **common)),
        }
    rows["mpc_solver_steps_per_interval"] = {
        "oracle": make_control_baseline("oracle", params).iterations,
        "causal_mpc_and_previews": CAUSAL_MPC_ITERATIONS,
    }
    rows["evaluation"] = {
        "episodes": args.episodes,
        "intervals": args.intervals,
        "traces": args.traces,
    }
    rows["control_cost"] = costs

    def gap_percent(cost: float, reference: str) -> float:
        return 100.0 * (cost - costs[reference]["control_cost"]) / costs[reference]["control_cost"]

    references = ("exact_oracle", "oracle", "causal_mpc")
    for name, costs_of_seeds in per_seed.items():
        for reference in references:
            rows[f"{name}_gap_to_{reference}_percent"] = {
                "mean": gap_percent(costs[name]["control_cost"], reference),
                "best_seed": gap_percent(min(costs_of_seeds), reference),
                "worst_seed": gap_percent(max(costs_of_seeds), reference),
            }
    rows["causal_mpc_gap_to_oracle_percent"] = gap_percent(
        costs["causal_mpc"]["control_cost"], "oracle"
    )
    rows["gap_to_exact_oracle_percent"] = {
        name: gap_percent(c["control_cost"], "exact_oracle")
        for name, c in costs.items()
        if name != "exact_oracle"
    }
    rows["pi_star_training"] = training

    print(f"{'figure':<50} value")
    for key in ("mappo_batched", "mappo_pettingzoo_wrapper"):
        if key not in rows:  # --fps-iterations 0
            continue
        r = rows[key]
        print(f"{key + ' frames/s (B=' + str(r['B']) + ')':<50} {r['frames_per_s']:,.0f}")
        print(f"{key + ' collection frames/s':<50} {r['collect_frames_per_s']:,.0f}")
    for name, c in costs.items():
        print(f"{'control cost ' + name:<50} {c['control_cost']:.5f}")
    for name in per_seed:
        for reference in references:
            gap = rows[f"{name}_gap_to_{reference}_percent"]
            print(
                f"{name + ' gap to ' + reference + ' (%, mean [best, worst])':<50} "
                f"{gap['mean']:.1f} [{gap['best_seed']:.1f}, {gap['worst_seed']:.1f}]"
            )
    print(f"{'causal_mpc gap to oracle (%)':<50} {rows['causal_mpc_gap_to_oracle_percent']:.1f}")
    for name, gap in rows["gap_to_exact_oracle_percent"].items():
        print(f"{name + ' gap to exact_oracle (%)':<50} {gap:.1f}")

    if not args.quick:
        atomic_write_json(
            args.output,
            {
                **provenance("training"),
                "device": args.device,
                **rows,
            },
        )
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
