"""Per-iteration stage timings of short ``vdtn-marl jocc experiment=paper`` runs, side by side,
and what they make of one paper-scale JOCC iteration.

    vdtn-marl jocc experiment=paper experiment.jocc_iterations=2 experiment.control_iterations=2 \
        experiment.rra_iterations=2 control.warm_start=none algo.num_envs=64 \
        algo.rollout_steps=400 hydra.run.dir=runs/old        # and the same with 256 × 100
    python studies/2026-12-06-paper-stage-timings/paper_stage_timings.py old=runs/old new=runs/new \
        --out studies/2026-12-06-paper-stage-timings/paper_stage_timings.json

Run the runs at the same time (or alternately) so that they share the machine's load: the first
run is the reference, and every stage of the others is reported as a ratio to it. Per run it
reads ``metrics.csv`` (wall seconds of every PPO iteration), ``jocc.log`` (the evaluation
stage's seconds) and ``config.yaml`` (batch sizes, budgets). Stages: π\\* (``control_perfect``),
π̃ under random RRA (``control_impaired`` of JOCC iteration 0), π̃ under the learned RRA (of
iterations ≥ 1), RRA. The first iteration of each stage in a run fits the observation scaling
and is left out of the medians when there are others. The paper estimate multiplies the
medians by ``experiment=paper``'s budgets (``--control-iterations``, ``--rra-iterations``) and
adds one evaluation (π*'s warm start, once per run, is not included). Under load these wall
seconds hold other jobs' time: ``--cpu-share LABEL=CPU/WALL`` (a run's user + system seconds
and its wall seconds, e.g. from ``/usr/bin/time -v``) also scales that run's estimate to a
core of its own, assuming its share of the core was even over the run.

A whole run measures instead of extrapolating: every JOCC iteration in ``jocc.log`` is reported
with its stages' wall seconds (their ``done in`` lines) and its own wall seconds, from the end of
the iteration before (the run's start for the first) to its last stage's end, so π*'s warm
start, the value fit and the checkpoints count. ``--time-v LABEL=FILE`` adds the run's peak RSS
and CPU seconds from ``/usr/bin/time -v -o FILE``:

    /usr/bin/time -v -o runs/paper/time.txt vdtn-marl jocc experiment=paper \
        experiment.jocc_iterations=2 hydra.run.dir=runs/paper
    python studies/2026-12-06-paper-stage-timings/paper_stage_timings.py paper=runs/paper \
        --time-v paper=runs/paper/time.txt \
            --out studies/2026-12-06-paper-stage-timings/paper_iteration.json
"""

from __future__ import annotations

import argparse
import csv
import re
import statistics
from datetime import datetime
from pathlib import Path

RESULTS = Path(__file__).parent / "paper_stage_timings.json"
TARGET_S = 30 * 60.0  # DESIGN §7: one experiment=paper JOCC iteration on 2 cores
STAGES = ("pi_star", "pi_tilde_random", "pi_tilde_learned", "rra")
EVALUATE_DONE = re.compile(r"stage evaluate done in ([0-9.]+) s")
#: a ``jocc.log`` line: its time stamp, then the run's start or a stage's end
LOG_TIME = re.compile(r"^\[(\d{4}-\d\d-\d\d \d\d:\d\d:\d\d),(\d{3})\]")
STAGE_DONE = re.compile(r"JOCC iteration (\d+), stage (\S+) done in ([0-9.]+) s")
RUN_START = re.compile(r" - jocc seed=")
PEAK_RSS = re.compile(r"Maximum resident set size \(kbytes\): (\d+)")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("runs", nargs="+", help="LABEL=RUN_DIR, the reference first")
    p.add_argument("--control-iterations", type=int, default=500, help="π* and π̃ budget")
    p.add_argument("--rra-iterations", type=int, default=300, help="RRA budget")
    p.add_argument("--load", default="", help="load averages seen during the runs (recorded)")
    p.add_argument("--cpu-share", action="append", default=[], help="LABEL=CPU_S/WALL_S")
    p.add_argument(
        "--time-v",
        action="append",
        default=[],
        help="LABEL=FILE: the run's `/usr/bin/time -v -o FILE` report (peak RSS, CPU share)",
    )
    p.add_argument("--out", type=Path, default=RESULTS)
    args = p.parse_args(argv)
    shares = {}
    for item in args.cpu_share:
        label, _, fraction = item.partition("=")
        cpu, _, wall = fraction.partition("/")
        try:
            share = float(cpu) / float(wall)
        except (ValueError, ZeroDivisionError):
            share = -1.0
        if not 0 < share <= 1:
            p.error(f"--cpu-share {item!r} must look like LABEL=CPU_S/WALL_S with 0 < CPU <= WALL")
        shares[label] = share
    args.cpu_share = shares
    reports = {}
    for item in args.time_v:
        label, _, path = item.partition("=")
        report = Path(path).read_text() if path and Path(path).is_file() else ""
        if not label or not PEAK_RSS.search(report):
            p.error(f"--time-v {item!r} must be LABEL=FILE of a `/usr/bin/time -v` report")
        reports[label] = time_report(report)
    args.time_v = reports
    runs = []
    for item in args.runs:
        label, _, path = item.partition("=")
        if not label or not path:
            p.error(f"run {item!r} must look like LABEL=RUN_DIR")
        if not (Path(path) / "metrics.csv").is_file():
            p.error(f"run {item!r}: {path}/metrics.csv does not exist")
        runs.append((label, Path(path)))
    args.runs = runs
    return args


