"""DRRA trained 3× longer: does the V2I margin of `headline` 2.1's `jocc_k050_ws` over DRRA
survive DRRA at its plateau?

`headline` 2.1's DRRA cells still improve their reward at the benchmark's budget (3 JOCC
iterations × 16 RRA PPO iterations; `../2026-12-07-rra-curves-headline-2.1/`). This study runs
DRRA on platoon4 with 48 RRA PPO iterations per JOCC iteration (`drra_long`, everything else
as the benchmark's `drra` cells, the same shared π* per seed), as a submission to the
benchmark, so that its cells use the same held-out scenarios and seeds:

    OMP_NUM_THREADS=1 vdtn-marl bench benchmark=headline out_dir=OUT \\
        '+submissions.drra_long=["rra=drra","control=learned","experiment.jocc_iterations=3","experiment.rra_iterations=48"]' \\
        'cells=["platoon4/drra_long/*"]' shard=K num_shards=2 report=false

where OUT holds the benchmark's cells and their shared π* checkpoints (the π* runs of
`benchmarks/results/cells/headline-v2.1/`, retrained by `cells='[*/pi_star/*]'` where their
checkpoints are missing). Then

    python studies/2026-12-07-drra-at-its-plateau/run.py OUT

copies the `drra_long` records (summary, config, metrics, evaluation) into `runs/` here and
compares them, paired by seed, with the committed `drra` and `jocc_k050_ws` cells: per metric
the mean over the seeds both have and the paired difference with its 95 % Student-t interval;
and the RRA reward's change between the last two JOCC iterations (the plateau measure of the
curves study). Writes `results.json`; without OUT it reads `runs/` alone.
"""

from __future__ import annotations

import csv
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
METRICS = (
    "v2i_throughput_mbps_per_link",
    "cam_delivery_rate",
    "gap_error_abs_m",
    "speed_error_abs_mps",
    "control_cost",
)


def _t(values) -> dict:
    x = np.asarray(values, dtype=float)
    n, mean = len(x), float(np.mean(x))
    half = float(stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n)) if n > 1 else math.nan
    return {"n": n, "mean": mean, "ci_low": mean - half, "ci_high": mean + half}


def _summary(run: Path) -> dict:
    return json.loads((run / "summary.json").read_text(encoding="utf-8"))


def _rra_plateau(run: Path) -> float:
    with (run / "metrics.csv").open(newline="", encoding="utf-8") as f:
        rra = [r for r in csv.DictReader(f) if r["stage"] == "rra"]
    it = np.array([int(r["jocc_iteration"]) for r in rra])
    reward = np.array([float(r["reward_mean"]) for r in rra])
    return float(reward[it == it.max()].mean() - reward[it == it.max() - 1].mean())


def main(argv: list[str]) -> None:
    if argv:
        source = Path(argv[0]) / "platoon4" / "drra_long"
        for run in sorted(source.glob("seed*")):
            if (run / "summary.json").is_file():
                (RUNS / run.name).mkdir(parents=True, exist_ok=True)
                for name in FILES:
                    shutil.copy2(run / name, RUNS / run.name / name)
    seeds = sorted(int(p.name[4:]) for p in RUNS.glob("seed*"))
    assert seeds, f"no drra_long runs in {RUNS}"
    arms = {
        "drra_long": {s: _summary(RUNS / f"seed{s}") for s in seeds},
        "drra": {s: _summary(CELLS / "drra" / f"seed{s}") for s in seeds},
        "jocc_k050_ws": {s: _summary(CELLS / "jocc_k050_ws" / f"seed{s}") for s in seeds},
    }
    out: dict = {"seeds": seeds, "means": {}, "paired": {}}
    for arm, runs in arms.items():
        out["means"][arm] = {m: _t([runs[s][m] for s in seeds]) for m in METRICS}
    for a, b in (("drra_long", "drra"), ("jocc_k050_ws", "drra_long"), ("jocc_k050_ws", "drra")):
        out["paired"][f"{a} - {b}"] = {
            m: _t([arms[a][s][m] - arms[b][s][m] for s in seeds]) for m in METRICS
        }
    out["rra_reward_last_minus_previous_jocc_iteration"] = {
        "drra_long": _t([_rra_plateau(RUNS / f"seed{s}") for s in seeds]),
        "drra": _t([_rra_plateau(CELLS / "drra" / f"seed{s}") for s in seeds]),
    }
    tmp = HERE / "results.json.tmp"
    tmp.write_text(json.dumps(out, indent=1), encoding="utf-8")
    tmp.replace(HERE / "results.json")
    print(f"platoon4, seeds {seeds}")
    for arm, m in out["means"].items():
        print(f"  {arm:13s} " + "  ".join(f"{k} {v['mean']:.4f}" for k, v in m.items()))
    for pair, m in out["paired"].items():
        print(f"  {pair}:")
        for k, v in m.items():
            print(f"    {k:30s} {v['mean']:+.4f} [{v['ci_low']:+.4f}, {v['ci_high']:+.4f}]")
    for arm, v in out["rra_reward_last_minus_previous_jocc_iteration"].items():
        print(f"  RRA reward, last − previous JOCC iteration, {arm}: {v['mean']:+.4f} "
              f"[{v['ci_low']:+.4f}, {v['ci_high']:+.4f}]")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
