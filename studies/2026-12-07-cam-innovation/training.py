"""Does the learned RRA use the CAM innovation? `headline` 2.1's two JOCC methods, trained again
with ``rra.cam_innovation=true``, paired by seed with their committed cells.

The arms are submissions to the benchmark, so their cells use the same held-out scenarios,
seeds, budgets and shared π* per seed as the committed ones, and differ only in the RRA
observation (two more inputs, so also in the RRA network's initial weights):

    OMP_NUM_THREADS=1 vdtn-marl bench benchmark=headline out_dir=OUT \\
        '+submissions.jocc_k050_innov=["rra=jocc","rra.kappa1=0.5","control=learned","experiment.jocc_iterations=3","experiment.rra_iterations=16","rra.cam_innovation=true"]' \\
        '+submissions.jocc_k050_ws_innov=["rra=jocc","rra.kappa1=0.5","rra.warm_start=opportunistic","rra.validate_every=4","control=learned","experiment.jocc_iterations=3","experiment.rra_iterations=16","rra.cam_innovation=true"]' \\
        'cells=["platoon4/jocc_k050_innov/*","platoon4/jocc_k050_ws_innov/*"]' \\
        shard=K num_shards=2 report=false

where OUT holds the benchmark's cells and their shared π* checkpoints (the π* runs of
`benchmarks/results/cells/headline-v2.1/`, retrained by `cells='[*/pi_star/*]'` where their
checkpoints are missing). Then

    python studies/2026-12-07-cam-innovation/training.py OUT

copies the two arms' records (summary, config, metrics, evaluation) into `runs/` here and
compares each, paired by seed, with the committed cell of the same method without the feature
and with DRRA: per metric the mean over the seeds and the paired difference with its 95 %
Student-t interval. Writes `training.json`; without OUT it reads `runs/` alone.
"""

from __future__ import annotations

import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np
from scipy import stats

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CELLS = ROOT / "benchmarks/results/cells/headline-v2.1/platoon4"
RUNS = HERE / "runs"
FILES = ("summary.json", "config.yaml", "metrics.csv", "evaluation.csv")
ARMS = {"jocc_k050_innov": "jocc_k050", "jocc_k050_ws_innov": "jocc_k050_ws"}
METRICS = (
    "cam_delivery_rate",
    "v2i_throughput_mbps_per_link",
    "gap_error_abs_m",
    "speed_error_abs_mps",
    "control_cost",
    "ivoi_mean",
)


def _t(values) -> dict:
    x = np.asarray(values, dtype=float)
    n, mean = len(x), float(np.mean(x))
    half = float(stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    return {"n": n, "mean": mean, "ci_low": mean - half, "ci_high": mean + half}


def _summary(run: Path) -> dict:
    return json.loads((run / "summary.json").read_text(encoding="utf-8"))


def main(argv: list[str]) -> None:
    if argv:
        for arm in ARMS:
            for run in sorted((Path(argv[0]) / "platoon4" / arm).glob("seed*")):
                if (run / "summary.json").is_file():
                    (RUNS / arm / run.name).mkdir(parents=True, exist_ok=True)
                    for name in FILES:
                        shutil.copy2(run / name, RUNS / arm / run.name / name)
    out: dict = {"scenario": "platoon4", "arms": {}}
    for arm, base in ARMS.items():
        seeds = sorted(int(p.name[4:]) for p in (RUNS / arm).glob("seed*"))
        if not seeds:
            print(f"{arm}: no runs in {RUNS / arm}")
            continue
        runs = {
            arm: {s: _summary(RUNS / arm / f"seed{s}") for s in seeds},
            base: {s: _summary(CELLS / base / f"seed{s}") for s in seeds},
            "drra": {s: _summary(CELLS / "drra" / f"seed{s}") for s in seeds},
        }
        for name, by_seed in runs.items():
            assert all(r["cam_delivery_rate"] is not None for r in by_seed.values()), name
        result = {
            "seeds": seeds,
            "means": {
                k: {m: _t([v[s][m] for s in seeds]) for m in METRICS} for k, v in runs.items()
            },
            "paired": {
                f"{a} - {b}": {
                    m: _t([runs[a][s][m] - runs[b][s][m] for s in seeds]) for m in METRICS
                }
                for a, b in ((arm, base), (arm, "drra"))
            },
        }
        out["arms"][arm] = result
        print(f"{arm} (seeds {seeds})")
        for name, means in result["means"].items():
            print(f"  {name:20s} " + "  ".join(f"{k} {v['mean']:.4f}" for k, v in means.items()))
        for pair, diffs in result["paired"].items():
            print(f"  {pair}:")
            for k, v in diffs.items():
                print(f"    {k:30s} {v['mean']:+.4f} [{v['ci_low']:+.4f}, {v['ci_high']:+.4f}]")
    tmp = HERE / "training.json.tmp"
    tmp.write_text(json.dumps(out, indent=1), encoding="utf-8")
    tmp.replace(HERE / "training.json")


if __name__ == "__main__":
    main(sys.argv[1:])
