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

Targets (printed, not asserted; DESIGN §7): ≥ 12,000 subframes/s for (a) with the rollout VoI
on a quiet machine, and ≥ 2× the peer's subframes/s side by side; ≥ 4,000,000 agent-subframe
steps/s for (b) at B = 4096 on the CPU (2 cores), no lower at a larger B, and ≥ 160× the peer's
agent-subframe steps/s side by side; ≥ 100,000,000 on CUDA. From B = 128 the CPU twin makes
the next interval's random draws on a second thread while the subframes run (the same numbers;
``--draw-ahead off`` adds rows that draw at each interval's start, for the ratio).

Every measurement runs ``--repeats`` times (interleaved: all rows, then all rows again), and the
table and the targets use the median; the JSON keeps every run, with the load average before
and after, because the figures move with whatever else runs on the machine. torch runs on
``--threads`` intra-op threads (default 1: on a 2-core machine with other work, a second
thread costs more in wake-ups than it gains, even for the batched core; the NumPy path of the
PettingZoo environments uses one thread for its own torch calls whatever this says).

With ``--peer liang PATH`` it also times Liang et al.'s public NumPy V2X simulator
(github.com/le-liang/MARLspectrumSharingV2X; ``PATH`` is the user's checkout, nothing of it
ships with vdtn-marl) in the same run, interleaved with the other rows, and prints each row's
ratio to it (median of the per-run ratios): its ``Environ`` with the training script's
settings (4 vehicles, 1 neighbour, 4 resource blocks, 4 power levels), random actions, and per
subframe what its training loop does besides the networks: ``act_for_training``, new fast
fading, ``Compute_Interference`` and every agent's observation (``get_state`` of
``main_marl_train.py``, read from the checkout); every 100 subframes (its 100 ms episode) new
positions, neighbours and slow fading, and fresh demands. Its agent-subframe steps are
4 × its subframes.

Rows on CUDA (``--device cuda``, added by default when torch sees a GPU) use
``--cuda-batch-sizes`` (default 1,024 to 65,536).

    python benchmarks/throughput.py                       # defaults, ~1.5 minutes
    python benchmarks/throughput.py --seconds 1 --repeats 1 --batch-sizes 1 1024 --no-cuda
    python benchmarks/throughput.py --peer liang ~/src/MARLspectrumSharingV2X
