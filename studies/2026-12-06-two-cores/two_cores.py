"""What the second core can give a JOCC stage: its batch split over processes, one per core,
against one process on one core; and the PPO update on two threads against one.

    python studies/2026-12-06-two-cores/two_cores.py  # writes two_cores.json
    python studies/2026-12-06-two-cores/two_cores.py --stages pi_tilde_learned --iterations 2 \
        --repeats 1 \
        --out /tmp/two_cores.json

A run (``vdtn-marl jocc``, ``threads=1``) uses one core for torch and, at B ≥ 128 scenarios,
the twin's draw-ahead thread on the second core for a small part of the time
(``studies/2026-12-03-draw-ahead/draw_ahead.json``). The idle core could run half of a stage's
scenarios: k worker processes of B/k scenarios each collect B × rollout frames together, and the
trainer updates on their joined batch. This script measures what that can gain at most, without the
collector's messages; ``sharded_collection.py`` times the collector that is built
(``algo.collector_workers``).

Per stage (``pi_star``, ``pi_tilde_random``, ``pi_tilde_learned``, ``rra``: as in
``benchmarks/stage_throughput.py``, the ``experiment=paper`` loop and batch sizes) and repeat, two
arms in fresh processes, one after the other (the order alternates between repeats):

- ``one``: one process at the paper's B. Each timed iteration collects, then updates on the
  data twice, on 1 torch thread and on 2 (the order alternates; the same shapes, so the same
  work; the second update starts from the first's weights, which does not change its cost).
- ``shards``: ``--shards`` processes at B / k scenarios each and the paper's rollout steps
  (together the same frames per iteration), started together. Each timed iteration begins at
  a barrier that all of them pass, and lasts until the slowest has collected: the time of a
  collection sharded per PPO iteration. It leaves out what such a collector would add: the
  copy of each shard's batch to the trainer, and the policy's new weights sent to the shards.
  So the ratio is an upper bound of what sharding can give this stage on this machine.

The estimate adds a JOCC iteration's training stages (500 π*, 500 π̃ and 300 RRA iterations
of ``experiment=paper``; evaluation, warm start and checkpoints left out), each iteration its
median collection plus update: one process on one thread; one process with its updates on two
threads (``algo.update_threads=2``); and sharded collection with the update on two threads.
The JSON keeps every timing, the load average and the CPU. ``--summarise PATH`` recomputes
the table and the estimate of a results file from the timings it keeps.
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing as mp
import os
import resource
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = HERE.parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import stage_throughput  # noqa: E402  (the sibling script: the stage loop it builds)

RESULTS = HERE / "two_cores.json"
STAGES = ("pi_star", "pi_tilde_random", "pi_tilde_learned", "rra")
ARMS = ("one", "shards")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stages", default=",".join(STAGES), help=f"some of {', '.join(STAGES)}")
    p.add_argument("--shards", type=int, default=2, help="processes of the sharded arm")
    p.add_argument("--iterations", type=int, default=3, help="timed PPO iterations per arm")
    p.add_argument("--repeats", type=int, default=3, help="rounds of both arms per stage")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument(
        "--summarise", type=Path, metavar="PATH", help="recompute a results file from its runs"
    )
    args = p.parse_args(argv)
    from vdtn_marl.reporting.benchmarking import parse_names

    args.stages = parse_names("--stages", args.stages, STAGES)
    if not 2 <= args.shards <= 16:
        p.error(f"--shards {args.shards} must be in [2, 16]")
    if args.iterations < 1 or args.repeats < 1:
        p.error(f"--iterations {args.iterations} and --repeats {args.repeats} must be >= 1")
    return args


def paper_sizes() -> dict:
    """The ``experiment=paper`` batch sizes and iteration budgets."""
    budgets = stage_throughput._budgets()
    algo = budgets["paper_algo"]
    return {
        "control": (int(algo["num_envs"]), int(algo["rollout_steps"])),
        "rra": (int(algo["rra_num_envs"]), int(algo["rra_rollout_steps"])),
        "control_iterations": int(budgets["control_iterations"]),
        "rra_iterations": int(budgets["rra_iterations"]),
    }


# ---------------------------------------------------------------------- a worker (a child)
def _trainer(stage: str, batch: int, rollout: int):
    st = stage_throughput
    if stage == "rra":
        overrides = [f"algo.rra_num_envs={batch}", f"algo.rra_rollout_steps={rollout}"]
    else:
        overrides = [f"algo.num_envs={batch}", f"algo.rollout_steps={rollout}"]
    _, loop = st._loop(overrides)
    trainer = st.stage_trainer(loop, stage)
    trainer.fit_observation_scaling()
    trainer.train_iteration()  # warm-up
    return trainer


def _update_s(trainer, data, threads: int) -> float:
    """Seconds of one update on ``threads`` torch threads, as ``algo.update_threads`` runs it."""
    trainer.algo = dataclasses.replace(trainer.algo, update_threads=threads)
    began = time.perf_counter()
    trainer.update(data)
    return time.perf_counter() - began


def worker(job: dict, barrier, results) -> None:
    """Build the job's stage at its batch size, then time its collections, each started at the
    barrier; the ``one`` arm also times the update on 1 and 2 threads."""
    try:
        trainer = _trainer(job["stage"], job["batch"], job["rollout"])
        rows = []
        for i in range(job["iterations"]):
            barrier.wait()
            began = time.perf_counter()
            data = trainer.collect()
            row = {"collect_s": time.perf_counter() - began, "frames": int(data.numel())}
            if job["arm"] == "one":
                order = (1, 2) if i % 2 == 0 else (2, 1)
                for threads in order:
                    row[f"update_{threads}_thread_s"] = _update_s(trainer, data, threads)
            trainer.iteration += 1
            rows.append(row)
        results.put(
            {
                "shard": job["shard"],
                "iterations": rows,
                "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
            }
        )
    except BaseException as error:  # the parent must hear of it, not wait forever
        barrier.abort()
        results.put({"shard": job["shard"], "error": f"{type(error).__name__}: {error}"})
        raise


def run_arm(stage: str, arm: str, shards: int, iterations: int, sizes: dict) -> dict:
    """One arm of one stage: its processes, started together; per iteration the slowest
    shard's collection."""
    batch, rollout = sizes["rra" if stage == "rra" else "control"]
    k = 1 if arm == "one" else shards
    if batch % k:
        raise SystemExit(f"--shards {k} must divide the paper's B = {batch} of {stage}")
    ctx = mp.get_context("spawn")  # fresh interpreters: each process's own peak RSS
    barrier, results = ctx.Barrier(k), ctx.Queue()
    jobs = [
        {
            "stage": stage,
            "arm": arm,
            "batch": batch // k,
            "rollout": rollout,
            "iterations": iterations,
            "shard": s,
        }
        for s in range(k)
    ]
    load_before = os.getloadavg()[0]
    processes = [ctx.Process(target=worker, args=(job, barrier, results)) for job in jobs]
    for process in processes:
        process.start()
    out = [results.get() for _ in processes]
    for process in processes:
        process.join()
    errors = [o["error"] for o in out if "error" in o]
    if errors:
        raise SystemExit(f"{stage} {arm}: {errors[0]}")
    out.sort(key=lambda o: o["shard"])
    collect = [max(o["iterations"][i]["collect_s"] for o in out) for i in range(iterations)]
    row = {
        "stage": stage,
        "arm": arm,
        "processes": k,
        "batch_per_process": batch // k,
        "rollout_steps": rollout,
        "frames_per_iteration": sum(o["iterations"][0]["frames"] for o in out),
        "collect_s": collect,
        "shards": out,
        "peak_rss_mb": max(o["peak_rss_mb"] for o in out),
        "load_average_1min_before": load_before,
        "load_average_1min_after": os.getloadavg()[0],
    }
    if arm == "one":
        for threads in (1, 2):
            row[f"update_{threads}_thread_s"] = [
                r[f"update_{threads}_thread_s"] for r in out[0]["iterations"]
            ]
    return row


