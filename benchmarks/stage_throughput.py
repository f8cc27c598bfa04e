"""Training throughput of each JOCC stage at several batch sizes, and a paper iteration's time.

    python benchmarks/stage_throughput.py          # writes results/stage_throughput.json
    python benchmarks/stage_throughput.py --stages pi_tilde_random --control-batches 64,256 \
        --iterations 2 --repeats 1 --no-warm-start --out /tmp/stages.json

Every cell (one stage at one batch size) runs in a fresh process that builds the JOCC loop of
``vdtn-marl jocc experiment=paper`` with the cell's batch size (``algo.num_envs`` and
``algo.rollout_steps``, or ``algo.rra_num_envs`` and ``algo.rra_rollout_steps``), so that its
peak RSS is the loop's own (every trainer's environment built, as in a run). It fits the
stage's observation scaling (timed apart), runs one warm-up PPO iteration, then times
``--iterations`` iterations: collection, update, and frames/s (one frame = one scenario-step
of the stage's clock: an interval for π* and π̃, a subframe for RRA). The batch sizes keep the
samples per iteration of ``experiment=paper`` (B × rollout steps = 64 × 400 for the vehicles,
128 × 500 for the RRA agents). Stages:

- ``pi_star``: π*, perfect observations (no radio);
- ``pi_tilde_random``: π̃ under uniformly random RRA (JOCC iteration 0): each interval
  simulates the T = 50 radio subframes of its CAMs;
- ``pi_tilde_learned``: π̃ under a learned RRA policy (JOCC iterations ≥ 1): the RRA actor
  picks every subframe's actions (its weights do not change the cost);
- ``rra``: the RRA agents, with π̃ as control module and the ``td`` IVoI estimator;
- ``evaluate`` (one size, ``experiment.eval_episodes`` scenarios in one batch): the JOCC
  evaluation stage, and one checkpoint write;
- ``warm_start``: π*'s imitation of the causal MPC (once per run; its size is fixed).

Cells run ``--repeats`` times, interleaved (every cell, then every cell again); the table
reports medians and, per stage, the median over repeats of each size's frames/s divided by the
reference size's (the ``experiment=paper`` sizes, read from its config) measured in the same
repeat. The estimate of one ``experiment=paper`` JOCC iteration adds the chosen sizes' median
seconds: warm start + scaling fits + 500 π* + 500 π̃ + 300 RRA iterations + evaluation +
checkpoints; a second estimate does the same at the ``paper`` sizes, where they were measured.
The JSON keeps every run with the load average before and after; other processes on the cores
slow every figure.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "results" / "stage_throughput.json"
STAGES = ("pi_star", "pi_tilde_random", "pi_tilde_learned", "rra", "evaluate", "warm_start")
CONTROL_STAGES = ("pi_star", "pi_tilde_random", "pi_tilde_learned")
#: samples per PPO iteration of ``experiment=paper`` before this benchmark chose its sizes:
#: 64 scenarios × 400 intervals (vehicles), 128 scenarios × 500 subframes (RRA agents)
CONTROL_FRAMES = 64 * 400
RRA_FRAMES = 128 * 500


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stages", default=",".join(STAGES), help=f"some of {', '.join(STAGES)}")
    p.add_argument(
        "--control-batches",
        default="64,128,256,512",
        help="B of the vehicle stages; rollout steps = 25,600 / B",
    )
    p.add_argument(
        "--rra-batches", default="64,128,256,512", help="B of the RRA stage; rollout = 64,000 / B"
    )
    p.add_argument("--iterations", type=int, default=3, help="timed PPO iterations per cell")
    p.add_argument("--repeats", type=int, default=2, help="interleaved runs of every cell")
    p.add_argument(
        "--choose",
        default="",
        help="sizes for the estimate, e.g. 'control=256,rra=256' (default: the fastest "
        "measured control size with rollouts of at least --min-control-rollout intervals, and "
        "the fastest RRA size with at least --min-rra-rollout subframes)",
    )
    p.add_argument("--min-control-rollout", type=int, default=100)
    p.add_argument("--min-rra-rollout", type=int, default=250)
    p.add_argument("--no-warm-start", action="store_true", help="skip the warm_start cell")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument("--cell", help=argparse.SUPPRESS)  # internal: run one cell, print JSON
    args = p.parse_args(argv)
    from vdtn_marl.reporting.benchmarking import parse_names

    args.stages = parse_names("--stages", args.stages, STAGES)
    if args.no_warm_start and "warm_start" in args.stages:
        args.stages.remove("warm_start")
    for flag in ("control_batches", "rra_batches"):
        text = getattr(args, flag)
        frames = CONTROL_FRAMES if flag == "control_batches" else RRA_FRAMES
        try:
            sizes = [int(part) for part in text.split(",") if part.strip()]
        except ValueError:
            sizes = []
        if not sizes or any(b < 1 or frames % b for b in sizes):
            p.error(f"--{flag.replace('_', '-')} {text!r} must list divisors of {frames}")
        setattr(args, flag, sizes)
    if args.iterations < 1 or args.repeats < 1:
        p.error("--iterations and --repeats must be >= 1")
    return args


# ---------------------------------------------------------------------- one cell (a child)
def _loop(overrides: list[str]):
    from vdtn_marl.experiment.compose import (
        compose_config,
        hydra_compose,
        job_config,
        to_run_config,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation

    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", ["experiment=paper", *overrides])))
    cfg.progress = False
    return cfg, JointOptimisation(cfg, tempfile.mkdtemp(prefix="stage_throughput_"))


def _learned_rra(loop) -> None:
    """Make the loop's RRA policy the (scaled) RRA actor, as after a first RRA stage."""
    loop.rra.fit_observation_scaling()
    loop.rra.iteration = 1
    loop.rra_slot.policy = loop.rra_policy()


