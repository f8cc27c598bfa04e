"""Paired cost of a restart's start in either order of its draws: the interval's draws first
and the new episodes' after them (``DigitalTwin.restart``: the draws made ahead on the second
thread are kept) against the new episodes' first (``reset(mask, begin=False)`` then
``begin_interval()``: the draws made ahead are discarded and the interval's drawn again on the
main thread).

    python studies/2026-12-06-restart-draws/restart_draws.py  # writes restart_draws.json
    python studies/2026-12-06-restart-draws/restart_draws.py --batch-sizes 256 --repeats 1 \
        --out /tmp/rd.json

Per batch size a default (platoon4) twin (draws ahead from
``link.DRAW_AHEAD_MIN_BATCH`` scenarios) runs ``--intervals`` intervals of random RRA actions
and a CACC close; after each, ``--fraction`` of its scenarios (at least one) restart with the
rest's next interval, as π̃'s persisting scenarios do at about half of their intervals
(``studies/2026-12-06-steady-state-resets/steady_state_resets.py``). Only the restart is timed (wall
seconds), so the noise of the subframes around it stays out. The two orders run ``--repeats`` times,
alternating which goes first, each from the same seed: the same scenarios restart at the same
intervals in both. The table gives the median milliseconds per restart either way and the
median over repeats of (new episodes first / interval first).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "restart_draws.json"
ORDERS = ("interval_first", "episodes_first")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[256, 1024])
    p.add_argument("--intervals", type=int, default=40, help="timed restarts per order and repeat")
    p.add_argument("--repeats", type=int, default=3, help="rounds of both orders")
    p.add_argument("--fraction", type=float, default=0.02, help="share of scenarios restarting")
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if min(args.batch_sizes) < 2:
        p.error(f"--batch-sizes {args.batch_sizes} must be >= 2 (some scenarios go on)")
    if args.intervals < 1 or args.repeats < 1:
        p.error(f"--intervals {args.intervals} and --repeats {args.repeats} must be >= 1")
    if not 0.0 <= args.fraction < 1.0:
        p.error(f"--fraction {args.fraction} must be in [0, 1)")
    return args


def time_restarts(order: str, batch: int, intervals: int, fraction: float, seed: int = 0):
    """Seconds of each of ``intervals`` restarts in ``order``, and whether the twin draws ahead."""
    import torch

    from vdtn_marl.policies.cacc import CACCController
    from vdtn_marl.sim.params import TwinParams
    from vdtn_marl.sim.twin import DigitalTwin

    params = TwinParams.from_overrides(episode_intervals=400)
    cacc = CACCController(params.platoon)
    twin = DigitalTwin(params, batch_size=batch, seed=seed)
    actions = torch.Generator().manual_seed(seed + 1)
    shape = (batch, twin.num_links)
    seconds = []
    for k in range(intervals):
        for _ in range(twin.subframes_per_interval):
            twin.step_subframe(torch.randint(0, params.radio.num_actions, shape, generator=actions))
        twin.finish_interval(cacc(twin.vehicle_observation(perfect=False)), perfect=False)
        ended = torch.rand(batch, generator=actions) < fraction
        ended[k % batch] = True
        ended[(k + 1) % batch] = False  # some go on
        began = time.perf_counter()
        if order == "interval_first":
            twin.restart(ended)
        else:
            twin.reset(mask=ended, begin=False)
            twin.begin_interval()
        seconds.append(time.perf_counter() - began)
    return seconds, twin.draw_ahead


def main(argv=None) -> int:
    args = parse_args(argv)
    import torch

    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    torch.set_num_threads(1)
    load_start = os.getloadavg()
    rows, runs = [], []
    print(f"{'B':>6} {'interval first ms':>17} {'episodes first ms':>17} {'ratio':>6}")
    for batch in args.batch_sizes:
        ms = {order: [] for order in ORDERS}
        ratios = []
        for repeat in range(args.repeats):
            mean = {}
            for order in ORDERS if repeat % 2 == 0 else ORDERS[::-1]:
                seconds, ahead = time_restarts(order, batch, args.intervals, args.fraction)
                mean[order] = statistics.mean(seconds) * 1e3
                ms[order].append(mean[order])
                runs.append({"batch": batch, "repeat": repeat, "order": order, "seconds": seconds})
            ratios.append(mean["episodes_first"] / mean["interval_first"])
        row = {
            "batch": batch,
            "draw_ahead": ahead,
            **{f"{order}_ms": statistics.median(ms[order]) for order in ORDERS},
            "episodes_first_over_interval_first": statistics.median(ratios),
            "ratio_min": min(ratios),
            "ratio_max": max(ratios),
        }
        rows.append(row)
        print(
            f"{batch:>6} {row['interval_first_ms']:>17.2f} {row['episodes_first_ms']:>17.2f} "
            f"{row['episodes_first_over_interval_first']:>6.2f}",
            flush=True,
        )
    atomic_write_json(
        args.out,
        {
            **provenance("restart_draws"),
            "load_average_start": list(load_start),
            "load_average_end": list(os.getloadavg()),
            "intervals": args.intervals,
            "repeats": args.repeats,
            "fraction": args.fraction,
            "rows": rows,
            "runs": runs,
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
