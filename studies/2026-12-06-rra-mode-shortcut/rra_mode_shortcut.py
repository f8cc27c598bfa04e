"""What the learned RRA policy's cheaper deterministic call gives π̃'s PPO iterations.

    python studies/2026-12-06-rra-mode-shortcut/rra_mode_shortcut.py  # writes \
        rra_mode_shortcut.json
    python studies/2026-12-06-rra-mode-shortcut/rra_mode_shortcut.py --batch-sizes 64 \
        --repeats 1 --out /tmp/m.json

Under the learned RRA every subframe of π̃'s radio calls the RRA policy once, for the mode of
its Categorical (:func:`vdtn_marl.algos.networks.categorical_mode`). The call as shipped (1)
takes the argmax of the logits when every row's best logit leads its others by a margin that
the probabilities' rounding cannot close (:func:`~vdtn_marl.algos.networks.mode_shortcut`),
instead of a logsumexp, a softmax and a max, and (2) reads the network's weights once per
interval's radio (``ActorPolicy.bound``) instead of at every call. The reference arm is the
call without both: no shortcut, the weights read at every call.

Per batch size B (the ``experiment=paper`` loop as ``benchmarks/stage_throughput.py`` builds it,
rollout 25,600 / B intervals, torch on the run's 1 intra-op thread plus the draw-ahead thread), in
one process: ``--repeats`` interleaved pairs of whole PPO iterations (collect + update), the
reference first in even pairs and second in odd ones; the ratio is the median over pairs of
reference / shipped seconds. The same iterations count the policy's calls, those in which
some row took the long way (a near tie), and those rows. After each pair, the policy's
actions on the twin's current RRA observation are compared bit for bit between the arms and
with the actor's own TensorDict path (``ActorPolicy.action``: TorchRL's deterministic
Categorical).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = HERE.parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import stage_throughput  # noqa: E402  (the sibling script: the stage loop it builds)
from stage_throughput import CONTROL_FRAMES, timed_iteration  # noqa: E402

RESULTS = HERE / "rra_mode_shortcut.json"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[256, 1024])
    p.add_argument("--repeats", type=int, default=5, help="interleaved iteration pairs per B")
    p.add_argument(
        "--frames",
        type=int,
        default=CONTROL_FRAMES,
        help="samples per PPO iteration (B × rollout intervals); the paper's by default",
    )
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if args.frames < 1:
        p.error(f"--frames {args.frames} must be >= 1")
    bad = [b for b in args.batch_sizes if b < 1 or args.frames % b]
    if bad:
        p.error(f"--batch-sizes {bad} must be >= 1 and divide --frames {args.frames}")
    if args.repeats < 1:
        p.error(f"--repeats {args.repeats} must be >= 1")
    return args


@contextlib.contextmanager
def reference():
    """Inside the block the policy's call is the reference: the probabilities computed at
    every call (no shortcut) and the weights read at every call (no binding)."""
    from vdtn_marl.algos import networks
    from vdtn_marl.algos.ppo import ActorPolicy

    shortcut, bound = networks.mode_shortcut, ActorPolicy.bound
    networks.mode_shortcut = lambda logits: None
    ActorPolicy.bound = lambda policy: policy
    try:
        yield
    finally:
        networks.mode_shortcut, ActorPolicy.bound = shortcut, bound


class ShortcutCount:
    """Counts the shipped arm's mode calls, those with some row that took the long way, and
    the rows (scenario × link) of all calls and of those rows."""

    def __enter__(self):
        from vdtn_marl.algos import networks

        self.networks, self.original = networks, networks.mode_shortcut
        self.calls = self.long_way = self.rows = self.near_rows = 0
        original = self.original

        def counted(logits):
            out = original(logits)
            self.calls += 1
            self.long_way += out is None or out[1] is not None
            if out is not None and out[1] is not None:
                self.near_rows += out[1].numel()
            self.rows += logits[..., 0].numel()
            return out

        networks.mode_shortcut = counted
        return self

    def __exit__(self, *exc):
        self.networks.mode_shortcut = self.original
        return False


def measure(batch: int, repeats: int, frames: int = CONTROL_FRAMES) -> dict:
    import torch

    st = stage_throughput
    _, loop = st._loop([f"algo.num_envs={batch}", f"algo.rollout_steps={frames // batch}"])
    trainer = st.stage_trainer(loop, "pi_tilde_learned")
    trainer.fit_observation_scaling()
    policy = loop.rra_slot.policy
    if getattr(policy, "mode", None) is None:
        raise SystemExit("the learned RRA policy has no CategoricalMode fast path")
    trainer.train_iteration()  # warm-up
    twin = trainer.env.twin
    shipped, ref, identical = [], [], []
    calls = long_way = rows = near_rows = 0
    for repeat in range(repeats):
        for arm in ("reference", "shipped") if repeat % 2 == 0 else ("shipped", "reference"):
            if arm == "reference":
                with reference():
                    ref.append(timed_iteration(trainer))
            else:
                with ShortcutCount() as count:
                    shipped.append(timed_iteration(trainer))
                calls, long_way = calls + count.calls, long_way + count.long_way
                rows, near_rows = rows + count.rows, near_rows + count.near_rows
        observation = twin.rra_observation().clone()
        with torch.no_grad():
            fast = policy(observation)
            with reference():
                slow = policy(observation)
            own = policy.action(observation)
        identical.append(bool(torch.equal(fast, slow) and torch.equal(fast, own)))
    return {
        "batch_size": batch,
        "intervals_per_iteration": frames // batch,
        "reference": ref,
        "shipped": shipped,
        "reference_s": statistics.median(r["seconds"] for r in ref),
        "shipped_s": statistics.median(r["seconds"] for r in shipped),
        "reference_collect_s": statistics.median(r["collect_s"] for r in ref),
        "shipped_collect_s": statistics.median(r["collect_s"] for r in shipped),
        "reference_over_shipped": statistics.median(
            r["seconds"] / s["seconds"] for r, s in zip(ref, shipped, strict=True)
        ),
        "collect_reference_over_shipped": statistics.median(
            r["collect_s"] / s["collect_s"] for r, s in zip(ref, shipped, strict=True)
        ),
        "mode_calls": calls,
        "long_way_calls": long_way,
        "mode_rows": rows,
        "near_rows": near_rows,
        "actions_bit_identical": all(identical),
    }


def main(argv=None) -> int:
    args = parse_args(argv)
    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    load_start = os.getloadavg()
    rows = []
    for batch in args.batch_sizes:
        print(f"B = {batch}: {args.repeats} interleaved iteration pairs ...", flush=True)
        rows.append(measure(batch, args.repeats, args.frames))
    result = {
        **provenance("rra_mode_shortcut"),
        "load_average_start": list(load_start),
        "load_average_end": list(os.getloadavg()),
        "repeats": args.repeats,
        "frames_per_iteration": args.frames,
        "rows": rows,
    }
    print(
        f"\n{'B':>5} {'reference s':>11} {'shipped s':>9} {'ref/shipped':>11} "
        f"{'collect ratio':>13} {'long way':>10} {'identical':>9}"
    )
    for r in rows:
        print(
            f"{r['batch_size']:>5} {r['reference_s']:>11.2f} {r['shipped_s']:>9.2f} "
            f"{r['reference_over_shipped']:>11.2f} {r['collect_reference_over_shipped']:>13.2f} "
            f"{r['long_way_calls']:>4}/{r['mode_calls']:<5} {r['actions_bit_identical']!s:>9}"
        )
    atomic_write_json(args.out, result)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
