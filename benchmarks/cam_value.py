"""CAM value: what one delivered CAM is worth to the acting system, and what IVoI credits it with.

JOCC's RRA agent of link i is paid κ2·ξ_i at the end of the interval in which it (maybe)
delivered follower i's CAM. This script measures, with common random numbers, how much that
delivery is actually worth and how much of it ξ at that interval credits.

For every checkpoint (a run's ``checkpoints/last.pt``; config from the checkpoint) it runs the
acting system (π̃ or the run's control baseline on impaired observations, the run's CAM
completion, the RRA policy of ``--rra``) on the run's held-out scenarios (``--episodes``, the
run's evaluation seed). At every start interval k of ``--starts``, after the interval's
subframes, it copies the twin twice (``copy.deepcopy``: platoon, channel, random state, RRA
and completion state), picks in every scenario one follower at random among those whose CAM of
interval k arrived in time for the decision, and in the second copy drops that CAM
(:meth:`~vdtn_marl.sim.twin.DigitalTwin.drop_cams`). Both copies then run on for
``--horizon`` intervals with the same channel draws and the same RRA draws (a learned or greedy
RRA policy sees the same observations until the platoons' CAM content diverges). Per dropped
CAM:

- **value**: the platoon's discounted control return (sum over followers, γ per interval from
  interval k; a collision ends a copy's episode, as in the environment) of the copy that kept
  the CAM minus that of the copy that lost it;
- **td credit**: ξ_i at interval k from the ``td`` estimator (π*'s critic) in the first copy
  minus that in the second: the part of the value that the RRA agent of link i is paid for
  at the interval of the delivery;
- **one-step credit**: the ``cam_lost`` baseline of
  :class:`~vdtn_marl.voi.RolloutIVoIEstimator` (one interval, then π*'s critic), computed
  in the first copy alone, as an environment can; it should match the td credit up to what
  the other followers do in that interval.

Reported per checkpoint: the number of CAMs, each mean with its 95% CI over CAMs, the
Pearson correlation between value and td credit, and how persistent delivery is in the acting
run (the fraction of CAMs in time, and that fraction right after a CAM of the same link that
was in time and right after one that was not): a comparison of intervals whose CAM was
delivered with intervals whose CAM was lost compares such runs, not single deliveries. The
value is what an RRA agent would have to learn from; if the credit at the delivery interval is
near zero or negative while the value is positive, the value shows up only in later
intervals' ξ, after the RRA agent's discount has shrunk it.
Writes ``benchmarks/results/cam_value.json`` atomically. Example (the committed JSON):

    python benchmarks/cam_value.py \\
        outputs/bench/reduced-v2.1/platoon4/jocc_k050/seed{0,1,2,3,4}/checkpoints/last.pt
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path

import torch
from rich.console import Console
from rich.progress import track
from rich.table import Table

from vdtn_marl.algos.baselines import RRA_BASELINES, make_rra_baseline
from vdtn_marl.algos.evaluate import bind_to_twin
from vdtn_marl.algos.jocc import EVAL_SEED_OFFSET, JointOptimisation
from vdtn_marl.benchmarking import (
    checkpoint_run,
    ci_summary,
    loaded_checkpoints,
    provenance,
    table_console,
)
from vdtn_marl.results import pyplot_agg, save_figure
from vdtn_marl.runs import atomic_write_json
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord
from vdtn_marl.voi import close_interval

RESULTS = Path("benchmarks/results/cam_value.json")
LEARNED = "learned"
DEFAULT_STARTS = "20,40,60,80,100,120,140,160"


class ActingSystem:
    """One copy of the acting system on a twin: control policy, completer and RRA policy,
    stepped one control interval at a time."""

    def __init__(self, twin: DigitalTwin, control, completion, rra):
        self.twin = twin
        self.control = control
        self.completion = completion
        self.rra = rra

    def copy(self, base_control, base_rra) -> ActingSystem:
        """An independent copy in the same state. Policies bound to a twin are bound again to
        the copied twin; the others (and the completer) are copied with their state."""
        twin = copy.deepcopy(self.twin)

        def again(base, current):
            return bind_to_twin(base, twin) if hasattr(base, "bind") else copy.deepcopy(current)

        return ActingSystem(
            twin,
            again(base_control, self.control),
            copy.deepcopy(self.completion),
            again(base_rra, self.rra),
        )

    def run_subframes(self) -> None:
        twin = self.twin
        for _ in range(twin.subframes_per_interval):
            twin.step_subframe(torch.as_tensor(self.rra(twin.rra_observation())).long())

    def _decide(self, cams_lost: bool) -> torch.Tensor:
        observation = self.twin.vehicle_observation(False, cams_lost=cams_lost)
        return self.control(self.completion.complete(observation, self.twin.interval))

    def finish(self, estimator=None) -> IntervalRecord:
        """Decide and integrate the interval, recording what ``estimator`` needs (the command
        a lost CAM would have led to, for the ``cam_lost`` baseline)."""
        return close_interval(self.twin, estimator, self._decide)

    def begin(self) -> None:
        self.twin.begin_interval()


def discounted_platoon_return(
    system: ActingSystem, first: IntervalRecord, horizon: int, gamma: float
) -> torch.Tensor:
    """Σ_h γ^h Σ_i r_i over ``horizon`` intervals from ``first`` (already run), [B] float64;
    a collision ends a scenario's sum after its interval."""
    total = first.reward.double().sum(-1)
    alive = ~first.collided.any(-1)
    weight = gamma
    for _ in range(1, horizon):
        system.begin()
        system.run_subframes()
        record = system.finish()
        total += weight * alive.double() * record.reward.double().sum(-1)
        alive &= ~record.collided.any(-1)
        weight *= gamma
    return total


