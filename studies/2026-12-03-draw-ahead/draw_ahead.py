"""Paired cost of drawing ahead: the JOCC stages of ``experiment=paper`` with the twin's next
interval's draws made on a second thread (``DigitalTwin.draw_ahead``) against drawn at each
interval's start, and the time of a paper JOCC iteration either way.

    python studies/2026-12-03-draw-ahead/draw_ahead.py  # writes draw_ahead.json
    python studies/2026-12-03-draw-ahead/draw_ahead.py --stages pi_tilde_random --repeats 1 \
        --out /tmp/da.json

Per stage (``--stages``, default all four) one ``experiment=paper`` loop (``threads=1``, the
stage's own batch sizes) is built, its observation scaling fitted and one PPO iteration run as
a warm-up; then ``--repeats`` × ``--iterations`` pairs of PPO iterations (collection and
update) on the same trainer, one with the draws made ahead and one without, in alternating
order (the same environment: switching the attribute changes where the draws are made, not
the numbers), timed in wall and process-CPU seconds. Stages:

- ``pi_star``: π*, perfect observations: no radio, so no draws (a control: the ratio is 1);
- ``pi_tilde_random``: π̃ under uniformly random RRA (JOCC iteration 0): every interval runs
  its 50 radio subframes at the vehicle batch (256 scenarios);
- ``pi_tilde_learned``: π̃ under the learned RRA policy (JOCC iterations ≥ 1);
- ``rra``: the RRA agents (128 scenarios).

The table gives each stage's median wall seconds per iteration either way and the median over
pairs of (without / with), and the wall minutes of a JOCC iteration at the paper's budgets
(500 π*, 500 π̃ and 300 RRA iterations; the first with π̃ under random RRA, later ones under
the learned RRA; evaluation and checkpoints, about 0.2 min, not included). The JSON keeps
every iteration, the peak RSS and the load average before and after: other processes on the
two cores slow both settings and take the second core from the draws.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "draw_ahead.json"
STAGES = ("pi_star", "pi_tilde_random", "pi_tilde_learned", "rra")
SETTINGS = ("ahead", "at_start")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--stages", default=",".join(STAGES), help=f"some of {', '.join(STAGES)}")
    p.add_argument("--repeats", type=int, default=3, help="rounds of --iterations pairs")
    p.add_argument("--iterations", type=int, default=2, help="pairs of PPO iterations per round")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    from vdtn_marl.reporting.benchmarking import parse_names

    args.stages = parse_names("--stages", args.stages, STAGES)
    if args.repeats < 1 or args.iterations < 1:
        p.error("--repeats and --iterations must be >= 1")
    return args


def _paper_loop():
    from vdtn_marl.experiment.compose import (
        compose_config,
        hydra_compose,
        job_config,
        to_run_config,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation

    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", ["experiment=paper", "threads=1"])))
    cfg.progress = False
    return JointOptimisation(cfg, tempfile.mkdtemp(prefix="draw_ahead_"))


def _trainer(loop, stage: str):
    trainer = {"pi_star": loop.pi_star, "rra": loop.rra}.get(stage, loop.pi_tilde)
    if stage == "pi_tilde_learned":  # the RRA actor acts, as after a first RRA stage
        loop.rra.fit_observation_scaling()
        loop.rra.iteration = 1
        loop.rra_slot.policy = loop.rra_policy()
    elif stage == "pi_tilde_random":
        loop.rra_slot.policy = loop.rra_policy()
    return trainer


def time_stage(stage: str, repeats: int, iterations: int) -> tuple[list[dict], dict]:
    """Every timed iteration of ``stage`` (see the module doc) and the stage's facts."""
    loop = _paper_loop()
    trainer = _trainer(loop, stage)
    twin = trainer.env.twin
    eligible = twin.draw_ahead  # what the twin chose at construction (B, device, backend)
    trainer.fit_observation_scaling()
    trainer.train_iteration()  # warm-up
    runs = []
    for repeat in range(repeats):
        for index in range(iterations):
            pair = repeat * iterations + index
            # the pair's order alternates, so that a drift within a pair favours neither
            for setting in SETTINGS if pair % 2 == 0 else SETTINGS[::-1]:
                twin.draw_ahead = eligible and setting == "ahead"
                began, began_cpu = time.perf_counter(), time.process_time()
                trainer.train_iteration()
                runs.append(
                    {
                        "stage": stage,
                        "setting": setting,
                        "pair": pair,
                        "wall_s": time.perf_counter() - began,
                        "cpu_s": time.process_time() - began_cpu,
                    }
                )
            last = {r["setting"]: r["wall_s"] for r in runs[-2:]}
            ahead, at_start = last["ahead"], last["at_start"]
            print(
                f"[{repeat}.{index}] {stage:<17} ahead {ahead:6.2f} s  at start "
                f"{at_start:6.2f} s  ratio {at_start / ahead:5.2f}",
                flush=True,
            )
    twin.draw_ahead = eligible
    facts = {
        "batch_size": twin.batch_size,
        "radio": twin.radio_enabled,
        "draw_ahead_eligible": eligible,
        "frames_per_iteration": twin.batch_size * trainer.rollout_steps,
        "control_iterations": loop.cfg.experiment.control_iterations,
        "rra_iterations": loop.cfg.experiment.rra_iterations,
    }
    return runs, facts