def stage_of(row: dict) -> str | None:
    """The benchmark's stage name of one ``metrics.csv`` row."""
    if row["stage"] == "control_perfect":
        return "pi_star"
    if row["stage"] == "control_impaired":
        return "pi_tilde_random" if int(row["jocc_iteration"]) == 0 else "pi_tilde_learned"
    return "rra" if row["stage"] == "rra" else None


def read_run(path: Path) -> dict:
    """Median seconds and frames/s per stage, and the evaluations' seconds, of one run."""
    import yaml

    seconds: dict[str, list[float]] = {}
    frames: dict[str, int] = {}
    counts: dict[int, dict[str, int]] = {}
    with open(path / "metrics.csv", newline="") as handle:
        for row in csv.DictReader(handle):
            per_stage = counts.setdefault(int(row["jocc_iteration"]), {})
            per_stage[row["stage"]] = per_stage.get(row["stage"], 0) + 1
            stage = stage_of(row)
            if stage is not None:
                seconds.setdefault(stage, []).append(float(row["seconds"]))
                frames[stage] = int(row["frames"])
    log = (path / "jocc.log").read_text() if (path / "jocc.log").is_file() else ""
    cfg = yaml.safe_load((path / "config.yaml").read_text())
    stages = {}
    for stage, values in seconds.items():
        timed = values[1:] if len(values) > 1 and stage != "pi_tilde_learned" else values
        median = statistics.median(timed)
        stages[stage] = {
            "seconds_per_iteration": median,
            "frames_per_iteration": frames[stage],
            "frames_per_s": frames[stage] / median,
            "iterations_timed": len(timed),
            "all_seconds": values,
        }
    algo = cfg.get("algo", {})
    return {
        "path": str(path),
        "batch": {
            k: algo.get(k)
            for k in ("num_envs", "rollout_steps", "rra_num_envs", "rra_rollout_steps")
        },  # fmt: skip
        "eval_episodes": cfg.get("experiment", {}).get("eval_episodes"),
        "stages": stages,
        "evaluate_s": [float(s) for s in EVALUATE_DONE.findall(log)],
        "measured": measured_iterations(log, counts),
    }


def time_report(text: str) -> dict:
    """Peak RSS (MB), CPU and wall seconds of a ``/usr/bin/time -v`` report."""

    def field(name: str) -> str:
        match = re.search(rf"{re.escape(name)}: (.+)", text)
        return match.group(1).strip() if match else ""

    wall = 0.0
    for part in field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":"):
        wall = 60.0 * wall + float(part or 0.0)
    cpu = float(field("User time (seconds)") or 0.0) + float(field("System time (seconds)") or 0.0)
    return {
        "peak_rss_mb": int(PEAK_RSS.search(text).group(1)) / 1024.0,
        "cpu_s": cpu,
        "wall_s": wall,
        "cpu_share": cpu / wall if wall > 0 else None,
    }


def measured_iterations(log: str, budgets: dict) -> list[dict]:
    """Per JOCC iteration of a run's ``jocc.log``: each stage's wall seconds (its ``done in``
    line), and the iteration's wall seconds from the end of the one before (the run's start
    for the first) to its last stage's end: warm start, value fit and checkpoints included.
    ``budgets`` (``"stage": PPO iterations``, from ``metrics.csv``) marks the stages a run
    cut short."""

    def stamp(line: str):
        match = LOG_TIME.match(line)
        if match is None:
            return None
        moment = datetime.strptime(match.group(1), "%Y-%m-%d %H:%M:%S")
        return moment.timestamp() + int(match.group(2)) / 1000.0

    out: dict[int, dict] = {}
    last_end = None
    for line in log.splitlines():
        if RUN_START.search(line) and last_end is None:
            last_end = stamp(line)
            continue
        match = STAGE_DONE.search(line)
        if match is None:
            continue
        iteration, stage, seconds = int(match.group(1)), match.group(2), float(match.group(3))
        entry = out.setdefault(iteration, {"jocc_iteration": iteration, "stages": {}})
        entry["stages"][stage] = seconds
        moment = stamp(line)
        if moment is not None:
            entry.setdefault("began", last_end)
            entry["ended"] = moment
            last_end = moment
    rows = []
    for iteration in sorted(out):
        entry = out[iteration]
        began, ended = entry.pop("began", None), entry.pop("ended", None)
        entry["wall_s"] = None if began is None or ended is None else ended - began
        done = budgets.get(iteration, {})
        entry["ppo_iterations"] = done
        entry["complete"] = "evaluate" in entry["stages"]
        rows.append(entry)
    return rows


