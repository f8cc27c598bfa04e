"""π* trained to its plateau: where does PPO's validation return stop rising, from which start,
and is the π* it keeps at least as good as its start, the causal MPC and the CACC?

For each case (scenario, seed) and arm, `vdtn-marl train task=control` with the budgets of the
`headline` benchmark's cells (`experiment.name=reduced`, held-out evaluation 16 × 200
intervals) but 300 π* PPO iterations, validation every 10 (the best kept, the start a
candidate), no early stop, so that the whole learning curve is seen:

- `mpc_start`: π* imitates the causal MPC first (control.warm_start=causal_mpc, the default);
- `mpc_start_lr1e-4`: the same with algo.lr=1e-4 (3e-4 is the default);
- `cacc_start`: π* starts from the CACC prior (control.warm_start=none);
- `cacc_start_lr1e-4`: the same with algo.lr=1e-4.

The cases are the (scenario, seed) pairs whose π* failed the reference check in the
`headline` 2.0 cells (platoon4 seeds 3 and 8; platoon8 seeds 0 and 1).

    python studies/2026-12-07-pi-star-plateau/run.py [--arms ...] [--cases platoon4:3 ...]
    python studies/2026-12-07-pi-star-plateau/run.py --runs ARM:SCENARIO:SEED ...

(`--runs` runs only the listed ones instead of every arm on every case.)

Writes `runs/<arm>/<scenario>-seed<k>/` (the runs) and `results.json` (per run: the kept
iteration, the best validation return and where it was reached, the reference check's J* − J_c
with their scenario intervals, the control cost) and `learning_curves.png` (validation
return per PPO iteration, one panel per case).
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
COMMON = [
    "experiment.name=reduced", "experiment.control_iterations=300",
    "experiment.checkpoint_every=0", "control=learned", "progress=false",
]  # fmt: skip
ARMS = {
    "mpc_start": [],
    "mpc_start_lr1e-4": ["algo.lr=0.0001"],
    "cacc_start": ["control.warm_start=none"],
    "cacc_start_lr1e-4": ["control.warm_start=none", "algo.lr=0.0001"],
}
CASES = ("platoon4:3", "platoon4:8", "platoon8:0", "platoon8:1")
KEYS = ("pi_star_minus_start", "pi_star_minus_causal_mpc", "pi_star_minus_cacc")


def run(arm: str, scenario: str, seed: int, out: Path) -> dict:
    run_dir = out / "runs" / arm / f"{scenario}-seed{seed}"
    summary = run_dir / "summary.json"
    if summary.is_file():
        return json.loads(summary.read_text())
    exe = Path(sys.executable).with_name("vdtn-marl")
    argv = [
        str(exe), "train", "task=control", f"scenario={scenario}", f"seed={seed}", *COMMON,
        f"hydra.run.dir={run_dir}", f"warm_start_cache={out / 'warm_starts'}", *ARMS[arm],
    ]  # fmt: skip
    began = time.perf_counter()
    subprocess.run(
        argv, check=True, capture_output=True, env={**os.environ, "OMP_NUM_THREADS": "1"}
    )
    print(f"{arm} {scenario} seed {seed}: {time.perf_counter() - began:.0f} s", flush=True)
    return json.loads(summary.read_text())


def validation_curve(run_dir: Path) -> list[tuple[int, float]]:
    with open(run_dir / "metrics.csv", newline="") as handle:
        rows = [r for r in csv.DictReader(handle) if r["stage"] == "control_perfect"]
    curve = [(int(r["iteration"]), float(r["validation_return"] or "nan")) for r in rows]
    return [(k, v) for k, v in curve if math.isfinite(v)]


def plot(out: Path, arms: list[str], cases: list[tuple[str, int]]) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(cases), figsize=(4.2 * len(cases), 3.8), squeeze=False)
    for ax, (scenario, seed) in zip(axes[0], cases, strict=True):
        for arm in arms:
            run_dir = out / "runs" / arm / f"{scenario}-seed{seed}"
            if (run_dir / "metrics.csv").is_file():
                ks, vs = zip(*validation_curve(run_dir), strict=True)
                ax.plot(ks, vs, ".-", label=arm, color=f"C{list(ARMS).index(arm)}")
        ax.set(title=f"{scenario}, seed {seed}", xlabel="π* PPO iteration",
               ylabel="validation return (per follower, interval)")  # fmt: skip
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "learning_curves.png"
    fig.savefig(path, dpi=110)
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--arms", nargs="+", default=list(ARMS), choices=list(ARMS))
    p.add_argument("--cases", nargs="+", default=list(CASES), help="scenario:seed")
    p.add_argument("--runs", nargs="+", default=None, help="arm:scenario:seed")
    p.add_argument("--out", type=Path, default=HERE)
    args = p.parse_args(argv)
    from vdtn_marl.io.files import atomic_write_json

    if args.runs:
        todo = [(r.split(":")[0], r.split(":")[1], int(r.split(":")[2])) for r in args.runs]
    else:
        cases = [(c.split(":")[0], int(c.split(":")[1])) for c in args.cases]
        todo = [(arm, scenario, seed) for scenario, seed in cases for arm in args.arms]
    arms = list(dict.fromkeys(arm for arm, _, _ in todo))
    cases = list(dict.fromkeys((scenario, seed) for _, scenario, seed in todo))
    began = time.perf_counter()
    runs = []
    for arm, scenario, seed in todo:
        s = run(arm, scenario, seed, args.out)
        curve = validation_curve(args.out / "runs" / arm / f"{scenario}-seed{seed}")
        best_k, best_v = max(curve, key=lambda kv: kv[1])
        runs.append({
            "arm": arm, "scenario": scenario, "seed": seed,
            "kept_iteration": s["selected_iterations"].get("control_perfect"),
            "best_validation": best_v, "best_validation_at": best_k,
            "validation_at_end": curve[-1][1],
            "control_cost": s["control_cost"], "cacc_control_cost": s["cacc_control_cost"],
            "reference_ok": s["reference_ok"], "reference_problems": s["reference_problems"],
            **{f"{k}{x}": s[f"{k}{x}"] for k in KEYS for x in ("", "_ci_low", "_ci_high")},
        })  # fmt: skip
    path = plot(args.out, arms, cases)
    result = {
        "command": " ".join([Path(sys.argv[0]).name, *(argv or sys.argv[1:])]),
        "date": dt.date.today().isoformat(),
        "load_average": os.getloadavg(),
        "seconds": time.perf_counter() - began,
        "common_overrides": COMMON,
        "arms": ARMS,
        "runs": runs,
        "plot": path.name,
    }
    atomic_write_json(args.out / "results.json", result)
    for r in runs:
        print(
            f"{r['scenario']} s{r['seed']} {r['arm']:<18} kept {r['kept_iteration']:>4} "
            f"best val {r['best_validation']:.4f}@{r['best_validation_at']} cost "
            f"{r['control_cost']:.4f} mpc {r['pi_star_minus_causal_mpc']:+.3f} "
            f"[{r['pi_star_minus_causal_mpc_ci_low']:+.3f}, "
            f"{r['pi_star_minus_causal_mpc_ci_high']:+.3f}] ok {r['reference_ok']}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
