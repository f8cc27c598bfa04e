"""Entry points of the training code, called by the CLI (``vdtn-marl train|jocc|eval``).

Each takes a :class:`~vdtn_marl.config.RunConfig` (validated here) and a run directory, writes
its outputs there atomically (``metrics.csv``, ``evaluation.csv``, ``checkpoints/``,
``summary.json``) and returns the summary dict it wrote. ``cfg.resume`` continues an
interrupted run from its last checkpoint.
"""

from __future__ import annotations

from pathlib import Path

from vdtn_marl.algos.checkpoint import load_checkpoint
from vdtn_marl.algos.jocc import JointOptimisation
from vdtn_marl.config import RunConfig, to_dict, validate
from vdtn_marl.runs import SUMMARY_FILE, atomic_write_json
from vdtn_marl.sim.params import ConfigError


def _start(cfg: RunConfig, run_dir: str | Path, task: str) -> JointOptimisation:
    loop = JointOptimisation(validate(cfg), run_dir, task=task)
    if cfg.checkpoint and not (cfg.resume and loop.checkpoint_path.exists()):
        loop.load_policies(load_checkpoint(cfg.checkpoint, to_dict(cfg)))
    return loop


def train(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Train one group (``cfg.task``): ``control`` trains π* on perfect observations;
    ``control_impaired`` trains π* and then π̃ under the configured RRA policy; ``rra`` trains
    π* (for v*) and then the RRA agents with π̃ (or the control baseline) as control module.
    ``cfg.checkpoint`` starts from the policies of an earlier run."""
    return _start(cfg, run_dir, cfg.task).run()


def jocc(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Run ``cfg.experiment.jocc_iterations`` iterations of joint optimisation (JOCC)."""
    return _start(cfg, run_dir, "jocc").run()


def evaluate(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Evaluate the policies in ``cfg.checkpoint`` (control and RRA as configured: learned
    policies come from the checkpoint, baselines by name) on the held-out scenarios."""
    if not cfg.checkpoint:
        raise ConfigError("checkpoint=None: eval needs checkpoint=<path to a .pt file>")
    loop = JointOptimisation(validate(cfg), run_dir, task="jocc")
    payload = load_checkpoint(cfg.checkpoint, to_dict(cfg))
    loop.load_policies(payload)
    loop.position["iteration"] = int(payload["position"]["iteration"])
    row = loop.evaluate()
    summary = loop.summary(row["eval_seconds"], resumed=False)
    summary["checkpoint"] = str(Path(cfg.checkpoint).resolve())
    summary["task"] = "eval"
    atomic_write_json(Path(run_dir) / SUMMARY_FILE, summary)
    return summary
