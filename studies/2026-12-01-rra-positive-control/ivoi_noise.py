"""IVoI noise tolerance: can the RRA learner pick up a VoI reward of ξ's size and noise?

A positive control for JOCC's RRA stage. The RRA agents are trained exactly as in JOCC, by
default with κ1 = 0 (the VoI term only; ``--kappa1`` adds the V2I throughput term back), but
ξ is replaced by a synthetic IVoI whose value is known:

    ξ_i = effect · 1[follower i's CAM was delivered within its interval] + noise · N(0, 1),

so with κ1 = 0 the only thing that pays is CAM delivery. ``--effect`` defaults to what
``studies/2026-12-01-jocc-v1-diagnosis/ivoi_signal.py`` measured for the ``td`` estimator under
random RRA (0.035 per interval, unscaled), ``--noise`` to multiples of ξ's per-interval standard
deviation there
(≈ 0.1 without the intervals that end in a collision, ≈ 1.3 with them). With no noise the
learner should deliver far more CAMs than random RRA (≈ 16 %); the noise at which it stops
doing so is how much noise a useful IVoI estimator may carry at this budget. Budgets are
those of the ``reduced`` leaderboard (8 PPO iterations for π* and π̃, 16 for the RRA agents);
the evaluation is JOCC's (16 held-out scenarios × 10 s).

``--credit`` compares RRA learning problems paired by seed (:data:`CREDITS`). Writes
``ivoi_noise.json`` beside this file, atomically. The committed JSON:

    # the v1 positive control (studies/2026-12-01-rra-positive-control/README.md)
    python studies/2026-12-01-rra-positive-control/ivoi_noise.py --seeds 0,1,2 --noise 0 \
        --credit paper,paper_long_gae,legacy \
        --traces udds --output studies/2026-12-01-rra-positive-control/ivoi_positive_control.json
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import torch
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RRAConfig,
    RunConfig,
    ScenarioConfig,
    validate,
)
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.reporting.benchmarking import parse_numbers, parse_seeds, provenance
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord

RESULTS = Path(__file__).parent / "ivoi_noise.json"


class SyntheticIVoI:
    """ξ [B, F] = ``effect`` where follower i's CAM (link i) arrived within its interval, else
    0, plus ``noise`` · N(0, 1) from its own seeded generator (reward units)."""

    def __init__(self, effect: float, noise: float, seed: int):
        if noise < 0:
            raise ValueError(f"noise={noise!r} must be >= 0")
        self.effect = float(effect)
        self.noise = float(noise)
        self.generator = torch.Generator().manual_seed(seed)
        self.calls = 0

    def __call__(self, twin: DigitalTwin, record: IntervalRecord) -> torch.Tensor:
        self.calls += 1
        delay = record.cam_delay_subframes
        delivered = (delay <= twin.subframes_per_interval).float()
        noise = torch.randn(delivered.shape, generator=self.generator).to(delivered.device)
        return self.effect * delivered + self.noise * noise


#: ``--credit`` settings of the RRA learning problem: ``paper`` is the default (γ = 0.99 per
#: control interval, GAE λ = 0.95 per subframe, silent subframes masked, scenarios persisting
#: across PPO iterations, 32 scenarios × 5 intervals per batch); ``paper_long_gae`` the same
#: with λ = 0.95 per interval (λ^(1/T) per subframe: the sampled return, not the critic, carries
#: the later intervals' credit); ``legacy`` the setting before them (γ = 0.99 per subframe,
#: every subframe trains, fresh resets, 64 scenarios × 2 intervals).
CREDITS = {
    "paper": {},
    "paper_long_gae": dict(rra_lmbda=0.95 ** (1 / 50)),
    "legacy": dict(
        rra_credit="subframe", rra_mask_silent=False, persistent_envs=False,
        rra_num_envs=64, rra_rollout_steps=100,
    ),
}  # fmt: skip


def reduced_config(
    seed: int,
    kappa1: float = 0.0,
    traces: str = "synthetic",
    credit: str = "paper",
    rra_iterations: int = 16,
) -> RunConfig:
    """JOCC with ``kappa1`` (κ2 = 1 − κ1) at the ``reduced`` leaderboard budgets (platoon4
    defaults, leader traces ``traces``; π* from the CACC prior: the synthetic ξ does not read
    it), with the RRA learning problem of ``credit`` (:data:`CREDITS`)."""
    experiment = replace(
        ExperimentConfig(),
        control_iterations=8,
        rra_iterations=rra_iterations,
        checkpoint_every=0,
    )
    return RunConfig(
        scenario=ScenarioConfig(traces=traces),
        rra=RRAConfig(name="jocc", kappa1=kappa1),
        control=ControlConfig(warm_start="none"),
        algo=replace(AlgoConfig(), **CREDITS[credit]),
        experiment=experiment,
        seed=seed,
        progress=False,
    )


def train_with_synthetic_ivoi(cfg: RunConfig, effect: float, noise: float) -> dict:
    """Run one JOCC iteration of ``cfg`` with ξ replaced by :class:`SyntheticIVoI`; returns
    the run's summary and how often the synthetic IVoI was called."""
    cfg = validate(cfg)
    if cfg.rra.name != "jocc" or cfg.rra.kappa2_value == 0.0:
        raise ValueError("the synthetic IVoI enters the RRA reward only with rra=jocc, κ2 > 0")
    with tempfile.TemporaryDirectory(prefix="ivoi_noise_") as run_dir:
        loop = JointOptimisation(cfg, run_dir)
        synthetic = SyntheticIVoI(effect, noise, seed=cfg.seed)
        loop.rra.env.ivoi_estimator = synthetic  # the RRA agents' reward; evaluation keeps td
        summary = loop.run()
    return {**summary, "synthetic_ivoi_calls": synthetic.calls}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", default="0,1", help="run seeds (one run per seed × noise)")
    parser.add_argument("--noise", default="0,0.03,0.1,0.3", help="std devs of ξ's noise")
    parser.add_argument("--effect", type=float, default=0.035, help="ξ of a delivered CAM")
    parser.add_argument(
        "--kappa1", type=float, default=0.0, help="weight of V2I throughput, in [0, 1)"
    )
    parser.add_argument(
        "--traces",
        default="synthetic",
        help="leader trace set (default synthetic, with which the committed figures were "
        "measured; runs default to udds)",
    )
    parser.add_argument(
        "--credit",
        default="paper",
        help=f"RRA learning problems to compare, paired by seed: {', '.join(CREDITS)}",
    )
    parser.add_argument("--rra-iterations", type=int, default=16, help="RRA PPO iterations")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    credits = args.credit.split(",")
    for credit in credits:
        if credit not in CREDITS:
            raise SystemExit(f"--credit {credit!r} must be one of {', '.join(CREDITS)}")
    if args.rra_iterations < 1:
        raise SystemExit(f"--rra-iterations {args.rra_iterations!r} must be >= 1")
    seeds = parse_seeds("--seeds", args.seeds)
    noises = parse_numbers("--noise", args.noise)
    if not 0.0 <= args.kappa1 < 1.0:
        raise SystemExit(f"--kappa1 {args.kappa1!r} must be in [0, 1) (κ2 = 1 − κ1 > 0)")
    torch.set_num_threads(1)
    console = Console()
    began = time.perf_counter()
    rows = []
    for credit in credits:
        for noise in noises:
            for seed in seeds:
                start = time.perf_counter()
                cfg = reduced_config(seed, args.kappa1, args.traces, credit, args.rra_iterations)
                summary = train_with_synthetic_ivoi(cfg, args.effect, noise)
                rows.append(
                    {
                        "credit": credit,
                        "noise": noise,
                        "seed": seed,
                        "cam_delivery_rate": summary["cam_delivery_rate"],
                        "v2i_throughput_mbps_per_link": summary["v2i_throughput_mbps_per_link"],
                        "control_cost": summary["control_cost"],
                        "seconds": time.perf_counter() - start,
                    }
                )
                console.print(
                    f"{credit}, noise {noise:g}, seed {seed}: "
                    f"CAM delivery {summary['cam_delivery_rate']:.3f}"
                )
    title = f"RRA trained on ξ = {args.effect:g}·1[delivered] + noise·N(0,1), κ1 = {args.kappa1:g}"
    table = Table(title=escape(title))
    columns = ("credit", "noise", "seed", "CAM delivery", "V2I per link (Mbps)", "control cost")
    for column in columns:
        table.add_column(column, justify="right")
    for row in rows:
        table.add_row(
            row["credit"],
            f"{row['noise']:g}",
            str(row["seed"]),
            f"{row['cam_delivery_rate']:.3f}",
            f"{row['v2i_throughput_mbps_per_link']:.3f}",
            f"{row['control_cost']:.4f}",
        )
    console.print(table)
    atomic_write_json(
        args.output,
        {
            **provenance("ivoi_noise"),
            "effect": args.effect,
            "kappa1": args.kappa1,
            "traces": args.traces,
            "credits": {c: CREDITS[c] for c in credits},
            "budget": f"8 PPO iterations for π* and π̃, {args.rra_iterations} for the RRA agents",
            "seconds": time.perf_counter() - began,
            "rows": rows,
        },
    )
    console.print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
