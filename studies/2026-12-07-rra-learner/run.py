"""Can the learned RRA reach the opportunistic witness? A paired look at the RRA learner's
options on platoon4, one JOCC iteration at `reduced`'s budgets (π* and π̃ 8 PPO iterations,
the RRA agents 16). π̃ trains under random RRA in iteration 0 for the learned-RRA arms (the
same π* and π̃ for those arms of a seed), under the baseline itself for `opportunistic`.

Arms (each `vdtn-marl jocc` with the overrides below beside the common ones):

- `opportunistic`: the hand-made baseline (no RRA learning): the witness;
- `drra`: the delay-aware learned RRA;
- `jocc_fixed`: JOCC, κ1 = 0.5, the paper's fixed term scales, from scratch (today's default);
- `jocc_fixed_ws`: as `jocc_fixed`, warm-started by imitating the opportunistic baseline, its
  best policy kept by validation every 4 PPO iterations;
- `jocc_ws_long`: as `jocc_fixed_ws`, with RRA batches that start after K ~ U{0..150}
  intervals (`algo.rra_burn_in_intervals=150`) and GAE λ = 0.999 per subframe
  (`algo.rra_lmbda`, a λ-horizon of about 20 intervals instead of 20 subframes): the
  optimiser's horizon the objective study (2026-12-07-rra-objective) points at.

    python studies/2026-12-07-rra-learner/run.py --seeds 0 1 2

Writes `runs/<arm>/seed<s>/` and `results.json`: per seed the evaluation's CAM delivery,
V2I per link, |gap| and |speed| errors, and for each arm its paired-by-seed difference from
`drra` and from `opportunistic` with Student-t 95 % intervals.
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
COMMON = [
    "experiment.name=reduced", "experiment.control_iterations=8", "experiment.rra_iterations=16",
    "experiment.checkpoint_every=0", "experiment.jocc_iterations=1", "scenario=platoon4",
]  # fmt: skip
WARM = ["rra.warm_start=opportunistic", "rra.validate_every=4"]
ARMS = {
    "opportunistic": ["rra=opportunistic", "control=learned"],
    "drra": ["rra=drra", "control=learned"],
    "jocc_fixed": ["rra=jocc", "rra.kappa1=0.5", "control=learned"],
    "jocc_fixed_ws": ["rra=jocc", "rra.kappa1=0.5", "control=learned", *WARM],
    "jocc_ws_long": [
        "rra=jocc", "rra.kappa1=0.5", "control=learned", *WARM,
        "algo.rra_burn_in_intervals=150", "algo.rra_lmbda=0.999",
    ],
}  # fmt: skip
KEYS = (
    "cam_delivery_rate", "v2i_throughput_mbps_per_link", "gap_error_abs_m",
    "speed_error_abs_mps", "control_cost",
)  # fmt: skip


def run(arm: str, seed: int, out: Path) -> dict:
    run_dir = out / "runs" / arm / f"seed{seed}"
    summary = run_dir / "summary.json"
    if summary.is_file():
        return json.loads(summary.read_text())
    exe = Path(sys.executable).with_name("vdtn-marl")
    argv = [
        str(exe), "jocc", f"seed={seed}", "progress=false", f"hydra.run.dir={run_dir}",
        f"warm_start_cache={out / 'warm_starts'}", *COMMON, *ARMS[arm],
    ]  # fmt: skip
    began = time.perf_counter()
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    done = subprocess.run(argv, capture_output=True, text=True, env=env)
    if done.returncode:  # recorded, and the other arms go on
        error = done.stderr.strip().splitlines()[-1] if done.stderr.strip() else "failed"
        print(f"{arm} seed {seed} failed: {error}", flush=True)
        return {"failed": error}
    print(f"{arm} seed {seed}: {time.perf_counter() - began:.0f} s", flush=True)
    return json.loads(summary.read_text())


def t_interval(values: list[float]) -> list[float]:
    from scipy import stats

    n = len(values)
    mean = sum(values) / n
    if n < 2:
        return [mean, math.nan, math.nan]
    sd = math.sqrt(sum((v - mean) ** 2 for v in values) / (n - 1))
    half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return [mean, mean - half, mean + half]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--arms", nargs="+", default=list(ARMS), choices=list(ARMS))
    p.add_argument("--out", type=Path, default=HERE)
    args = p.parse_args(argv)
    from vdtn_marl.io.files import atomic_write_json

    began = time.perf_counter()
    per_seed: dict[str, dict[int, dict]] = {arm: {} for arm in args.arms}
    for seed in args.seeds:  # seed by seed, so that a partial run is already paired
        for arm in args.arms:
            summary = run(arm, seed, args.out)
            if "failed" in summary:
                per_seed[arm][seed] = {"failed": summary["failed"]}
                continue
            per_seed[arm][seed] = {k: summary.get(k) for k in (*KEYS, "reference_ok")}
            per_seed[arm][seed]["term_scales"] = summary.get("term_scales")
            per_seed[arm][seed]["rra_selected"] = summary.get("selected_iterations", {}).get("rra")
    ok = {arm: [s for s in args.seeds if "failed" not in per_seed[arm][s]] for arm in args.arms}
    paired = {}
    for reference in ("drra", "opportunistic"):
        if reference not in args.arms:
            continue
        for arm in args.arms:
            if arm == reference:
                continue
            both = [s for s in ok[arm] if s in ok[reference]]
            if not both:
                continue
            paired[f"{arm} - {reference}"] = {
                k: t_interval([per_seed[arm][s][k] - per_seed[reference][s][k] for s in both])
                for k in KEYS
            }
    means = {arm: {k: t_interval([per_seed[arm][s][k] for s in ok[arm]]) for k in KEYS}
             for arm in args.arms if ok[arm]}  # fmt: skip
    result = {
        "command": " ".join(["run.py", *(argv if argv is not None else sys.argv[1:])]),
        "date": dt.date.today().isoformat(),
        "load_average": os.getloadavg(),
        "seconds": time.perf_counter() - began,
        "common_overrides": COMMON,
        "arms": ARMS,
        "seeds": args.seeds,
        "per_seed": per_seed,
        "mean_t95": means,
        "paired_by_seed_t95": paired,
    }
    atomic_write_json(args.out / "results.json", result)
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"platoon4, 1 JOCC iteration, seeds {args.seeds} (mean [t95])")
    for column in ("arm", *KEYS):
        table.add_column(column)
    for arm in means:
        table.add_row(arm, *(f"{m:.4g} [{lo:.3g}, {hi:.3g}]" for m, lo, hi in means[arm].values()))
    Console(width=200).print(table)
    for name, diffs in paired.items():
        print(name, {k: [round(x, 4) for x in v] for k, v in diffs.items()})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
