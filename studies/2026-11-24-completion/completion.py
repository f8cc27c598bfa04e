"""Data completion: prediction error, control cost and EVoI of each completion mode.

For every mode of ``completion`` (``none``, ``hold``, ``kalman``, ``learned``) the batched twin
runs B scenarios for one episode with CAMs carried by the random RRA policy, and every follower
is driven by the linear CACC on its impaired observation after completion
(docs/model.md §4.7). A run with perfect observation on the same seed (same leader traces,
same initial states) is the reference. Reported per mode:

- prediction error: RMSE (m/s²) of the predecessor's acceleration (feature 3) and command
  (feature 4) in the completed observation against their exact values at kΔt, over the stale
  decisions (CAM age > 0) and over all decisions (fresh ones are exact in every mode);
- control cost: −(mean control reward per follower and interval), mean and 95% CI over the
  B scenarios; with its ingredients: RMS gap and speed errors, mean |u| and mean |jerk|;
- EVoI = J(impaired, with completion) − J(perfect), J the episode control return of a scenario
  summed over followers (undiscounted; the discounted one, γ = 0.99, is in the JSON), mean and
  95% CI over scenarios (normal approximation, 1.96·s/√B); paired by seed.

The learned predictor is trained first (``train_completion_predictor``, another seed than the
evaluation). Writes ``studies/2026-11-24-completion/completion.json`` atomically.

    python studies/2026-11-24-completion/completion.py                       # B = 64, one 20 s \
        episode per mode
    python studies/2026-11-24-completion/completion.py --batch-size 128 --traces constant
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from vdtn_marl.algos.completion import train_completion_predictor
from vdtn_marl.core.interval import IntervalEngine
from vdtn_marl.io.files import atomic_write_json, script_command
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.sim.completion import (
    CAM_ACCEL,
    CAM_AGE,
    CAM_COMMAND,
    COMPLETION_MODES,
    make_completion,
)
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin

DISCOUNT = 0.99
Z95 = 1.96


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch-size", type=int, default=64, help="scenarios B per mode")
    p.add_argument("--intervals", type=int, default=400, help="episode length (intervals)")
    p.add_argument("--seed", type=int, default=0, help="evaluation seed")
    p.add_argument("--train-seed", type=int, default=1, help="seed of the learned predictor")
    p.add_argument("--train-batch-size", type=int, default=128)
    p.add_argument("--train-intervals", type=int, default=100, help="intervals per scenario")
    p.add_argument("--train-epochs", type=int, default=30)
    p.add_argument("--traces", default="synthetic", help="leader trace set (registered name)")
    p.add_argument("--device", default="cpu")
    p.add_argument("--threads", type=int, default=2, help="torch intra-op threads")
    p.add_argument("--out", type=Path, default=Path(__file__).parent / "completion.json")
    args = p.parse_args(argv)
    if args.batch_size < 2:
        p.error("--batch-size must be >= 2 (confidence intervals)")
    if args.intervals < 1:
        p.error("--intervals must be >= 1")
    return args


def mean_ci(values: torch.Tensor) -> dict:
    v = values.double()
    half = Z95 * float(v.std()) / math.sqrt(v.numel())
    return {"mean": float(v.mean()), "ci95": half}


def run(params: TwinParams, args, completion: str | None, predictor=None) -> dict:
    """One episode of B scenarios; ``completion=None`` is the perfect-observation reference."""
    perfect = completion is None
    twin = DigitalTwin(
        params, batch_size=args.batch_size, device=args.device, seed=args.seed, radio=not perfect
    )
    controller = CACCController(params.platoon)
    rra = RandomRRAPolicy(params.radio.num_actions, args.seed)
    completer = None if perfect else make_completion(completion, predictor, params.platoon)
    engine = IntervalEngine(  # the random RRA's actions are valid: not checked, as in training
        twin, perfect=perfect, rra_policy=rra, completion=completer, validate_rra=False
    )
    b, f = args.batch_size, twin.num_followers
    dev = twin.device
    ret = torch.zeros(b, device=dev, dtype=torch.float64)
    ret_discounted = torch.zeros_like(ret)
    alive = torch.ones(b, dtype=torch.bool, device=dev)
    collided = torch.zeros(b, dtype=torch.bool, device=dev)
    sq_err = torch.zeros(2, device=dev, dtype=torch.float64)
    sq_err_stale = torch.zeros(2, device=dev, dtype=torch.float64)
    count = count_stale = 0
    # per scenario: Σ over followers and live intervals of e_p², e_v², |u|, |jerk|
    terms = torch.zeros(4, b, device=dev, dtype=torch.float64)
    live_steps = torch.zeros(b, device=dev, dtype=torch.float64)
    weight = 1.0
    start = time.perf_counter()
    for _ in range(params.episode_intervals):
        if perfect:
            obs = engine.observe()
        else:
            engine.run_radio()
            raw = twin.vehicle_observation(perfect=False)  # and completed: its error is measured
            obs = completer.complete(raw, twin.interval)
            stale = (raw[..., CAM_AGE] > 0) & alive[:, None]
            err = (obs[..., CAM_ACCEL : CAM_COMMAND + 1] - twin.cam_snapshot).double() ** 2
            live = alive[:, None].expand(b, f)
            sq_err += err[live].sum(0)
            sq_err_stale += err[stale].sum(0)
            count += int(live.sum())
            count_stale += int(stale.sum())
        before = twin.topology.followers_of(twin.platoon.command_mps2)
        record = engine.close(controller(obs)).record
        reward = record.reward.double().sum(-1) * alive
        jerk = (record.command_mps2 - before) / params.platoon.control_interval_s
        step_terms = torch.stack(
            [
                record.gap_error_m.double() ** 2,
                record.speed_error_mps.double() ** 2,
                record.command_mps2.double().abs(),
                jerk.double().abs(),
            ]
        ).sum(-1)
        terms += step_terms * alive
        live_steps += alive.double() * f
        ret += reward
        ret_discounted += weight * reward
        weight *= DISCOUNT
        hit = record.collided.any(-1) & alive
        collided |= hit
        alive &= ~hit
        engine.advance(radio=False)  # the radio runs at the top of the loop
    if dev.type == "cuda":
        torch.cuda.synchronize(dev)
    out = {
        "mode": "perfect" if perfect else completion,
        "return": ret.cpu(),
        "return_discounted": ret_discounted.cpu(),
        "collisions": int(collided.sum()),
        "seconds": time.perf_counter() - start,
        "gap_error_rms_m": float((terms[0].sum() / live_steps.sum()).sqrt()),
        "speed_error_rms_mps": float((terms[1].sum() / live_steps.sum()).sqrt()),
        "mean_abs_command_mps2": float(terms[2].sum() / live_steps.sum()),
        "mean_abs_jerk_mps3": float(terms[3].sum() / live_steps.sum()),
    }
    if not perfect:
        rmse_all = (sq_err / max(count, 1)).sqrt().tolist()
        rmse_stale = (sq_err_stale / max(count_stale, 1)).sqrt().tolist()
        out |= {
            "stale_fraction": count_stale / max(count, 1),
            "rmse_accel_stale_mps2": rmse_stale[0],
            "rmse_command_stale_mps2": rmse_stale[1],
            "rmse_accel_all_mps2": rmse_all[0],
            "rmse_command_all_mps2": rmse_all[1],
        }
    return out


def summarise(result: dict, reference: dict, num_followers: int, intervals: int) -> dict:
    ret, ret_d = result["return"], result["return_discounted"]
    summary = {k: v for k, v in result.items() if k not in ("return", "return_discounted")}
    summary["control_cost_per_follower_interval"] = mean_ci(-ret / (num_followers * intervals))
    summary["return"] = mean_ci(ret)
    summary["evoi"] = mean_ci(ret - reference["return"])
    summary["evoi_discounted"] = mean_ci(ret_d - reference["return_discounted"])
    return summary


def print_report(rows: list[dict]) -> None:
    def ci(d, scale=1.0, digits=3):
        return f"{d['mean'] * scale:.{digits}f} ± {d['ci95'] * scale:.{digits}f}"

    header = [
        "mode",
        "accel RMSE stale",
        "cmd RMSE stale",
        "accel RMSE all",
        "gap err RMS (m)",
        "|jerk| (m/s³)",
        "control cost",
        "EVoI (episode)",
        "collisions",
    ]
    table = []
    for r in rows:
        dash = "-"
        table.append(
            [
                r["mode"],
                f"{r['rmse_accel_stale_mps2']:.4f}" if "rmse_accel_stale_mps2" in r else dash,
                f"{r['rmse_command_stale_mps2']:.4f}" if "rmse_command_stale_mps2" in r else dash,
                f"{r['rmse_accel_all_mps2']:.4f}" if "rmse_accel_all_mps2" in r else dash,
                f"{r['gap_error_rms_m']:.3f}",
                f"{r['mean_abs_jerk_mps3']:.2f}",
                ci(r["control_cost_per_follower_interval"], digits=4),
                ci(r["evoi"], digits=2),
                str(r["collisions"]),
            ]
        )
    try:
        from rich.console import Console
        from rich.table import Table
    except ImportError:
        widths = [max(len(h), *(len(row[i]) for row in table)) for i, h in enumerate(header)]
        fmt = "  ".join(f"{{:>{w}}}" for w in widths)
        print(fmt.format(*header))
        print("  ".join("-" * w for w in widths))
        for row in table:
            print(fmt.format(*row))
        return
    t = Table(title="data completion: prediction error (m/s²), control cost, EVoI")
    for i, h in enumerate(header):
        t.add_column(h, justify="left" if i == 0 else "right")
    for row in table:
        t.add_row(*row)
    Console(width=180).print(t)


def main(argv=None) -> int:
    args = parse_args(argv)
    torch.set_num_threads(args.threads)
    params = TwinParams.from_overrides(episode_intervals=args.intervals, traces=args.traces)

    print(f"training the learned predictor (seed {args.train_seed}) ...", flush=True)
    predictor = train_completion_predictor(
        params,
        seed=args.train_seed,
        batch_size=args.train_batch_size,
        intervals=args.train_intervals,
        epochs=args.train_epochs,
        device=args.device,
    )
    info = predictor.training_info
    print(
        f"  {info['stale_rows']} stale rows, train RMSE accel {info['train_rmse_accel_mps2']:.4f}"
        f" cmd {info['train_rmse_command_mps2']:.4f} m/s², {info['seconds']:.1f} s",
        flush=True,
    )
    print("perfect observation ...", flush=True)
    reference = run(params, args, None)
    results = []
    for mode in COMPLETION_MODES:
        print(f"completion={mode} ...", flush=True)
        results.append(run(params, args, mode, predictor if mode == "learned" else None))
    f = params.platoon.num_followers
    rows = [summarise(r, reference, f, args.intervals) for r in [reference, *results]]
    print()
    print_report(rows)

    payload = {
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "command": script_command(),
        "argv": sys.argv[1:] if argv is None else list(argv),
        "torch_version": torch.__version__,
        "numpy_version": np.__version__,
        "python_version": platform.python_version(),
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "device": args.device,
        "batch_size": args.batch_size,
        "intervals": args.intervals,
        "seed": args.seed,
        "traces": args.traces,
        "rra_policy": "random",
        "controller": "linear CACC (docs/model.md §2.5)",
        "discount": DISCOUNT,
        "ci": "95%, normal approximation over scenarios",
        "learned_predictor": {
            "train_seed": args.train_seed,
            "train_batch_size": args.train_batch_size,
            "train_intervals": args.train_intervals,
            "epochs": args.train_epochs,
            **info,
        },
        "results": rows,
    }
    atomic_write_json(args.out, payload)
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
