"""Where the batched core's time goes, beside what this machine can do at most.

For each batch size B the script drives ``DigitalTwin(batch_size=B)`` as
``benchmarks/throughput.py`` does (random RRA actions and ``rra_observation()`` every subframe;
at each interval end the impaired vehicle observation, a CACC command, ``finish_interval`` and
``begin_interval``) and reports, per 50 ms control interval:

- the wall time of its phases: the T subframes (``step_subframe`` + ``rra_observation``), the
  interval's close (vehicle observation, CACC, ``finish_interval``) and the next interval's
  start (``begin_interval``: shadowing, the interval's fading draws, tables and RRA
  observation buffer), as milliseconds and shares, and the agent-subframe steps/s they add
  up to. The twin draws at each interval's start (``draw_ahead=False``), so that the draws
  show in the start's profile; ``benchmarks/throughput.py`` times both ways. With
  ``--draw-ahead`` the twin makes the next interval's draws on a second thread (the default
  of ``DigitalTwin``): the phases are then the main thread's, and a fourth, ``wait``, is the
  time the start waits for that thread before it begins (the thread's operators are in no
  phase's table);
- torch profiler tables of the start of an interval and of the subframes: each operator's
  share of the phase's self CPU time and its calls per interval;
- the machine's limits measured in the same run: ``Tensor.normal_`` draws/s (the reference
  fading is two normal draws per gain), NumPy's float32 exponential draws/s (one per gain with
  ``--fading-draws exponential``), a large ``copy_``'s memory bandwidth, and the least time an
  interval's draws and table writes can take at those rates.

Prints markdown tables (``docs/profile.md`` holds a copy) and writes JSON with the command,
the date and the load average. torch runs on ``--threads`` intra-op threads (default 1).

    python benchmarks/profile_core.py                            # B = 1, 64, 1024, 4096
    python benchmarks/profile_core.py --batch-sizes 64 --intervals 5 --out /tmp/profile.json
    python benchmarks/profile_core.py --batch-sizes 1024 4096 --draw-ahead   # two threads
    python benchmarks/profile_core.py --device cuda --batch-sizes 4096 65536
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch.profiler import ProfilerActivity, profile, record_function

from vdtn_marl.io.files import atomic_write_json, script_command
from vdtn_marl.reporting.benchmarking import cpu_model

PHASES = ("subframes", "close", "start")
#: the phases with ``--draw-ahead``: ``wait`` is the start's wait for the second thread
PHASES_AHEAD = ("subframes", "close", "wait", "start")
PHASE_HELP = {
    "subframes": "T × (step_subframe + rra_observation)",
    "close": "vehicle observation + CACC + finish_interval",
    "wait": "waiting at the start for the next interval's draws made on the second thread",
    "start": "begin_interval (shadowing, fading draws, tables, RRA observation buffer)",
}
TOP_OPS = 8
LIMIT_VALUES = 1 << 24  # values per measurement of the machine's limits (64 MiB of float32)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[1, 64, 1024, 4096])
    p.add_argument("--device", default="cpu", help="torch device of the twin (cpu or cuda)")
    p.add_argument(
        "--intervals", type=int, default=0, help="timed intervals per B (0: about --seconds)"
    )
    p.add_argument("--seconds", type=float, default=4.0, help="timed seconds per B")
    p.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--fading-draws",
        choices=("normal", "exponential"),
        default="normal",
        help="the twin's fast-fading draws (DigitalTwin fading_draws)",
    )
    p.add_argument(
        "--draw-ahead",
        action="store_true",
        help="the next interval's draws on a second thread (DigitalTwin draw_ahead=True, from "
        "B = 128 on the CPU); default: at each interval's start, so that they show in its table",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="results JSON (default benchmarks/results/profile_core.json, "
        "profile_core_exponential.json with --fading-draws exponential, with _draw_ahead "
        "before .json with --draw-ahead)",
    )
    args = p.parse_args(argv)
    if args.out is None:
        suffix = "" if args.fading_draws == "normal" else f"_{args.fading_draws}"
        suffix += "_draw_ahead" if args.draw_ahead else ""
        args.out = Path(f"benchmarks/results/profile_core{suffix}.json")
    if any(b < 1 for b in args.batch_sizes):
        p.error(f"--batch-sizes {args.batch_sizes} must all be >= 1")
    if args.intervals < 0:
        p.error(f"--intervals {args.intervals} must be >= 0")
    if args.seconds <= 0:
        p.error(f"--seconds {args.seconds} must be > 0")
    if args.threads < 1:
        p.error(f"--threads {args.threads} must be >= 1")
    if args.device.startswith("cuda") and not torch.cuda.is_available():
        p.error(f"--device {args.device}: torch sees no CUDA device")
    return args


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


class CoreDriver:
    """The throughput benchmark's loop over a twin, one phase at a time."""

    def __init__(
        self, batch: int, device: str, seed: int, fading_draws: str = "normal",
        draw_ahead: bool = False,
    ):  # fmt: skip
        from vdtn_marl.policies.cacc import CACCController
        from vdtn_marl.sim.twin import DigitalTwin

        # by default the draws at the interval start (not on a second thread), so that each
        # phase's operators are its own
        self.twin = DigitalTwin(
            batch_size=batch,
            device=device,
            seed=seed,
            fading_draws=fading_draws,
            draw_ahead=draw_ahead,
        )
        self.phases = PHASES_AHEAD if draw_ahead else PHASES
        self.device = self.twin.device
        self.controller = CACCController(self.twin.params.platoon)
        self.generator = torch.Generator(device=self.device)
        self.generator.manual_seed(seed)
        self.batch = batch

    def subframes(self) -> None:
        twin = self.twin
        shape = (twin.subframes_per_interval, self.batch, twin.num_links)
        n_act = twin.params.radio.num_actions
        draws = torch.randint(0, n_act, shape, generator=self.generator, device=self.device)
        for t in range(twin.subframes_per_interval):
            twin.step_subframe(draws[t])
            twin.rra_observation()

    def close(self) -> None:
        twin = self.twin
        twin.finish_interval(self.controller(twin.vehicle_observation(False)), perfect=False)

    def wait(self) -> None:
        # the draws being made ahead (a private attribute: this script measures the thread)
        pending = self.twin._workspace.ahead
        if pending is not None:
            pending.wait()

    def start(self) -> None:
        twin = self.twin
        if int(twin.interval[0]) >= twin.params.episode_intervals:
            twin.reset()
        else:
            twin.begin_interval()

    def interval(self, times: dict[str, float] | None = None) -> None:
        for phase in self.phases:
            begin = time.perf_counter()
            with record_function(phase):
                getattr(self, phase)()
            if times is not None:
                _sync(self.device)
                times[phase] += time.perf_counter() - begin


