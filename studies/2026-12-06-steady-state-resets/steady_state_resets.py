"""What π̃'s collection costs in a run's steady state against freshly reset scenarios: the
partial resets that persisting scenarios bring, counted and timed in one process.

    python studies/2026-12-06-steady-state-resets/steady_state_resets.py \
        RUN_DIR/checkpoints/last.pt \
        --out studies/2026-12-06-steady-state-resets/steady_state_resets.json

``benchmarks/stage_throughput.py`` times each stage from freshly reset scenarios: they all
start at interval 0, so their episodes end together (every 400 intervals, once per 4 PPO
iterations of ``experiment=paper``) and only a collision resets a few of them in between. A
run's scenarios persist across PPO iterations (``algo.persistent_envs``): every collision
starts that scenario's episode anew at another offset, so after some hundreds of iterations
episodes end at many intervals. At such an interval the TorchRL environment starts the
ended scenarios' episodes together with the others' next interval, one interval start and one
radio run for the whole batch (``IntervalEngine.restart_ended``); the ``separate`` arm times
what that replaces: the others' next interval (``advance``), then the ended scenarios' reset
with its own interval start and radio run (``reset``).

From a ``jocc`` checkpoint (its config, weights and π̃'s persisting scenarios; the RRA policy
π̃ trains under at that point: the learned one once the RRA agents have trained), three arms
of π̃'s collection, interleaved ``--repeats`` times, each ``--iterations`` PPO iterations of
collection (no update, so every arm acts with the checkpoint's weights):

- ``run``: the checkpoint's scenarios, as the run continues them (restored before each repeat);
- ``reset_first``: the same, each restart drawing the new episodes' numbers before the
  interval's (``DigitalTwin.reset(begin=False)`` then ``begin_interval``), so that the draws
  made ahead on the second thread are discarded and the interval's are drawn again;
- ``separate``: the same, each ending restarted by ``advance`` and ``reset`` (two radio runs);
- ``fresh``: the same weights from scenarios reset with the trainer's seed of the checkpoint's
  iteration, timed after one collection (its warm-up), as ``benchmarks/stage_throughput.py`` times
  them.

Per arm: collection seconds (median over its iterations), radio runs per interval, and per
iteration the intervals at which some scenarios were reset and how many scenarios were. The
ratios of the medians say what the one-start restart saves (run / separate), what keeping the
draws made ahead saves (run / reset_first) and how much a benchmark from fresh scenarios
underestimates a run's π̃ iteration (run / fresh; the PPO update, the same in all arms, is not
part of it).
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "steady_state_resets.json"
ARMS = ("run", "reset_first", "separate", "fresh")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("checkpoint", type=Path, help="a jocc run's checkpoints/last.pt")
    p.add_argument("--iterations", type=int, default=3, help="PPO collections per arm and repeat")
    p.add_argument("--repeats", type=int, default=2, help="interleaved run/fresh pairs")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if not args.checkpoint.is_file():
        p.error(f"checkpoint {str(args.checkpoint)!r} does not exist")
    if args.iterations < 1 or args.repeats < 1:
        p.error(f"--iterations {args.iterations} and --repeats {args.repeats} must be >= 1")
    return args


class Counts:
    """Counts, inside ``with``, the radio runs and the resets: the intervals at which scenarios
    restart (``IntervalEngine.reset`` or ``restart_ended``), how many do, and at how many all
    of them do. ``separate``: ``restart_ended`` does what it replaces, ``advance`` of the
    others, then ``reset`` of the ended scenarios, which runs their first interval's radio
    besides the others' next interval's. ``reset_first``: the twin's restart draws the new
    episodes' numbers before the interval's."""

    def __init__(self, separate: bool = False, reset_first: bool = False):
        self.separate = separate
        self.reset_first = reset_first

    def __enter__(self):
        from vdtn_marl.core.interval import IntervalEngine
        from vdtn_marl.sim.twin import DigitalTwin

        self.radio_runs, self.resets, self.reset_rows, self.whole = 0, 0, 0, 0
        self._saved = (
            (IntervalEngine, "run_radio", IntervalEngine.run_radio),
            (IntervalEngine, "reset", IntervalEngine.reset),
            (IntervalEngine, "restart_ended", IntervalEngine.restart_ended),
            (DigitalTwin, "restart", DigitalTwin.restart),
        )
        radio, reset, restart = (saved[2] for saved in self._saved[:3])
        separate = self.separate

        def counted_restart(engine, going):
            ended = ~going
            if not bool(ended.any()) or bool(ended.all()):  # advance, or reset (counted)
                return restart(engine, going)
            if separate:
                engine.advance(going)
                return engine.reset(ended)  # counted there
            self.resets += 1
            self.reset_rows += int(ended.sum())
            return restart(engine, going)

        def counted_radio(engine, *args, **kwargs):
            self.radio_runs += 1
            return radio(engine, *args, **kwargs)

        def counted_reset(engine, mask=None, *args, **kwargs):
            rows = engine.twin.batch_size if mask is None else int(mask.sum())
            self.resets += 1
            self.reset_rows += rows
            self.whole += rows == engine.twin.batch_size
            return reset(engine, mask, *args, **kwargs)

        IntervalEngine.run_radio = counted_radio
        IntervalEngine.reset = counted_reset
        IntervalEngine.restart_ended = counted_restart
        if self.reset_first:

            def restart_reset_first(twin, mask):
                twin.reset(mask=mask, begin=False)
                twin.begin_interval()

            DigitalTwin.restart = restart_reset_first
        return self

    def __exit__(self, *exc):
        for owner, name, original in self._saved:
            setattr(owner, name, original)
        return False


def load_loop(checkpoint: Path, run_dir: Path):
    """The checkpoint's loop (weights and π̃'s persisting scenarios), writing in ``run_dir``,
    with π̃'s RRA slot holding the policy π̃ trains under from that point, and torch on the run's
    threads."""
    import torch

    from vdtn_marl.experiment.checkpoint import run_config
    from vdtn_marl.experiment.jocc import JointOptimisation

    threads = run_config(checkpoint)[0].threads
    if threads:
        torch.set_num_threads(threads)
    loop = JointOptimisation.from_checkpoint(checkpoint, run_dir, needs_pi_tilde=True)
    loop.rra_slot.policy = loop.rra_policy()
    return loop


def collect(trainer, iterations: int, arm: str = "run") -> list[dict]:
    rows = []
    for _ in range(iterations):
        with Counts(arm == "separate", arm == "reset_first") as counts:
            began, began_cpu = time.perf_counter(), time.process_time()
            data = trainer.collect()
            seconds, cpu = time.perf_counter() - began, time.process_time() - began_cpu
        intervals = int(data.shape[-1])
        rows.append(
            {
                "seconds": seconds,
                "cpu_seconds": cpu,
                "intervals": intervals,
                "radio_runs": counts.radio_runs,
                "reset_intervals": counts.resets,
                "reset_scenarios": counts.reset_rows,
                "whole_batch_resets": counts.whole,
            }
        )
        trainer.iteration += 1  # the next collection continues, as the run's would
    return rows


def summarise(rows: list[dict]) -> dict:
    intervals = sum(r["intervals"] for r in rows)
    n = len(rows)
    return {
        "collect_s": statistics.median(r["seconds"] for r in rows),
        "collect_cpu_s": statistics.median(r["cpu_seconds"] for r in rows),
        "radio_runs_per_interval": sum(r["radio_runs"] for r in rows) / intervals,
        "reset_intervals_per_iteration": sum(r["reset_intervals"] for r in rows) / n,
        "reset_scenarios_per_iteration": sum(r["reset_scenarios"] for r in rows) / n,
        "iterations": n,
    }


def main(argv=None) -> int:
    args = parse_args(argv)
    import torch

    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    load_start = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="steady_state_") as tmp:
        loop = load_loop(args.checkpoint, Path(tmp) / "run")
        trainer = loop.pi_tilde
        start_iteration = trainer.iteration
        env_state, carry = trainer.env.state_dict(), trainer._carry
        rng = torch.get_rng_state()
        runs: dict[str, list[dict]] = {arm: [] for arm in ARMS}
        for repeat in range(args.repeats):
            for arm in ARMS:
                print(f"repeat {repeat + 1}/{args.repeats}: {arm} ...", flush=True)
                trainer.iteration = start_iteration
                torch.set_rng_state(rng)
                trainer.env.load_state_dict(env_state)
                trainer._carry = None if arm == "fresh" else carry.clone()
                if arm == "fresh":  # reset, then one collection untimed, as stage_throughput.py
                    collect(trainer, 1)
                runs[arm] += collect(trainer, args.iterations, arm)
        policy = type(loop.rra_slot.policy).__name__
        batch = tuple(trainer.env.batch_size)
    arms = {arm: summarise(rows) for arm, rows in runs.items()}
    ratio = arms["run"]["collect_s"] / arms["fresh"]["collect_s"]
    saved = arms["run"]["collect_s"] / arms["separate"]["collect_s"]
    kept = arms["run"]["collect_s"] / arms["reset_first"]["collect_s"]
    result = {
        **provenance("steady_state_resets"),
        "load_average_start": list(load_start),
        "load_average_end": list(os.getloadavg()),
        "checkpoint": str(args.checkpoint),
        "pi_tilde_iteration": start_iteration,
        "rra_policy": policy,
        "batch": list(batch),
        "arms": arms,
        "run_over_fresh_collect_s": ratio,
        "run_over_separate_collect_s": saved,
        "run_over_reset_first_collect_s": kept,
        "runs": runs,
    }
    print(f"\nπ̃ at PPO iteration {start_iteration}, B = {batch[0]}, RRA policy {policy}")
    print(
        f"{'arm':<11} {'collect s':>9} {'radio/int':>9} {'reset int/it':>12} {'reset scen/it':>13}"
    )
    for arm, s in arms.items():
        print(
            f"{arm:<11} {s['collect_s']:>9.2f} {s['radio_runs_per_interval']:>9.2f} "
            f"{s['reset_intervals_per_iteration']:>12.1f} "
            f"{s['reset_scenarios_per_iteration']:>13.1f}"
        )
    print(f"run / separate collection seconds: {saved:.2f} (one restart start against two)")
    print(f"run / reset_first collection seconds: {kept:.2f} (the draws made ahead kept)")
    print(f"run / fresh collection seconds: {ratio:.2f}")
    atomic_write_json(args.out, result)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
