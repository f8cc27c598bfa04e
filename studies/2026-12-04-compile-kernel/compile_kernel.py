"""Whether ``torch.compile`` pays for the link-major subframe kernel, and whether it keeps its
numbers: the kernel's arithmetic (``link.link_major_arithmetic``, the very function the twin
runs from B = 256 on) called eagerly and compiled, on the same interval, in one process.

    python studies/2026-12-04-compile-kernel/compile_kernel.py  # writes compile_kernel.json
    python studies/2026-12-04-compile-kernel/compile_kernel.py --batch-sizes 256 --repeats 2 \
        --out /tmp/ck.json

Per batch size B a ``DigitalTwin`` (seed ``--seed``, draws at the interval start) gives one
interval's tables and random RRA actions; the kernel runs its T subframes from the interval's
start state, eagerly and compiled (``torch.compile(dynamic=False)``, TorchInductor; on the
CPU it writes and compiles C++ at run time, so it needs a C++ compiler). The script reports
the first compiled call's seconds (compilation), whether every output of every subframe is
bit for bit the eager one's, and µs per subframe either way, ``--repeats`` interleaved pairs
of ``--intervals`` intervals (medians; the ratio is the median over pairs of eager /
compiled). Only the arithmetic is timed: the twin's wrapper (table slicing, state rebinding)
costs the same either way. Where compilation fails the row says why and the script goes on.

This is a measurement, not a switch: the twin runs the kernel eagerly (docs/profile.md, *Not
done*). torch runs on 1 intra-op thread.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "compile_kernel.json"


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[256, 1024, 4096])
    p.add_argument("--repeats", type=int, default=5, help="interleaved pairs per B")
    p.add_argument("--intervals", type=int, default=4, help="intervals per timing")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    if any(b < 1 for b in args.batch_sizes):
        p.error(f"--batch-sizes {args.batch_sizes} must all be >= 1")
    if args.repeats < 1 or args.intervals < 1:
        p.error(f"--repeats {args.repeats} and --intervals {args.intervals} must be >= 1")
    return args


class Interval:
    """One interval of a twin's link-major kernel: its arguments, and a run of its T
    subframes through ``kernel`` (``link.link_major_arithmetic`` or a compiled copy)."""

    def __init__(self, batch: int, seed: int):
        import torch

        from vdtn_marl.sim import link
        from vdtn_marl.sim.twin import DigitalTwin

        twin = DigitalTwin(batch_size=batch, seed=seed, draw_ahead=False)
        self.subframes = twin.subframes_per_interval
        self.tables = twin.tables.link_major()
        generator = torch.Generator().manual_seed(seed)
        self.actions = torch.randint(
            0,
            twin.params.radio.num_actions,
            (self.subframes, batch, twin.num_links),
            generator=generator,
        )
        self.remaining = twin.link_state.remaining_bits
        # the kernel's own constants, as the twin passes them
        self.constants = link.link_major_constants(twin._decode, twin._const, self.tables[0][0])

    def run(self, kernel) -> list:
        remaining, outputs = self.remaining, []
        for t in range(self.subframes):
            out = kernel(
                *(table[t] for table in self.tables), self.actions[t], remaining, *self.constants
            )
            remaining = out[5].T
            outputs.append(out)
        return outputs


def _seconds(fn) -> float:
    began = time.perf_counter()
    fn()
    return time.perf_counter() - began


def measure(batch: int, seed: int, repeats: int, intervals: int) -> dict:
    import torch

    from vdtn_marl.sim.link import link_major_arithmetic

    interval = Interval(batch, seed)
    row: dict = {"batch_size": batch, "subframes": interval.subframes}
    compiled = torch.compile(link_major_arithmetic, dynamic=False)
    try:
        row["compile_s"] = _seconds(lambda: interval.run(compiled))
    except Exception as error:  # no C++ compiler, an unsupported platform, ...
        row["compiled"] = False
        row["error"] = f"{type(error).__name__}: {str(error).splitlines()[0][:300]}"
        return row
    row["compiled"] = True
    eager_out, compiled_out = interval.run(link_major_arithmetic), interval.run(compiled)
    pairs = [
        (a, b)
        for sa, sb in zip(eager_out, compiled_out, strict=True)
        for a, b in zip(sa, sb, strict=True)
    ]
    row["bit_identical"] = all(torch.equal(a, b) for a, b in pairs)
    row["differing_values"] = sum(int((a != b).sum()) for a, b in pairs)
    eager, fast = [], []
    per = 1e6 / (intervals * interval.subframes)
    for _ in range(repeats):
        for kernel, runs in ((link_major_arithmetic, eager), (compiled, fast)):
            runs.append(
                per * _seconds(lambda k=kernel: [interval.run(k) for _ in range(intervals)])
            )
    row.update(
        eager_us=statistics.median(eager),
        compiled_us=statistics.median(fast),
        eager_over_compiled=statistics.median(e / c for e, c in zip(eager, fast, strict=True)),
        eager_runs_us=eager,
        compiled_runs_us=fast,
    )
    return row


def main(argv=None) -> int:
    args = parse_args(argv)
    import torch

    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    torch.set_num_threads(1)
    load_start = os.getloadavg()
    rows = []
    for batch in args.batch_sizes:
        print(f"B = {batch}: compiling and timing ...", flush=True)
        rows.append(measure(batch, args.seed, args.repeats, args.intervals))
    print(f"\n{'B':>6} {'compile s':>9} {'bit for bit':>11} {'eager µs':>9} {'compiled µs':>11} "
          f"{'eager/compiled':>14}")  # fmt: skip
    for r in rows:
        if not r["compiled"]:
            print(f"{r['batch_size']:>6} compilation failed: {r['error']}")
            continue
        print(
            f"{r['batch_size']:>6} {r['compile_s']:>9.1f} {str(r['bit_identical']):>11} "
            f"{r['eager_us']:>9.0f} {r['compiled_us']:>11.0f} {r['eager_over_compiled']:>14.2f}"
        )
    atomic_write_json(
        args.out,
        {
            **provenance("compile_kernel"),
            "load_average_start": list(load_start),
            "load_average_end": list(os.getloadavg()),
            "repeats": args.repeats,
            "intervals": args.intervals,
            "seed": args.seed,
            "rows": rows,
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
