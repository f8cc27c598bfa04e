"""Videos of the leaderboard (``vdtn-marl bench … video=true``): per scenario, each of the
benchmark's two ``trace_methods`` on its best and its worst held-out evaluation scenario.

The run of the method's first complete seed is loaded from its checkpoint and evaluated again
as the cell evaluated it (same config, same held-out scenarios) with
``video_scenarios=best_worst`` (:func:`vdtn_marl.experiment.evaluate.evaluate_stage`): the
scenarios of the highest and the lowest control return of the acting system, one frame per
control interval. The files land in the report folder as
``leaderboard_<scenario>_<method>_{best,worst}.<gif|mp4>`` (atomically); the evaluation's own
files go to a scratch folder that is removed.
"""

from __future__ import annotations

import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from vdtn_marl.experiment.checkpoint import checkpoint_path
from vdtn_marl.experiment.config import BenchConfig
from vdtn_marl.io.files import atomic_write_bytes
from vdtn_marl.leaderboard.grid import Cell, complete_summary


@dataclass(frozen=True)
class LeaderboardVideo:
    """One video of the report: ``cell``'s run on its ``label`` (best, worst) held-out
    scenario (index ``scenario_index`` of the evaluation batch)."""

    cell: Cell
    label: str
    scenario_index: int
    path: Path


def video_cells(cfg: BenchConfig, cells: Sequence[Cell], composed: Mapping) -> list[Cell]:
    """Per scenario and trace method, the complete cell of the lowest seed (none when no seed
    of it is complete)."""
    out_dir = Path(cfg.out_dir)
    chosen = []
    for scenario in cfg.benchmark.scenarios:
        for method in cfg.benchmark.trace_methods:
            mine = sorted(
                (c for c in cells if (c.scenario, c.method) == (scenario, method)),
                key=lambda c: c.seed,
            )
            done = [c for c in mine if complete_summary(c.directory(out_dir), composed[c][0])]
            if done and checkpoint_path(done[0].directory(out_dir)).is_file():
                chosen.append(done[0])
    return chosen


def write_videos(
    cfg: BenchConfig, cells: Sequence[Cell], composed: Mapping, report_dir: str | Path
) -> list[LeaderboardVideo]:
    """Evaluate each cell of :func:`video_cells` again with ``video_scenarios=best_worst`` and
    write its two videos to ``report_dir``; returns them in report order."""
    from vdtn_marl.experiment.jocc import JointOptimisation

    written = []
    with tempfile.TemporaryDirectory(prefix="vdtn-marl-videos-") as scratch:
        for number, cell in enumerate(video_cells(cfg, cells, composed)):
            path = checkpoint_path(cell.directory(cfg.out_dir))
            loop = JointOptimisation.from_checkpoint(path, Path(scratch) / f"run{number}")
            loop.cfg.video, loop.cfg.video_format = True, cfg.video_format
            loop.cfg.video_scenarios, loop.cfg.progress = "best_worst", False
            loop.evaluate()
            for label in ("best", "worst"):
                source = loop.videos[f"episode_{label}"]
                name = f"leaderboard_{cell.scenario}_{cell.method}_{label}.{cfg.video_format}"
                target = atomic_write_bytes(Path(report_dir) / name, source.read_bytes())
                index = loop.video_indices[f"episode_{label}"]
                written.append(LeaderboardVideo(cell, label, index, target))
            loop.loggers.close()
    return written