"""

from __future__ import annotations

import argparse
import ast
import datetime as dt
import importlib.util
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

from vdtn_marl.io.files import atomic_write_json, script_command
from vdtn_marl.reporting.benchmarking import cpu_model

TARGET_ENV_SUBFRAMES_PER_S = 12_000.0
TARGET_ENV_PEER_RATIO = 2.0
TARGET_CORE_AGENT_STEPS_PER_S = {"cpu": 4_000_000.0, "cuda": 100_000_000.0}
TARGET_CORE_BATCH = 4096
#: the batched core at TARGET_CORE_BATCH against the peer's agent-subframe steps/s (DESIGN §7)
TARGET_CORE_PEER_RATIO = 160.0
PEERS = ("liang",)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seconds", type=float, default=3.0, help="timed seconds per measurement")
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[1, 64, 1024, 4096])
    p.add_argument("--cuda-batch-sizes", type=int, nargs="+", default=[1024, 4096, 16384, 65536])
    p.add_argument(
        "--peer",
        nargs=2,
        metavar=("NAME", "PATH"),
        help="time a peer simulator from a checkout in the same run: liang PATH",
    )
    p.add_argument(
        "--device",
        nargs="+",
        default=["cpu"],
        help="devices for the batched core (cuda is added when available)",
    )
    p.add_argument("--no-cuda", action="store_true", help="do not add cuda automatically")
    p.add_argument(
        "--fading-draws",
        nargs="+",
        choices=("normal", "exponential"),
        default=["normal"],
        help="the batched core's fast-fading draws (DigitalTwin fading_draws), one row each",
    )
    p.add_argument(
        "--draw-ahead",
        nargs="+",
        choices=("on", "off"),
        default=["on"],
        help="the batched core's draws: 'on' makes the next interval's on a second thread "
        "(DigitalTwin draw_ahead, the default), 'off' at each interval's start; one row each",
    )
    p.add_argument(
        "--rows",
        nargs="+",
        choices=("env", "core"),
        default=["env", "core"],
        help="which rows: the PettingZoo env (a), the batched core (b)",
    )
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
    if any(b < 1 for b in args.batch_sizes + args.cuda_batch_sizes):
        p.error("--batch-sizes and --cuda-batch-sizes must all be >= 1")
    if args.peer is not None:
        name, path = args.peer
        if name not in PEERS:
            p.error(f"--peer {name!r} must be one of {', '.join(PEERS)}")
        missing = [f for f in LIANG_FILES if not (Path(path).expanduser() / f).is_file()]
        if missing:
            p.error(
                f"--peer liang {path}: no {', '.join(missing)} there (give the path of a "
                "checkout of github.com/le-liang/MARLspectrumSharingV2X)"
            )
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
    batch: int,
    device: str,
    backend: str,
    seconds: float,
    seed: int,
    traces: str,
    fading_draws: str = "normal",
    draw_ahead: bool = True,
) -> dict:
    from vdtn_marl.policies.cacc import CACCController
    from vdtn_marl.sim.twin import DigitalTwin

    twin = DigitalTwin(
        batch_size=batch,
        device=device,
        seed=seed,
        backend=backend,
        trace_source=traces,
        fading_draws=fading_draws,
        draw_ahead=draw_ahead,
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
        "name": f"DigitalTwin B={batch} {backend}/{dev.type}"
        + ("" if fading_draws == "normal" else f" {fading_draws} fading")
        + ("" if draw_ahead else ", draw-ahead off"),
        "fading_draws": fading_draws,
        # whether the next interval's draws were made on a second thread (DigitalTwin)
        "draw_ahead": twin.draw_ahead,
        "draw_ahead_requested": draw_ahead,
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


# ---------------------------------------------------------------------- (c) the peer
#: the files of Liang et al.'s checkout the harness reads: the simulator, and the training
#: script whose settings and per-agent observation (``get_state``) it takes
LIANG_FILES = ("Environment_marl.py", "main_marl_train.py")
#: module-level names of ``main_marl_train.py`` that set up its environment
LIANG_SETTINGS = (
    "up_lanes", "down_lanes", "left_lanes", "right_lanes", "width", "height", "n_veh",
    "n_neighbor",
)  # fmt: skip


def load_liang(path: str | Path) -> dict:
    """Liang et al.'s simulator module, its training script's settings and ``get_state``,
    read from a checkout at ``path`` (the script itself imports TensorFlow: only these
    assignments and that function are taken from its source, nothing else runs)."""
    root = Path(path).expanduser().resolve()
    spec = importlib.util.spec_from_file_location("liang_environment_marl", root / LIANG_FILES[0])
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    tree = ast.parse((root / LIANG_FILES[1]).read_text(encoding="utf-8"))
    wanted = [
        node
        for node in tree.body
        if (
            isinstance(node, ast.Assign)
            and all(isinstance(t, ast.Name) and t.id in LIANG_SETTINGS for t in node.targets)
        )
        or (isinstance(node, ast.FunctionDef) and node.name == "get_state")
    ]
    namespace: dict = {"np": np}
    exec(compile(ast.Module(body=wanted, type_ignores=[]), str(root / LIANG_FILES[1]), "exec"),
         namespace)  # fmt: skip
    missing = [k for k in (*LIANG_SETTINGS, "get_state") if k not in namespace]
    if missing:
        raise SystemExit(f"--peer liang {path}: {LIANG_FILES[1]} defines no {', '.join(missing)}")
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True, text=True, check=True,
        ).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown"
    return {"module": module, "settings": namespace, "path": str(root), "commit": commit}


def bench_liang(peer: dict, seconds: float, seed: int) -> dict:
    """Liang et al.'s ``Environ`` as its training loop drives it, with random actions."""
    cfg, get_state = peer["settings"], peer["settings"]["get_state"]
    n_veh, n_neighbor = cfg["n_veh"], cfg["n_neighbor"]
    np.random.seed(seed)  # the simulator draws from NumPy's global generator
    env = peer["module"].Environ(
        cfg["down_lanes"], cfg["up_lanes"], cfg["left_lanes"], cfg["right_lanes"],
        cfg["width"], cfg["height"], n_veh, n_neighbor,
    )  # fmt: skip
    env.new_random_game()
    steps_per_episode = int(round(env.time_slow / env.time_fast))
    n_rb, n_power = env.n_RB, len(env.V2V_power_dB_List)
    rng = np.random.default_rng(seed)
    agents = [(i, j) for i in range(n_veh) for j in range(n_neighbor)]

    def new_episode() -> None:
        env.renew_positions()
        env.renew_neighbor()
        env.renew_channel()
        env.renew_channels_fastfading()
        env.demand = env.demand_size * np.ones((n_veh, n_neighbor))
        env.individual_time_limit = env.time_slow * np.ones((n_veh, n_neighbor))
        env.active_links = np.ones((n_veh, n_neighbor), dtype="bool")

    def run(duration: float) -> tuple[int, float]:
        steps = 0
        start = time.perf_counter()
        deadline = start + duration
        while True:
            new_episode()
            draws = np.stack(
                [
                    rng.integers(0, n_rb, (steps_per_episode, n_veh, n_neighbor)),
                    rng.integers(0, n_power, (steps_per_episode, n_veh, n_neighbor)),
                ],
                axis=-1,
            ).astype("int32")
            for step in range(steps_per_episode):
                for i, j in agents:
                    get_state(env, [i, j], 0.5, 0.02)
                env.act_for_training(draws[step].copy())
                env.renew_channels_fastfading()
                env.Compute_Interference(draws[step])
                steps += 1
            if time.perf_counter() >= deadline:
                break
        return steps, time.perf_counter() - start

    run(0.0)  # warm-up: one episode
    steps, elapsed = run(seconds)
    rate = steps / elapsed
    return {
        "name": f"Liang et al. Environ ({n_veh} vehicles, numpy, random actions)",
        "kind": "peer",
        "peer": "liang",
        "peer_path": peer["path"],
        "peer_commit": peer["commit"],
        "batch_size": 1,
        "device": "cpu",
        "backend": "numpy",
        "num_links": n_veh * n_neighbor,
        "subframes": steps,
        "seconds": elapsed,
        "subframes_per_s": rate,
        "agent_steps_per_s": rate * n_veh * n_neighbor,
    }