def stage_trainer(loop, stage: str):
    """The trainer of ``stage`` (one of ``CONTROL_STAGES`` or ``rra``), with the RRA policy
    that stage runs under: the RRA actor for ``pi_tilde_learned``, random RRA for
    ``pi_tilde_random``."""
    if stage == "pi_tilde_learned":
        _learned_rra(loop)
    elif stage == "pi_tilde_random":
        loop.rra_slot.policy = loop.rra_policy()
    return {"pi_star": loop.pi_star, "rra": loop.rra}.get(stage, loop.pi_tilde)


def timed_iteration(trainer) -> dict:
    """One PPO iteration of ``trainer`` as a run does it (collect, update), timed: wall
    seconds of each part and of the whole, and the intervals collected."""
    began = time.perf_counter()
    data = trainer.collect()
    collected = time.perf_counter()
    trainer.update(data)
    trainer.iteration += 1
    done = time.perf_counter()
    return {
        "collect_s": collected - began,
        "update_s": done - collected,
        "seconds": done - began,
        "intervals": int(data.shape[-1]),
    }


def run_cell(cell: dict) -> dict:
    """Time one stage at one batch size in this process (see the module doc)."""
    stage, batch, iterations = cell["stage"], cell.get("batch"), cell["iterations"]
    overrides = []
    if stage in CONTROL_STAGES:
        overrides = [f"algo.num_envs={batch}", f"algo.rollout_steps={CONTROL_FRAMES // batch}"]
    elif stage == "rra":
        overrides = [f"algo.rra_num_envs={batch}", f"algo.rra_rollout_steps={RRA_FRAMES // batch}"]
    load_before = os.getloadavg()[0]
    began = time.perf_counter()
    cfg, loop = _loop(overrides)
    out = {"build_s": time.perf_counter() - began}
    if stage in ("evaluate", "warm_start"):
        if stage == "evaluate":
            loop.pi_star.fit_observation_scaling()
            loop.pi_tilde.fit_observation_scaling()
            _learned_rra(loop)
            began, began_cpu = time.perf_counter(), time.process_time()
            loop.evaluate()
            out["seconds"] = time.perf_counter() - began
            out["cpu_seconds"] = time.process_time() - began_cpu
            began = time.perf_counter()
            loop.save()
            out["checkpoint_s"] = time.perf_counter() - began
            out["episodes"] = cfg.experiment.eval_episodes
        else:
            began, began_cpu = time.perf_counter(), time.process_time()
            loop._warm_start_pi_star()
            out["seconds"] = time.perf_counter() - began
            out["cpu_seconds"] = time.process_time() - began_cpu
    else:
        trainer = stage_trainer(loop, stage)
        began, began_cpu = time.perf_counter(), time.process_time()
        trainer.fit_observation_scaling()
        out["scaling_s"] = time.perf_counter() - began
        out["scaling_cpu_s"] = time.process_time() - began_cpu
        trainer.train_iteration()  # warm-up
        collect, update, collect_cpu, update_cpu, frames = [], [], [], [], 0
        for _ in range(iterations):
            began, began_cpu = time.perf_counter(), time.process_time()
            data = trainer.collect()
            collected, collected_cpu = time.perf_counter(), time.process_time()
            trainer.update(data)
            trainer.iteration += 1
            collect.append(collected - began)
            update.append(time.perf_counter() - collected)
            collect_cpu.append(collected_cpu - began_cpu)
            update_cpu.append(time.process_time() - collected_cpu)
            frames = int(data.numel())
        total = [c + u for c, u in zip(collect, update, strict=True)]
        total_cpu = [c + u for c, u in zip(collect_cpu, update_cpu, strict=True)]
        out.update(
            rollout_steps=int(trainer.rollout_steps),
            frames_per_iteration=frames,
            collect_s=collect,
            update_s=update,
            seconds_per_iteration=statistics.median(total),
            frames_per_s=frames / statistics.median(total),
            collect_frames_per_s=frames / statistics.median(collect),
            collect_cpu_s=collect_cpu,
            update_cpu_s=update_cpu,
            cpu_seconds_per_iteration=statistics.median(total_cpu),
            frames_per_cpu_s=frames / statistics.median(total_cpu),
        )
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    out["load_average_1min_before"] = load_before
    out["load_average_1min_after"] = os.getloadavg()[0]
    return out


