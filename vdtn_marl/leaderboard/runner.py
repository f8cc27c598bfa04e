"""Running a benchmark: every cell of this job's shard, skipping complete ones, then the report."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vdtn_marl.experiment.compose import check_pi_star, hydra_compose
from vdtn_marl.experiment.config import BenchConfig, selected_cells
from vdtn_marl.io.files import CONFIG_FILE, atomic_write_json, atomic_write_text, run_lock
from vdtn_marl.leaderboard import pi_star
from vdtn_marl.leaderboard.grid import (
    MANIFEST_FILE,
    WARM_START_DIR,
    Cell,
    check_eval_pairing,
    check_out_dir,
    complete_summary,
    compose_cell,
    manifest,
    plan,
    with_recorded_submissions,
)
from vdtn_marl.leaderboard.report import write_report


def run_cell(cell: Cell, data: dict, run_cfg: Any, out_dir: str | Path) -> dict:
    """Run (or continue) one cell in its directory and return its summary."""
    from omegaconf import OmegaConf

    from vdtn_marl.experiment import api

    cell_dir = cell.directory(out_dir)
    cell_dir.mkdir(parents=True, exist_ok=True)
    with run_lock(cell_dir):  # two launchers of one shard: the second refuses the cell
        atomic_write_text(cell_dir / CONFIG_FILE, OmegaConf.to_yaml(OmegaConf.create(data)))
        return api.jocc(run_cfg, cell_dir)  # also writes evaluation_raw.npz for the plots


@dataclass
class BenchmarkResult:
    done: list[Cell]  # complete cells of this job (run now or before)
    ran: list[Cell]  # cells this job ran (or continued)
    failed: list[tuple[Cell, str]]
    pending: list[Cell]  # cells of the whole grid still without a complete summary
    report: dict[str, Path] | None = None


def run_benchmark(cfg: BenchConfig, command: str = "") -> BenchmarkResult:
    """Run or resume this job's share of the grid, then write the report (see module doc).

    A cell that fails is reported and the others go on; the report covers the complete cells
    and says how many are missing.
    """
    from vdtn_marl.io.log import progress

    check_out_dir(cfg)
    cfg = with_recorded_submissions(cfg)  # earlier submissions stay in the grid and report
    cells = plan(cfg)
    wanted = set(selected_cells(cfg.cells, [c.name for c in cells]))
    mine = [c for c in cells if c.name in wanted][cfg.shard :: cfg.num_shards]
    out_dir = Path(cfg.out_dir)
    atomic_write_json(out_dir / MANIFEST_FILE, manifest(cfg))
    done, ran, failed = [], [], []
    with hydra_compose():
        composed = {cell: compose_cell(cell, cfg.device) for cell in cells}
        check_eval_pairing({cell: data for cell, (data, _) in composed.items()})
        title = f"bench {cfg.benchmark.name} v{cfg.benchmark.version}"
        if cfg.num_shards > 1:
            title += f" shard {cfg.shard}/{cfg.num_shards}"
        shared = pi_star.pi_star_runs(cfg.benchmark, cells)  # benchmark.pi_star
        pi_star_composed = {
            run: pi_star.compose_pi_star(run, cfg.device) for run in shared.values()
        }
        needed = list(dict.fromkeys(shared[(c.scenario, c.seed)] for c in mine if shared))
        # `cells` patterns may name π* runs themselves (e.g. [*/pi_star/*]): trained first
        chosen = [r for r in shared.values() if cfg.cells and selected_cells(cfg.cells, [r.name])]
        for run in (share := chosen[cfg.shard :: cfg.num_shards]) if cfg.run else ():
            pi_star.ensure(run, pi_star_composed, out_dir, share)
        with progress(len(mine), title, cfg.progress) as bar:
            for cell in mine:
                data, run_cfg = composed[cell]
                cell_dir = cell.directory(out_dir)
                bar.set_postfix_str(cell.name)
                if complete_summary(cell_dir, data) is not None:
                    done.append(cell)
                    bar.update(1)
                    continue
                if not cfg.run:  # report only: a missing cell stays missing
                    bar.update(1)
                    continue
                if cfg.share_warm_starts:  # the results do not depend on it (warm_start.py)
                    run_cfg.warm_start_cache = str(out_dir / WARM_START_DIR)
                try:
                    if shared:
                        run = shared[(cell.scenario, cell.seed)]
                        path = pi_star.ensure(run, pi_star_composed, out_dir, needed)
                        data["control"]["pi_star"] = run_cfg.control.pi_star = str(path)
                        check_pi_star(run_cfg)
                    run_cell(cell, data, run_cfg, out_dir)
                except Exception as exc:  # one failing cell does not stop the grid
                    failed.append((cell, f"{type(exc).__name__}: {exc}"))
                    bar.write(f"cell {cell.name} failed: {type(exc).__name__}: {exc}")
                else:
                    ran.append(cell)
                    done.append(cell)
                bar.update(1)
        pending = [
            c for c in cells if complete_summary(c.directory(out_dir), composed[c][0]) is None
        ]
    result = BenchmarkResult(done=done, ran=ran, failed=failed, pending=pending)
    if cfg.report and len(pending) < len(cells):
        result.report = write_report(cfg, command=command, cells=cells, composed=composed)
    return result