# ---------------------------------------------------------------------- report
def _peer_ratios(results: list[dict]) -> None:
    """Each row's ratio to the peer's row, median of the per-run ratios (runs of one repeat
    ran back to back): subframes/s for the B = 1 rows, agent-subframe steps/s for the others.
    Written into the rows as ``peer_ratio`` and ``peer_ratio_runs``."""
    peer = next((r for r in results if r["kind"] == "peer"), None)
    if peer is None:
        return
    for r in results:
        if r is peer:
            continue
        per_agent = r["kind"] == "core" and r["batch_size"] > 1
        ours, theirs = (
            (r["runs_agent_steps_per_s"], peer["runs_agent_steps_per_s"])
            if per_agent
            else (r["runs_subframes_per_s"], peer["runs_subframes_per_s"])
        )
        ratios = [a / b for a, b in zip(ours, theirs, strict=True)]
        r["peer_ratio"] = statistics.median(ratios)
        r["peer_ratio_runs"] = ratios
        r["peer_ratio_of"] = "agent-subframe steps/s" if per_agent else "subframes/s"


def _peer_target(r: dict, ratio: float, part: str, unit: str) -> dict:
    """Row ``r`` against ``ratio`` × the peer's ``unit`` (median of the per-run ratios)."""
    return {
        "target": f"{part} {r['name']}: >= {ratio:g}x the peer's {unit}",
        "value": r["peer_ratio"],
        "range": [min(r["peer_ratio_runs"]), max(r["peer_ratio_runs"])],
        "met": r["peer_ratio"] >= ratio,
    }


