"""The JOCC loop's checkpoint: what it holds, writing it, and continuing a run from it.

A run keeps one checkpoint, ``checkpoints/last.pt`` in its directory (:func:`checkpoint_path`),
written every ``experiment.checkpoint_every`` PPO iterations and at the end of every stage,
in the file format of :mod:`vdtn_marl.algos.checkpoint` (one ``torch.save`` file, written
atomically, read back with ``weights_only=True``). Its payload (:func:`payload`):

============  ==========================================================================
key           what
============  ==========================================================================
config        the run's config (:func:`~vdtn_marl.experiment.config.to_dict`)
task          ``jocc``, ``control``, ``control_impaired`` or ``rra``
position      JOCC iteration, index of the next stage, the trainer iteration the stage in
              progress began at (``stage_start``, None between stages), and what stages
              recorded (``selected_iterations``, ``warm_start``, ``value_fit``)
trainers      every trainer's state (policies, critics, optimisers) by name: ``pi_star``,
              ``pi_tilde`` and, where RRA agents learn, ``rra``
rng           torch's RNG states
log_rows      rows of ``metrics.csv`` (``train``) and ``evaluation.csv`` (``eval``)
version       the package version that wrote it
value_fit     with ``rra.value_fit=acting``: the fitted v* of the td estimator
============  ==========================================================================

:func:`resume` continues a run from it and, on the same device, reproduces an uninterrupted
run bit for bit; :func:`run_config` reads the config of a checkpoint's run.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from vdtn_marl import __version__
from vdtn_marl.algos.checkpoint import load_checkpoint, rng_state, save_checkpoint, set_rng_state
from vdtn_marl.algos.trainer import Trainer
from vdtn_marl.errors import CheckpointError
from vdtn_marl.experiment.config import RunConfig, from_saved_dict, to_dict
from vdtn_marl.io.files import (
    CHECKPOINT_DIR,
    EVALUATION_FILE,
    check_summary_file,
    remove_stale_temp_files,
)
from vdtn_marl.io.metrics import MetricsLog

LAST_CHECKPOINT = "last.pt"


class CheckpointedLoop(Protocol):
    """What a checkpoint saves of the JOCC loop and restores into it
    (:class:`~vdtn_marl.experiment.jocc.JointOptimisation`)."""

    cfg: RunConfig
    task: str
    run_dir: Path
    position: dict[str, Any]
    train_log: MetricsLog
    eval_log: MetricsLog
    v_fit: Any  # rra.value_fit=acting: the fitted v* (a module), else None

    def trainers(self) -> dict[str, Trainer]: ...

    def prepare_load(self, position: dict[str, Any]) -> None:
        """Make the loop's objects those of a run at ``position`` (before the trainers'
        states, which include their environments', are loaded into them)."""


def checkpoint_path(run_dir: str | Path) -> Path:
    """``run_dir/checkpoints/last.pt``."""
    return Path(run_dir) / CHECKPOINT_DIR / LAST_CHECKPOINT


def payload(loop: CheckpointedLoop) -> dict[str, Any]:
    """The checkpoint of ``loop`` as it stands (see the module doc for the keys)."""
    return {
        "config": to_dict(loop.cfg),
        "task": loop.task,
        "position": dict(loop.position),
        "trainers": {name: t.state_dict() for name, t in loop.trainers().items()},
        "rng": rng_state(),
        "log_rows": {"train": len(loop.train_log.rows), "eval": len(loop.eval_log.rows)},
        "version": __version__,
        **({"value_fit": loop.v_fit.state_dict()} if loop.v_fit is not None else {}),
    }


def save(loop: CheckpointedLoop, path: Path | None = None) -> Path:
    """Write ``loop``'s checkpoint to ``path`` (default: its run's ``checkpoints/last.pt``)."""
    return save_checkpoint(path or checkpoint_path(loop.run_dir), payload(loop))


def load_policies(loop: CheckpointedLoop, saved: dict[str, Any]) -> None:
    """Load every trainer state a checkpoint holds (policies, critics, optimisers) into
    ``loop``'s trainers, and its fitted v* where both have one."""
    if "position" in saved:
        loop.prepare_load(saved["position"])
    for name, trainer in loop.trainers().items():
        state = saved["trainers"].get(name)
        if state is not None:
            try:
                trainer.load_state_dict(state)
            except (RuntimeError, KeyError) as err:
                raise CheckpointError(
                    f"checkpoint trainer {name!r} does not fit this config ({err})"
                ) from err
    if loop.v_fit is not None and "value_fit" in saved:
        loop.v_fit.load_state_dict(saved["value_fit"])


def resume(loop: CheckpointedLoop) -> bool:
    """Continue ``loop`` from its run's ``checkpoints/last.pt`` if it exists (trainers, position,
    RNG state, and the metrics logs cut back to the rows the checkpoint counted); returns
    whether it did."""
    path = checkpoint_path(loop.run_dir)
    if not path.exists():
        return False
    saved = load_checkpoint(path, to_dict(loop.cfg))
    if saved.get("task") != loop.task:
        raise CheckpointError(
            f"checkpoint {str(path)!r} is from task={saved.get('task')!r}, not task={loop.task!r}"
        )
    load_policies(loop, saved)
    loop.position = dict(saved["position"])
    set_rng_state(saved["rng"])
    rows = saved["log_rows"]
    check_summary_file(loop.run_dir)
    loggers = loop.train_log.loggers
    train_log = MetricsLog.resume(loop.run_dir, expected_rows=rows["train"], loggers=loggers)
    eval_log = MetricsLog.resume(
        loop.run_dir, filename=EVALUATION_FILE, expected_rows=rows["eval"], loggers=loggers
    )
    remove_stale_temp_files(loop.run_dir)  # of a writer killed mid-write
    loop.train_log, loop.eval_log = train_log, eval_log
    loop.train_log.truncate(rows["train"])
    loop.eval_log.truncate(rows["eval"])
    return True


def run_config(path: str | Path, needs_pi_tilde: bool = False) -> tuple[RunConfig, dict[str, Any]]:
    """The config of a checkpoint's run and the checkpoint. ``needs_pi_tilde`` refuses a
    checkpoint of a run with learned control that trained no π̃."""
    saved = load_checkpoint(path)
    try:
        cfg = from_saved_dict(saved["config"])
    except (KeyError, TypeError) as err:
        raise CheckpointError(f"checkpoint {str(path)!r} holds no run config ({err})") from err
    task = saved.get("task")
    trains_pi_tilde = task in ("jocc", "control_impaired")
    if needs_pi_tilde and cfg.control.name == "learned" and not trains_pi_tilde:
        raise CheckpointError(
            f"checkpoint {str(path)!r} is from task={task!r}, which trains no π̃; "
            "use a checkpoint of a jocc or control_impaired run"
        )
    return cfg, saved
