"""IVoI signal: does the VoI reward that JOCC gives the RRA agents favour CAM delivery?

JOCC's RRA agent of link i earns κ2·s_ξ·ξ_i at the end of each control interval, ξ_i the IVoI
of follower i (docs/model.md §5). That term can only teach an RRA agent to deliver CAMs if ξ is
higher, in expectation, on the intervals whose CAM was delivered than on those whose CAM was
lost. This script measures it for trained JOCC runs.

For every checkpoint (a run's ``checkpoints/last.pt``; its config comes from the checkpoint)
it loads π*, π̃ (or the run's control baseline) and, if the run learned one, the RRA policy,
then evaluates the acting system on the run's held-out scenarios (the evaluation seed of the
run) under each RRA policy of ``--rra`` (``learned`` is the run's own RRA policy) with each
IVoI estimator of ``--estimators``: ``td`` (π*'s critic), ``rollout`` (as the run configured
it: ``rra.rollout_intervals`` intervals of π*, 10 by default, then with
``rra.rollout_bootstrap`` the critic), ``rollout:H`` (H intervals, then the critic; ``rollout:1``
is the actual command's TD error minus π*'s own, both over the same trace) or ``rollout:H:mc``
(H intervals and no critic: for large H the critic-free reference); a ``:lost`` suffix
(``rollout:1:lost``, ``rollout:100:mc:lost``) compares the actual command with the one a lost
CAM would have led to instead of with π*'s (the ``cam_lost`` baseline: exactly 0 where the CAM
was not in time, so its delivered − lost is the immediate value of the delivery). Reported per
checkpoint × RRA policy × estimator:

- CAM delivery rate, collision rate (fraction of scenarios), control cost;
- EVoI = J̃ − J* (discounted control return per follower, paired by scenario) and the IVoI
  sum Σ_k γ^k ξ_k of the same evaluation, each with its 95% CI over scenarios; the VoI
  identity says they agree in expectation for the true advantage of π*, so a gap between
  them is the estimator's bias (a critic trained for a few iterations, a truncated rollout);
- mean ξ over the follower-intervals whose CAM was delivered within its interval and over
  those whose CAM was not, and the difference delivered − lost, paired by scenario (the
  scenarios with both), each with its 95% CI over scenarios, and the standard deviation of ξ
  over all follower-intervals (the noise the RRA agents learn against). ξ is unscaled
  (reward units of the control reward; the RRA reward multiplies it by κ2·s_ξ).

Only under ``random`` RRA is a CAM's delivery independent of the platoon's state, so only
there is delivered − lost the effect of delivery on ξ. Under a learned policy it also
reflects where the policy delivers (one that delivers when the platoon is in trouble shows a
lower ξ on delivered CAMs even if delivery helps).

``--clip C`` clips every ξ to [−C, C]; with C well below the collision penalty (100) it shows
how much of a difference and of ξ's spread comes from the intervals that end in a collision.
``--reward weight_jerk=0`` (repeatable; ``weight_speed``, ``weight_accel``, ``weight_jerk``,
``collision_penalty``) evaluates the same policies with other control-reward weights, so that
returns, EVoI and ξ leave that term out: it shows which term of the reward a difference comes
from. Writes ``ivoi_signal.json`` beside this file, atomically. Example:

    python studies/2026-12-01-jocc-v1-diagnosis/ivoi_signal.py \\
        outputs/jocc/RUN/checkpoints/last.pt
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

import torch
from rich.console import Console
from rich.table import Table

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.ppo import ActorPolicy
from vdtn_marl.experiment.api import loaded_checkpoints
from vdtn_marl.experiment.config import IVOI_ESTIMATORS
from vdtn_marl.experiment.evaluate import EVAL_SEED_OFFSET
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.policies import RRA_BASELINES, make_rra_baseline
from vdtn_marl.reporting.benchmarking import (
    checkpoint_run,
    ci_summary,
    parse_names,
    provenance,
    table_console,
)
from vdtn_marl.scenarios import scenario_params
from vdtn_marl.sim.params import ConfigError, TwinParams
from vdtn_marl.voi import expected_voi

RESULTS = Path(__file__).parent / "ivoi_signal.json"
LEARNED = "learned"
#: control-reward parameters ``--reward`` may change (docs/model.md §2)
REWARD_KEYS = ("weight_speed", "weight_accel", "weight_jerk", "collision_penalty")


def _reward_overrides(items: list[str]) -> dict[str, float]:
    overrides = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or key not in REWARD_KEYS:
            raise SystemExit(f"--reward {item!r}: expected KEY=VALUE, KEY one of {REWARD_KEYS}")
        try:
            overrides[key] = float(value)
        except ValueError:
            raise SystemExit(f"--reward {item!r}: {value!r} is not a number") from None
    return overrides


def parse_estimators(text: str) -> list[str]:
    """Estimator specs (see the module doc) from ``"td,rollout:100:mc,rollout:1:lost"``."""
    specs = [part.strip() for part in text.split(",") if part.strip()]
    usage = (
        f"--estimators {text!r} must list some of {', '.join(IVOI_ESTIMATORS)}, "
        "rollout:H, rollout:H:mc, rollout:H:lost or rollout:H:mc:lost (H an integer >= 1)"
    )
    if not specs:
        raise SystemExit(usage)
    for spec in specs:
        name, *rest = spec.split(":")
        if name not in IVOI_ESTIMATORS or (rest and name != "rollout"):
            raise SystemExit(usage)
        if rest and (
            not rest[0].isdigit()
            or int(rest[0]) < 1
            or rest[1:] not in ([], ["mc"], ["lost"], ["mc", "lost"])
        ):
            raise SystemExit(usage)
    return specs


def make_estimator(loop: JointOptimisation, spec: str, clip: float | None = None):
    """The IVoI estimator of a spec accepted by :func:`parse_estimators`; with ``clip`` its ξ
    is clipped to [−clip, clip]."""
    name, *rest = spec.split(":")
    if not rest:
        estimator = loop.ivoi_estimator(name)
    else:
        estimator = loop.ivoi_estimator(
            name,
            rollout_intervals=int(rest[0]),
            bootstrap="mc" not in rest[1:],
            baseline="cam_lost" if "lost" in rest[1:] else "optimal",
        )
    return estimator if clip is None else ClippedIVoI(estimator, clip)


class ClippedIVoI:
    """ξ of ``estimator`` clipped to [−clip, clip] (``--clip``): with a clip well below the
    collision penalty the intervals that end in a collision no longer dominate ξ's mean and
    spread."""

    def __init__(self, estimator, clip: float):
        self.estimator = estimator
        self.clip = clip

    @property
    def needs_command_if_lost(self) -> bool:
        return getattr(self.estimator, "needs_command_if_lost", False)

    def __call__(self, twin, record) -> torch.Tensor:
        return self.estimator(twin, record).clamp(-self.clip, self.clip)


def measure(
    loop: JointOptimisation,
    rra_names: list[str],
    estimators: list[str],
    episodes: int,
    params: TwinParams | None = None,
    clip: float | None = None,
) -> list[dict]:
    """One row per RRA policy × estimator for the loaded run (see the module doc); ``params``
    replaces the run's model parameters (e.g. other reward weights), ``clip`` clips ξ."""
    cfg = loop.cfg
    params = params or loop.params
    common = dict(
        episodes=episodes, intervals=cfg.experiment.eval_intervals,
        seed=EVAL_SEED_OFFSET + cfg.seed, gamma=loop.gamma, device=loop.device,
        trace_source=loop.eval_traces,
    )  # fmt: skip
    optimal = evaluate_system(
        params, ActorPolicy(loop.pi_star.actor, "vehicle"), None, perfect=True, **common
    )
    rows = []
    for rra_name in rra_names:
        if rra_name == LEARNED and not cfg.rra.learned:
            continue  # a run with a fixed RRA policy has no learned one
        for estimator in estimators:
            began = time.perf_counter()
            # a fresh policy per evaluation: the random one replays the same draws
            rra_policy = (
                loop.rra_policy()
                if rra_name == LEARNED
                else make_rra_baseline(rra_name, params, cfg.seed)
            )
            acting = evaluate_system(
                params,
                loop.control_policy(),
                rra_policy,
                perfect=False,
                ivoi_estimator=make_estimator(loop, estimator, clip),
                completion=loop.completion,
                **common,
            )
            evoi, low, high = expected_voi(acting.returns, optimal.returns)
            m = acting.metrics
            rows.append(
                {
                    "rra": f"{cfg.rra.name} ({LEARNED})" if rra_name == LEARNED else rra_name,
                    "estimator": estimator,
                    "cam_delivery_rate": m["cam_delivery_rate"],
                    "collision_rate": m["collision_rate"],
                    "control_cost": m["control_cost"],
                    "evoi": {"mean": evoi, "low": low, "high": high, "n": episodes},
                    "ivoi_sum": ci_summary(acting.ivoi_sums.double()),
                    "ivoi_delivered": ci_summary(acting.ivoi_delivered),
                    "ivoi_lost": ci_summary(acting.ivoi_lost),
                    "ivoi_delivered_minus_lost": ci_summary(
                        acting.ivoi_delivered - acting.ivoi_lost
                    ),
                    "ivoi_std": m["ivoi_std"],
                    "seconds": time.perf_counter() - began,
                }
            )
    return rows


