"""The metric loggers of a run beside its CSV tables: TensorBoard, Weights & Biases and MLflow
through TorchRL's loggers (:mod:`torchrl.record.loggers`), chosen by ``experiment.loggers``.

``csv`` is the run's own ``metrics.csv`` and ``evaluation.csv`` (:class:`~.metrics.MetricsLog`),
always written: plots, resumes and the leaderboard read them. The other loggers get the same
rows as scalars: a training row as ``<stage>/<key>`` at the trainer's PPO iteration, an
evaluation row as ``eval/<key>`` at its JOCC iteration. They are opened on the first scalar, so
a run that logs none (``--cfg job``, a failed validation) leaves no trace in them.

- ``csv`` (always): ``metrics.csv``, ``evaluation.csv``;
- ``tensorboard`` (``pip install 'vdtn-marl[tensorboard]'``): ``<run>/tensorboard/``;
- ``wandb`` (``vdtn-marl[wandb]``): the W&B project ``$WANDB_PROJECT`` (default ``vdtn-marl``),
  run files in ``<run>/wandb/``; ``WANDB_MODE=offline`` needs no network;
- ``mlflow`` (``vdtn-marl[mlflow]``): ``$MLFLOW_TRACKING_URI``, by default the SQLite store
  ``<run>/mlflow.db``, in the experiment ``$MLFLOW_EXPERIMENT_NAME`` (default ``vdtn-marl``).

TensorBoard and W&B loggers come from :func:`torchrl.record.loggers.get_logger`. MLflow's is
TorchRL's :class:`~torchrl.record.loggers.MLFlowLogger` built here: ``get_logger`` gives it a
file store (``file://``), which MLflow 3.10 and later refuse.

This module imports nothing of the package but its errors, and TorchRL only when a logger
opens.
"""

from __future__ import annotations

import importlib.util
import logging
import math
import os
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vdtn_marl.errors import ConfigError

_log = logging.getLogger(__name__)

#: The default W&B project and MLflow experiment (``$WANDB_PROJECT``,
#: ``$MLFLOW_EXPERIMENT_NAME`` override them).
PROJECT = "vdtn-marl"
TENSORBOARD_DIR = "tensorboard"
MLFLOW_DB = "mlflow.db"


@dataclass(frozen=True)
class LoggerSpec:
    """A logger of :data:`LOGGERS`: the module it needs (None: always available) and the extra
    of vdtn-marl that installs it."""

    module: str | None
    extra: str | None


#: ``experiment.loggers`` choices, in the order a run opens them.
LOGGERS: dict[str, LoggerSpec] = {
    "csv": LoggerSpec(None, None),
    "tensorboard": LoggerSpec("tensorboard", "tensorboard"),
    "wandb": LoggerSpec("wandb", "wandb"),
    "mlflow": LoggerSpec("mlflow", "mlflow"),
}
DEFAULT_LOGGERS = ("csv",)


def installed(module: str) -> bool:
    """Whether ``module`` can be imported (found without importing it)."""
    return importlib.util.find_spec(module) is not None


def check_loggers(names: Sequence[str], key: str = "experiment.loggers") -> tuple[str, ...]:
    """``names`` as a tuple, or :class:`ConfigError` naming ``key``: a name that is not a
    logger, one given twice, or a logger whose package is not installed (with the extra that
    installs it)."""
    if isinstance(names, str) or not isinstance(names, Sequence):
        raise ConfigError(f"{key}={names!r} must be a list of {', '.join(LOGGERS)}")
    shown = "[" + ",".join(str(n) for n in names) + "]"
    for name in names:
        if name not in LOGGERS:
            raise ConfigError(
                f"{key}={shown}: {name!r} is not a logger; choose from {', '.join(LOGGERS)}"
            )
        if list(names).count(name) > 1:
            raise ConfigError(f"{key}={shown} names {name} twice")
        spec = LOGGERS[name]
        if spec.module is not None and not installed(spec.module):
            raise ConfigError(
                f"{key}={shown}: {name} is not installed; pip install 'vdtn-marl[{spec.extra}]'"
            )
    return tuple(names)


def _scalars(row: Mapping[str, Any], skip: str | None) -> dict[str, float]:
    """The finite real numbers of ``row`` (bools and texts are left out), but ``skip``."""
    return {
        k: float(v)
        for k, v in row.items()
        if k != skip and isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
    }


