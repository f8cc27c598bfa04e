"""Cost of the networks' tanh activation (``algo.activation``): the kernels, the RRA policy call
and the paper-scale training stages, each activation against ``tanh`` in the same run.

    python studies/2026-12-03-activation-cost/activation_cost.py  # writes activation_cost.json
    python studies/2026-12-03-activation-cost/activation_cost.py --stages none --repeats 3 \
        --out /tmp/act.json

Three parts, each interleaved (every activation, then every activation again, ``--repeats``
times), timed in process CPU seconds with torch on one thread:

1. **Kernels**: one activation of a [rows, 64] float32 tensor (a hidden layer of 64 cells) at
   the row counts of the RRA policy call in the RRA stage (128 scenarios × 3 links), in π̃'s
   radio (256 × 3) and of a PPO minibatch (4096 × 3): ``torch.tanh`` (``tanh``), 2·sigmoid(2x)
   − 1 (``tanh_sigmoid``) and, for scale, NumPy's ``np.tanh`` on the same data (not an option:
   NumPy arrays cannot carry autograd).
2. **RRA policy call**: the learned RRA policy's fast path (``ActorPolicy``, one call per 1 ms
   subframe) at B = 256 scenarios, built as ``vdtn-marl jocc experiment=smoke`` builds it with
   each activation.
3. **Training stages** (``--stages``, default ``pi_star,pi_tilde_learned,rra``): PPO
   iterations of each stage at ``experiment=paper``'s batch sizes, one loop per activation in
   this process, alternating between them iteration by iteration (``--iterations`` per repeat;
   ``pi_tilde_learned``: the RRA actor picks every subframe's actions), and the three stages'
   sum at the paper's budgets (500 π*, 500 π̃ and 300 RRA iterations: the training part of a
   later JOCC iteration).

The table gives medians and, per row, the median over repeats of tanh's time divided by the
activation's (> 1: faster than tanh). The two activations differ in the last bits, so they give
different (equally valid) runs; ``tests/algos/test_networks.py`` bounds the difference.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "activation_cost.json"
ROWS = {"rra_stage_call": 128 * 3, "pi_tilde_rra_call": 256 * 3, "ppo_minibatch": 4096 * 3}
CELLS = 64
STAGES = ("pi_star", "pi_tilde_learned", "rra")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5, help="interleaved runs of every row")
    p.add_argument("--calls", type=int, default=300, help="calls per kernel or policy timing")
    p.add_argument("--stages", default=",".join(STAGES), help=f"some of {STAGES}, or none")
    p.add_argument("--iterations", type=int, default=2, help="PPO iterations per repeat")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    from vdtn_marl.reporting.benchmarking import parse_names

    args.stages = [] if args.stages == "none" else parse_names("--stages", args.stages, STAGES)
    if args.repeats < 1 or args.calls < 1 or args.iterations < 1:
        p.error("--repeats, --calls and --iterations must be >= 1")
    return args


def _cpu_us(fn, calls: int) -> float:
    fn()
    began = time.process_time()
    for _ in range(calls):
        fn()
    return 1e6 * (time.process_time() - began) / calls


def _rra_policy(activation: str):
    from vdtn_marl.algos.ppo import ActorPolicy
    from vdtn_marl.experiment.compose import (
        compose_config,
        hydra_compose,
        job_config,
        to_run_config,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation

    overrides = ["experiment=smoke", f"algo.activation={activation}"]
    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", overrides)))
    cfg.progress = False
    loop = JointOptimisation(cfg, tempfile.mkdtemp(prefix="activation_cost_"))
    policy = ActorPolicy(loop.rra.actor, "rra")
    if policy.mode is None:
        raise SystemExit("the RRA actor has no fast path (CategoricalMode.of returned None)")
    return policy


def _ratio_rows(runs: list[dict], key: str, reference: str = "tanh") -> list[dict]:
    """Median per (part, name) and the median over repeats of reference / this."""
    rows = []
    for part, name in dict.fromkeys((r["part"], r["name"]) for r in runs):
        mine = [r for r in runs if r["part"] == part and r["name"] == name]
        ratios = []
        for r in mine:
            ref = [
                q
                for q in runs
                if q["part"] == part and q["name"] == reference and q["repeat"] == r["repeat"]
            ]
            if ref:
                ratios.append(ref[0][key] / r[key])
        rows.append(
            {
                "part": part,
                "name": name,
                "runs": len(mine),
                key: statistics.median(r[key] for r in mine),
                "tanh_over_this": statistics.median(ratios) if ratios else None,
            }
        )
    return rows


def _paper_loop(activation: str):
    from vdtn_marl.experiment.compose import (
        compose_config,
        hydra_compose,
        job_config,
        to_run_config,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation

    overrides = ["experiment=paper", "threads=1", f"algo.activation={activation}"]
    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", overrides)))
    cfg.progress = False
    return JointOptimisation(cfg, tempfile.mkdtemp(prefix="activation_cost_"))


def _time_stages(args, activations) -> tuple[list[dict], dict]:
    """Per stage: one ``experiment=paper`` loop per activation in this process, each fitted and
    warmed up (one PPO iteration), then ``--repeats`` × ``--iterations`` PPO iterations timed
    in CPU seconds, alternating between the activations iteration by iteration (so both see
    the same machine)."""
    budgets = {}
    runs = []
    for stage in args.stages:
        trainers = {}
        for activation in activations:
            loop = _paper_loop(activation)
            budgets = {
                "control_iterations": loop.cfg.experiment.control_iterations,
                "rra_iterations": loop.cfg.experiment.rra_iterations,
            }
            trainer = {"pi_star": loop.pi_star, "rra": loop.rra}.get(stage, loop.pi_tilde)
            if stage == "pi_tilde_learned":  # the RRA actor acts, as after a first RRA stage
                loop.rra.fit_observation_scaling()
                loop.rra.iteration = 1
                loop.rra_slot.policy = loop.rra_policy()
            trainer.fit_observation_scaling()
            trainer.train_iteration()  # warm-up
            trainers[activation] = trainer
        for repeat in range(args.repeats):
            for index in range(args.iterations):
                for activation, trainer in trainers.items():
                    began = time.process_time()
                    trainer.train_iteration()
                    runs.append(
                        {
                            "part": stage,
                            "name": activation,
                            # the pair: this iteration of every activation, back to back
                            "repeat": repeat * args.iterations + index,
                            "cpu_s": time.process_time() - began,
                        }
                    )
            shown = {r["name"]: r["cpu_s"] for r in runs if r["part"] == stage}
            print(
                f"[{repeat}] {stage:<17} "
                + "  ".join(f"{a} {shown[a]:.2f}" for a in activations)
                + " CPU s/iteration",
                flush=True,
            )
        del trainers
    return runs, budgets


def main(argv=None) -> int:
    args = parse_args(argv)
    import numpy as np
    import torch

    from vdtn_marl.algos.networks import ACTIVATION_CLASSES
    from vdtn_marl.algos.params import ACTIVATIONS
    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    torch.set_num_threads(1)
    load_start = os.getloadavg()
    generator = torch.Generator().manual_seed(0)
    data = {part: torch.randn(rows, CELLS, generator=generator) * 2 for part, rows in ROWS.items()}
    kernels = {name: ACTIVATION_CLASSES[name].function for name in ACTIVATIONS}
    policies = {a: _rra_policy(a) for a in ACTIVATIONS}
    links, features = policies["tanh"].mode.n_agents, policies["tanh"].mode.scaler.center.numel()
    observation = torch.randn(256, links, features, generator=generator)
    kernel_runs, policy_runs = [], []
    for repeat in range(args.repeats):
        for part, x in data.items():
            array = x.numpy()
            for name, fn in [*kernels.items(), ("np.tanh (NumPy)", None)]:
                call = (lambda a=array: np.tanh(a)) if fn is None else (lambda fn=fn, x=x: fn(x))
                us = _cpu_us(call, args.calls)
                kernel_runs.append({"part": part, "name": name, "repeat": repeat, "us": us})
        for name, policy in policies.items():
            us = _cpu_us(lambda policy=policy: policy(observation), args.calls)
            policy_runs.append({"part": "rra_call_B256", "name": name, "repeat": repeat, "us": us})
    kernel_rows = _ratio_rows(kernel_runs, "us")
    policy_rows = _ratio_rows(policy_runs, "us")
    print(f"{'kernel / call':<20} {'rows':>6} {'activation':<16} {'µs':>8} {'tanh/this':>9}")
    for row in kernel_rows:
        print(
            f"{row['part']:<20} {ROWS[row['part']]:>6} {row['name']:<16} {row['us']:>8.1f} "
            f"{row['tanh_over_this']:>9.2f}"
        )
    for row in policy_rows:
        print(
            f"{row['part']:<20} {256 * links:>6} {row['name']:<16} {row['us']:>8.1f} "
            f"{row['tanh_over_this']:>9.2f}"
        )

    stage_runs, stage_rows, budgets, training_min = [], [], {}, {}
    if args.stages:
        stage_runs, budgets = _time_stages(args, ACTIVATIONS)
        stage_rows = _ratio_rows(stage_runs, "cpu_s")
        iterations = {
            "pi_star": budgets["control_iterations"],
            "pi_tilde_learned": budgets["control_iterations"],
            "rra": budgets["rra_iterations"],
        }
        print(f"\n{'stage':<17} {'activation':<13} {'CPU s/iter':>10} {'tanh/this':>9}")
        for row in stage_rows:
            print(
                f"{row['part']:<17} {row['name']:<13} {row['cpu_s']:>10.2f} "
                f"{row['tanh_over_this']:>9.2f}"
            )
        for activation in ACTIVATIONS:
            mine = {r["part"]: r["cpu_s"] for r in stage_rows if r["name"] == activation}
            if set(mine) == set(iterations):
                training_min[activation] = sum(iterations[s] * mine[s] for s in mine) / 60.0
        for activation, minutes in training_min.items():
            print(
                f"experiment=paper, training stages of a later JOCC iteration with "
                f"{activation}: {minutes:.1f} CPU min"
            )
    atomic_write_json(
        args.out,
        {
            **provenance("activation_cost"),
            "load_average_start": load_start,
            "load_average_end": os.getloadavg(),
            "cells": CELLS,
            "calls": args.calls,
            "repeats": args.repeats,
            "kernels": kernel_rows,
            "rra_policy_call": policy_rows,
            "stages": stage_rows,
            "paper_budgets": budgets,
            "training_cpu_min_later_iteration": training_min,
            "runs": {"kernels": kernel_runs, "rra_policy_call": policy_runs, "stages": stage_runs},
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