def spawn(cell: dict) -> dict:
    """Run one cell in a fresh interpreter (its own peak RSS) and return its result."""
    command = [sys.executable, __file__, "--cell", json.dumps(cell)]
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"cell {cell} failed:\n{done.stderr[-4000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------- the table
def _stage_batches(args, stage: str) -> list[int | None]:
    if stage in CONTROL_STAGES:
        return args.control_batches
    if stage == "rra":
        return args.rra_batches
    return [None]


def summarise(stage: str, runs: list[dict], reference: int | None) -> list[dict]:
    """Median rows per batch size of one stage, with the ratio to the reference size."""
    rows = []
    sizes = sorted({r["batch"] for r in runs}, key=lambda b: -1 if b is None else b)
    for batch in sizes:
        mine = [r for r in runs if r["batch"] == batch]
        row = {"stage": stage, "batch": batch, "runs": len(mine)}
        row["peak_rss_mb"] = max(r["peak_rss_mb"] for r in mine)
        if "frames_per_s" not in mine[0]:
            row["seconds"] = statistics.median(r["seconds"] for r in mine)
            row["cpu_seconds"] = statistics.median(r["cpu_seconds"] for r in mine)
            if "checkpoint_s" in mine[0]:
                row["checkpoint_s"] = statistics.median(r["checkpoint_s"] for r in mine)
            rows.append(row)
            continue
        for key in (
            "frames_per_s",
            "collect_frames_per_s",
            "seconds_per_iteration",
            "scaling_s",
            "scaling_cpu_s",
            "frames_per_cpu_s",
            "cpu_seconds_per_iteration",
        ):
            row[key] = statistics.median(r[key] for r in mine)
        row["update_s"] = statistics.median(u for r in mine for u in r["update_s"])
        row["rollout_steps"] = mine[0]["rollout_steps"]
        row["frames_per_iteration"] = mine[0]["frames_per_iteration"]
        for key, figure in (
            ("ratio_to_reference", "frames_per_s"),
            ("cpu_ratio_to_reference", "frames_per_cpu_s"),
        ):
            ratios = []
            for r in mine:
                ref = [q for q in runs if q["batch"] == reference and q["repeat"] == r["repeat"]]
                if ref:
                    ratios.append(r[figure] / ref[0][figure])
            row[key] = statistics.median(ratios) if ratios else None
        rows.append(row)
    return rows


