"""IVoI estimator error on the states the acting system visits (the seed's open problem).

JOCC pays the RRA agents the ``td`` IVoI, ξ = R + γ·v*(S′) − v*(S) with π*'s critic v*. Its
expectation is π*'s advantage A*(S, ũ) only where v* is accurate, and v* is trained on the
states π* visits under perfect observation, not on the states π̃ drives the platoon into under
impaired observation. This script measures the td estimator's error there.

For every checkpoint (a run's ``checkpoints/last.pt``; its config from the checkpoint) it runs
the acting system (π̃ or the run's control baseline on impaired observations, the run's CAM
completion) under each RRA policy of ``--rra`` (``learned``: the run's own) on the run's
held-out evaluation scenarios, and at every interval computes, on the same twin and interval
record, ξ of ``td`` and of a reference estimator (``--reference``, default ``rollout:100:mc``:
100 intervals of π* in the twin from the perfect state, no critic, γ as the run's; the
Monte-Carlo advantage of π* on the known trace). Per follower-interval it records both, and
reports: the reference's mean and standard deviation, the td estimator's bias (mean of
td − reference), RMSE, the Pearson correlation, and the share of the reference's variance the
td estimate explains (1 − MSE/Var); the same split by whether the CAM arrived within its
interval; and intervals that end in a collision counted apart (their penalty dominates both).
A correlation near 0 or a negative explained share says v* is poor on these states, and the
RRA agents learn against noise.

Writes ``studies/2026-12-01-jocc-v1-diagnosis/ivoi_estimator_error.json`` atomically. Example:

    python studies/2026-12-01-jocc-v1-diagnosis/ivoi_estimator_error.py \
        outputs/evidence/RUN/checkpoints/last.pt \\
        --rra learned,random --episodes 8
"""

from __future__ import annotations

import argparse
import importlib.util
import math
import time
from pathlib import Path

import torch
from rich.console import Console
from rich.table import Table

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.ppo import CriticValue
from vdtn_marl.experiment.api import loaded_checkpoints
from vdtn_marl.experiment.evaluate import EVAL_SEED_OFFSET
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.policies import RRA_BASELINES, make_rra_baseline
from vdtn_marl.reporting.benchmarking import (
    checkpoint_run,
    parse_names,
    provenance,
)
from vdtn_marl.voi import TDIVoIEstimator

RESULTS = Path(__file__).parent / "ivoi_estimator_error.json"
LEARNED = "learned"


