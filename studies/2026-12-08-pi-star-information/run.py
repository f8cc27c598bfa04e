"""Is π* below the causal MPC because it sees less? Per-follower returns on perfect observations.

The causal MPC plans the commands of all followers jointly from the twin's true state (every
vehicle's gap, speed and acceleration, and the leader's acceleration); π* is one policy per
follower that reads its own 8-wide observation (its errors, its predecessor's CAM). If π*'s
deficit against the causal MPC comes from that information, it should be near 0 at follower 1
(whose predecessor is the leader) and grow towards the rear.

For each seed it loads the shared π* of ``headline`` 2.1 from ``--cells`` (a copy of
``benchmarks/results/cells/headline-v2.1`` whose π* runs hold their checkpoints: rerun them
with ``vdtn-marl bench benchmark=headline out_dir=DIR cells='[*/pi_star/*]'``), scores π*, the
causal MPC and the CACC on the run's 16 held-out scenarios × 200 intervals (perfect
observations, the reference check's scenarios), and writes each follower's mean discounted
return and the paired differences (Student-t 95 %) to ``results.json``.

    python studies/2026-12-08-pi-star-information/run.py --cells DIR --seeds 7 8 0 1
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import torch
import yaml

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.ppo import ActorPolicy
from vdtn_marl.experiment.checkpoint import load_checkpoint
from vdtn_marl.experiment.compose import to_run_config
from vdtn_marl.experiment.evaluate import evaluation_scenarios
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.policies import make_control_baseline
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.voi import mean_ci

HERE = Path(__file__).resolve().parent


def follower_returns(loop: JointOptimisation, policy) -> torch.Tensor:
    scenarios = evaluation_scenarios(loop.cfg, loop.eval_traces, loop.device)
    with torch.random.fork_rng(devices=[]):
        result = evaluate_system(loop.params, policy, None, perfect=True, **scenarios)
    return result.follower_returns.double()  # [E, F]


def score_seed(cells: Path, scenario: str, seed: int) -> dict:
    run_dir = cells / scenario / "pi_star" / f"seed{seed}"
    saved = json.loads((run_dir / "summary.json").read_text())
    data = yaml.safe_load((run_dir / "config.yaml").read_text())  # the run's composed config
    cfg = to_run_config({**data, "device": "cpu", "progress": False}, "train")
    with tempfile.TemporaryDirectory() as tmp:
        loop = JointOptimisation(cfg, tmp, task="control")
        checkpoint = load_checkpoint(run_dir / "checkpoints" / "last.pt")
        loop.pi_star.load_state_dict(checkpoint["trainers"]["pi_star"])
        policies = {
            "pi_star": ActorPolicy(loop.pi_star.actor, "vehicle"),
            "causal_mpc": make_control_baseline("causal_mpc", loop.params),
            "cacc": CACCController(loop.params.platoon),
        }
        returns = {name: follower_returns(loop, p) for name, p in policies.items()}
    star = returns["pi_star"]
    row = {
        "scenario": scenario,
        "seed": seed,
        "summary_pi_star_minus_causal_mpc": saved["pi_star_minus_causal_mpc"],
        "recomputed_pi_star_minus_causal_mpc": float((star - returns["causal_mpc"]).mean()),
        "followers": [],
    }
    for f in range(star.shape[1]):
        entry = {"follower": f + 1}
        for name in ("causal_mpc", "cacc"):
            mean, low, high = mean_ci(star[:, f] - returns[name][:, f])
            entry[f"pi_star_minus_{name}"] = [mean, low, high]
        entry.update({f"J_{k}": float(v[:, f].mean()) for k, v in returns.items()})
        row["followers"].append(entry)
    return row


def plot(paths: list[Path], out: Path) -> None:
    """J* − J_MPC per follower, one panel per results file, one line per seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(paths), figsize=(5.5 * len(paths), 4), squeeze=False)
    for ax, path in zip(axes[0], paths, strict=True):
        rows = json.loads(path.read_text())["rows"]
        for i, row in enumerate(rows):
            f = [e["follower"] + 0.06 * (i - len(rows) / 2) for e in row["followers"]]
            mean, low, high = zip(
                *(e["pi_star_minus_causal_mpc"] for e in row["followers"]), strict=True
            )
            yerr = [
                [m - lo for m, lo in zip(mean, low, strict=True)],
                [hi - m for m, hi in zip(mean, high, strict=True)],
            ]
            ax.errorbar(f, mean, yerr=yerr, marker="o", capsize=3, label=f"seed {row['seed']}")
        ax.set_xticks([e["follower"] for e in rows[0]["followers"]])
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_title(f"{rows[0]['scenario']}: π* − causal MPC, perfect observations")
        ax.set_xlabel("follower (1 = behind the leader)")
        ax.set_ylabel("J* − J_MPC, discounted return (mean, t 95 %)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=Path)
    ap.add_argument("--scenario", default="platoon4")
    ap.add_argument("--seeds", type=int, nargs="+", default=[7, 8, 0, 1])
    ap.add_argument("--out", type=Path, default=HERE / "results.json")
    ap.add_argument("--plot", type=Path, nargs="+", help="only plot these results files")
    args = ap.parse_args()
    if args.plot:
        plot(args.plot, HERE / "followers.png")
        return
    if args.cells is None:
        ap.error("--cells DIR is required (a headline 2.1 cells folder with π* checkpoints)")
    rows = []
    for seed in args.seeds:
        row = score_seed(args.cells, args.scenario, seed)
        rows.append(row)
        print(
            f"{args.scenario} seed {seed}: J* − J_MPC per follower "
            + "  ".join(
                f"{e['follower']}: {e['pi_star_minus_causal_mpc'][0]:+.3f} "
                f"[{e['pi_star_minus_causal_mpc'][1]:+.3f}, "
                f"{e['pi_star_minus_causal_mpc'][2]:+.3f}]"
                for e in row["followers"]
            )
            + f"  (mean {row['recomputed_pi_star_minus_causal_mpc']:+.3f}, "
            f"summary {row['summary_pi_star_minus_causal_mpc']:+.3f})",
            flush=True,
        )
    atomic_write_json(args.out, {"command": "python " + " ".join(sys.argv), "rows": rows})


if __name__ == "__main__":
    main()