# ---------------------------------------------------------------------- the table
def summarise(runs: list[dict], stages: list[str]) -> list[dict]:
    """Per stage: median collection of each arm, the median over repeats of one / shards
    (paired within a repeat), and the update's medians on 1 and 2 threads."""
    rows = []
    for stage in stages:
        mine = [r for r in runs if r["stage"] == stage]
        one = [r for r in mine if r["arm"] == "one"]
        shards = [r for r in mine if r["arm"] == "shards"]
        ratios = []
        for r in one:
            paired = [s for s in shards if s["repeat"] == r["repeat"]]
            if paired:
                ratios.append(
                    statistics.median(r["collect_s"]) / statistics.median(paired[0]["collect_s"])
                )
        update_1 = [u for r in one for u in r["update_1_thread_s"]]
        update_2 = [u for r in one for u in r["update_2_thread_s"]]
        rows.append(
            {
                "stage": stage,
                "frames_per_iteration": one[0]["frames_per_iteration"] if one else None,
                "collect_one_s": statistics.median(c for r in one for c in r["collect_s"]),
                "collect_shards_s": statistics.median(c for r in shards for c in r["collect_s"]),
                "one_over_shards": statistics.median(ratios) if ratios else None,
                "one_over_shards_range": [min(ratios), max(ratios)] if ratios else None,
                "update_1_thread_s": statistics.median(update_1),
                "update_2_threads_s": statistics.median(update_2),
                "update_1_over_2": statistics.median(
                    a / b for a, b in zip(update_1, update_2, strict=True)
                ),
                "peak_rss_mb_one": max(r["peak_rss_mb"] for r in one),
                "peak_rss_mb_shards": max(r["peak_rss_mb"] for r in shards),
            }
        )
    return rows