def profile_batch(
    batch: int, device: str, seconds: float, intervals: int, seed: int, fading_draws: str,
    draw_ahead: bool = False,
) -> dict:  # fmt: skip
    driver = CoreDriver(batch, device, seed, fading_draws, draw_ahead)
    twin = driver.twin
    driver.interval()  # warm-up: buffers, caches
    _sync(driver.device)
    times = dict.fromkeys(driver.phases, 0.0)
    count = 0
    start = time.perf_counter()
    while (count < intervals) if intervals else (time.perf_counter() - start < seconds):
        driver.interval(times)
        count += 1
    per_interval_ms = {k: 1000.0 * v / count for k, v in times.items()}
    total_ms = sum(per_interval_ms.values())
    steps = twin.subframes_per_interval * batch * twin.num_links

    profiled = max(1, min(count, 5))
    activities = [ProfilerActivity.CPU]
    if driver.device.type == "cuda":
        activities.append(ProfilerActivity.CUDA)
    with profile(activities=activities) as prof:
        for _ in range(profiled):
            driver.interval()
        _sync(driver.device)
    return {
        "batch_size": batch,
        "device": str(driver.device),
        "num_links": twin.num_links,
        "subframes_per_interval": twin.subframes_per_interval,
        "intervals_timed": count,
        "per_interval_ms": per_interval_ms,
        "interval_ms": total_ms,
        "agent_steps_per_s": steps / (total_ms / 1000.0),
        "ops": {phase: _phase_ops(prof, phase, profiled) for phase in ("start", "subframes")},
        "fading_draws": twin.fading_draws,
        "draw_ahead": twin.draw_ahead,
        "draws_per_interval": _draws_per_interval(twin),
        "table_bytes_per_interval": _table_bytes(twin),
    }


def _phase_ops(prof, phase: str, intervals: int) -> list[dict]:
    """The operators called (directly or not) under ``phase``: self CPU time per interval and
    share, calls per interval, most expensive first."""
    totals: dict[str, list[float]] = {}
    for e in prof.events():
        if not e.name.startswith("aten::"):
            continue
        parent = e.cpu_parent
        while parent is not None and parent.name != phase:
            parent = parent.cpu_parent
        if parent is not None:
            entry = totals.setdefault(e.name, [0.0, 0])
            entry[0] += e.self_cpu_time_total
            entry[1] += 1
    whole = sum(v[0] for v in totals.values()) or 1.0
    rows = sorted(totals.items(), key=lambda kv: -kv[1][0])
    return [
        {
            "op": name,
            "self_ms_per_interval": us / 1000.0 / intervals,
            "share": us / whole,
            "calls_per_interval": calls / intervals,
        }
        for name, (us, calls) in rows[:TOP_OPS]
    ]


def _draws_per_interval(twin) -> int:
    """Fast-fading draws of one interval: two normals per gain, or one exponential."""
    from vdtn_marl.sim.link import fading_width

    gains = fading_width(twin.num_links, twin.num_subchannels)
    per_gain = 2 if twin.fading_draws == "normal" else 1
    return per_gain * twin.subframes_per_interval * twin.batch_size * gains