def _pick_one(in_time: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """One True per row of ``in_time`` [B, L], chosen uniformly among its True entries (rows
    without any stay all False)."""
    scores = torch.rand(in_time.shape, generator=generator).masked_fill(~in_time.cpu(), -1.0)
    chosen = torch.zeros_like(in_time.cpu())
    best = scores.argmax(-1)
    rows = torch.arange(in_time.shape[0])
    chosen[rows, best] = in_time.cpu()[rows, best]
    return chosen.to(in_time.device)


def delivery_persistence(in_time: torch.Tensor, alive: torch.Tensor) -> dict[str, float]:
    """Fraction of CAMs in time overall, after a CAM of the same link in time and after one
    that was not; ``in_time`` [K, B, L] per interval, ``alive`` [K, B] (only pairs of
    consecutive intervals in which the scenario was running count)."""
    counted = alive[:, :, None].expand_as(in_time).double()
    both = (alive[:-1] & alive[1:])[:, :, None].expand_as(in_time[1:]).double()
    before, after = in_time[:-1].double(), in_time[1:].double()
    return {
        "in_time": float((in_time.double() * counted).sum() / counted.sum()),
        "after_in_time": float((before * after * both).sum() / (before * both).sum()),
        "after_miss": float(((1 - before) * after * both).sum() / ((1 - before) * both).sum()),
    }


def _pearson(x: torch.Tensor, y: torch.Tensor) -> float:
    if x.numel() < 3 or float(x.std()) == 0.0 or float(y.std()) == 0.0:
        return float("nan")
    return float(torch.corrcoef(torch.stack([x, y]))[0, 1])


def measure(
    loop: JointOptimisation,
    rra_name: str,
    episodes: int,
    starts: list[int],
    horizon: int,
    show_progress: bool = True,
) -> dict:
    """Per dropped CAM: value, td credit and one-step credit (see the module doc)."""
    cfg, params = loop.cfg, loop.params
    seed = EVAL_SEED_OFFSET + cfg.seed
    twin = DigitalTwin(
        params, batch_size=episodes, device=loop.device, seed=seed,
        trace_source=loop.eval_traces, radio=True, backend="torch",
    )  # fmt: skip
    twin.reset(seed=seed)
    base_control = loop.control_policy()
    base_rra = (
        loop.rra_policy() if rra_name == LEARNED else make_rra_baseline(rra_name, params, cfg.seed)
    )
    completion = copy.deepcopy(loop.completion)
    completion.reset()
    td = loop.ivoi_estimator("td")
    one_step = loop.ivoi_estimator(
        "rollout", rollout_intervals=1, bootstrap=True, baseline="cam_lost"
    )
    main = ActingSystem(
        twin, bind_to_twin(base_control, twin), completion, bind_to_twin(base_rra, twin)
    )
    generator = torch.Generator().manual_seed(seed)
    alive = torch.ones(episodes, dtype=torch.bool, device=twin.device)
    value, td_credit, one_step_credit = [], [], []
    in_time_history, alive_history = [], []
    last = max(starts)
    steps = track(range(last + 1), description="intervals", disable=not show_progress)
    for k in steps:
        if k > 0:
            main.begin()
        main.run_subframes()
        in_time_history.append(twin.switch_subframe(perfect=False) < twin.subframes_per_interval)
        alive_history.append(alive.clone())
        if k in starts:
            kept = main.copy(base_control, base_rra)
            lost = kept.copy(base_control, base_rra)
            in_time = twin.switch_subframe(perfect=False) < twin.subframes_per_interval
            drop = _pick_one(in_time & alive[:, None], generator)
            lost.twin.drop_cams(drop)
            record_kept = kept.finish(one_step)
            record_lost = lost.finish()
            td_kept = td(kept.twin, record_kept)
            td_lost = td(lost.twin, record_lost)
            one_step_kept = one_step(kept.twin, record_kept)
            sampled = drop.any(-1)
            value.append(
                (
                    discounted_platoon_return(kept, record_kept, horizon, loop.gamma)
                    - discounted_platoon_return(lost, record_lost, horizon, loop.gamma)
                )[sampled]
            )
            td_credit.append((td_kept - td_lost)[drop].double())
            one_step_credit.append(one_step_kept[drop].double())
        record = main.finish()
        alive &= ~record.collided.any(-1)
    value_all = torch.cat(value).cpu()
    td_all = torch.cat(td_credit).cpu()
    one_all = torch.cat(one_step_credit).cpu()
    return {
        "rra": f"{cfg.rra.name} ({LEARNED})" if rra_name == LEARNED else rra_name,
        "cams": int(value_all.numel()),
        "value": ci_summary(value_all),
        "td_credit": ci_summary(td_all),
        "one_step_credit": ci_summary(one_all),
        "correlation_value_td_credit": _pearson(value_all, td_all),
        "value_sd": float(value_all.std()) if value_all.numel() > 1 else float("nan"),
        "delivery": delivery_persistence(
            torch.stack(in_time_history).cpu(), torch.stack(alive_history).cpu()
        ),
    }


def _fmt(stat: dict) -> str:
    return f"{stat['mean']:+.4f} [{stat['low']:+.4f}, {stat['high']:+.4f}]"


def print_table(runs: list[dict], console: Console) -> None:
    table = Table(title="What one delivered CAM is worth (platoon return over the horizon)")
    columns = ("run", "RRA", "CAMs", "value", "td credit", "one-step credit", "corr", "sd")
    for column in (*columns, "in time (after in time / miss)"):
        table.add_column(column, justify="left" if column in ("run", "RRA") else "right")
    for run in runs:
        row = run["result"]
        table.add_row(
            f"{run['scenario']} seed {run['seed']} ({run['rra_reward']})",
            row["rra"],
            str(row["cams"]),
            _fmt(row["value"]),
            _fmt(row["td_credit"]),
            _fmt(row["one_step_credit"]),
            f"{row['correlation_value_td_credit']:+.2f}",
            f"{row['value_sd']:.3f}",
            "{in_time:.2f} ({after_in_time:.2f} / {after_miss:.2f})".format(**row["delivery"]),
        )
    console.print(table)


def plot_runs(runs: list[dict], path: Path, note: str) -> Path:
    """PNG: per run, the value of a CAM (left) and what the IVoI credits it with at its
    interval (right, td and one-step), each mean with its 95% CI."""
    plt = pyplot_agg()
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 0.45 * len(runs) + 2.2), sharey=True)
    labels = [f"{r['scenario']} seed {r['seed']}" for r in runs]
    y = list(range(len(runs)))

    def forest(ax, key, offset, color, label):
        stats = [r["result"][key] for r in runs]
        means = [s["mean"] for s in stats]
        errors = [
            [s["mean"] - s["low"] for s in stats],
            [s["high"] - s["mean"] for s in stats],
        ]
        ys = [v + offset for v in y]
        ax.errorbar(means, ys, xerr=errors, fmt="o", color=color, capsize=3, label=label)

    forest(left, "value", 0.0, "tab:blue", "value over the horizon")
    forest(right, "td_credit", -0.12, "tab:red", "td credit")
    forest(right, "one_step_credit", 0.12, "tab:orange", "one-step (cam_lost) credit")
    rra = runs[0]["result"]["rra"]
    left.set_title(f"What one delivered CAM is worth ({rra} RRA)")
    right.set_title("What the IVoI credits it with at its interval")
    for ax in (left, right):
        ax.axvline(0.0, color="0.5", linewidth=0.8)
        ax.set_xlabel("control return (reward units)")
        ax.legend(loc="best", fontsize=8)
    left.set_yticks(y, labels)
    left.invert_yaxis()
    return save_figure(fig, path, note)


