"""The π* a benchmark's cells share: one per scenario and seed (``benchmark.pi_star``).

π* is the controller on perfect observations, the reference of IVoI and EVoI. It does not
depend on the RRA policy or on who acts, so every method of a scenario and seed can be
measured against one π*, trained once (to its plateau: ``control.pi_star_patience``) instead
of once per cell with the cell's budget. With ``benchmark.pi_star`` a list of overrides, the
grid first gets, per scenario and seed, a ``vdtn-marl train task=control`` run in
``<out_dir>/<scenario>/pi_star/seed<k>/`` composed as ``scenario=S experiment=E <overrides>
<benchmark.pi_star> seed=K``; every cell of that scenario and seed then loads its π* from the
run's checkpoint (``control.pi_star``) and trains none of its own. A cell's summary names the
π* it used and its SHA-256 (``pi_star_source``).

Sharded jobs share the π* runs: a job trains the π* a cell needs unless another job is
training it (the run directory's lock), in which case it trains another π* its cells need
meanwhile, or waits for it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vdtn_marl.errors import RunDirInUse
from vdtn_marl.experiment.config import PI_STAR_NAME, BenchmarkConfig
from vdtn_marl.io.files import CONFIG_FILE, SUMMARY_FILE, atomic_write_text, read_json, run_lock
from vdtn_marl.leaderboard.grid import check_same_config, compose_run

_log = logging.getLogger(__name__)
#: seconds between two looks at a π* another job trains
POLL_SECONDS = 10.0


@dataclass(frozen=True)
class PiStarRun:
    """The shared π* of one scenario and seed."""

    scenario: str
    seed: int
    overrides: tuple[str, ...]

    @property
    def name(self) -> str:
        return f"{self.scenario}/{PI_STAR_NAME}/seed{self.seed}"

    def directory(self, out_dir: str | Path) -> Path:
        return Path(out_dir) / self.scenario / PI_STAR_NAME / f"seed{self.seed}"

    def checkpoint(self, out_dir: str | Path) -> Path:
        from vdtn_marl.experiment.checkpoint import checkpoint_path

        return checkpoint_path(self.directory(out_dir))


def pi_star_runs(
    benchmark: BenchmarkConfig, cells: Iterable[Any]
) -> dict[tuple[str, int], PiStarRun]:
    """The π* run of every (scenario, seed) of ``cells``, in the cells' order (empty where
    ``benchmark.pi_star`` is null)."""
    if benchmark.pi_star is None:
        return {}
    runs: dict[tuple[str, int], PiStarRun] = {}
    for cell in cells:
        key = (cell.scenario, cell.seed)
        if key not in runs:
            overrides = (
                f"scenario={cell.scenario}",
                f"experiment={benchmark.experiment}",
                *map(str, benchmark.overrides),
                *map(str, benchmark.pi_star),
                "task=control",
                f"seed={cell.seed}",
            )
            runs[key] = PiStarRun(cell.scenario, cell.seed, overrides)
    return runs


def compose_pi_star(run: PiStarRun, device: str) -> tuple[dict, Any]:
    """(composed config as plain data, validated RunConfig) of a π* run."""
    return compose_run(run.name, run.overrides, device, "train")


def finished(run: PiStarRun, data: dict, out_dir: str | Path) -> bool:
    """Whether the π* run ended (its summary and checkpoint are written) with the config
    ``data``; a finished run of another config raises :class:`LeaderboardError`."""
    path = run.directory(out_dir) / SUMMARY_FILE
    if not path.is_file() or not run.checkpoint(out_dir).is_file():
        return False
    try:
        summary = read_json(path)
    except (OSError, ValueError):
        return False
    if summary.get("task") != "control":
        return False
    check_same_config(path, summary, data)
    return True


def train(run: PiStarRun, data: dict, run_cfg: Any, out_dir: str | Path) -> None:
    """Train (or continue) the π* run in its directory; :class:`RunDirInUse` where another
    job holds it."""
    from omegaconf import OmegaConf

    from vdtn_marl.experiment import api

    run_dir = run.directory(out_dir)
    with run_lock(run_dir):
        if finished(run, data, out_dir):  # another job ended it while we looked
            return
        atomic_write_text(run_dir / CONFIG_FILE, OmegaConf.to_yaml(OmegaConf.create(data)))
        _log.info("training the shared π* %s", run.name)
        api.train(run_cfg, run_dir)


def ensure(
    run: PiStarRun,
    composed: dict[PiStarRun, tuple[dict, Any]],
    out_dir: str | Path,
    meanwhile: Iterable[PiStarRun] = (),
    sleep: Callable[[float], None] = time.sleep,
) -> Path:
    """The checkpoint of ``run``'s π*, trained here unless it is done; while another job trains
    it, train one of ``meanwhile`` (other π* this job will need) that no one trains, or wait."""
    while not finished(run, composed[run][0], out_dir):
        try:
            train(run, *composed[run], out_dir)
            continue
        except RunDirInUse:
            pass
        for other in meanwhile:
            if other == run or finished(other, composed[other][0], out_dir):
                continue
            try:
                train(other, *composed[other], out_dir)
                break
            except RunDirInUse:
                continue
        else:
            _log.info("waiting for the shared π* %s, which another job trains", run.name)
            sleep(POLL_SECONDS)
    return run.checkpoint(out_dir)


#: What the report shows of each shared π* run (its summary's keys).
REPORT_KEYS = (
    "control_cost", "pi_star_minus_start", "pi_star_minus_causal_mpc", "pi_star_minus_cacc",
)  # fmt: skip


def report_rows(
    benchmark: BenchmarkConfig, cells: Iterable[Any], out_dir: str | Path
) -> list[dict]:
    """One row per finished shared π* run of ``cells`` (none where ``benchmark.pi_star`` is
    null): PPO iterations, the iteration kept, where it reached its plateau, its control cost
    on perfect observations and its reference check against its start, the causal MPC and
    the CACC (mean and interval of J* − J_c over the held-out scenarios)."""
    rows = []
    for (scenario, seed), run in pi_star_runs(benchmark, cells).items():
        path = run.directory(out_dir) / SUMMARY_FILE
        if not path.is_file():
            continue
        s = read_json(path)
        plateau = (s.get("plateaus") or {}).get("control_perfect")
        row = {
            "scenario": scenario,
            "seed": seed,
            "ppo_iterations": (s.get("trainer_iterations") or {}).get("pi_star"),
            "selected_iteration": (s.get("selected_iterations") or {}).get("control_perfect"),
            "plateau_at": plateau["stopped_at"] if plateau else None,
            "reference_ok": s.get("reference_ok"),
            "reference_problems": s.get("reference_problems") or "",
        }
        for key in REPORT_KEYS:
            row[key] = s.get(key)
            if key.startswith("pi_star_minus_"):
                row[f"{key}_ci_low"], row[f"{key}_ci_high"] = (
                    s.get(f"{key}_ci_low"),
                    s.get(f"{key}_ci_high"),
                )
        rows.append(row)
    return rows


def report_markdown(rows: list[dict]) -> list[str]:
    """The report's section on the shared π* runs (empty without any)."""
    if not rows:
        return []

    def diff(row: dict, key: str) -> str:
        mean, low, high = (row.get(f"{key}{s}") for s in ("", "_ci_low", "_ci_high"))
        if mean is None:
            return "–"
        return f"{mean:+.4f} [{low:+.4f}, {high:+.4f}]" if low is not None else f"{mean:+.4f}"

    lines = [
        "## The shared π*",
        "",
        "One π* per scenario and seed (`benchmark.pi_star`), trained by `vdtn-marl train "
        "task=control` and loaded by every cell of that scenario and seed. J* − J_c: π*'s "
        "discounted return minus the comparator's on perfect observations, per follower, over "
        "the held-out scenarios (mean [95 % t interval]; above 0: π* is better).",
        "",
        "| scenario | seed | PPO iterations | kept | plateau at | control cost | "
        "J* − J start | J* − J causal MPC | J* − J CACC | check |",
        "|---|--:|--:|--:|--:|--:|--:|--:|--:|---|",
    ]
    for r in rows:
        cost = "–" if r["control_cost"] is None else f"{r['control_cost']:.4f}"
        check = "passed" if r["reference_ok"] else f"FAILED: {r['reference_problems']}"
        lines.append(
            f"| {r['scenario']} | {r['seed']} | {r['ppo_iterations']} | {r['selected_iteration']} "
            f"| {r['plateau_at'] if r['plateau_at'] is not None else '–'} | {cost} | "
            f"{diff(r, 'pi_star_minus_start')} | {diff(r, 'pi_star_minus_causal_mpc')} | "
            f"{diff(r, 'pi_star_minus_cacc')} | {check} |"
        )
    return [*lines, ""]
