"""Simulation throughput of the digital twin and its PettingZoo face.

Measures

(a) the joint PettingZoo env ``TwoTimescaleEnv`` (B = 1) with random actions, with the default
    κ1 = 0.5 (rollout VoI estimator at every interval end) and with κ1 = 1.0 (no VoI):
    subframes/s and agent-steps/s (agents acting per step, summed);
(b) the batched core ``DigitalTwin(batch_size=B, backend="torch")`` driven directly: random RRA
    actions and ``rra_observation()`` every subframe, and at each interval end the impaired
    vehicle observation, a CACC command, ``finish_interval`` and ``begin_interval``. Reported as
    subframes/s (of the whole batch) and agent-subframe steps/s = B × L × subframes/s. Also B = 1
    with the NumPy kernel.

Targets (printed, not asserted): ≥ 10,000 subframes/s for (a) and ≥ 1,000,000 agent-subframe
steps/s for (b) at B ≥ 1024.

Every measurement runs ``--repeats`` times (interleaved: all rows, then all rows again), and the
table and the targets use the median; the JSON keeps every run, with the load average before
and after, because the figures move with whatever else runs on the machine. torch runs on
``--threads`` intra-op threads (default 1: on a 2-core machine with other work, a second
thread costs more in wake-ups than it gains, even for the batched core; the NumPy path of the
PettingZoo environments uses one thread for its own torch calls whatever this says).

    python benchmarks/throughput.py                       # defaults, ~1.5 minutes
    python benchmarks/throughput.py --seconds 1 --repeats 1 --batch-sizes 1 1024 --no-cuda
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

from vdtn_marl.io.files import atomic_write_json, script_command

TARGET_ENV_SUBFRAMES_PER_S = 10_000.0
TARGET_CORE_AGENT_STEPS_PER_S = 1_000_000.0
TARGET_CORE_MIN_BATCH = 1024


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=3.0, help="timed seconds per measurement")
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[1, 64, 1024, 4096])
    p.add_argument(
        "--device",
        nargs="+",
        default=["cpu"],
        help="devices for the batched core (cuda is added when available)",
    )
    p.add_argument("--no-cuda", action="store_true", help="do not add cuda automatically")
    p.add_argument("--out", type=Path, default=Path("benchmarks/results/throughput.json"))
    p.add_argument("--threads", type=int, default=1, help="torch intra-op threads")
    p.add_argument("--repeats", type=int, default=3, help="runs per measurement (median used)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--traces",
        default="synthetic",
        help="leader trace set (default synthetic, with which the committed figures were "
        "measured; episode resets cost more or less with another set)",
    )
    args = p.parse_args(argv)
    if args.seconds <= 0:
        p.error("--seconds must be > 0")
    if args.repeats < 1:
        p.error("--repeats must be >= 1")
    if args.threads < 1:
        p.error("--threads must be >= 1")
    if any(b < 1 for b in args.batch_sizes):
        p.error("--batch-sizes must all be >= 1")
    devices = list(dict.fromkeys(args.device))
    if (
        not args.no_cuda
        and torch.cuda.is_available()
        and not any(d.startswith("cuda") for d in devices)
    ):
        devices.append("cuda")
    args.device = devices
    return args


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


# ---------------------------------------------------------------------- (a) PettingZoo env
def bench_env(kappa1: float, seconds: float, seed: int, traces: str) -> dict:
    from vdtn_marl.envs import TwoTimescaleEnv

    env = TwoTimescaleEnv(kappa1=kappa1, seed=seed, traces=traces)
    rng = np.random.default_rng(seed)
    n_act = env.twin.params.radio.num_actions
    pp = env.twin.params.platoon
    rra = env.rra_agents
    vehicles = env.vehicle_agents

    def run(duration: float) -> tuple[int, int, float]:
        _, infos = env.reset(seed=int(rng.integers(1 << 31)))
        steps = agent_steps = 0
        start = time.perf_counter()
        deadline = start + duration
        while True:
            # batches of draws keep the random-action cost out of the env's timing
            rra_draws = rng.integers(0, n_act, size=(256, len(rra)))
            cmd_draws = rng.uniform(
                pp.accel_min_mps2, pp.accel_max_mps2, size=(256, len(vehicles), 1)
            )
            for j in range(256):
                actions = {name: rra_draws[j, i] for i, name in enumerate(rra)}
                for i, name in enumerate(vehicles):
                    if infos[name]["acts"]:
                        actions[name] = cmd_draws[j, i].astype(np.float32)
                agent_steps += len(actions)
                _, _, term, trunc, infos = env.step(actions)
                steps += 1
                if not env.agents:
                    _, infos = env.reset()
            if time.perf_counter() >= deadline:
                break
        return steps, agent_steps, time.perf_counter() - start

    run(min(0.5, seconds / 4))  # warm-up
    steps, agent_steps, elapsed = run(seconds)
    env.close()
    return {
        "name": f"TwoTimescaleEnv kappa1={kappa1:g}"
        + (" (rollout VoI)" if kappa1 < 1 else " (no VoI)"),
        "kind": "env",
        "kappa1": kappa1,
        "batch_size": 1,
        "device": "cpu",
        "backend": "numpy",
        "subframes": steps,
        "seconds": elapsed,
        "subframes_per_s": steps / elapsed,
        "agent_steps_per_s": agent_steps / elapsed,
    }


# ---------------------------------------------------------------------- (b) batched core
def bench_core(
    batch: int, device: str, backend: str, seconds: float, seed: int, traces: str
) -> dict:
    from vdtn_marl.policies.cacc import CACCController
    from vdtn_marl.sim.twin import DigitalTwin

    twin = DigitalTwin(
        batch_size=batch, device=device, seed=seed, backend=backend, trace_source=traces
    )
    dev = twin.device
    controller = CACCController(twin.params.platoon)
    t_int = twin.subframes_per_interval
    n_act = twin.params.radio.num_actions
    gen = torch.Generator(device=dev)
    gen.manual_seed(seed)
    shape = (batch, twin.num_links)
    episode = twin.params.episode_intervals

    def interval() -> None:
        # one draw per interval: [T, B, L] actions
        draws = torch.randint(0, n_act, (t_int, *shape), generator=gen, device=dev)
        if backend == "numpy":
            draws = draws.numpy()
        for t in range(t_int):
            twin.step_subframe(draws[t])
            twin.rra_observation()
        obs = twin.vehicle_observation(False)
        twin.finish_interval(controller(obs), perfect=False)
        if int(twin.interval[0]) >= episode:
            twin.reset()
        else:
            twin.begin_interval()

    def run(duration: float) -> tuple[int, float]:
        _sync(dev)
        start = time.perf_counter()
        deadline = start + duration
        intervals = 0
        while True:  # whole intervals, at least one; the per-interval check is negligible
            interval()
            intervals += 1
            if time.perf_counter() >= deadline:
                _sync(dev)
                if time.perf_counter() >= deadline:
                    break
        return intervals * t_int, time.perf_counter() - start

    run(0.0)  # warm-up: one full interval (allocator, kernels, caches)
    subframes, elapsed = run(seconds)
    rate = subframes / elapsed
    name = dev.type if dev.type == "cpu" else torch.cuda.get_device_name(dev)
    return {
        "name": f"DigitalTwin B={batch} {backend}/{dev.type}",
        "kind": "core",
        "batch_size": batch,
        "device": str(dev),
        "device_name": name,
        "backend": backend,
        "num_links": twin.num_links,
        "subframes": subframes,
        "seconds": elapsed,
        "subframes_per_s": rate,
        "agent_steps_per_s": rate * batch * twin.num_links,
    }


# ---------------------------------------------------------------------- report
def _targets(results: list[dict]) -> list[dict]:
    out = []
    env = [r for r in results if r["kind"] == "env"]
    for r in env:
        out.append(
            {
                "target": f"(a) {r['name']}: >= {TARGET_ENV_SUBFRAMES_PER_S:,.0f} subframes/s",
                "value": r["subframes_per_s"],
                "range": [r["min_subframes_per_s"], r["max_subframes_per_s"]],
                "met": r["subframes_per_s"] >= TARGET_ENV_SUBFRAMES_PER_S,
            }
        )
    for r in results:
        if r["kind"] == "core" and r["batch_size"] >= TARGET_CORE_MIN_BATCH:
            out.append(
                {
                    "target": (
                        f"(b) {r['name']}: >= {TARGET_CORE_AGENT_STEPS_PER_S:,.0f} "
                        "agent-subframe steps/s"
                    ),
                    "value": r["agent_steps_per_s"],
                    "range": [
                        r["min_subframes_per_s"] * r["batch_size"] * r["num_links"],
                        r["max_subframes_per_s"] * r["batch_size"] * r["num_links"],
                    ],
                    "met": r["agent_steps_per_s"] >= TARGET_CORE_AGENT_STEPS_PER_S,
                }
            )
    return out


def print_report(results: list[dict], targets: list[dict]) -> None:
    header = ["measurement", "B", "device", "subframes/s", "range (runs)", "agent-steps/s"]
    rows = [
        [
            r["name"],
            str(r["batch_size"]),
            r["device"],
            f"{r['subframes_per_s']:,.0f}",
            f"{r['min_subframes_per_s']:,.0f}–{r['max_subframes_per_s']:,.0f}",
            f"{r['agent_steps_per_s']:,.0f}",
        ]
        for r in results
    ]
    target_lines = [
        f"{'MET    ' if t['met'] else 'NOT MET'}  {t['target']} (median {t['value']:,.0f}, "
        f"runs {t['range'][0]:,.0f}–{t['range'][1]:,.0f})"
        for t in targets
    ]
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        widths = [max(len(h), *(len(row[i]) for row in rows)) for i, h in enumerate(header)]
        fmt = "  ".join(f"{{:<{w}}}" if i < 3 else f"{{:>{w}}}" for i, w in enumerate(widths))
        print(fmt.format(*header))
        print("  ".join("-" * w for w in widths))
        for row in rows:
            print(fmt.format(*row))
        print()
        for line in target_lines:
            print(line)
        return
    table = Table(title="vdtn_marl simulation throughput")
    for i, h in enumerate(header):
        table.add_column(h, justify="right" if i >= 3 else "left")
    for row in rows:
        table.add_row(*row)
    console = Console(width=140)
    console.print(table)
    for t, line in zip(targets, target_lines, strict=True):
        console.print(line, style="green" if t["met"] else "red", markup=False, highlight=False)


def _summarise(runs: list[dict]) -> dict:
    """The median run (the lower one for an even count), with every run's rate kept."""
    rates = [r["subframes_per_s"] for r in runs]
    median = sorted(runs, key=lambda r: r["subframes_per_s"])[(len(runs) - 1) // 2]
    return {
        **median,
        "repeats": len(runs),
        "runs_subframes_per_s": rates,
        "min_subframes_per_s": min(rates),
        "max_subframes_per_s": max(rates),
    }


def main(argv=None) -> int:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    seconds, seed = args.seconds, args.seed
    jobs = [
        (f"TwoTimescaleEnv kappa1={k:g}", lambda k=k: bench_env(k, seconds, seed, args.traces))
        for k in (0.5, 1.0)
    ]
    jobs.append(
        (
            "DigitalTwin B=1 numpy/cpu",
            lambda: bench_core(1, "cpu", "numpy", seconds, seed, args.traces),
        )
    )
    for device in args.device:
        for batch in args.batch_sizes:
            jobs.append(
                (
                    f"DigitalTwin B={batch} torch/{device}",
                    lambda b=batch, d=device: bench_core(b, d, "torch", seconds, seed, args.traces),
                )
            )
    load_before = os.getloadavg()
    runs: list[list[dict]] = [[] for _ in jobs]
    for repeat in range(args.repeats):
        for (label, job), job_runs in zip(jobs, runs, strict=True):
            print(f"measuring {label} (run {repeat + 1} of {args.repeats}) ...", flush=True)
            job_runs.append(job())
    load_after = os.getloadavg()
    results = [_summarise(job_runs) for job_runs in runs]
    targets = _targets(results)
    print()
    print_report(results, targets)

    cuda_names = [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
    payload = {
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "command": script_command(),
        "argv": sys.argv[1:] if argv is None else list(argv),
        "torch_version": torch.__version__,
        "numpy_version": np.__version__,
        "python_version": platform.python_version(),
        "platform": platform.platform(),
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "load_average_before": list(load_before),
        "load_average_after": list(load_after),
        "repeats": args.repeats,
        "devices": args.device,
        "device_names": {"cpu": platform.processor() or platform.machine(), "cuda": cuda_names},
        "seconds_per_measurement": args.seconds,
        "traces": args.traces,
        "targets": targets,
        "results": results,
    }
    atomic_write_json(args.out, payload)
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
