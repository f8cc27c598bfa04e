"""Training benchmark: MAPPO frames/s, and the control cost of learned π* against the oracle.

    python benchmarks/training.py                      # full run, writes results/training.json
    python benchmarks/training.py --iterations 5 --quick

Figures:
- MAPPO frames/s (collection + PPO update) on the batched TorchRL face at B scenarios
  (default 256; one frame = one scenario-step, i.e. F vehicle-agent steps), and through
  TorchRL's ``PettingZooWrapper`` around the registered ``vdtn/platoon-control-v0`` (B = 1);
- control cost (−mean reward per follower and interval, perfect observation, held-out
  scenarios) of π* after ``--iterations`` MAPPO iterations, of linear CACC, of the oracle
  (model-predictive over the known leader trace) and of the causal MPC (the same optimiser
  without the leader's future), and π*'s gap to the oracle in percent (target: within 10%) and
  to the causal MPC. The oracle–causal-MPC gap is the value of previewing the leader trace,
  which π* (it observes only the present) cannot learn;
- the value of preview: the control cost of the same MPC when it knows only the next
  ``--preview-s`` seconds of the leader trace (0 s is the causal MPC, the whole 6 s horizon
  the oracle).
"""

from __future__ import annotations

import argparse
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import torch

from vdtn_marl import __version__
from vdtn_marl.algos.baselines import ORACLE_HORIZON_INTERVALS, make_control_baseline
from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.ppo import ActorPolicy, PPOTrainer
from vdtn_marl.config import AlgoConfig, ScenarioConfig
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.runs import atomic_write_json, progress
from vdtn_marl.sim.cacc import CACCController
from vdtn_marl.sim.params import TwinParams

RESULTS = Path(__file__).parent / "results" / "training.json"


def frames_per_second(trainer: PPOTrainer, iterations: int) -> dict[str, float]:
    trainer.train_iteration()  # warm-up (also fits the observation scaling)
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
    return {"frames_per_s": frames / total_s, "collect_frames_per_s": frames / collect_s}


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=256, help="scenarios B of the batched face")
    parser.add_argument("--iterations", type=int, default=150, help="MAPPO iterations for π*")
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
    parser.add_argument("--fps-iterations", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=32, help="evaluation scenarios")
    parser.add_argument("--intervals", type=int, default=200, help="evaluation intervals")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (0: default)")
    parser.add_argument("--quick", action="store_true", help="small figures, no JSON written")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    torch.manual_seed(args.seed)
    if args.threads:
        torch.set_num_threads(args.threads)
    rows: dict[str, object] = {}
    previews = _preview_intervals(args.preview_s, TwinParams().platoon.control_interval_s)

    algo = AlgoConfig(num_envs=args.batch, rollout_steps=50, minibatch_size=4096, epochs=4)
    env = VDTNTorchRLEnv("control", batch_size=args.batch, device=args.device, seed=args.seed)
    trainer = PPOTrainer(env, "vehicle", algo, seed=args.seed, prior=CACCController())
    rows["mappo_batched"] = {"B": args.batch, **frames_per_second(trainer, args.fps_iterations)}

    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    import vdtn_marl

    wrapped = PettingZooWrapper(
        vdtn_marl.make("vdtn/platoon-control-v0"), return_state=False, use_mask=False
    )
    wrapped_trainer = PPOTrainer(
        wrapped, "vehicle", replace(algo, minibatch_size=256, rollout_steps=200), seed=args.seed
    )
    rows["mappo_pettingzoo_wrapper"] = {"B": 1, **frames_per_second(wrapped_trainer, 2)}

    # π* against CACC and the oracle on held-out scenarios (perfect observation)
    params = TwinParams.from_overrides(episode_intervals=max(args.intervals, 200))
    # the training defaults of `vdtn-marl train` / `jocc`, with the model selection switches
    default = replace(
        AlgoConfig(), validate_every=args.validate_every, lr_schedule=args.lr_schedule
    )
    learner = PPOTrainer(
        VDTNTorchRLEnv(
            "control",
            batch_size=default.num_envs,
            device=args.device,
            seed=args.seed,
            episode_intervals=ScenarioConfig().episode_intervals,
        ),
        "vehicle",
        default,
        seed=args.seed,
        prior=CACCController(),
    )
    began = time.perf_counter()
    learner.begin_stage(args.iterations)  # for --lr-schedule and --validate-every
    with progress(args.iterations, "training π*") as bar:
        for _ in range(args.iterations):
            stats = learner.train_iteration()
            bar.update(1)
            bar.set_postfix(reward=f"{stats.reward_mean:.4f}")
    selected = learner.finish_stage()["best_iteration"]
    train_s = time.perf_counter() - began
    common = dict(
        perfect=True, episodes=args.episodes, intervals=args.intervals, seed=10**9 + args.seed,
        device=args.device,
    )  # fmt: skip
    costs = {}
    for name, policy in (
        ("pi_star", ActorPolicy(learner.actor, "vehicle")),
        ("cacc", CACCController(params.platoon)),
        ("oracle", make_control_baseline("oracle", params)),
        ("causal_mpc", make_control_baseline("causal_mpc", params)),
    ):
        began_eval = time.perf_counter()
        result = evaluate_system(params, policy, None, **common)
        costs[name] = {**_costs(result), "eval_seconds": time.perf_counter() - began_eval}
    for preview_s, intervals in previews.items():
        mpc = make_control_baseline("oracle", params, preview_intervals=intervals)
        costs[f"mpc_preview_{preview_s:g}s"] = {
            "preview_s": preview_s,
            **_costs(evaluate_system(params, mpc, None, **common)),
        }
    oracle = costs["oracle"]["control_cost"]
    rows["control_cost"] = costs
    rows["pi_star_gap_to_oracle_percent"] = (
        100.0 * (costs["pi_star"]["control_cost"] - oracle) / oracle
    )
    rows["pi_star_gap_to_causal_mpc_percent"] = (
        100.0
        * (costs["pi_star"]["control_cost"] - costs["causal_mpc"]["control_cost"])
        / costs["causal_mpc"]["control_cost"]
    )
    rows["pi_star_training"] = {
        "iterations": args.iterations,
        "seconds": train_s,
        "lr_schedule": default.lr_schedule,
        "validate_every": default.validate_every,
        "selected_iteration": selected,
    }

    print(f"{'figure':<42} value")
    for key in ("mappo_batched", "mappo_pettingzoo_wrapper"):
        r = rows[key]
        print(f"{key + ' frames/s (B=' + str(r['B']) + ')':<42} {r['frames_per_s']:,.0f}")
        print(f"{key + ' collection frames/s':<42} {r['collect_frames_per_s']:,.0f}")
    for name, c in costs.items():
        print(f"{'control cost ' + name:<42} {c['control_cost']:.5f}")
    print(f"{'pi_star gap to oracle (%)':<42} {rows['pi_star_gap_to_oracle_percent']:.1f}")
    print(f"{'pi_star gap to causal MPC (%)':<42} {rows['pi_star_gap_to_causal_mpc_percent']:.1f}")

    if not args.quick:
        atomic_write_json(
            args.output,
            {
                "command": "python " + " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
                "vdtn_marl_version": __version__,
                "torch": torch.__version__,
                "machine": f"{platform.processor() or platform.machine()}, "
                f"{torch.get_num_threads()} torch threads",
                "device": args.device,
                **rows,
            },
        )
        print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