def _choice(args, rows: list[dict]) -> dict[str, int]:
    chosen = {}
    for part in filter(None, (p.strip() for p in args.choose.split(","))):
        key, _, value = part.partition("=")
        if key not in ("control", "rra") or not value.isdigit():
            raise SystemExit(f"--choose {args.choose!r} must look like 'control=256,rra=256'")
        chosen[key] = int(value)
    by_stage = {}
    for row in rows:
        by_stage.setdefault(row["stage"], []).append(row)

    def fastest(stages, minimum):
        best, best_s = None, None
        for batch in {r["batch"] for s in stages for r in by_stage.get(s, [])}:
            cells = [r for s in stages for r in by_stage.get(s, []) if r["batch"] == batch]
            if len(cells) < len([s for s in stages if s in by_stage]):
                continue
            if cells[0]["rollout_steps"] < minimum:
                continue
            seconds = sum(r["seconds_per_iteration"] for r in cells)
            if best_s is None or seconds < best_s:
                best, best_s = batch, seconds
        return best

    if "control" not in chosen:
        pick = fastest(CONTROL_STAGES, args.min_control_rollout)
        if pick is not None:
            chosen["control"] = pick
    if "rra" not in chosen:
        pick = fastest(("rra",), args.min_rra_rollout)
        if pick is not None:
            chosen["rra"] = pick
    return chosen


def estimate(rows: list[dict], chosen: dict[str, int], budgets: dict, cpu: bool = False) -> dict:
    """Seconds of one ``experiment=paper`` JOCC iteration at the chosen sizes, from the
    medians (the first iteration: warm start and π̃ under random RRA; later ones: π̃ under the
    learned RRA, no warm start). ``cpu``: from the process's CPU seconds instead of wall
    seconds (what the run would take with a core to itself: torch runs on one thread)."""
    per_iteration = "cpu_seconds_per_iteration" if cpu else "seconds_per_iteration"
    scaling = "scaling_cpu_s" if cpu else "scaling_s"
    seconds = "cpu_seconds" if cpu else "seconds"

    def row(stage, batch=None):
        found = [r for r in rows if r["stage"] == stage and r["batch"] == batch]
        return found[0] if found else None

    parts: dict[str, float] = {}
    control, rra = chosen.get("control"), chosen.get("rra")
    missing = []
    for stage, batch, iterations in (
        ("pi_star", control, budgets["control_iterations"]),
        ("pi_tilde_random", control, budgets["control_iterations"]),
        ("pi_tilde_learned", control, budgets["control_iterations"]),
        ("rra", rra, budgets["rra_iterations"]),
    ):
        found = row(stage, batch)
        if found is None:
            missing.append(stage)
            continue
        parts[stage] = iterations * found[per_iteration]
        parts[f"{stage}_scaling_fit"] = found[scaling]
    for stage in ("evaluate", "warm_start"):
        found = row(stage)
        if found is None:
            missing.append(stage)
            continue
        parts[stage] = found[seconds]
        if stage == "evaluate":
            saves = budgets["checkpoints"]
            parts["checkpoints"] = saves * found["checkpoint_s"]
    first = sum(v for k, v in parts.items() if not k.startswith("pi_tilde_learned"))
    later = sum(
        v
        for k, v in parts.items()
        if not k.startswith("pi_tilde_random") and k != "warm_start" and "scaling" not in k
    )
    return {
        "chosen_batches": chosen,
        "budgets": budgets,
        "seconds": parts,
        "first_iteration_s": first,
        "first_iteration_min": first / 60.0,
        "later_iteration_s": later,
        "later_iteration_min": later / 60.0,
        "missing": missing,
    }


