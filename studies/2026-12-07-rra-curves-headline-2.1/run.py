"""The RRA agents' learning curves in `headline` 2.1: do they reach a plateau within the
benchmark's budget (3 JOCC iterations × 16 RRA PPO iterations), from which start?

Reads the committed records of the benchmark's cells (`metrics.csv`, `evaluation.csv` and
`summary.json` of each cell under `benchmarks/results/cells/headline-v2.1/`); trains nothing.
For each scenario and learned-RRA method (`jocc_k050_ws`: warm-started by imitating the
opportunistic RRA; `jocc_k050`: the paper's reading, from scratch; `drra`) and each RRA PPO
iteration: the mean over the 10 seeds, with its 95 % Student-t interval, of the training reward
(`reward_mean`, the RRA reward per subframe of the iteration's own rollouts) and, where the
method validates (`rra.validate_every=4`), of the deterministic validation return; and per JOCC
iteration the held-out evaluation (CAM delivery, V2I per link, |gap error|).

Also the paired change of the validation return from its first to its last point (seeds
paired). Plateau measure, per seed: the last 16 RRA iterations' training reward (JOCC iteration 2)
minus the 16 before them (JOCC iteration 1), paired by seed over the 10 seeds (t interval).
An interval that holds 0 means no change is detectable between the last two JOCC iterations.

    python studies/2026-12-07-rra-curves-headline-2.1/run.py

Writes `results.json` and `curves.png` beside this script.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
CELLS = ROOT / "benchmarks/results/cells/headline-v2.1"
SCENARIOS = ("platoon4", "platoon8")
METHODS = ("jocc_k050_ws", "jocc_k050", "drra")
SEEDS = range(10)
EVAL_KEYS = ("cam_delivery_rate", "v2i_throughput_mbps_per_link", "gap_error_abs_m")


def _t_interval(values) -> dict:
    x = np.asarray([v for v in values if not math.isnan(v)], dtype=float)
    n = len(x)
    mean = float(x.mean()) if n else math.nan
    if n < 2:
        return {"n": n, "mean": mean, "ci_low": math.nan, "ci_high": math.nan}
    half = float(stats.t.ppf(0.975, n - 1) * x.std(ddof=1) / math.sqrt(n))
    return {"n": n, "mean": mean, "ci_low": mean - half, "ci_high": mean + half}


def _rows(path: Path) -> list[dict]:
    with path.open(newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def _cell(scenario: str, method: str, seed: int) -> dict:
    run = CELLS / scenario / method / f"seed{seed}"
    rra = [r for r in _rows(run / "metrics.csv") if r["stage"] == "rra"]
    summary = json.loads((run / "summary.json").read_text(encoding="utf-8"))
    return {
        "reward": [float(r["reward_mean"]) for r in rra],
        "validation": [float(r["validation_return"] or "nan") for r in rra],
        "jocc_iteration": [int(r["jocc_iteration"]) for r in rra],
        "evaluation": _rows(run / "evaluation.csv"),
        "selected": (summary.get("selected_iterations") or {}).get("rra"),
    }


def main() -> None:
    results: dict = {"cells": str(CELLS.relative_to(ROOT)), "scenarios": {}}
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), squeeze=False)
    for row, scenario in enumerate(SCENARIOS):
        out = results["scenarios"][scenario] = {}
        for method in METHODS:
            cells = [_cell(scenario, method, s) for s in SEEDS]
            iters = len(cells[0]["reward"])
            assert all(len(c["reward"]) == iters for c in cells), (scenario, method)
            reward = [_t_interval([c["reward"][i] for c in cells]) for i in range(iters)]
            val = [_t_interval([c["validation"][i] for c in cells]) for i in range(iters)]
            by_jocc = np.array(cells[0]["jocc_iteration"])  # the same in every seed
            last, prev = by_jocc == by_jocc.max(), by_jocc == by_jocc.max() - 1
            change = _t_interval(
                [np.mean(np.array(c["reward"])[last]) - np.mean(np.array(c["reward"])[prev])
                 for c in cells]
            )  # fmt: skip
            vidx = [i for i in range(iters) if not math.isnan(cells[0]["validation"][i])]
            val_change = (
                _t_interval([c["validation"][vidx[-1]] - c["validation"][vidx[0]] for c in cells])
                if vidx
                else None
            )
            evaluation = {
                key: [
                    _t_interval([float(c["evaluation"][j][key]) for c in cells])
                    for j in range(len(cells[0]["evaluation"]))
                ]
                for key in EVAL_KEYS
            }
            out[method] = {
                "rra_iterations": iters,
                "training_reward": reward,
                "validation_return": [v for v in val if v["n"]],
                "validation_iterations": [i for i, v in enumerate(val) if v["n"]],
                "last_minus_previous_jocc_iteration_reward": change,
                "validation_last_minus_first": val_change,
                "selected_rra_iteration": [c["selected"] for c in cells],
                "evaluation_per_jocc_iteration": evaluation,
            }
            x = np.arange(iters)
            m = np.array([r["mean"] for r in reward])
            lo = np.array([r["ci_low"] for r in reward])
            hi = np.array([r["ci_high"] for r in reward])
            (line,) = axes[row][0].plot(x, m, label=method)
            axes[row][0].fill_between(x, lo, hi, alpha=0.2, color=line.get_color())
            vi = out[method]["validation_iterations"]
            if vi:
                vm = np.array([v["mean"] for v in out[method]["validation_return"]])
                vlo = np.array([v["ci_low"] for v in out[method]["validation_return"]])
                vhi = np.array([v["ci_high"] for v in out[method]["validation_return"]])
                axes[row][1].errorbar(vi, vm, yerr=[vm - vlo, vhi - vm], marker="o",
                                      capsize=3, label=method, color=line.get_color())  # fmt: skip
        for col, title in enumerate(("training reward per subframe", "validation return")):
            ax = axes[row][col]
            ax.set_title(f"{scenario}: RRA {title} (mean, 95% t CI, 10 seeds)", fontsize=9)
            ax.set_xlabel("RRA PPO iteration (16 per JOCC iteration)")
            for b in (16, 32):
                ax.axvline(b - 0.5, color="grey", lw=0.5, ls=":")
            ax.legend(fontsize=8)
            ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(HERE / "curves.png", dpi=110)
    tmp = HERE / "results.json.tmp"
    tmp.write_text(json.dumps(results, indent=1, allow_nan=True), encoding="utf-8")
    tmp.replace(HERE / "results.json")
    for scenario in SCENARIOS:
        print(scenario)
        for method, r in results["scenarios"][scenario].items():
            c = r["last_minus_previous_jocc_iteration_reward"]
            first, final = r["training_reward"][1]["mean"], r["training_reward"][-1]["mean"]
            ev = r["evaluation_per_jocc_iteration"]
            print(
                f"  {method:13s} reward it1 {first:+.4f} last {final:+.4f}; last−previous JOCC "
                f"iteration {c['mean']:+.4f} [{c['ci_low']:+.4f}, {c['ci_high']:+.4f}]; "
                "delivery per JOCC iteration "
                + ", ".join(f"{e['mean']:.3f}" for e in ev["cam_delivery_rate"])
                + "; V2I "
                + ", ".join(f"{e['mean']:.3f}" for e in ev["v2i_throughput_mbps_per_link"])
            )
            if r["validation_last_minus_first"]:
                v = r["validation_last_minus_first"]
                print(
                    f"    validation last − first {v['mean']:+.5f} [{v['ci_low']:+.5f}, "
                    f"{v['ci_high']:+.5f}]"
                )


if __name__ == "__main__":
    main()