def summarise(runs: list[dict]) -> list[dict]:
    rows = []
    for stage in dict.fromkeys(r["stage"] for r in runs):
        mine = [r for r in runs if r["stage"] == stage]
        by = {s: [r for r in mine if r["setting"] == s] for s in SETTINGS}
        pairs = sorted({r["pair"] for r in mine})
        ratios = []
        for pair in pairs:
            one = {r["setting"]: r["wall_s"] for r in mine if r["pair"] == pair}
            if set(one) == set(SETTINGS):
                ratios.append(one["at_start"] / one["ahead"])
        rows.append(
            {
                "stage": stage,
                "pairs": len(ratios),
                **{f"wall_s_{s}": statistics.median(r["wall_s"] for r in by[s]) for s in SETTINGS},
                **{f"cpu_s_{s}": statistics.median(r["cpu_s"] for r in by[s]) for s in SETTINGS},
                "at_start_over_ahead": statistics.median(ratios),
                "ratio_min": min(ratios),
                "ratio_max": max(ratios),
            }
        )
    return rows


def iteration_minutes(rows: list[dict], budgets: dict) -> dict:
    """Wall minutes of a first and a later ``experiment=paper`` JOCC iteration's training
    stages, per setting, where every stage they need was measured."""
    seconds = {r["stage"]: r for r in rows}
    plans = {
        "first": {"pi_star": "control", "pi_tilde_random": "control", "rra": "rra"},
        "later": {"pi_star": "control", "pi_tilde_learned": "control", "rra": "rra"},
    }
    out = {}
    for name, plan in plans.items():
        if not set(plan) <= set(seconds):
            continue
        for setting in SETTINGS:
            total = sum(
                budgets[f"{clock}_iterations"] * seconds[stage][f"wall_s_{setting}"]
                for stage, clock in plan.items()
            )
            out[f"{name}_{setting}"] = total / 60.0
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    import torch

    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    torch.set_num_threads(1)
    load_start = os.getloadavg()
    runs, facts = [], {}
    for stage in args.stages:
        stage_runs, facts[stage] = time_stage(stage, args.repeats, args.iterations)
        runs += stage_runs
    rows = summarise(runs)
    budgets = next(iter(facts.values()))
    minutes = iteration_minutes(rows, budgets)
    print(
        f"\n{'stage':<17} {'B':>5} {'ahead s/it':>10} {'at start s/it':>13} "
        f"{'at start / ahead (pairs)':>26}"
    )
    for row in rows:
        spread = f"{row['ratio_min']:.2f}–{row['ratio_max']:.2f}"
        print(
            f"{row['stage']:<17} {facts[row['stage']]['batch_size']:>5} "
            f"{row['wall_s_ahead']:>10.2f} {row['wall_s_at_start']:>13.2f} "
            f"{row['at_start_over_ahead']:>9.2f} ({spread}, {row['pairs']})"
        )
    for name in ("first", "later"):
        if f"{name}_ahead" in minutes:
            print(
                f"experiment=paper, {name} JOCC iteration's training stages: "
                f"{minutes[f'{name}_ahead']:.1f} min with the draws ahead, "
                f"{minutes[f'{name}_at_start']:.1f} min without (wall)"
            )
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"peak RSS {peak_mb:,.0f} MB")
    atomic_write_json(
        args.out,
        {
            **provenance("draw_ahead"),
            "load_average_start": load_start,
            "load_average_end": os.getloadavg(),
            "repeats": args.repeats,
            "iterations": args.iterations,
            "stages": facts,
            "rows": rows,
            "paper_iteration_training_wall_min": minutes,
            "peak_rss_mb": peak_mb,
            "runs": runs,
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
