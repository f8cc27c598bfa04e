"""Paired learning check of a change of ``experiment=paper``'s vehicle batch shape (or of
another setting, ``--new-overrides``).

    python studies/2026-12-06-paper-batch-pairing/paper_batch_pairing.py  # writes \
        paper_batch_pairing.json
    python studies/2026-12-06-paper-batch-pairing/paper_batch_pairing.py --stages pi_star \
        --seeds 0 --iterations 4 \
        --eval-every 2 --out /tmp/pairing.json                # a quick look
    python studies/2026-12-06-paper-batch-pairing/paper_batch_pairing.py --old 256x100 \
        --new 256x100 \
        --new-overrides algo.activation=tanh_sigmoid \
            --out studies/2026-12-06-paper-batch-pairing/paper_activation_pairing.json

Two arms share everything but ``algo.num_envs`` × ``algo.rollout_steps`` (the samples per PPO
iteration are equal, so iterations compare at equal frames) and the Hydra overrides of
``--old-overrides`` / ``--new-overrides`` (none by default): ``--old`` (the earlier
``experiment=paper`` shape, 64 scenarios × 400 intervals: whole 20 s episodes) and ``--new``
(more scenarios, shorter rollouts; the environments persist across iterations, so episodes
run on over several batches and GAE bootstraps at the batch end). For every seed, both arms
are built from ``experiment=paper`` with the same seed, train the same number of PPO
iterations from the CACC prior (``control.warm_start=none``, so the batch shape, not the
imitation, moves the curve), and are scored every ``--eval-every`` iterations on the same
held-out scenarios (``--eval-episodes`` × 400 intervals of the held-out traces):

- ``pi_star``: π*, perfect observation, scored on perfect observation;
- ``pi_tilde``: π̃ under uniformly random RRA (``rra=random``, as JOCC iteration 0), scored
  under the same random RRA with its seed fixed.

Arms run interleaved (seed 0 old, seed 0 new, seed 1 old, ...). The table prints, per stage
and evaluation point, the control cost of each arm (mean over seeds) and the paired
difference new − old (mean, min and max over seeds; negative: the new shape learned more per
frame) with its 95 % Student-t interval over the seeds, and each arm's median CPU seconds per
iteration and their ratio (per wall-time learning). The JSON keeps every evaluation, the
command, the date and the load average; it is rewritten after every arm (``complete`` says
whether every arm ran). ``--summarize RESULT`` recomputes a result's table from its runs
(e.g. after a change of what the table reports) and rewrites it, running nothing.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "paper_batch_pairing.json"
STAGES = ("pi_star", "pi_tilde")
#: the held-out evaluation's seed (the same scenarios for every arm and seed)
EVAL_SEED = 10**9 + 7


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stages", default=",".join(STAGES), help=f"some of {', '.join(STAGES)}")
    p.add_argument("--seeds", default="0,1,2", help="run seeds (one pair each)")
    p.add_argument("--old", default="64x400", help="scenarios x rollout intervals of the old arm")
    p.add_argument("--new", default="256x100", help="scenarios x rollout intervals of the new arm")
    p.add_argument("--old-overrides", default="", help="Hydra overrides of the old arm")
    p.add_argument("--new-overrides", default="", help="Hydra overrides of the new arm")
    p.add_argument("--iterations", type=int, default=30, help="PPO iterations per arm")
    p.add_argument("--eval-every", type=int, default=10, help="iterations between evaluations")
    p.add_argument("--eval-episodes", type=int, default=64, help="held-out scenarios")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument(
        "--summarize", type=Path, metavar="RESULT", help="recompute RESULT's table; run nothing"
    )
    args = p.parse_args(argv)
    if args.summarize is not None and not args.summarize.is_file():
        p.error(f"--summarize {args.summarize}: no such result file")
    from vdtn_marl.reporting.benchmarking import parse_names, parse_seeds

    args.stages = parse_names("--stages", args.stages, STAGES)
    args.seeds = parse_seeds("--seeds", args.seeds)
    for flag in ("old", "new"):
        text = getattr(args, flag)
        envs, _, steps = text.partition("x")
        if not (envs.isdigit() and steps.isdigit() and int(envs) > 0 and int(steps) > 0):
            p.error(f"--{flag} {text!r} must look like 64x400 (scenarios x intervals, both >= 1)")
        setattr(args, flag, (int(envs), int(steps)))
    for flag in ("old_overrides", "new_overrides"):
        overrides = getattr(args, flag).split()
        if any("=" not in item for item in overrides):
            p.error(f"--{flag.replace('_', '-')} {getattr(args, flag)!r} must be key=value items")
        setattr(args, flag, overrides)
    if args.old[0] * args.old[1] != args.new[0] * args.new[1]:
        p.error(f"--old {args.old} and --new {args.new} must have equal samples per iteration")
    if args.iterations < 1 or not 1 <= args.eval_every <= args.iterations:
        p.error("--iterations must be >= 1 and --eval-every in [1, --iterations]")
    if args.eval_episodes < 1:
        p.error(f"--eval-episodes {args.eval_episodes} must be >= 1")
    return args


def _loop(seed: int, shape: tuple[int, int], extra: list[str] = ()):
    from vdtn_marl.experiment.compose import (
        compose_config,
        hydra_compose,
        job_config,
        to_run_config,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation

    overrides = [
        "experiment=paper",
        "rra=random",
        "control.warm_start=none",
        f"seed={seed}",
        f"algo.num_envs={shape[0]}",
        f"algo.rollout_steps={shape[1]}",
        *extra,
    ]
    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", overrides)))
    cfg.progress = False
    return JointOptimisation(cfg, tempfile.mkdtemp(prefix="paper_batch_pairing_"))


def run_arm(stage: str, seed: int, shape: tuple[int, int], args, extra=()) -> dict:
    """Train one arm (``extra``: its Hydra overrides) and score it every ``--eval-every``
    iterations."""
    from vdtn_marl.algos.evaluate import evaluate_system
    from vdtn_marl.algos.ppo import ActorPolicy

    loop = _loop(seed, shape, list(extra))
    trainer = loop.pi_star if stage == "pi_star" else loop.pi_tilde
    intervals = loop.params.episode_intervals

    def score() -> dict:
        result = evaluate_system(
            loop.params,
            ActorPolicy(trainer.actor, "vehicle"),
            None,
            perfect=stage == "pi_star",
            episodes=args.eval_episodes,
            intervals=intervals,
            seed=EVAL_SEED,
            trace_source=loop.eval_traces,
            completion=loop.completion,
        )
        keys = ("control_cost", "gap_error_abs_m", "speed_error_abs_mps", "collision_rate")
        return {key: float(result.metrics[key]) for key in keys}

    evaluations = [{"iteration": 0, "frames": 0, **score()}]
    cpu, worker_cpu, wall, frames = [], [], [], 0
    shards = getattr(trainer, "shards", None)  # algo.collector_workers
    trainer.begin_stage(args.iterations)
    for _ in range(args.iterations):
        began, began_cpu = time.perf_counter(), time.process_time()
        stats = trainer.train_iteration()
        cpu.append(time.process_time() - began_cpu)
        worker_cpu.append(shards.last_cpu_s if shards is not None else 0.0)
        wall.append(time.perf_counter() - began)
        frames += shape[0] * shape[1]
        if trainer.iteration % args.eval_every == 0:
            evaluations.append({"iteration": trainer.iteration, "frames": frames, **score()})
    trainer.finish_stage()
    loop.close()  # an arm's collector workers (algo.collector_workers), if any
    return {
        "stage": stage,
        "seed": seed,
        "num_envs": shape[0],
        "rollout_steps": shape[1],
        "evaluations": evaluations,
        "last_reward_mean": float(stats.reward_mean),
        "cpu_s_per_iteration": statistics.median(cpu),
        # the collector workers' CPU seconds of an iteration's collection (all together)
        "worker_cpu_s_per_iteration": statistics.median(worker_cpu),
        "wall_s_per_iteration": statistics.median(wall),
        "load_average_1min_end": os.getloadavg()[0],
    }


def _arm_cpu(run: dict) -> float | None:
    """An arm's CPU seconds per iteration, its collector workers' included (None: a run with
    workers that did not record theirs)."""
    if "worker_cpu_s_per_iteration" not in run:
        overrides = " ".join(run.get("overrides") or [])
        if "collector_workers=" in overrides and "collector_workers=0" not in overrides:
            return None
        return run["cpu_s_per_iteration"]
    return run["cpu_s_per_iteration"] + run["worker_cpu_s_per_iteration"]


def _median_or_none(values) -> float | None:
    values = list(values)
    return None if any(v is None for v in values) else statistics.median(values)


def pair_rows(runs: list[dict], stage: str) -> list[dict]:
    """Per evaluation point: each arm's mean cost over seeds and the paired new − old (mean,
    min, max and 95 % Student-t interval over the seeds)."""
    from vdtn_marl.leaderboard.stats import t_ci

    rows = []
    old = {r["seed"]: r for r in runs if r["stage"] == stage and r["arm"] == "old"}
    new = {r["seed"]: r for r in runs if r["stage"] == stage and r["arm"] == "new"}
    seeds = sorted(set(old) & set(new))
    if not seeds:
        return rows
    for point in range(len(old[seeds[0]]["evaluations"])):
        costs_old = [old[s]["evaluations"][point]["control_cost"] for s in seeds]
        costs_new = [new[s]["evaluations"][point]["control_cost"] for s in seeds]
        diffs = [n - o for n, o in zip(costs_new, costs_old, strict=True)]
        _, low, high = t_ci(diffs)
        rows.append(
            {
                "stage": stage,
                "iteration": old[seeds[0]]["evaluations"][point]["iteration"],
                "frames": old[seeds[0]]["evaluations"][point]["frames"],
                "seeds": len(seeds),
                "cost_old": statistics.fmean(costs_old),
                "cost_new": statistics.fmean(costs_new),
                "diff_mean": statistics.fmean(diffs),
                "diff_min": min(diffs),
                "diff_max": max(diffs),
                "diff_t95_low": low,
                "diff_t95_high": high,
                # the trainer's process and its collector workers; None where a run with
                # workers did not record theirs
                "cpu_s_per_iteration_old": _median_or_none(_arm_cpu(old[s]) for s in seeds),
                "cpu_s_per_iteration_new": _median_or_none(_arm_cpu(new[s]) for s in seeds),
                "cpu_ratio_new_to_old": _median_or_none(
                    None
                    if None in (_arm_cpu(new[s]), _arm_cpu(old[s]))
                    else _arm_cpu(new[s]) / _arm_cpu(old[s])
                    for s in seeds
                ),
            }
        )
    return rows


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.summarize is not None:
        return summarize(args.summarize)
    import torch

    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    torch.set_num_threads(1)
    load_start = os.getloadavg()
    runs = []

    def write(rows: list[dict]) -> None:
        atomic_write_json(
            args.out,
            {
                **provenance("paper_batch_pairing"),
                "load_average_start": load_start,
                "load_average_end": os.getloadavg(),
                "old": args.old,
                "new": args.new,
                "old_overrides": args.old_overrides,
                "new_overrides": args.new_overrides,
                "iterations": args.iterations,
                "eval_every": args.eval_every,
                "eval_episodes": args.eval_episodes,
                "eval_seed": EVAL_SEED,
                "complete": len(runs) == 2 * len(args.stages) * len(args.seeds),
                "rows": rows,
                "runs": runs,
            },
        )

    for stage in args.stages:
        for seed in args.seeds:
            for arm in ("old", "new"):
                shape, extra = getattr(args, arm), getattr(args, f"{arm}_overrides")
                run = {**run_arm(stage, seed, shape, args, extra), "arm": arm, "overrides": extra}
                runs.append(run)
                write([row for s in args.stages for row in pair_rows(runs, s)])  # so far
                last = run["evaluations"][-1]
                print(
                    f"{stage:<8} seed {seed} {arm} {shape[0]}x{shape[1]} {' '.join(extra)}: cost "
                    f"{run['evaluations'][0]['control_cost']:.4f} -> {last['control_cost']:.4f}, "
                    f"{_arm_cpu(run):.2f} CPU s/iteration "
                    f"(load {run['load_average_1min_end']:.2f})",
                    flush=True,
                )
    rows = [row for stage in args.stages for row in pair_rows(runs, stage)]
    print_table(rows)
    write(rows)
    print(f"wrote {args.out}")
    return 0


def print_table(rows: list[dict]) -> None:
    print(
        f"\n{'stage':<8} {'iter':>5} {'frames':>9} {'cost old':>9} {'cost new':>9} "
        f"{'new-old':>9} {'95% t interval':>21} {'min':>9} {'max':>9} {'CPU new/old':>11}"
    )
    for row in rows:
        interval = f"[{row['diff_t95_low']:+.4f}, {row['diff_t95_high']:+.4f}]"
        print(
            f"{row['stage']:<8} {row['iteration']:>5} {row['frames']:>9,} "
            f"{row['cost_old']:>9.4f} {row['cost_new']:>9.4f} {row['diff_mean']:>+9.4f} "
            f"{interval:>21} {row['diff_min']:>+9.4f} {row['diff_max']:>+9.4f} "
            f"{_number(row['cpu_ratio_new_to_old']):>11}"
        )


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def summarize(path: Path) -> int:
    """Recompute the table of the result ``path`` from its runs, print and rewrite it."""
    import json

    from vdtn_marl.io.files import atomic_write_json

    result = json.loads(path.read_text())
    runs = result.get("runs")
    if not isinstance(runs, list):
        raise SystemExit(f"--summarize {path}: not a paper_batch_pairing result (no runs)")
    stages = [stage for stage in STAGES if any(run.get("stage") == stage for run in runs)]
    rows = [row for stage in stages for row in pair_rows(runs, stage)]
    print_table(rows)
    atomic_write_json(path, {**result, "rows": rows})
    print(f"rewrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