def _fmt(stat: dict) -> str:
    if stat["n"] == 0:
        return "-"
    if stat["n"] == 1:
        return f"{stat['mean']:+.3g}"
    return f"{stat['mean']:+.3g} [{stat['low']:+.3g}, {stat['high']:+.3g}]"


def print_table(runs: list[dict], console: Console) -> None:
    table = Table(title="IVoI signal (ξ unscaled; 95% CIs over scenarios)")
    for column in (
        "run", "RRA", "estimator", "CAM delivery", "collisions", "EVoI", "Σγᵏξ",
        "ξ | delivered", "ξ | lost", "delivered − lost", "sd(ξ)",
    ):  # fmt: skip
        table.add_column(column, justify="left" if column in ("run", "RRA") else "right")
    for run in runs:
        for row in run["rows"]:
            table.add_row(
                f"{run['scenario']} seed {run['seed']}",
                row["rra"],
                row["estimator"],
                f"{row['cam_delivery_rate']:.3f}",
                f"{row['collision_rate']:.3f}",
                _fmt(row["evoi"]),
                _fmt(row["ivoi_sum"]),
                _fmt(row["ivoi_delivered"]),
                _fmt(row["ivoi_lost"]),
                _fmt(row["ivoi_delivered_minus_lost"]),
                f"{row['ivoi_std']:.3g}",
            )
    console.print(table)