def _ivoi_signal():
    """studies/2026-12-01-jocc-v1-diagnosis/ivoi_signal.py (estimator specs are parsed and built the
    same way)."""
    spec = importlib.util.spec_from_file_location(
        "ivoi_signal", Path(__file__).with_name("ivoi_signal.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class PairedIVoI:
    """Pays ``estimate``'s ξ and records it beside ``reference``'s on the same interval, with
    whether each follower's CAM arrived in time and whether the interval ended in a
    collision."""

    def __init__(self, estimate, reference):
        self.estimate = estimate
        self.reference = reference
        self.rows: list[torch.Tensor] = []  # [B·F, 4]: estimate, reference, delivered, collided

    @property
    def needs_command_if_lost(self) -> bool:
        return any(
            getattr(e, "needs_command_if_lost", False) for e in (self.estimate, self.reference)
        )

    def __call__(self, twin, record) -> torch.Tensor:
        xi = self.estimate(twin, record)
        ref = self.reference(twin, record)
        delivered = (record.cam_delay_subframes <= twin.subframes_per_interval).float()
        collided = record.collided.any(-1, keepdim=True).expand_as(xi).float()
        self.rows.append(
            torch.stack([xi.double(), ref.double(), delivered.double(), collided.double()], -1)
            .reshape(-1, 4)
            .cpu()
        )
        return xi


def error_stats(estimate: torch.Tensor, reference: torch.Tensor) -> dict:
    """Bias, RMSE, correlation and explained share of ``estimate`` against ``reference``."""
    n = int(estimate.numel())
    if n < 2:
        return {"n": n}
    error = estimate - reference
    var = float(reference.var())
    mse = float((error**2).mean())
    corr = torch.corrcoef(torch.stack([estimate, reference]))[0, 1]
    return {
        "n": n,
        "reference_mean": float(reference.mean()),
        "reference_std": math.sqrt(var),
        "estimate_mean": float(estimate.mean()),
        "estimate_std": float(estimate.std()),
        "bias": float(error.mean()),
        "rmse": math.sqrt(mse),
        "correlation": float(corr) if torch.isfinite(corr) else float("nan"),
        "explained": 1.0 - mse / var if var > 0 else float("nan"),
    }


def summarise(rows: torch.Tensor) -> dict:
    """Error statistics over all follower-intervals without a collision, split by delivery,
    and the collision intervals apart."""
    estimate, reference, delivered, collided = rows.unbind(-1)
    calm = collided == 0
    out = {"all": error_stats(estimate[calm], reference[calm])}
    for name, mask in (("delivered", delivered == 1), ("lost", delivered == 0)):
        out[name] = error_stats(estimate[calm & mask], reference[calm & mask])
    out["collision_intervals"] = error_stats(estimate[~calm], reference[~calm])
    return out


#: --td-value: whose v* the td estimator reads: the run's (its fitted copy with
#: rra.value_fit=acting, else π*'s critic) or π*'s critic itself
TD_VALUES = ("run", "pi_star")


def td_estimator(loop: JointOptimisation, td_value: str):
    if td_value == "pi_star":
        return TDIVoIEstimator(CriticValue(loop.pi_star.critic, "vehicle"), loop.gamma)
    return _ivoi_signal().make_estimator(loop, "td")


def measure(
    loop: JointOptimisation, rra: str, reference: str, episodes: int, td_value: str = "run"
) -> dict:
    signal = _ivoi_signal()
    cfg = loop.cfg
    rra_policy = (
        loop.rra_policy() if rra == LEARNED else make_rra_baseline(rra, loop.params, cfg.seed)
    )
    paired = PairedIVoI(td_estimator(loop, td_value), signal.make_estimator(loop, reference))
    began = time.perf_counter()
    acting = evaluate_system(
        loop.params, loop.control_policy(), rra_policy, perfect=False,
        episodes=episodes, intervals=cfg.experiment.eval_intervals,
        seed=EVAL_SEED_OFFSET + cfg.seed, gamma=loop.gamma, device=loop.device,
        trace_source=loop.eval_traces, ivoi_estimator=paired, completion=loop.completion,
    )  # fmt: skip
    fitted = td_value == "run" and loop.v_fit is not None
    return {
        "rra": f"{cfg.rra.name} ({LEARNED})" if rra == LEARNED else rra,
        "td_value": "fitted on the acting system's states" if fitted else "π*'s critic",
        "cam_delivery_rate": acting.metrics["cam_delivery_rate"],
        "collision_rate": acting.metrics["collision_rate"],
        **summarise(torch.cat(paired.rows)),
        "seconds": time.perf_counter() - began,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoints", nargs="+", type=Path, help="runs' checkpoints/last.pt")
    parser.add_argument("--rra", default="learned,random", help="RRA policies (learned: the run's)")
    parser.add_argument("--reference", default="rollout:100:mc", help="reference estimator spec")
    parser.add_argument("--episodes", type=int, default=8, help="held-out scenarios per run")
    parser.add_argument(
        "--td-value", default="run",
        help="whose v* td reads, comma-separated: run (the run's: fitted with "
        "rra.value_fit=acting), pi_star (π*'s critic)",
    )  # fmt: skip
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    td_values = parse_names("--td-value", args.td_value, TD_VALUES)
    if args.episodes < 1:
        raise SystemExit(f"--episodes {args.episodes!r} must be >= 1")
    signal = _ivoi_signal()
    (reference,) = signal.parse_estimators(args.reference)
    rras = parse_names("--rra", args.rra, (LEARNED, *RRA_BASELINES))
    torch.set_num_threads(1)
    console = Console()
    began = time.perf_counter()
    runs = []
    for path, loop in loaded_checkpoints(args.checkpoints, "ivoi_estimator_error_"):
        rows = [
            measure(loop, rra, reference, args.episodes, td_value)
            for td_value in td_values
            for rra in rras
        ]
        runs.append({**checkpoint_run(path, loop.cfg), "rows": rows})
    table = Table(title=f"td IVoI against {reference} on the acting system's states")
    for column in ("run", "RRA", "v*", "n", "ref std", "bias", "RMSE", "corr", "explained"):
        table.add_column(column, justify="right")
    for run in runs:
        for row in run["rows"]:
            s = row["all"]
            table.add_row(
                Path(run["checkpoint"]).parent.parent.name, row["rra"], row["td_value"],
                str(s.get("n", 0)),
                *(f"{s.get(k, float('nan')):.4f}" for k in
                  ("reference_std", "bias", "rmse", "correlation", "explained")),
            )  # fmt: skip
    console.print(table)
    atomic_write_json(
        args.output,
        {
            **provenance("ivoi_estimator_error"),
            "reference": reference,
            "episodes": args.episodes,
            "seconds": time.perf_counter() - began,
            "runs": runs,
        },
    )
    console.print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