def paper_iteration(run: dict, control_iterations: int, rra_iterations: int) -> dict:
    """Seconds of one paper JOCC iteration at this run's timings: the first (π̃ under random
    RRA) and the later ones (π̃ under the learned RRA); the warm start is not included."""
    s = {k: v["seconds_per_iteration"] for k, v in run["stages"].items()}
    evaluate = statistics.median(run["evaluate_s"]) if run["evaluate_s"] else 0.0
    out = {"evaluate_s": evaluate}
    for name, pi_tilde in (("first", "pi_tilde_random"), ("later", "pi_tilde_learned")):
        if not all(k in s for k in ("pi_star", pi_tilde, "rra")):
            out[f"{name}_s"] = None
            continue
        out[f"{name}_s"] = (
            control_iterations * (s["pi_star"] + s[pi_tilde]) + rra_iterations * s["rra"] + evaluate
        )
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    runs = {label: read_run(path) for label, path in args.runs}
    reference = args.runs[0][0]
    print(f"{'stage':<17} " + " ".join(f"{label + ' s/it':>12} {'ratio':>6}" for label in runs))
    ratios: dict[str, dict[str, float]] = {}
    for stage in STAGES:
        ref = runs[reference]["stages"].get(stage)
        cells = []
        for label, run in runs.items():
            mine = run["stages"].get(stage)
            ratio = None
            if mine and ref:
                ratio = mine["seconds_per_iteration"] / ref["seconds_per_iteration"]
                ratios.setdefault(label, {})[stage] = ratio
            cells.append(
                f"{mine['seconds_per_iteration'] if mine else float('nan'):>12.1f} "
                f"{ratio if ratio is not None else float('nan'):>6.2f}"
            )
        print(f"{stage:<17} " + " ".join(cells))
    estimates = {
        label: paper_iteration(run, args.control_iterations, args.rra_iterations)
        for label, run in runs.items()
    }
    for label, est in estimates.items():
        share = args.cpu_share.get(label)
        if share is not None:
            est["cpu_share"] = share
            for key in ("first_s", "later_s", "evaluate_s"):
                value = est[key]
                est[f"{key[:-2]}_own_core_s"] = None if value is None else value * share
        for suffix, what in (("", "these timings"), ("_own_core", "a core of its own")):
            if f"first{suffix}_s" not in est:
                continue
            first, later = est[f"first{suffix}_s"], est[f"later{suffix}_s"]
            print(
                f"{label}: paper JOCC iteration at {what}: first "
                f"{'–' if first is None else f'{first / 60:.0f} min'}, later "
                f"{'–' if later is None else f'{later / 60:.0f} min'} "
                f"(evaluation {est[f'evaluate{suffix}_s']:.0f} s)"
            )
    for label, run in runs.items():
        for entry in run["measured"]:
            stages = ", ".join(f"{k} {v / 60:.1f}" for k, v in entry["stages"].items())
            wall = entry["wall_s"]
            print(
                f"{label}: JOCC iteration {entry['jocc_iteration']} measured: "
                f"{'–' if wall is None else f'{wall / 60:.1f} min'} "
                f"({'complete' if entry['complete'] else 'cut short'}; stages in min: {stages}; "
                f"target {TARGET_S / 60:.0f} min)"
            )
        report = args.time_v.get(label)
        if report is not None:
            print(
                f"{label}: peak RSS {report['peak_rss_mb']:,.0f} MB, CPU {report['cpu_s']:,.0f} s "
                f"over {report['wall_s']:,.0f} s wall"
            )
    atomic_write_json(
        args.out,
        {
            **provenance("paper_stage_timings"),
            "load_average": args.load,
            "reference": reference,
            "budgets": {
                "control_iterations": args.control_iterations,
                "rra_iterations": args.rra_iterations,
            },
            "runs": runs,
            "ratios_to_reference": ratios,
            "time_v": args.time_v,
            "target_s": TARGET_S,
            "paper_iteration_at_these_timings": estimates,
        },
    )
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