def summarise(runs: list[dict]) -> list[dict]:
    """Per run kind (scenario, RRA reward) × RRA policy × estimator, over the runs (seeds):
    the mean of each figure, and how many runs' delivered − lost CI lies above / below 0."""
    groups: dict[tuple, list[dict]] = {}
    for run in runs:
        for row in run["rows"]:
            key = (run["scenario"], run["rra_reward"], row["rra"], row["estimator"])
            groups.setdefault(key, []).append(row)
    summary = []
    for (scenario, reward, rra, estimator), rows in groups.items():
        diffs = [r["ivoi_delivered_minus_lost"] for r in rows]
        diffs = [d for d in diffs if d["n"]]
        summary.append(
            {
                "scenario": scenario,
                "rra_reward": reward,
                "rra": rra,
                "estimator": estimator,
                "runs": len(rows),
                **{
                    key: _finite_mean(_value(r[key]) for r in rows)
                    for key in (
                        "cam_delivery_rate",
                        "collision_rate",
                        "evoi",
                        "ivoi_sum",
                        "ivoi_delivered",
                        "ivoi_lost",
                        "ivoi_std",
                    )  # fmt: skip
                },
                "ivoi_delivered_minus_lost": (
                    statistics.fmean(d["mean"] for d in diffs) if diffs else float("nan")
                ),
                "runs_delivered_above_lost": sum(d["n"] > 1 and d["low"] > 0 for d in diffs),
                "runs_delivered_below_lost": sum(d["n"] > 1 and d["high"] < 0 for d in diffs),
            }
        )
    return summary