def _table_bytes(twin) -> int:
    """Bytes of float32 the interval's start writes at least once: the draws, the tables and
    the RRA observation buffer."""
    from vdtn_marl.sim.link import fading_width

    links, t, b = twin.num_links, twin.subframes_per_interval, twin.batch_size
    gains = fading_width(links, twin.num_subchannels)
    return 4 * t * b * (2 * gains + gains + links * twin.rra_obs_dim)


def machine_limits(device: str, seed: int) -> dict:
    """normal_ draws/s, uniform_ draws/s and copy bandwidth (read + write), medians of 5."""
    dev = torch.device(device)
    gen = torch.Generator(device=dev)
    gen.manual_seed(seed)
    x = torch.empty(LIMIT_VALUES, device=dev)
    y = torch.empty_like(x)
    x.normal_(generator=gen)
    y.copy_(x)

    def median_s(fn) -> float:
        runs = []
        for _ in range(5):
            _sync(dev)
            begin = time.perf_counter()
            fn()
            _sync(dev)
            runs.append(time.perf_counter() - begin)
        return float(np.median(runs))

    normal_s = median_s(lambda: x.normal_(generator=gen))
    uniform_s = median_s(lambda: x.uniform_(generator=gen))
    copy_s = median_s(lambda: y.copy_(x))
    rng = np.random.Generator(np.random.SFC64(seed))
    z = np.empty(LIMIT_VALUES, np.float32)
    exponential_s = median_s(lambda: rng.standard_exponential(out=z, dtype=np.float32))
    return {
        "normal_per_s": LIMIT_VALUES / normal_s,
        "numpy_exponential_per_s": LIMIT_VALUES / exponential_s,
        "uniform_per_s": LIMIT_VALUES / uniform_s,
        "copy_bytes_per_s": 2 * 4 * LIMIT_VALUES / copy_s,
    }


def report(results: list[dict], limits: dict) -> str:
    ahead = any("wait" in r["per_interval_ms"] for r in results)
    phases = PHASES_AHEAD if ahead else PHASES
    lines = [
        "| B | "
        + " | ".join(f"{p} ms" for p in phases)
        + " | interval ms | agent-subframe steps/s | draws + tables at the limits, ms |",
        "|--:|" + "--:|" * (len(phases) + 3),
    ]
    for r in results:
        ms = r["per_interval_ms"]
        total = r["interval_ms"]
        floor = 1000.0 * (
            r["draws_per_interval"]
            / limits["normal_per_s" if r["fading_draws"] == "normal" else "numpy_exponential_per_s"]
            + r["table_bytes_per_interval"] / limits["copy_bytes_per_s"]
        )
        lines.append(
            f"| {r['batch_size']:,} | "
            + " | ".join(
                f"{ms.get(p, 0.0):.2f} ({100 * ms.get(p, 0.0) / total:.0f} %)" for p in phases
            )
            + f" | {total:.2f} | {r['agent_steps_per_s']:,.0f} | {floor:.2f} |"
        )
    for r in results:
        for phase, ops in r["ops"].items():
            lines += [
                "",
                f"B = {r['batch_size']:,}, {phase} ({PHASE_HELP[phase]}): operators by self time",
                "",
                "| operator | ms per interval | share | calls per interval |",
                "|---|--:|--:|--:|",
            ]
            lines += [
                f"| {o['op']} | {o['self_ms_per_interval']:.3f} | {100 * o['share']:.0f} % "
                f"| {o['calls_per_interval']:.0f} |"
                for o in ops
            ]
    lines += [
        "",
        f"Machine limits: normal_ {limits['normal_per_s'] / 1e6:,.0f} M draws/s, uniform_ "
        f"{limits['uniform_per_s'] / 1e6:,.0f} M draws/s, NumPy's float32 exponential "
        f"{limits['numpy_exponential_per_s'] / 1e6:,.0f} M draws/s, copy "
        f"{limits['copy_bytes_per_s'] / 1e9:,.1f} GB/s (read + write).",
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    load_before = os.getloadavg()
    limits = machine_limits(args.device, args.seed)
    results = []
    for batch in args.batch_sizes:
        print(f"profiling B = {batch} on {args.device} ...", flush=True)
        results.append(
            profile_batch(
                batch,
                args.device,
                args.seconds,
                args.intervals,
                args.seed,
                args.fading_draws,
                args.draw_ahead,
            )
        )
    limits_after = machine_limits(args.device, args.seed)
    load_after = os.getloadavg()
    text = report(results, limits)
    print()
    print(text)
    payload = {
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "command": script_command(),
        "torch_version": torch.__version__,
        "numpy_version": np.__version__,
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "device": args.device,
        "fading_draws": args.fading_draws,
        "draw_ahead": args.draw_ahead,
        "device_name": (
            torch.cuda.get_device_name(torch.device(args.device))
            if args.device.startswith("cuda")
            else cpu_model()
        ),
        "load_average_before": list(load_before),
        "load_average_after": list(load_after),
        "limits": limits,
        "limits_after": limits_after,
        "results": results,
        "markdown": text,
    }
    atomic_write_json(args.out, payload)
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