class RunLoggers:
    """The TorchRL loggers of one run (``names`` from :data:`LOGGERS` but ``csv``), opened on
    the first scalar. ``run_name`` names the run in W&B and MLflow; ``hparams`` (a flat dict,
    the run's config) is their run config."""

    def __init__(
        self,
        names: Sequence[str],
        run_dir: str | Path,
        run_name: str,
        hparams: Mapping[str, Any] | None = None,
    ):
        self.names = tuple(n for n in check_loggers(names) if n != "csv")
        self.run_dir = Path(run_dir)
        self.run_name = run_name
        self.hparams = dict(hparams or {})
        self._loggers: list[Any] | None = None

    @property
    def opened(self) -> list[Any]:
        """The TorchRL loggers opened so far (none before the first scalar)."""
        return list(self._loggers or [])

    def _open(self) -> list[Any]:
        """Open every logger; one that cannot (W&B without a login, say) is dropped with one
        warning line: the run goes on, its CSV tables and results are not lost."""
        if self._loggers is None:
            self._loggers = []
            for name in self.names:
                try:
                    self._loggers.append(self._build(name))
                except Exception as err:  # noqa: BLE001 - any failure of a third-party logger
                    reason = (str(err).strip().splitlines() or [""])[0]
                    _log.warning(
                        "logger %s did not open (%s: %s); the run goes on without it "
                        "(its numbers are in metrics.csv and evaluation.csv)",
                        name, type(err).__name__, reason,
                    )  # fmt: skip
        return self._loggers

    def _build(self, name: str):
        from torchrl.record.loggers import get_logger

        run_dir = self.run_dir.resolve()
        if name == "tensorboard":
            return get_logger("tensorboard", str(run_dir), TENSORBOARD_DIR)
        if name == "wandb":
            project = os.environ.get("WANDB_PROJECT", PROJECT)
            options = {"project": project, "config": self.hparams}
            return get_logger("wandb", str(run_dir), self.run_name, wandb_kwargs=options)
        if name == "mlflow":
            import mlflow
            from torchrl.record.loggers import MLFlowLogger

            uri = os.environ.get("MLFLOW_TRACKING_URI") or f"sqlite:///{run_dir / MLFLOW_DB}"
            experiment = os.environ.get("MLFLOW_EXPERIMENT_NAME", PROJECT)
            logger = MLFlowLogger(
                experiment, uri, artifact_location=(run_dir / "mlartifacts").as_uri()
            )
            mlflow.set_tag("mlflow.runName", self.run_name)
            if self.hparams:
                logger.log_hparams({k: str(v) for k, v in self.hparams.items()})
            return logger
        raise ValueError(f"logger {name!r} is not one of {', '.join(LOGGERS)}")

    def log(self, row: Mapping[str, Any], step: int, prefix: str, skip: str | None = None):
        """Every finite number of ``row`` but ``skip`` as the scalar ``<prefix>/<key>`` at
        ``step``, to every logger."""
        if not self.names:
            return
        scalars = _scalars(row, skip)
        if not scalars:
            return
        for logger in self._open():
            for key, value in scalars.items():
                logger.log_scalar(f"{prefix}/{key}", value, step=step)
            flush = getattr(logger.experiment, "flush", None)
            if callable(flush):
                flush()

    def close(self) -> None:
        """Finish every opened logger (W&B and MLflow end their run, TensorBoard closes its
        event file)."""
        for logger in self._loggers or []:
            try:
                close = getattr(logger, "close", None)
                if callable(close):
                    close()
                else:  # TorchRL before 0.11: the logger's experiment ends itself
                    end = getattr(logger.experiment, "finish", None)
                    end = end or getattr(logger.experiment, "close", None)
                    if callable(end):
                        end()
            except Exception as err:  # a logger that fails to close loses no result
                _log.warning("logger %s did not close cleanly: %s", type(logger).__name__, err)
        mlflow = sys.modules.get("mlflow")  # TorchRL's MLFlowLogger leaves its run active
        if self._loggers and "mlflow" in self.names and mlflow is not None:
            if mlflow.active_run() is not None:
                mlflow.end_run()
        self._loggers = None