def _budgets() -> dict:
    cfg, _ = None, None
    from vdtn_marl.experiment.compose import compose_config, hydra_compose, job_config

    with hydra_compose():
        cfg = job_config(compose_config("config", ["experiment=paper"]))
    e = cfg["experiment"]
    stage_iterations = 2 * e["control_iterations"] + e["rra_iterations"]
    every = e["checkpoint_every"]
    return {
        "control_iterations": e["control_iterations"],
        "rra_iterations": e["rra_iterations"],
        "eval_episodes": e["eval_episodes"],
        "eval_intervals": e["eval_intervals"],
        # every checkpoint_every iterations of a stage, and after every stage
        "checkpoints": (stage_iterations // every if every else 0) + 4,
        "paper_algo": {
            k: cfg["algo"][k]
            for k in ("num_envs", "rollout_steps", "rra_num_envs", "rra_rollout_steps")
        },
    }


def reference_batches(budgets: dict) -> dict[str, int]:
    """The ``experiment=paper`` batch sizes: the reference of the ratios, and the sizes of the
    second estimate."""
    algo = budgets["paper_algo"]
    return {"control": int(algo["num_envs"]), "rra": int(algo["rra_num_envs"])}


def _fmt(value, spec=",.0f"):
    return "–" if value is None else format(value, spec)


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.cell:
        cell = json.loads(args.cell)
        import torch  # noqa: F401  (imported here so the parent stays light)

        print(json.dumps(run_cell(cell)))
        return 0
    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    cells = [
        {"stage": stage, "batch": batch, "iterations": args.iterations}
        for stage in args.stages
        for batch in _stage_batches(args, stage)
    ]
    runs = []
    load_start = os.getloadavg()
    for repeat in range(args.repeats):
        for cell in cells:
            if cell["stage"] == "warm_start" and repeat > 0:
                continue  # minutes, and its size is fixed: once
            result = spawn(cell)
            result.update(cell, repeat=repeat)
            runs.append(result)
            # the cells so far, in case the sweep is stopped (the summary replaces it)
            atomic_write_json(
                args.out, {**provenance("stage_throughput"), "complete": False, "runs": runs}
            )
            shown = result.get("frames_per_s", result.get("seconds"))
            print(
                f"[{repeat}] {cell['stage']:<17} B={cell['batch']}: {shown:,.1f} "
                f"(load {result['load_average_1min_before']:.2f})",
                flush=True,
            )
    budgets = _budgets()
    reference = reference_batches(budgets)
    rows = []
    for stage in args.stages:
        size = reference["rra" if stage == "rra" else "control"]
        rows += summarise(stage, [r for r in runs if r["stage"] == stage], size)
    chosen = _choice(args, rows)
    result = {
        **provenance("stage_throughput"),
        "load_average_start": load_start,
        "load_average_end": os.getloadavg(),
        "cpu_count": os.cpu_count(),
        "control_frames_per_iteration": CONTROL_FRAMES,
        "rra_frames_per_iteration": RRA_FRAMES,
        "reference_batches": reference,
        "rows": rows,
        "estimate": estimate(rows, chosen, budgets),
        "estimate_cpu": estimate(rows, chosen, budgets, cpu=True),
        "estimate_paper": estimate(rows, reference, budgets),
        "estimate_paper_cpu": estimate(rows, reference, budgets, cpu=True),
        "complete": True,
        "peak_rss_mb": max(r["peak_rss_mb"] for r in runs),
        "runs": runs,
    }
    print()
    print(
        f"{'stage':<17} {'B':>5} {'steps':>6} {'frames/s':>9} {'collect f/s':>11} "
        f"{'s/iter':>7} {'update s':>8} {'× paper':>7} {'f/cpu-s':>8} {'cpu × paper':>11} "
        f"{'RSS MB':>7}"
    )
    for row in rows:
        if "frames_per_s" in row:
            print(
                f"{row['stage']:<17} {row['batch']:>5} {row['rollout_steps']:>6} "
                f"{_fmt(row['frames_per_s']):>9} {_fmt(row['collect_frames_per_s']):>11} "
                f"{row['seconds_per_iteration']:>7.2f} {row['update_s']:>8.2f} "
                f"{_fmt(row['ratio_to_reference'], '.2f'):>7} "
                f"{_fmt(row['frames_per_cpu_s']):>8} "
                f"{_fmt(row['cpu_ratio_to_reference'], '.2f'):>11} {row['peak_rss_mb']:>7.0f}"
            )
        else:
            print(
                f"{row['stage']:<17} {'':>5} {'':>6} {'':>9} {'':>11} {row['seconds']:>7.1f} "
                f"{'':>8} {'':>7} {'':>8} {'':>11} {row['peak_rss_mb']:>7.0f}"
                f"   ({row['cpu_seconds']:.1f} CPU s)"
            )
    for name, label in (
        ("estimate", "wall s"),
        ("estimate_cpu", "CPU s"),
        ("estimate_paper", "wall s, the paper sizes"),
        ("estimate_paper_cpu", "CPU s, the paper sizes"),
    ):
        est = result[name]
        print(
            f"\nexperiment=paper, one JOCC iteration at {est['chosen_batches']} ({label}): "
            f"first {est['first_iteration_min']:.1f} min, later "
            f"{est['later_iteration_min']:.1f} min (missing: "
            f"{', '.join(est['missing']) or 'none'})"
        )
    print(f"peak RSS {result['peak_rss_mb']:,.0f} MB")
    atomic_write_json(args.out, result)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
