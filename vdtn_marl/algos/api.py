"""Entry points of the training code, called by the CLI (``vdtn-marl train|jocc|eval``).

Each takes a validated :class:`~vdtn_marl.config.RunConfig` and a run directory, writes its
outputs there atomically (``metrics.csv``, ``checkpoints/``, ``summary.json``, plots) and returns
the summary dict it wrote. ``cfg.resume`` continues an interrupted run from its last checkpoint.
"""

from __future__ import annotations

from pathlib import Path

from vdtn_marl.config import RunConfig


def train(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Train one group (``cfg.task``: control π*, control_impaired π̃, or rra)."""
    raise NotImplementedError("training lands with the MAPPO trainer")


def jocc(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Run ``cfg.experiment.jocc_iterations`` iterations of joint optimisation (JOCC)."""
    raise NotImplementedError("the JOCC loop lands with the MAPPO trainer")


def evaluate(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Evaluate the policies in ``cfg.checkpoint`` (or the baselines named in ``cfg``)."""
    raise NotImplementedError("evaluation lands with the MAPPO trainer")