def _targets(results: list[dict]) -> list[dict]:
    out = []
    for r in results:
        if r["kind"] == "env" and r["kappa1"] < 1:
            out.append(
                {
                    "target": f"(a) {r['name']}: >= {TARGET_ENV_SUBFRAMES_PER_S:,.0f} "
                    "subframes/s (on a quiet machine)",
                    "value": r["subframes_per_s"],
                    "range": [r["min_subframes_per_s"], r["max_subframes_per_s"]],
                    "met": r["subframes_per_s"] >= TARGET_ENV_SUBFRAMES_PER_S,
                }
            )
            if "peer_ratio" in r:
                out.append(_peer_target(r, TARGET_ENV_PEER_RATIO, "(a)", "subframes/s"))
    core = [r for r in results if r["kind"] == "core" and r["backend"] == "torch"]

    # one series per device, fading draws and --draw-ahead setting (rows below
    # DRAW_AHEAD_MIN_BATCH draw at the interval start in either series)
    def series(r):
        return r["device"], r["fading_draws"], r.get("draw_ahead_requested", True)

    for key in dict.fromkeys(series(r) for r in core):
        device, draws, ahead = key
        rows = sorted((r for r in core if series(r) == key), key=lambda r: r["batch_size"])
        target = TARGET_CORE_AGENT_STEPS_PER_S["cuda" if device.startswith("cuda") else "cpu"]
        at = [r for r in rows if r["batch_size"] >= TARGET_CORE_BATCH]
        if at:
            r = at[0]
            out.append(
                {
                    "target": f"(b) {r['name']}: >= {target:,.0f} agent-subframe steps/s",
                    "value": r["agent_steps_per_s"],
                    "range": [min(r["runs_agent_steps_per_s"]), max(r["runs_agent_steps_per_s"])],
                    "met": r["agent_steps_per_s"] >= target,
                }
            )
            if "peer_ratio" in r and not device.startswith("cuda"):
                unit = "agent-subframe steps/s"
                out.append(_peer_target(r, TARGET_CORE_PEER_RATIO, "(b)", unit))
        big = [r for r in rows if r["batch_size"] >= 1024]
        if len(big) > 1:
            rates = [r["agent_steps_per_s"] for r in big]
            sizes = ", ".join(f"{r['batch_size']:,}" for r in big)
            out.append(
                {
                    "target": f"(b) {device}, {draws} fading"
                    + ("" if ahead else ", draw-ahead off")
                    + ": agent-subframe steps/s no "
                    "lower at a larger B "
                    f"(B = {sizes})",
                    "value": min(b / a for a, b in zip(rates, rates[1:], strict=False)),
                    "range": [rates[0], rates[-1]],
                    "met": all(b >= a for a, b in zip(rates, rates[1:], strict=False)),
                }
            )
    return out


def print_report(results: list[dict], targets: list[dict]) -> None:
    peer = next((r for r in results if r["kind"] == "peer"), None)
    header = ["measurement", "B", "device", "subframes/s", "range (runs)", "agent-steps/s"]
    if peer is not None:
        header.append("× peer")
    rows = []
    for r in results:
        row = [
            r["name"],
            str(r["batch_size"]),
            r["device"],
            f"{r['subframes_per_s']:,.0f}",
            f"{r['min_subframes_per_s']:,.0f}–{r['max_subframes_per_s']:,.0f}",
            f"{r['agent_steps_per_s']:,.0f}",
        ]
        if peer is not None:
            row.append("1" if r is peer else f"{r['peer_ratio']:,.2f}")
        rows.append(row)
    target_lines = [
        f"{'MET    ' if t['met'] else 'NOT MET'}  {t['target']} (median {t['value']:,.2f}, "
        f"runs {t['range'][0]:,.2f}–{t['range'][1]:,.2f})"
        for t in targets
    ]
    if peer is not None:
        target_lines.insert(
            0,
            f"× peer: compared with {peer['name']} from {peer['peer_path']} (commit "
            f"{peer['peer_commit'][:12]}), timed in this run: subframes/s for B = 1 rows, "
            "agent-subframe steps/s (4 agents per subframe) for the batched rows; median of "
            "the per-run ratios",
        )
    widths = [max(len(h), *(len(row[i]) for row in rows)) for i, h in enumerate(header)]
    fmt = "  ".join(f"{{:<{w}}}" if i < 3 else f"{{:>{w}}}" for i, w in enumerate(widths))
    print(fmt.format(*header))
    print("  ".join("-" * w for w in widths))
    for row in rows:
        print(fmt.format(*row))
    print()
    for line in target_lines:
        print(line)