def _parse_starts(text: str, horizon: int, episode_intervals: int) -> list[int]:
    try:
        starts = sorted({int(part) for part in text.split(",") if part.strip()})
    except ValueError as err:
        raise SystemExit(f"--starts {text!r} must be integers separated by commas") from err
    if not starts or starts[0] < 0 or starts[-1] + horizon > episode_intervals:
        raise SystemExit(
            f"--starts {text!r} must lie in [0, {episode_intervals - horizon}] so that the "
            f"--horizon {horizon} intervals after each fit in an episode of "
            f"{episode_intervals} intervals"
        )
    return starts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoints", nargs="+", type=Path, help="JOCC checkpoints (.pt)")
    parser.add_argument(
        "--rra",
        default="random",
        help=f"RRA policy: {LEARNED} or one of {', '.join(RRA_BASELINES)}",
    )
    parser.add_argument("--episodes", type=int, default=32, help="held-out scenarios (>= 2)")
    parser.add_argument(
        "--starts", default=DEFAULT_STARTS, help="intervals at which a CAM is dropped"
    )
    parser.add_argument(
        "--horizon", type=int, default=40, help="intervals over which the value is summed"
    )
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (0: default)")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if args.rra not in (LEARNED, *RRA_BASELINES):
        raise SystemExit(f"--rra {args.rra!r} is not one of {LEARNED}, {', '.join(RRA_BASELINES)}")
    if args.episodes < 2:
        raise SystemExit(f"--episodes {args.episodes} must be >= 2")
    if args.horizon < 1:
        raise SystemExit(f"--horizon {args.horizon} must be >= 1")
    if args.threads:
        torch.set_num_threads(args.threads)
    console = table_console(file_width=200)
    began = time.perf_counter()
    runs = []
    for path, loop in loaded_checkpoints(args.checkpoints, "cam_value_", console):
        if args.rra == LEARNED and not loop.cfg.rra.learned:
            raise SystemExit(f"--rra {LEARNED}: {path} learned no RRA policy")
        starts = _parse_starts(args.starts, args.horizon, loop.params.episode_intervals)
        runs.append(
            {
                **checkpoint_run(path, loop.cfg),
                "result": measure(
                    loop, args.rra, args.episodes, starts, args.horizon, args.progress
                ),
            }
        )
    print_table(runs, console)
    note = (
        f"benchmarks/cam_value.py --rra {args.rra} --episodes {args.episodes} "
        f"--starts {args.starts} --horizon {args.horizon}; 95% CIs over CAMs"
    )
    plot = plot_runs(runs, args.output.with_suffix(".png"), note)
    console.print(f"wrote {plot}")
    atomic_write_json(
        args.output,
        {
            **provenance("cam_value"),
            "episodes": args.episodes,
            "starts": args.starts,
            "horizon": args.horizon,
            "seconds": time.perf_counter() - began,
            "runs": runs,
        },
    )
    console.print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
