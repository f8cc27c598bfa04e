"""Cost of one call of the learned RRA policy (every 1 ms subframe of π̃'s and the evaluation's
radio): the fast path (``CategoricalMode``, straight from the actor's layers) against the
actor's own TensorDict path (``ActorPolicy.action``), interleaved in one process.

    python studies/2026-12-05-rra-policy-call/rra_policy_call.py  # writes rra_policy_call.json
    python studies/2026-12-05-rra-policy-call/rra_policy_call.py --batches 64 --repeats 3 \
        --calls 100 --out /tmp/x.json

The RRA actor is the one ``vdtn-marl jocc`` builds (``experiment=smoke``'s network; the sizes of
the network are those of every experiment). Per batch size B (scenarios; observations
[B, links, features]), ``--repeats`` pairs of ``--calls`` calls each, fast then slow, timed in
process CPU seconds (torch on 1 thread); the table reports the median µs per call and the
median over pairs of slow / fast. Both paths return the same actions (checked per B).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "rra_policy_call.json"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batches", default="16,64,128,256", help="scenarios B per call")
    p.add_argument("--repeats", type=int, default=7, help="interleaved pairs per B")
    p.add_argument("--calls", type=int, default=300, help="calls per timing")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    from vdtn_marl.reporting.benchmarking import parse_seeds

    args.batches = parse_seeds("--batches", args.batches)
    if any(b < 1 for b in args.batches):
        p.error(f"--batches {args.batches} must be >= 1")
    if args.repeats < 1 or args.calls < 1:
        p.error("--repeats and --calls must be >= 1")
    return args


def _cpu_seconds(fn, observation, calls: int) -> float:
    began = time.process_time()
    for _ in range(calls):
        fn(observation)
    return (time.process_time() - began) / calls


def main(argv=None) -> int:
    args = parse_args(argv)
    import torch

    from vdtn_marl.algos.ppo import ActorPolicy
    from vdtn_marl.experiment.compose import (
        compose_config,
        hydra_compose,
        job_config,
        to_run_config,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation
    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    torch.set_num_threads(1)
    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", ["experiment=smoke"])))
    cfg.progress = False
    loop = JointOptimisation(cfg, tempfile.mkdtemp(prefix="rra_policy_call_"))
    policy = ActorPolicy(loop.rra.actor, "rra")
    if policy.mode is None:
        raise SystemExit("the RRA actor has no fast path (CategoricalMode.of returned None)")
    links, features = policy.mode.n_agents, policy.mode.scaler.center.numel()
    load_start = os.getloadavg()
    rows = []
    generator = torch.Generator().manual_seed(0)
    for batch in args.batches:
        observation = torch.randn(batch, links, features, generator=generator)
        if not torch.equal(policy(observation), policy.action(observation)):
            raise SystemExit(f"B={batch}: the fast path's actions differ from the actor's")
        fast, slow = [], []
        for _ in range(args.repeats):
            fast.append(_cpu_seconds(policy, observation, args.calls))
            slow.append(_cpu_seconds(policy.action, observation, args.calls))
        rows.append(
            {
                "batch": batch,
                "fast_us": 1e6 * statistics.median(fast),
                "actor_us": 1e6 * statistics.median(slow),
                "actor_over_fast": statistics.median(
                    s / f for s, f in zip(slow, fast, strict=True)
                ),
                "fast_runs_us": [1e6 * f for f in fast],
                "actor_runs_us": [1e6 * s for s in slow],
            }
        )
    print(f"{'B':>5} {'fast µs':>8} {'actor µs':>9} {'actor/fast':>10}")
    for row in rows:
        print(
            f"{row['batch']:>5} {row['fast_us']:>8.0f} {row['actor_us']:>9.0f} "
            f"{row['actor_over_fast']:>10.2f}"
        )
    atomic_write_json(
        args.out,
        {
            **provenance("rra_policy_call"),
            "load_average_start": load_start,
            "load_average_end": os.getloadavg(),
            "links": links,
            "features": features,
            "calls": args.calls,
            "repeats": args.repeats,
            "rows": rows,
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
