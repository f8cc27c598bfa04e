"""A short random-policy rollout of ``vdtn/vdtn-joint-v1`` with a results table.

    vdtn-marl rollout --intervals 40 --seed 0      (or: python -m vdtn_marl.cli.rollout ...)

Every RRA agent picks a uniformly random sub-channel × power level each subframe; every
follower picks a uniformly random acceleration at its tick. The table reports the V2I
throughput per link (Mbps), the CAM delivery rate and latency (ms), the mean |gap error| (m)
and |speed error| (m/s), and the mean IVoI of the interval.
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np

import vdtn_marl
from vdtn_marl.core.reward import RRAReward, check_kappa
from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment.config import validate_device


def run(intervals: int, seed: int, kappa1: float, device: str) -> dict[str, float]:
    env = vdtn_marl.make("vdtn/vdtn-joint-v1", seed=seed, kappa1=kappa1, device=device)
    _, infos = env.reset(seed=seed)
    for agent in env.possible_agents:
        env.action_space(agent).seed(seed)
    throughput, gap, speed, delays, delivered, ivoi = [], [], [], [], [], []
    steps = intervals * env.twin.subframes_per_interval
    try:
        from tqdm import trange
    except ImportError:  # progress bar is optional
        trange = range
    for _ in trange(steps, desc="subframes", leave=False):
        actions = {a: env.action_space(a).sample() for a in env.agents if infos[a]["acts"]}
        _, _, terminated, truncated, infos = env.step(actions)
        rra = [infos[a] for a in env.rra_agents]
        throughput.append(rra[0]["v2i_throughput_mbps"] / env.twin.num_subchannels)
        if rra[0]["closes_interval"]:
            for i, info in enumerate(rra):
                delivered.append(info["cam_delivered"])
                if info["cam_delivered"]:
                    delays.append(info["cam_delay_ms"])
                ivoi.append(info["ivoi"])
                vinfo = infos[env.vehicle_agents[i]]
                gap.append(abs(vinfo["gap_error_m"]))
                speed.append(abs(vinfo["speed_error_mps"]))
        if any(terminated.values()) or any(truncated.values()):
            break
    return {
        "V2I throughput per link (Mbps)": statistics.fmean(throughput),
        "CAM delivery rate": statistics.fmean(delivered) if delivered else float("nan"),
        "CAM latency, delivered (ms)": statistics.fmean(delays) if delays else float("nan"),
        "CAM latency p95 (ms)": float(np.percentile(delays, 95)) if delays else float("nan"),
        "mean |gap error| (m)": statistics.fmean(gap) if gap else float("nan"),
        "mean |speed error| (m/s)": statistics.fmean(speed) if speed else float("nan"),
        "mean IVoI per interval": statistics.fmean(ivoi) if ivoi else float("nan"),
        "control intervals": len(gap) // max(env.twin.num_followers, 1),  # a count
    }


def format_value(value: float) -> str:
    """A table cell: a count (an ``int``) as an integer, any other value with 3 decimals."""
    return str(value) if isinstance(value, int) else f"{value:.3f}"


def print_table(results: dict[str, float], title: str) -> None:
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        print(title)
        for key, value in results.items():
            print(f"  {key:<34} {format_value(value):>10}")
        return
    table = Table(title=title)
    table.add_column("metric", overflow="fold")
    table.add_column("value", justify="right", overflow="fold")
    for key, value in results.items():
        table.add_row(key, format_value(value))
    Console().print(table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="vdtn-marl rollout", description=__doc__.split("\n")[0])
    parser.add_argument("--intervals", type=int, default=40, help="50 ms control intervals (>= 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--kappa1", type=float, default=RRAReward.kappa1, help="κ1 in [0, 1]; κ2 = 1 − κ1"
    )
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args(argv)
    if args.intervals < 1:
        parser.error(f"--intervals={args.intervals} must be >= 1")
    try:
        check_kappa(args.kappa1, None)
        validate_device(args.device)
    except ConfigError as exc:
        parser.error(str(exc))
    results = run(args.intervals, args.seed, args.kappa1, args.device)
    print_table(
        results,
        f"vdtn/vdtn-joint-v1, random policies, {args.intervals} intervals, seed {args.seed}",
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