def estimate(rows: list[dict], sizes: dict) -> dict | None:
    """Minutes of a JOCC iteration's training stages (first: π̃ under random RRA; later: under
    the learned RRA) from the medians: one process on 1 thread, one process with its updates on
    2 threads, and sharded collection with the updates on 2 threads; None unless every stage
    was measured."""
    by = {r["stage"]: r for r in rows}
    if set(by) != set(STAGES):
        return None
    budget = {
        "pi_star": sizes["control_iterations"],
        "pi_tilde_random": sizes["control_iterations"],
        "pi_tilde_learned": sizes["control_iterations"],
        "rra": sizes["rra_iterations"],
    }
    out = {}
    for name, pi_tilde in (("first", "pi_tilde_random"), ("later", "pi_tilde_learned")):
        stages = ("pi_star", pi_tilde, "rra")
        one = sum(budget[s] * (by[s]["collect_one_s"] + by[s]["update_1_thread_s"]) for s in stages)
        two = sum(
            budget[s] * (by[s]["collect_shards_s"] + by[s]["update_2_threads_s"]) for s in stages
        )
        threads = sum(
            budget[s] * (by[s]["collect_one_s"] + by[s]["update_2_threads_s"]) for s in stages
        )
        out[name] = {
            "one_min": one / 60.0,
            "two_cores_min": two / 60.0,
            "one_over_two": one / two,
            # one collecting process, updates on 2 threads (algo.update_threads=2)
            "update_threads_min": threads / 60.0,
            "one_over_update_threads": one / threads,
        }
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    if args.summarise:
        return summarise_file(args.summarise)
    sizes = paper_sizes()
    runs = []
    load_start = os.getloadavg()
    for repeat in range(args.repeats):
        for stage in args.stages:
            arms = ARMS if repeat % 2 == 0 else ARMS[::-1]
            for arm in arms:
                began = time.perf_counter()
                row = run_arm(stage, arm, args.shards, args.iterations, sizes)
                row["repeat"] = repeat
                runs.append(row)
                atomic_write_json(
                    args.out, {**provenance("two_cores"), "complete": False, "runs": runs}
                )
                print(
                    f"[{repeat}] {stage:<17} {arm:<6} × {row['processes']}: collect "
                    f"{statistics.median(row['collect_s']):.2f} s  "
                    f"({time.perf_counter() - began:.0f} s, load "
                    f"{row['load_average_1min_before']:.2f})",
                    flush=True,
                )
    rows = summarise(runs, args.stages)
    result = {
        **provenance("two_cores"),
        "complete": True,
        "shards": args.shards,
        "iterations": args.iterations,
        "repeats": args.repeats,
        "paper_sizes": sizes,
        "load_average_start": list(load_start),
        "load_average_end": list(os.getloadavg()),
        "rows": rows,
        "estimate": estimate(rows, sizes),
        "runs": runs,
    }
    atomic_write_json(args.out, result)
    show(result)
    print(f"wrote {args.out}")
    return 0


def summarise_file(path: Path) -> int:
    """Recompute the rows and the estimate of the results file ``path`` from its runs."""
    import json

    from vdtn_marl.io.files import atomic_write_json

    try:
        result = json.loads(path.read_text())
        runs, stages = result["runs"], list(dict.fromkeys(r["stage"] for r in result["runs"]))
        result["rows"] = summarise(runs, stages)
        result["estimate"] = estimate(result["rows"], result["paper_sizes"])
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise SystemExit(f"--summarise {path}: not a two_cores.py results file ({error})") from None
    atomic_write_json(path, result)
    show(result)
    print(f"wrote {path}")
    return 0


def show(result: dict) -> None:
    rows = result["rows"]
    print(
        f"\n{'stage':<17} {'frames':>7} {'one s':>7} {'shards s':>9} {'one/shards':>11} "
        f"{'upd 1 thr':>10} {'upd 2 thr':>10} {'1/2':>5}"
    )
    for r in rows:
        print(
            f"{r['stage']:<17} {r['frames_per_iteration']:>7,} {r['collect_one_s']:>7.2f} "
            f"{r['collect_shards_s']:>9.2f} {r['one_over_shards']:>11.2f} "
            f"{r['update_1_thread_s']:>10.2f} {r['update_2_threads_s']:>10.2f} "
            f"{r['update_1_over_2']:>5.2f}"
        )
    if result["estimate"]:
        for name, e in result["estimate"].items():
            print(
                f"{name} JOCC iteration, training stages: one process {e['one_min']:.1f} min, "
                f"updates on 2 threads {e['update_threads_min']:.1f} min "
                f"({e['one_over_update_threads']:.2f}×), sharded collection too "
                f"{e['two_cores_min']:.1f} min ({e['one_over_two']:.2f}×)"
            )


if __name__ == "__main__":
    raise SystemExit(main())
