"""Does the paper's RRA objective itself rank silence above the opportunistic RRA policy?

For fixed RRA policies (off, random, round_robin, greedy, opportunistic), with the linear CACC
acting on impaired observations, on platoon4's held-out evaluation traces, this script computes
per scenario and per seed the two discounted terms of the RRA agents' return (docs/model.md §5):

- P = Σ_k Σ_t γ^((kT+t)/T) · s_g · g_{k,t}, g the subframe's V2I throughput Σ_m rate (Mbps),
  the same for every RRA agent;
- Ξ = Σ_k γ^((kT+T−1)/T) · s_ξ · ξ_{k,i}, mean over links i: ξ is paid with the reward of the
  interval's last subframe (t = T−1), whose per-subframe discount from the start is
  γ^((kT+T−1)/T) (the placement the RRA environment and GAE use: γ^(1/T) per subframe step);

with ξ the paper's IVoI (baseline ``optimal``) from counterfactual rollouts of the linear CACC
on perfect observations for ``--horizon`` intervals without bootstrap (exact for that reference:
platoon dynamics are deterministic given the trace). Then J(κ1) = κ1·P + (1 − κ1)·Ξ for
κ1 ∈ {0.25, 0.5, 0.75}, the CAM delivery, the V2I rate per link and |gap error|; each policy's
difference to ``opportunistic`` with a paired-by-seed Student-t 95 % interval; and the same
ranking with each term normalised by its off–greedy spread (a diagnostic).

A scenario whose platoon collides stops counting after the colliding interval (its episode
ends there, as in the environment).

    python studies/2026-12-07-rra-objective/rra_objective.py --seeds 5 --episodes 16 \
        --intervals 200 --horizon 100 40

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
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table
from scipy import stats

from vdtn_marl.core.interval import IntervalEngine
from vdtn_marl.experiment.compose import compose_config, hydra_compose, job_config, to_run_config
from vdtn_marl.experiment.evaluate import EVAL_SEED_OFFSET
from vdtn_marl.experiment.jocc import trace_sources
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.policies import make_control_baseline, make_rra_baseline
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi.estimators import RolloutIVoIEstimator, VoIReference

HERE = Path(__file__).resolve().parent
POLICIES = ("off", "random", "round_robin", "greedy", "opportunistic")
KAPPAS = (0.25, 0.5, 0.75)
GAMMA = 0.99  # per control interval (AlgoConfig.rra_gamma, rra_credit=interval)
# s_g and s_ξ of conf/rra/jocc.yaml (throughput_scale, ivoi_scale), written here so that the
# numbers do not move with the config
THROUGHPUT_SCALE = 0.004
IVOI_SCALE = 20.0
COMPARE_WITH = "opportunistic"
CHECKPOINTS = (10, 25, 50, 100, 150)  # partial sums of P and Ξ over the first K intervals


class OffRRAPolicy:
    """Every link on sub-channel 0 at the "off" power level (the last one): no V2V
    transmission, so no interference on any V2I uplink and no CAM delivered."""

    rowwise = True

    def __init__(self, num_power_levels: int):
        self.action = 0 * num_power_levels + (num_power_levels - 1)

    def __call__(self, observation):
        return torch.full(observation.shape[:-1], self.action, dtype=torch.long)


def make_policy(name: str, params, seed: int):
    if name == "off":
        return OffRRAPolicy(params.radio.num_power_levels)
    return make_rra_baseline(name, params, seed)


@torch.no_grad()
def run_policy(name, params, trace_source, seed, episodes, intervals, horizons):
    """Per-scenario numbers [B] of one RRA policy on one seed's scenarios. ``horizons``: the
    rollout horizons of ξ, the first the main one (``Xi``), the others ``Xi_h<H>``; ξ of every
    horizon is computed on the same intervals of the same run (ξ does not change the run)."""
    twin = DigitalTwin(
        params, batch_size=episodes, seed=seed, trace_source=trace_source, radio=True,
        backend="torch", draw_ahead=False,
    )  # fmt: skip
    twin.reset(seed=seed)
    rra = make_policy(name, params, seed)
    rra = rra.bind(twin) if hasattr(rra, "bind") else rra
    if hasattr(rra, "reset"):
        rra.reset()
    control = make_control_baseline("cacc", params)
    estimators = [
        RolloutIVoIEstimator.from_reference(
            VoIReference(policy=None, value=None, discount=GAMMA),
            horizon_intervals=h,
            bootstrap=False,
            baseline="optimal",
        )  # fmt: skip
        for h in horizons
    ]
    engine = IntervalEngine(twin, perfect=False, control=control, ivoi_estimator=estimators[0])
    t_sub = params.platoon.subframes_per_interval
    m = params.radio.num_subchannels if hasattr(params.radio, "num_subchannels") else None
    step = GAMMA ** (1.0 / t_sub)
    b = episodes
    alive = torch.ones(b, dtype=torch.float64)
    p_term = torch.zeros(b, dtype=torch.float64)
    xi_term = torch.zeros(b, dtype=torch.float64)
    xi_other = {h: torch.zeros(b, dtype=torch.float64) for h in horizons[1:]}
    checkpoints = {}  # K -> (P, Ξ) partial sums over the first K intervals
    xi_raw = torch.zeros(b, dtype=torch.float64)  # undiscounted Σ ξ (mean over links)
    g_sum = torch.zeros(b, dtype=torch.float64)  # Σ g over live subframes (Mbps)
    gap_sum = torch.zeros(b, dtype=torch.float64)
    sent = torch.zeros(b, dtype=torch.float64)
    delivered = torch.zeros(b, dtype=torch.float64)
    live_intervals = torch.zeros(b, dtype=torch.float64)
    collided_any = torch.zeros(b, dtype=torch.bool)
    n = 0  # subframe index from the start
    for k in range(intervals):
        if k > 0:
            twin.begin_interval()
        for _ in range(t_sub):
            actions = torch.as_tensor(rra(twin.rra_observation())).long()
            outcome = twin.step_subframe(actions)
            rate = outcome.v2i_rate_bps
            m = rate.shape[-1]
            g = rate.double().sum(-1) * 1e-6  # Mbps, as RRAReward.v2i_throughput_mbps
            p_term += alive * step**n * THROUGHPUT_SCALE * g
            g_sum += alive * g
            n += 1
        closed = engine.close()
        record = closed.record
        xi = closed.xi.double().mean(-1)  # [B], mean over links (link i carries follower i)
        xi_term += alive * step ** (n - 1) * IVOI_SCALE * xi
        xi_raw += alive * xi
        for h, est in zip(horizons[1:], estimators[1:], strict=True):
            xi = est(twin, record).double().mean(-1)
            xi_other[h] += alive * step ** (n - 1) * IVOI_SCALE * xi
        f = record.gap_error_m.shape[-1]
        gap_sum += alive * record.gap_error_m.abs().double().mean(-1)
        in_time = (record.cam_delay_subframes <= t_sub).double()
        delivered += alive * in_time.sum(-1)
        sent += alive * in_time.shape[-1]
        live_intervals += alive
        hit = record.collided.any(-1)
        collided_any |= hit & (alive > 0)
        alive = alive * (~hit).double()
        if k + 1 in CHECKPOINTS:
            checkpoints[k + 1] = (p_term.tolist(), xi_term.tolist())
    del f
    return {
        "P": p_term.tolist(),
        "Xi": xi_term.tolist(),
        **{f"Xi_h{h}": v.tolist() for h, v in xi_other.items()},
        "collided": collided_any.tolist(),
        "partial_sums": {str(kk): {"P": pp, "Xi": xx} for kk, (pp, xx) in checkpoints.items()},
        "xi_mean_per_follower_interval": (xi_raw / live_intervals).tolist(),
        "cam_delivery_rate": (delivered / sent).tolist(),
        "v2i_mbps_per_link": (g_sum / (live_intervals * t_sub) / m).tolist(),
        "interval_throughput_mbps": (g_sum / live_intervals).tolist(),
        "gap_error_abs_m": (gap_sum / live_intervals).tolist(),
        "collision_rate": collided_any.double().mean().item(),
    }


def t_interval(diffs) -> dict:
    """Mean and Student-t 95 % interval of paired differences (over seeds)."""
    d = np.asarray(diffs, dtype=float)
    mean = float(d.mean())
    if len(d) < 2:
        return {"mean": mean, "lo": float("nan"), "hi": float("nan"), "n": len(d)}
    half = float(stats.t.ppf(0.975, len(d) - 1) * d.std(ddof=1) / math.sqrt(len(d)))
    return {"mean": mean, "lo": mean - half, "hi": mean + half, "n": len(d)}


METRICS = ("P", "Xi", "cam_delivery_rate", "v2i_mbps_per_link", "gap_error_abs_m",
           "xi_mean_per_follower_interval", "interval_throughput_mbps")  # fmt: skip


def seed_means(per_seed: dict, seeds: list[int], key: str, keep=None) -> dict:
    """Per policy, the seed-level means of ``key`` over scenarios (over the scenarios ``keep``
    [seed index] -> bool mask marks, the same for every policy: paired)."""
    out = {}
    for p in per_seed:
        values = []
        for i, s in enumerate(seeds):
            v = np.asarray(per_seed[p][s][key], dtype=float)
            values.append(float(v[keep[i]].mean() if keep is not None else v.mean()))
        out[p] = values
    return out


def ranking(P: dict, Xi: dict, kappa: float) -> list[dict]:
    """Policies by mean J = κ1·P + (1 − κ1)·Ξ over seeds, each with its paired-by-seed
    difference to opportunistic."""
    j = {p: [kappa * a + (1 - kappa) * b for a, b in zip(P[p], Xi[p], strict=True)] for p in P}
    rows = []
    for p in P:
        diff = [a - b for a, b in zip(j[p], j[COMPARE_WITH], strict=True)]
        rows.append({
            "policy": p, "J_mean": float(np.mean(j[p])), "J_per_seed": j[p],
            "P_mean": float(np.mean(P[p])), "Xi_mean": float(np.mean(Xi[p])),
            "minus_" + COMPARE_WITH: t_interval(diff),
        })  # fmt: skip
    rows.sort(key=lambda r: -r["J_mean"])
    return rows


def analyse(per_seed: dict, seeds: list[int], horizons: list[int]) -> dict:
    """Rankings of J(κ1): on every scenario (the answer), with each term normalised by its
    off-greedy spread, on the scenarios where no policy collided, with ξ of the other rollout
    horizons, and of the partial sums over the first K intervals."""
    mean = {key: seed_means(per_seed, seeds, key) for key in METRICS}
    mean = {p: {key: mean[key][p] for key in METRICS} for p in per_seed}
    P = {p: mean[p]["P"] for p in per_seed}
    Xi = {p: mean[p]["Xi"] for p in per_seed}
    p_off, p_greedy = np.mean(P["off"]), np.mean(P["greedy"])
    x_off, x_greedy = np.mean(Xi["off"]), np.mean(Xi["greedy"])
    spreads = {
        "P_off": float(p_off), "P_greedy": float(p_greedy), "P_spread": float(p_off - p_greedy),
        "Xi_off": float(x_off), "Xi_greedy": float(x_greedy),
        "Xi_spread": float(x_greedy - x_off),
        "P_spread_per_seed": [a - b for a, b in zip(P["off"], P["greedy"], strict=True)],
        "Xi_spread_per_seed": [a - b for a, b in zip(Xi["greedy"], Xi["off"], strict=True)],
    }  # fmt: skip
    # P' = (P − P_greedy)/(P_off − P_greedy), Ξ' = (Ξ − Ξ_off)/(Ξ_greedy − Ξ_off), with the
    # spreads pooled over seeds (a per-seed normalisation would make off and greedy constant)
    P_n = {p: [(v - p_greedy) / (p_off - p_greedy) for v in P[p]] for p in P}
    Xi_n = {p: [(v - x_off) / (x_greedy - x_off) for v in Xi[p]] for p in Xi}
    # the scenarios where no policy collided (paired: the same scenarios for every policy)
    keep = [
        ~np.any([np.asarray(per_seed[p][s]["collided"]) for p in per_seed], axis=0) for s in seeds
    ]
    P_nc = seed_means(per_seed, seeds, "P", keep)
    Xi_nc = seed_means(per_seed, seeds, "Xi", keep)
    out = {
        "spreads": spreads, "seed_means": mean,
        "no_collision_scenarios": int(sum(k.sum() for k in keep)),
        "all_scenarios": int(sum(k.size for k in keep)),
        "spreads_no_collision": {
            "P_spread": float(np.mean(P_nc["off"]) - np.mean(P_nc["greedy"])),
            "Xi_spread": float(np.mean(Xi_nc["greedy"]) - np.mean(Xi_nc["off"])),
        },
        "rankings": {}, "rankings_normalised": {}, "rankings_no_collision": {},
        "rankings_by_horizon": {}, "rankings_first_k_intervals": {},
    }  # fmt: skip
    for kappa in KAPPAS:
        out["rankings"][str(kappa)] = ranking(P, Xi, kappa)
        out["rankings_normalised"][str(kappa)] = ranking(P_n, Xi_n, kappa)
        out["rankings_no_collision"][str(kappa)] = ranking(P_nc, Xi_nc, kappa)
    for h in horizons[1:]:
        Xi_h = seed_means(per_seed, seeds, f"Xi_h{h}")
        out["rankings_by_horizon"][str(h)] = {str(k): ranking(P, Xi_h, k) for k in KAPPAS}
    first = per_seed[COMPARE_WITH][seeds[0]]["partial_sums"]
    for kk in first:
        P_k, Xi_k = ({p: [float(np.mean(per_seed[p][s]["partial_sums"][kk][key])) for s in seeds]
                      for p in per_seed} for key in ("P", "Xi"))  # fmt: skip
        out["rankings_first_k_intervals"][kk] = {str(k): ranking(P_k, Xi_k, k) for k in KAPPAS}
    return out


def ranking_table(title: str, rows: list[dict]) -> Table:
    t = Table(title=title)
    for col, justify in (("rank", "left"), ("policy", "left"), ("mean P", "right"),
                         ("mean Ξ", "right"), ("mean J", "right"),
                         (f"J − J_{COMPARE_WITH} [95 % t]", "right")):  # fmt: skip
        t.add_column(col, justify=justify)
    for rank, r in enumerate(rows, 1):
        d = r["minus_" + COMPARE_WITH]
        t.add_row(str(rank), r["policy"], f"{r['P_mean']:.4f}", f"{r['Xi_mean']:.4f}",
                  f"{r['J_mean']:.4f}",
                  f"{d['mean']:+.4f} [{d['lo']:+.4f}, {d['hi']:+.4f}]")  # fmt: skip
    return t


def print_tables(console: Console, analysis: dict, per_seed: dict) -> None:
    mean = analysis["seed_means"]
    table = Table(title="Per policy (mean over seeds of the scenario means)")
    for col in ("policy", "P", "Ξ", "ξ/follower-interval", "CAM delivery", "V2I Mbps/link",
                "|gap| m", "collisions"):  # fmt: skip
        table.add_column(col, justify="right")
    for p in mean:
        coll = np.mean([np.mean(per_seed[p][s]["collided"]) for s in per_seed[p]])
        table.add_row(
            p, f"{np.mean(mean[p]['P']):.3f}", f"{np.mean(mean[p]['Xi']):.3f}",
            f"{np.mean(mean[p]['xi_mean_per_follower_interval']):.5f}",
            f"{np.mean(mean[p]['cam_delivery_rate']):.3f}",
            f"{np.mean(mean[p]['v2i_mbps_per_link']):.4f}",
            f"{np.mean(mean[p]['gap_error_abs_m']):.4f}", f"{coll:.3f}",
        )  # fmt: skip
    console.print(table)
    sp = analysis["spreads"]
    console.print(
        f"P: off {sp['P_off']:.3f}, greedy {sp['P_greedy']:.3f}, spread P_off − P_greedy = "
        f"{sp['P_spread']:.3f};  Ξ: off {sp['Xi_off']:.3f}, greedy {sp['Xi_greedy']:.3f}, "
        f"spread Ξ_greedy − Ξ_off = {sp['Xi_spread']:.3f}"
    )
    for label, title in (
        ("rankings", "J(κ1) = κ1·P + (1−κ1)·Ξ"),
        ("rankings_normalised", "J'(κ1) = κ1·P' + (1−κ1)·Ξ' (off–greedy spreads)"),
        ("rankings_no_collision", f"J(κ1) on the {analysis['no_collision_scenarios']}/"
         f"{analysis['all_scenarios']} scenarios where no policy collided"),
    ):  # fmt: skip
        for kappa, rows in analysis[label].items():
            console.print(ranking_table(f"{title}, κ1 = {kappa}", rows))
    for h, by_kappa in analysis["rankings_by_horizon"].items():
        console.print(ranking_table(f"J(0.5) with ξ of horizon {h}", by_kappa["0.5"]))
    for kk, by_kappa in analysis["rankings_first_k_intervals"].items():
        console.print(ranking_table(f"J(0.5) of the first {kk} intervals", by_kappa["0.5"]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5, help="paired seeds 0..N−1")
    parser.add_argument("--episodes", type=int, default=16, help="scenarios per seed")
    parser.add_argument("--intervals", type=int, default=200, help="control intervals")
    parser.add_argument("--horizon", type=int, nargs="+", default=[100],
                        help="rollout intervals of ξ: the first is the main one, the others "
                        "are reported as a check")  # fmt: skip
    parser.add_argument("--policies", nargs="+", default=list(POLICIES), choices=POLICIES)
    parser.add_argument("--out", type=Path, default=HERE / "results.json")
    args = parser.parse_args()
    if (
        "off" not in args.policies
        or "greedy" not in args.policies
        or (COMPARE_WITH not in args.policies)
    ):
        parser.error("--policies must include off, greedy and opportunistic")
    torch.set_num_threads(1)
    console = Console(width=150)
    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", ["scenario=platoon4"])))
    params = cfg.twin_params()
    _, eval_traces = trace_sources(cfg)
    seeds = list(range(args.seeds))
    per_seed: dict[str, dict[int, dict]] = {p: {} for p in args.policies}
    began = time.perf_counter()
    timings = {}
    with Progress(
        TextColumn("{task.description}"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(), TimeRemainingColumn(), console=console,
    ) as progress:  # fmt: skip
        task = progress.add_task("runs", total=len(seeds) * len(args.policies))
        for s in seeds:
            for p in args.policies:
                progress.update(task, description=f"seed {s} {p}")
                t0 = time.perf_counter()
                per_seed[p][s] = run_policy(
                    p, params, eval_traces, EVAL_SEED_OFFSET + s, args.episodes, args.intervals,
                    args.horizon,
                )  # fmt: skip
                timings[f"{p}/seed{s}"] = time.perf_counter() - t0
                progress.advance(task)
    runtime = time.perf_counter() - began
    analysis = analyse(per_seed, seeds, args.horizon)
    print_tables(console, analysis, per_seed)
    rank = [r["policy"] for r in analysis["rankings"]["0.5"]]
    off_above = rank.index("off") < rank.index(COMPARE_WITH)
    rank_n = [r["policy"] for r in analysis["rankings_normalised"]["0.5"]]
    console.print(
        f"κ1 = 0.5: off ranks {'ABOVE' if off_above else 'below'} opportunistic "
        f"(ranking {rank}); normalised: {rank_n}"
    )
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                              cwd=HERE, check=True).stdout.strip()  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        head = None
    results = {
        "command": " ".join(["python", *sys.argv]),
        "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "git_head": head,
        "load_average_at_end": list(os.getloadavg()),
        "runtime_s": runtime,
        "torch_threads": torch.get_num_threads(),
        "setup": {
            "scenario": "platoon4",
            "traces": "held-out evaluation traces (trace_sources)",
            "seeds": [EVAL_SEED_OFFSET + s for s in seeds],
            "episodes": args.episodes,
            "intervals": args.intervals,
            "subframes_per_interval": params.platoon.subframes_per_interval,
            "acting_control": "cacc, impaired observations, no completion",
            "ivoi": "rollout, baseline=optimal, reference = "
            "linear CACC on perfect observations, "
            f"horizons {args.horizon} intervals (the first is the "
            "main one), no bootstrap",
            "gamma_per_interval": GAMMA,
            "throughput_scale": THROUGHPUT_SCALE,
            "ivoi_scale": IVOI_SCALE,
            "discount_P": "gamma^((kT+t)/T) on subframe t of interval k",
            "discount_Xi": "gamma^((kT+T-1)/T): xi is paid with the reward of the last subframe",
            "normalisation": "P' = (P - P_greedy)/(P_off - P_greedy), Xi' = (Xi - Xi_off)/"
            "(Xi_greedy - Xi_off), with the spreads pooled over seeds",
            "collisions": "a scenario stops counting after its colliding interval",
        },  # fmt: skip
        "answer": {
            "kappa1_0.5_ranking": rank,
            "off_above_opportunistic": off_above,
            "kappa1_0.5_ranking_normalised": rank_n,
        },  # fmt: skip
        "analysis": analysis,
        "per_seed": {
            p: {str(EVAL_SEED_OFFSET + s): v for s, v in d.items()} for p, d in per_seed.items()
        },  # fmt: skip
        "timings_s": timings,
    }
    atomic_write_json(args.out, results)
    console.print(f"wrote {args.out} ({runtime:.0f} s)")


if __name__ == "__main__":
    main()