def _summarise(runs: list[dict]) -> dict:
    """The median run (the lower one for an even count), with every run's rate kept."""
    rates = [r["subframes_per_s"] for r in runs]
    median = sorted(runs, key=lambda r: r["subframes_per_s"])[(len(runs) - 1) // 2]
    return {
        **median,
        "repeats": len(runs),
        "runs_subframes_per_s": rates,
        "runs_agent_steps_per_s": [r["agent_steps_per_s"] for r in runs],
        "min_subframes_per_s": min(rates),
        "max_subframes_per_s": max(rates),
    }


def main(argv=None) -> int:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    seconds, seed = args.seconds, args.seed
    jobs = []
    if "env" in args.rows:
        jobs += [
            (f"TwoTimescaleEnv kappa1={k:g}", lambda k=k: bench_env(k, seconds, seed, args.traces))
            for k in (0.5, 1.0)
        ]
    if "core" in args.rows:
        jobs.append(
            (
                "DigitalTwin B=1 numpy/cpu",
                lambda: bench_core(1, "cpu", "numpy", seconds, seed, args.traces),
            )
        )
        for device in args.device:
            sizes = args.cuda_batch_sizes if device.startswith("cuda") else args.batch_sizes
            for draws in args.fading_draws:
                for ahead in args.draw_ahead:
                    for batch in sizes:
                        jobs.append(
                            (
                                f"DigitalTwin B={batch} torch/{device} {draws} fading, "
                                f"draw-ahead {ahead}",
                                lambda b=batch, d=device, f=draws, a=ahead == "on": bench_core(
                                    b, d, "torch", seconds, seed, args.traces, f, a
                                ),
                            )
                        )
    peer = None
    if args.peer is not None:
        peer = load_liang(args.peer[1])
        jobs.insert(0, ("Liang et al. Environ", lambda: bench_liang(peer, seconds, seed)))
    load_before = os.getloadavg()
    runs: list[list[dict]] = [[] for _ in jobs]
    for repeat in range(args.repeats):
        for (label, job), job_runs in zip(jobs, runs, strict=True):
            print(f"measuring {label} (run {repeat + 1} of {args.repeats}) ...", flush=True)
            job_runs.append(job())
    load_after = os.getloadavg()
    results = [_summarise(job_runs) for job_runs in runs]
    _peer_ratios(results)
    targets = _targets(results)
    print()
    print_report(results, targets)

    cuda_names = [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
    payload = {
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        # the peer's checkout is the user's own path: recorded as PEER_CHECKOUT
        "command": _redact(script_command(), args),
        "argv": [_redact(a, args) for a in (sys.argv[1:] if argv is None else list(argv))],
        "torch_version": torch.__version__,
        "numpy_version": np.__version__,
        "python_version": platform.python_version(),
        "platform": platform.platform(),
        "cpu": cpu_model(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "load_average_before": list(load_before),
        "load_average_after": list(load_after),
        "repeats": args.repeats,
        "devices": args.device,
        "device_names": {"cpu": cpu_model(), "cuda": cuda_names},
        "seconds_per_measurement": args.seconds,
        "traces": args.traces,
        "peer": None if peer is None else {"name": args.peer[0], "commit": peer["commit"]},
        "targets": targets,
        "results": results,
    }
    for r in results:
        r.pop("peer_path", None)
    atomic_write_json(args.out, payload)
    print(f"\nwrote {args.out}")
    return 0


def _redact(text: str, args: argparse.Namespace) -> str:
    if args.peer is None:
        return text
    return text.replace(args.peer[1], "PEER_CHECKOUT")


if __name__ == "__main__":
    sys.exit(main())
