"""What in the RRA state predicts the value of delivering this interval's CAM?

The RRA agents decide, subframe by subframe, whether the recipient gets its CAM in time. What
that is worth is the value of this interval's delivery: ξ(delivered) − ξ(had it been lost),
the ``cam_lost`` baseline of :class:`~vdtn_marl.voi.RolloutIVoIEstimator` (a difference of two
counterfactual rollouts with the same leader trace; exact for the linear CACC reference). This
script measures, per (interval, link) where the CAM was delivered in time, how well that value
is predicted by the features the RRA observation has (``cam_age``, the last CAM delay, the
recipient's gap and speed errors, the predecessor's acceleration, the recipient's command and
its two previous ones) and by one it does not have: the CAM content's innovation, the
predecessor's acceleration (and command) now minus what the recipient holds.

Acting system: the linear CACC on impaired observations (no completion), on platoon4's held-out
evaluation traces. RRA: the greedy baseline, with each link made silent for a whole interval
with probability ``--silent`` (drawn per interval and link), so that the recipients' CAM ages
vary as they do under a learned RRA that skips intervals. Each seed is one run; the fits are
scored on held-out seeds (leave one seed out). The committed results come from

    python studies/2026-12-07-cam-innovation/run.py --seeds 10 --episodes 16 --intervals 200 \
        --horizon 40
    python studies/2026-12-07-cam-innovation/run.py --seeds 10 --episodes 16 --intervals 200 \
        --horizon 100 --out studies/2026-12-07-cam-innovation/results_horizon100.json

Writes ``results.json`` (atomically) beside this file unless ``--out`` says otherwise.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch
from rich.console import Console
from rich.table import Table
from scipy import stats

from vdtn_marl.core.interval import IntervalEngine
from vdtn_marl.experiment.compose import compose_config, hydra_compose, job_config, to_run_config
from vdtn_marl.experiment.evaluate import EVAL_SEED_OFFSET
from vdtn_marl.experiment.jocc import trace_sources
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.policies import make_control_baseline, make_rra_baseline
from vdtn_marl.sim.platoon import spacing_errors
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi.estimators import RolloutIVoIEstimator, VoIReference

HERE = Path(__file__).resolve().parent
GAMMA = 0.99  # per control interval (AlgoConfig.gamma)
#: the RRA observation's features (or what they are made of), then the two innovations
OBSERVED = ("cam_age", "last_delay", "gap_error", "speed_error", "pred_accel", "command",
            "command_1", "command_2")  # fmt: skip
INNOVATION = ("innovation_accel", "innovation_command")


@torch.no_grad()
def run_seed(params, trace_source, seed: int, episodes: int, intervals: int, horizon: int,
             silent: float) -> dict[str, np.ndarray]:  # fmt: skip
    """Samples of one seed's run: the features at each interval's start and the value of that
    interval's delivery, per (scenario, interval, link), where the CAM was delivered in time
    and no collision had ended the scenario."""
    twin = DigitalTwin(
        params, batch_size=episodes, seed=seed, trace_source=trace_source, radio=True,
        backend="torch", draw_ahead=False,
    )  # fmt: skip
    twin.reset(seed=seed)
    greedy = make_rra_baseline("greedy", params, seed)
    greedy = greedy.bind(twin) if hasattr(greedy, "bind") else greedy
    off = 0 * params.radio.num_power_levels + (params.radio.num_power_levels - 1)
    control = make_control_baseline("cacc", params)
    estimator = RolloutIVoIEstimator.from_reference(
        VoIReference(policy=None, value=None, discount=GAMMA),
        horizon_intervals=horizon, bootstrap=False, baseline="cam_lost",
    )  # fmt: skip
    engine = IntervalEngine(twin, perfect=False, control=control, ivoi_estimator=estimator)
    pp = params.platoon
    t_sub = pp.subframes_per_interval
    rng = torch.Generator().manual_seed(seed)
    alive = torch.ones(episodes, dtype=torch.bool)
    rows: dict[str, list[np.ndarray]] = {k: [] for k in (*OBSERVED, *INNOVATION, "value")}
    history = torch.zeros(2, episodes, pp.num_followers)  # u_{k−2}, u_{k−3}
    last_delay = torch.zeros(episodes, pp.num_followers)
    for k in range(intervals):
        if k > 0:
            twin.begin_interval()
        state = twin.platoon
        gap_error, speed_error = spacing_errors(state, pp)
        held = twin.cam_held  # [B, F, 2]: the predecessor's acceleration and command held
        pred_accel = pp.topology.predecessors_of(state.accel_mps2)
        pred_command = pp.topology.predecessors_of(state.command_mps2)
        age = (twin.interval[:, None] - twin.cam_held_interval).float()
        features = {
            "cam_age": age.clamp(0, 10),
            "last_delay": last_delay,
            "gap_error": gap_error,
            "speed_error": speed_error,
            "pred_accel": pred_accel,
            "command": pp.topology.followers_of(state.command_mps2),
            "command_1": history[0],
            "command_2": history[1],
            "innovation_accel": pred_accel - held[..., 0],
            "innovation_command": pred_command - held[..., 1],
        }
        mute = torch.rand(episodes, pp.num_followers, generator=rng) < silent  # link i: F i
        for _ in range(t_sub):
            actions = torch.as_tensor(greedy(twin.rra_observation())).long()
            twin.step_subframe(torch.where(mute, off, actions))
        closed = engine.close()
        record = closed.record
        in_time = record.cam_delay_subframes <= t_sub
        keep = in_time & alive[:, None]
        for name, value in features.items():
            rows[name].append(value[keep].double().numpy())
        rows["value"].append(closed.xi[keep].double().numpy())
        history = torch.stack([pp.topology.followers_of(state.command_mps2), history[0]])
        last_delay = record.cam_delay_subframes.float() / (t_sub + 1)
        alive &= ~record.collided.any(-1)
    return {name: np.concatenate(parts) for name, parts in rows.items()}


def design(samples: dict[str, np.ndarray], names: tuple[str, ...]) -> np.ndarray:
    """Each feature signed and in absolute value, and a constant."""
    columns = [np.ones_like(samples["value"])]
    for name in names:
        columns += [samples[name], np.abs(samples[name])]
    return np.stack(columns, axis=1)


def held_out_r2(per_seed: list[dict], names: tuple[str, ...], target: str) -> list[float]:
    """R² on each seed of a least-squares fit on the other seeds (of ``target``: the value or
    its absolute value)."""
    out = []
    for i, test in enumerate(per_seed):
        train = [s for j, s in enumerate(per_seed) if j != i]
        x = np.concatenate([design(s, names) for s in train])
        y = np.concatenate([_target(s, target) for s in train])
        coef, *_ = np.linalg.lstsq(x, y, rcond=None)
        y_test = _target(test, target)
        residual = y_test - design(test, names) @ coef
        out.append(1.0 - float(np.sum(residual**2)) / float(np.sum((y_test - y_test.mean()) ** 2)))
    return out


def _target(samples: dict, target: str) -> np.ndarray:
    return np.abs(samples["value"]) if target == "abs_value" else samples["value"]


def t_interval(values) -> dict:
    d = np.asarray(values, dtype=float)
    mean = float(d.mean())
    half = float(stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / math.sqrt(len(d)))
    return {"mean": mean, "lo": mean - half, "hi": mean + half, "n": len(d)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=6)
    parser.add_argument("--episodes", type=int, default=16, help="scenarios per seed")
    parser.add_argument("--intervals", type=int, default=200, help="control intervals")
    parser.add_argument("--horizon", type=int, default=40, help="rollout intervals of ξ")
    parser.add_argument(
        "--silent",
        type=float,
        default=0.5,
        help="probability that a link stays silent for a whole interval",
    )
    parser.add_argument("--out", type=Path, default=HERE / "results.json")
    args = parser.parse_args()
    if not 0.0 <= args.silent < 1.0:
        parser.error(f"--silent={args.silent} must be in [0, 1)")
    if args.seeds < 3:
        parser.error(f"--seeds={args.seeds} must be >= 3 (held-out fits and t intervals)")
    torch.set_num_threads(1)
    console = Console(width=140)
    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", ["scenario=platoon4"])))
    params = cfg.twin_params()
    _, eval_traces = trace_sources(cfg)
    began = time.perf_counter()
    per_seed = []
    for s in range(args.seeds):
        t0 = time.perf_counter()
        per_seed.append(run_seed(params, eval_traces, EVAL_SEED_OFFSET + s, args.episodes,
                                 args.intervals, args.horizon, args.silent))  # fmt: skip
        console.print(f"seed {s}: {per_seed[-1]['value'].size} samples, "
                      f"{time.perf_counter() - t0:.0f} s")  # fmt: skip
    runtime = time.perf_counter() - began

    pooled = {k: np.concatenate([s[k] for s in per_seed]) for k in per_seed[0]}
    value = pooled["value"]
    correlations = {}
    for name in (*OBSERVED, *INNOVATION):
        rho = [stats.spearmanr(np.abs(s[name]), np.abs(s["value"])).statistic for s in per_seed]
        correlations[name] = t_interval(rho)
    fits = {}
    for target in ("value", "abs_value"):
        base = held_out_r2(per_seed, OBSERVED, target)
        full = held_out_r2(per_seed, (*OBSERVED, *INNOVATION), target)
        alone = held_out_r2(per_seed, INNOVATION, target)
        fits[target] = {
            "observed": t_interval(base),
            "observed_plus_innovation": t_interval(full),
            "innovation_alone": t_interval(alone),
            "gain_of_innovation": t_interval([b - a for a, b in zip(base, full, strict=True)]),
            "per_seed": {"observed": base, "observed_plus_innovation": full,
                         "innovation_alone": alone},
        }  # fmt: skip

    by_age = {}
    for age in range(1, 6):
        means = []
        for s in per_seed:
            hit = (s["cam_age"] == age) if age < 5 else (s["cam_age"] >= age)
            means.append(float(s["value"][hit].mean()) if hit.any() else float("nan"))
        label = str(age) if age < 5 else f">={age}"
        n = int(sum(((s["cam_age"] == age) if age < 5 else (s["cam_age"] >= age)).sum()
                    for s in per_seed))  # fmt: skip
        finite = [m for m in means if math.isfinite(m)]
        by_age[label] = {"samples": n, **(t_interval(finite) if len(finite) >= 2 else {})}

    table = Table(title="Mean value of delivery by the age of the CAM held (intervals) [95 % t]")
    for col in ("cam_age", "samples", "mean value of delivery"):
        table.add_column(col, justify="right")
    for label, r in by_age.items():
        shown = f"{r['mean']:+.2e} [{r['lo']:+.2e}, {r['hi']:+.2e}]" if "mean" in r else "-"
        table.add_row(label, str(r["samples"]), shown)
    console.print(table)
    table = Table(title="Spearman ρ(|feature|, |value of delivery|), per seed [95 % t]")
    table.add_column("feature")
    table.add_column("in the RRA state")
    table.add_column("ρ", justify="right")
    for name, c in correlations.items():
        table.add_row(name, "yes" if name in OBSERVED else "no",
                      f"{c['mean']:+.3f} [{c['lo']:+.3f}, {c['hi']:+.3f}]")  # fmt: skip
    console.print(table)
    table = Table(title="Held-out R² of a linear fit (leave one seed out) [95 % t]")
    for col in ("target", "RRA state's features", "+ innovation", "gain", "innovation alone"):
        table.add_column(col, justify="right")
    for target, f in fits.items():
        table.add_row(target, *(f"{f[k]['mean']:.3f} [{f[k]['lo']:.3f}, {f[k]['hi']:.3f}]"
                                for k in ("observed", "observed_plus_innovation",
                                          "gain_of_innovation", "innovation_alone")))  # fmt: skip
    console.print(table)
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              cwd=HERE, check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        head = None
    atomic_write_json(args.out, {
        "command": " ".join(["python", *sys.argv]),
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "git_head": head,
        "load_average_at_end": list(os.getloadavg()),
        "runtime_s": runtime,
        "setup": {
            "scenario": "platoon4", "seeds": [EVAL_SEED_OFFSET + s for s in range(args.seeds)],
            "episodes": args.episodes, "intervals": args.intervals, "horizon": args.horizon,
            "silent_probability": args.silent, "gamma_per_interval": GAMMA,
            "acting_control": "cacc, impaired observations, no completion",
            "rra": "greedy, each link silent for a whole interval with --silent",
            "value": "xi with baseline cam_lost (delivered minus had it been lost), "
                     "CACC reference, no bootstrap; samples where the CAM was in time",
        },
        "samples": int(value.size),
        "value_summary": {
            "mean": float(value.mean()), "std": float(value.std()),
            "abs_mean": float(np.abs(value).mean()),
            "quantiles": {str(q): float(np.quantile(value, q))
                          for q in (0.01, 0.1, 0.5, 0.9, 0.99)},
        },  # fmt: skip
        "value_by_cam_age": by_age,
        "spearman_abs": correlations,
        "held_out_r2": fits,
    })  # fmt: skip
    console.print(f"wrote {args.out} ({runtime:.0f} s)")


if __name__ == "__main__":
    main()
