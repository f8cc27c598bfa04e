"""π* as a reference: does fitting its critic before PPO and keeping its best policy by
validation make it at least as good as its start, the causal MPC and the CACC?

Paired by seed: for each seed, `vdtn-marl train task=control` (π* alone: its warm start by
imitation of the causal MPC, then `experiment.control_iterations` PPO iterations, then the
evaluation with the reference check) in each arm, sharing the warm start through
`warm_start_cache` (the arms differ only after it):

- `last_iterate`: control.pi_star_critic_warmup=0 control.pi_star_validate_every=0 (π* keeps
  PPO's last iterate, its critic untrained at the first update: the behaviour before
  2026-12-07);
- `critic_warmup`: control.pi_star_critic_warmup=10 control.pi_star_validate_every=0;
- `warmup_and_selection`: control.pi_star_critic_warmup=10 control.pi_star_validate_every=10
  (the default).

    python studies/2026-12-07-pi-star-reference/run.py --seeds 0 1 2 3 4 [--arms ...]

Writes `runs/<arm>/seed<s>/` (the runs: summary.json, metrics.csv) and `results.json`
(per-seed differences J* − J_c with their scenario intervals, paired arm differences with
Student-t intervals over seeds) and `learning_curves.png` (π*'s training reward and validation
return per PPO iteration, mean over seeds).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ARMS = {
    "last_iterate": ["control.pi_star_critic_warmup=0", "control.pi_star_validate_every=0"],
    "critic_warmup": ["control.pi_star_critic_warmup=10", "control.pi_star_validate_every=0"],
    "warmup_and_selection": [
        "control.pi_star_critic_warmup=10", "control.pi_star_validate_every=10",
    ],
}  # fmt: skip
KEYS = (
    "pi_star_minus_start", "pi_star_minus_causal_mpc", "pi_star_minus_cacc", "control_cost",
    "control_return", "gap_error_abs_m",
)  # fmt: skip


def run(arm: str, seed: int, out: Path, extra: list[str]) -> dict:
    run_dir = out / "runs" / arm / f"seed{seed}"
    summary = run_dir / "summary.json"
    if summary.is_file():
        return json.loads(summary.read_text())
    exe = Path(sys.executable).with_name("vdtn-marl")
    argv = [
        str(exe), "train", "task=control", f"seed={seed}", "progress=false",
        f"hydra.run.dir={run_dir}", f"warm_start_cache={out / 'warm_starts'}", *ARMS[arm], *extra,
    ]  # fmt: skip
    began = time.perf_counter()
    subprocess.run(
        argv, check=True, capture_output=True, env={**os.environ, "OMP_NUM_THREADS": "1"}
    )
    print(f"{arm} seed {seed}: {time.perf_counter() - began:.0f} s", flush=True)
    return json.loads(summary.read_text())


def t_interval(values: list[float]) -> tuple[float, float, float]:
    from scipy import stats

    n = len(values)
    mean = sum(values) / n
    if n < 2:
        return mean, math.nan, math.nan
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    half = stats.t.ppf(0.975, n - 1) * sd / math.sqrt(n)
    return mean, mean - half, mean + half


def curves(out: Path, arms: list[str], seeds: list[int]) -> Path:
    import csv

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for arm in arms:
        rewards, validations = {}, {}
        for seed in seeds:
            path = out / "runs" / arm / f"seed{seed}" / "metrics.csv"
            with open(path, newline="") as handle:
                for row in csv.DictReader(handle):
                    if row["stage"] != "control_perfect":
                        continue
                    k = int(row["iteration"])
                    rewards.setdefault(k, []).append(float(row["reward_mean"]))
                    v = float(row.get("validation_return") or "nan")
                    if math.isfinite(v):
                        validations.setdefault(k, []).append(v)
        ks = sorted(rewards)
        axes[0].plot(ks, [sum(rewards[k]) / len(rewards[k]) for k in ks], label=arm)
        ks = sorted(validations)
        if ks:
            axes[1].plot(
                ks, [sum(validations[k]) / len(validations[k]) for k in ks], "o-", label=arm
            )
    axes[0].set(xlabel="π* PPO iteration", ylabel="training reward per follower and interval",
                title="π* training reward (mean over seeds)")  # fmt: skip
    axes[1].set(xlabel="π* PPO iteration", ylabel="deterministic validation return",
                title="π* validation (arms that validate)")  # fmt: skip
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    path = out / "learning_curves.png"
    fig.savefig(path, dpi=110)
    return path


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p.add_argument("--arms", nargs="+", default=list(ARMS), choices=list(ARMS))
    p.add_argument("--out", type=Path, default=HERE)
    p.add_argument("overrides", nargs="*", help="more overrides for every run")
    args = p.parse_args(argv)
    from vdtn_marl.io.files import atomic_write_json

    began = time.perf_counter()
    summaries = {arm: {s: run(arm, s, args.out, args.overrides) for s in args.seeds}
                 for arm in args.arms}  # fmt: skip
    per_seed = {arm: {s: {k: summaries[arm][s].get(k) for k in KEYS + ("reference_ok",)}
                      for s in args.seeds} for arm in args.arms}  # fmt: skip
    by_arm = {
        arm: {k: t_interval([per_seed[arm][s][k] for s in args.seeds]) for k in KEYS}
        for arm in args.arms
    }
    fails = {
        arm: sum(not per_seed[arm][s]["reference_ok"] for s in args.seeds) for arm in args.arms
    }
    paired = {}
    base = args.arms[0]
    for arm in args.arms[1:]:
        paired[f"{arm} - {base}"] = {
            k: t_interval([per_seed[arm][s][k] - per_seed[base][s][k] for s in args.seeds])
            for k in ("control_return", "control_cost", "pi_star_minus_start")
        }
    plot = curves(args.out, args.arms, args.seeds)
    result = {
        "command": " ".join([Path(sys.argv[0]).name, *(argv or sys.argv[1:])]),
        "date": dt.date.today().isoformat(),
        "load_average": os.getloadavg(),
        "seconds": time.perf_counter() - began,
        "arms": ARMS,
        "seeds": args.seeds,
        "per_seed": per_seed,
        "by_arm_mean_t95": by_arm,
        "reference_failures": fails,
        "paired_by_seed_t95": paired,
        "plot": plot.name,
    }
    atomic_write_json(args.out / "results.json", result)
    for arm in args.arms:
        cells = ", ".join(
            f"{k} {m:+.4g} [{lo:+.3g}, {hi:+.3g}]" for k, (m, lo, hi) in by_arm[arm].items()
        )
        print(f"{arm}: reference fails {fails[arm]}/{len(args.seeds)}; {cells}")
    for name, diffs in paired.items():
        print(name, {k: tuple(round(x, 5) for x in v) for k, v in diffs.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
