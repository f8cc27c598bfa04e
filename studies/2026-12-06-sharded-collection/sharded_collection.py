"""What ``algo.collector_workers`` gives the JOCC stages of ``experiment=paper``.

    python studies/2026-12-06-sharded-collection/sharded_collection.py  # writes \
        sharded_collection.json
    python studies/2026-12-06-sharded-collection/sharded_collection.py \
        --stages pi_tilde_learned --pairs 1 \
        --out /tmp/sharded.json

Three arms, each a ``vdtn-marl jocc experiment=paper`` loop built in this process as
``benchmarks/stage_throughput.py`` builds it (the paper's batch sizes, torch on one thread):

- ``one``: the defaults (the trainer's process collects, its update on one thread);
- ``sharded``: ``algo.collector_workers=W`` (W spawned worker processes of B / W scenarios
  each collect the vehicle stages, :mod:`vdtn_marl.algos.shards`);
- ``sharded_threads``: that and ``algo.update_threads=W`` (the update on W threads, while
  the workers wait).

Per vehicle stage (``pi_star``, ``pi_tilde_random``, ``pi_tilde_learned``: π̃ under random
RRA, JOCC iteration 0, and under a learned RRA policy, iterations ≥ 1) every arm's trainer
fits its observation scaling and runs one untimed PPO iteration (which starts the workers),
then ``--pairs`` rounds of one whole timed PPO iteration per arm (collect, weights to the
workers and batches back included, update), the arms' order rotating from round to round.
Ratios are medians over rounds of ``one``'s seconds over the arm's, within a round. The RRA
stage is not sharded; ``one`` times it for the estimate (``--pairs`` iterations).

The estimate adds a JOCC iteration's training stages (500 π*, 500 π̃ and 300 RRA iterations;
π*'s warm start, the evaluation and the checkpoints left out) from each arm's medians, the
first iteration with π̃ under random RRA and a later one under the learned RRA. The JSON keeps
every timing, the load average, the CPU and the peak RSS of this process and of its workers.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = HERE.parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import stage_throughput  # noqa: E402  (the sibling script: the stage loop it builds)

RESULTS = HERE / "sharded_collection.json"
VEHICLE_STAGES = ("pi_star", "pi_tilde_random", "pi_tilde_learned")
STAGES = (*VEHICLE_STAGES, "rra")
ARMS = ("one", "sharded", "sharded_threads")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stages", default=",".join(STAGES), help=f"some of {', '.join(STAGES)}")
    p.add_argument("--workers", type=int, default=2, help="algo.collector_workers of the arms")
    p.add_argument("--pairs", type=int, default=5, help="timed rounds of the arms per stage")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    from vdtn_marl.algos.params import MAX_COLLECTOR_WORKERS
    from vdtn_marl.reporting.benchmarking import parse_names

    args.stages = parse_names("--stages", args.stages, STAGES)
    if not 1 <= args.workers <= MAX_COLLECTOR_WORKERS:
        p.error(f"--workers {args.workers} must be in [1, {MAX_COLLECTOR_WORKERS}]")
    if args.pairs < 1:
        p.error(f"--pairs {args.pairs} must be >= 1")
    return args


def _overrides(arm: str, workers: int) -> list[str]:
    return {
        "one": [],
        "sharded": [f"algo.collector_workers={workers}"],
        "sharded_threads": [
            f"algo.collector_workers={workers}",
            f"algo.update_threads={workers}",
        ],
    }[arm]


def measure_stage(loops: dict, stage: str, pairs: int) -> dict:
    """``pairs`` rotating rounds of one timed PPO iteration per arm of ``stage``."""
    arms = list(loops) if stage in VEHICLE_STAGES else ["one"]
    trainers = {arm: stage_throughput.stage_trainer(loops[arm], stage) for arm in arms}
    for trainer in trainers.values():
        if not trainer.scaling_fitted:
            trainer.fit_observation_scaling()
        trainer.train_iteration()  # untimed: starts the workers of a sharded arm
    runs: dict[str, list[dict]] = {arm: [] for arm in arms}
    for round_ in range(pairs):
        order = arms[round_ % len(arms) :] + arms[: round_ % len(arms)]
        for arm in order:
            runs[arm].append(stage_throughput.timed_iteration(trainers[arm]))
        print(
            f"  {stage} round {round_ + 1}/{pairs}: "
            + ", ".join(f"{arm} {runs[arm][-1]['seconds']:.2f} s" for arm in arms),
            flush=True,
        )
    row = {"stage": stage, "runs": runs}
    for arm in arms:
        row[f"{arm}_s"] = statistics.median(r["seconds"] for r in runs[arm])
        row[f"{arm}_collect_s"] = statistics.median(r["collect_s"] for r in runs[arm])
        row[f"{arm}_update_s"] = statistics.median(r["update_s"] for r in runs[arm])
        if arm != "one":
            row[f"one_over_{arm}"] = statistics.median(
                a["seconds"] / b["seconds"] for a, b in zip(runs["one"], runs[arm], strict=True)
            )
            row[f"collect_one_over_{arm}"] = statistics.median(
                a["collect_s"] / b["collect_s"] for a, b in zip(runs["one"], runs[arm], strict=True)
            )
    return row


def estimate(rows: list[dict], budgets: dict) -> dict | None:
    """Minutes of a first and a later JOCC iteration's training stages per arm."""
    by = {r["stage"]: r for r in rows}
    if not set(STAGES) <= set(by):
        return None
    control, rra = budgets["control_iterations"], budgets["rra_iterations"]
    out = {}
    for arm in ARMS:
        if f"{arm}_s" not in by["pi_star"]:
            continue
        base = control * by["pi_star"][f"{arm}_s"] + rra * by["rra"]["one_s"]
        out[arm] = {
            "first_min": (base + control * by["pi_tilde_random"][f"{arm}_s"]) / 60.0,
            "later_min": (base + control * by["pi_tilde_learned"][f"{arm}_s"]) / 60.0,
        }
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    load_start = os.getloadavg()
    budgets = stage_throughput._budgets()
    arms = ARMS if set(args.stages) & set(VEHICLE_STAGES) else ("one",)
    loops = {arm: stage_throughput._loop(_overrides(arm, args.workers))[1] for arm in arms}
    rows = []
    try:
        for stage in args.stages:
            print(f"{stage}: {args.pairs} rounds of {', '.join(arms)} ...", flush=True)
            rows.append(measure_stage(loops, stage, args.pairs))
    finally:
        for loop in loops.values():
            loop.close()
    result = {
        **provenance("sharded_collection"),
        "load_average_start": list(load_start),
        "load_average_end": list(os.getloadavg()),
        "workers": args.workers,
        "pairs": args.pairs,
        "cpu_count": os.cpu_count(),
        "paper_batch": {
            "num_envs": int(budgets["paper_algo"]["num_envs"]),
            "rollout_steps": int(budgets["paper_algo"]["rollout_steps"]),
            "rra_num_envs": int(budgets["paper_algo"]["rra_num_envs"]),
            "rra_rollout_steps": int(budgets["paper_algo"]["rra_rollout_steps"]),
        },
        "budgets": {k: budgets[k] for k in ("control_iterations", "rra_iterations")},
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "peak_rss_worker_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0,
        "rows": rows,
        "estimate": estimate(rows, budgets),
    }
    show(result)
    atomic_write_json(args.out, result)
    print(f"wrote {args.out}")
    return 0


def show(result: dict) -> None:
    print(
        f"\n{'stage':<18} {'one s':>6} {'sharded s':>9} {'one/sh':>6} {'collect':>7} "
        f"{'+threads s':>10} {'one/sh+t':>8}"
    )
    for r in result["rows"]:
        if "sharded_s" not in r:
            print(f"{r['stage']:<18} {r['one_s']:>6.2f}")
            continue
        print(
            f"{r['stage']:<18} {r['one_s']:>6.2f} {r['sharded_s']:>9.2f} "
            f"{r['one_over_sharded']:>6.2f} {r['collect_one_over_sharded']:>7.2f} "
            f"{r['sharded_threads_s']:>10.2f} {r['one_over_sharded_threads']:>8.2f}"
        )
    if result["estimate"]:
        print("\ntraining stages of a JOCC iteration (minutes): first, later")
        for arm, e in result["estimate"].items():
            print(f"  {arm:<16} {e['first_min']:6.1f} {e['later_min']:6.1f}")


if __name__ == "__main__":
    raise SystemExit(main())