def _finite_mean(values) -> float:
    """Mean of the finite values (NaN if none: e.g. ξ | lost where no run lost a CAM)."""
    finite = [v for v in values if math.isfinite(v)]
    return statistics.fmean(finite) if finite else float("nan")


def _value(figure) -> float:
    return figure["mean"] if isinstance(figure, dict) else figure


def print_summary(summary: list[dict], console: Console) -> None:
    title = "IVoI signal, mean over runs (runs whose delivered − lost CI is above / below 0)"
    table = Table(title=title)
    for column in (
        "runs of", "RRA", "estimator", "runs", "CAM delivery", "collisions", "EVoI", "Σγᵏξ",
        "ξ | delivered", "ξ | lost", "delivered − lost", "above / below 0", "sd(ξ)",
    ):  # fmt: skip
        table.add_column(column, justify="left" if column in ("runs of", "RRA") else "right")
    for row in summary:
        table.add_row(
            f"{row['scenario']} {row['rra_reward']}",
            row["rra"],
            row["estimator"],
            str(row["runs"]),
            f"{row['cam_delivery_rate']:.3f}",
            f"{row['collision_rate']:.3f}",
            f"{row['evoi']:+.3g}",
            f"{row['ivoi_sum']:+.3g}",
            f"{row['ivoi_delivered']:+.3g}",
            f"{row['ivoi_lost']:+.3g}",
            f"{row['ivoi_delivered_minus_lost']:+.3g}",
            f"{row['runs_delivered_above_lost']} / {row['runs_delivered_below_lost']}",
            f"{row['ivoi_std']:.3g}",
        )
    console.print(table)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoints", nargs="+", type=Path, help="JOCC checkpoints (.pt)")
    parser.add_argument(
        "--rra",
        default=",".join((LEARNED, "greedy", "random")),
        help=f"RRA policies, from {LEARNED}, {', '.join(RRA_BASELINES)}",
    )
    parser.add_argument(
        "--estimators",
        default="td,rollout",
        help=f"IVoI estimators: {', '.join(IVOI_ESTIMATORS)}, rollout:H[:mc][:lost]",
    )
    parser.add_argument(
        "--episodes", type=int, default=64, help="held-out scenarios per evaluation (>= 2)"
    )
    parser.add_argument(
        "--reward",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help=f"evaluate with another control-reward weight ({', '.join(REWARD_KEYS)})",
    )
    parser.add_argument(
        "--clip", type=float, default=None, help="clip ξ to [-CLIP, CLIP] (CLIP > 0)"
    )
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (0: default)")
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    rra_names = parse_names("--rra", args.rra, (LEARNED, *RRA_BASELINES))
    estimators = parse_estimators(args.estimators)
    reward = _reward_overrides(args.reward)
    if args.clip is not None and not args.clip > 0:
        raise SystemExit(f"--clip {args.clip!r} must be > 0")
    if args.episodes < 2:
        raise SystemExit(f"--episodes {args.episodes} must be >= 2 (confidence intervals)")
    if args.threads:
        torch.set_num_threads(args.threads)
    console = table_console(file_width=240)
    began = time.perf_counter()
    runs = []
    for path, loop in loaded_checkpoints(args.checkpoints, "ivoi_signal_", console):
        try:
            params = scenario_params(**loop.cfg.scenario.model_kwargs(), **reward)
        except ConfigError as err:
            raise SystemExit(f"--reward: {err}") from err
        runs.append(
            {
                **checkpoint_run(path, loop.cfg),
                "ivoi_scale": loop.cfg.rra.ivoi_scale,
                "rows": measure(loop, rra_names, estimators, args.episodes, params, args.clip),
            }
        )
    if reward:
        console.print(f"evaluated with control-reward overrides {reward}")
    if args.clip is not None:
        console.print(f"ξ clipped to [−{args.clip:g}, {args.clip:g}]")
    print_table(runs, console)
    summary = summarise(runs)
    print_summary(summary, console)
    atomic_write_json(
        args.output,
        {
            **provenance("ivoi_signal"),
            "episodes": args.episodes,
            "reward_overrides": reward,
            "clip": args.clip,
            "seconds": time.perf_counter() - began,
            "summary": summary,
            "runs": runs,
        },
    )
    console.print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
