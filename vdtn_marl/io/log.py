"""The run log and the progress bars.

The package logs with :mod:`logging` under ``vdtn_marl.*``, a few lines per stage and
checkpoint (:func:`logged_stage`, :func:`metrics_line`), never per PPO iteration. Inside the
CLI, Hydra sends them to the run's ``<command>.log``; :func:`keep_log_off_console` keeps them
off the terminal while progress bars (:func:`progress`) show the same progress.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

#: Root of the package's loggers.
LOGGER = "vdtn_marl"

_log = logging.getLogger(__name__)


def progress(total: int, description: str, enabled: bool = True):
    """A tqdm progress bar on the terminal (disabled when ``enabled`` is False)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=description, disable=not enabled, dynamic_ncols=True, leave=True)


@contextlib.contextmanager
def logged_stage(stage: str, detail: str, jocc_iteration: int) -> Iterator[None]:
    """Log one line when a stage starts and one when it ends, with its wall time (s).

    ``detail`` says what the stage does, e.g. ``"π* for 40 PPO iterations"``."""
    _log.info("JOCC iteration %d, stage %s: %s", jocc_iteration, stage, detail)
    began = time.perf_counter()
    yield
    seconds = time.perf_counter() - began
    _log.info("JOCC iteration %d, stage %s done in %.1f s", jocc_iteration, stage, seconds)


def metrics_line(metrics: Mapping[str, Any], keys: Sequence[str]) -> str:
    """``key=value`` for each of ``keys`` found in ``metrics`` (4 significant digits)."""

    def fmt(value: Any) -> str:
        return f"{value:.4g}" if isinstance(value, float) else str(value)

    return ", ".join(f"{key}={fmt(metrics[key])}" for key in keys if key in metrics)


class _PackageRecords(logging.Filter):
    """Drops the package's records below WARNING (progress bars show that progress)."""

    def filter(self, record: logging.LogRecord) -> bool:
        package = record.name == LOGGER or record.name.startswith(LOGGER + ".")
        return not package or record.levelno >= logging.WARNING


def keep_log_off_console(progress: bool) -> None:
    """With progress bars (``progress``), keep the package's INFO lines off the terminal
    handlers of the root logger; files (Hydra's ``<command>.log``) still get them. Without
    progress bars the terminal shows them instead (e.g. a SLURM job's output)."""
    for handler in logging.getLogger().handlers:
        if isinstance(handler, logging.FileHandler) or not isinstance(
            handler, logging.StreamHandler
        ):
            continue
        for old in [f for f in handler.filters if isinstance(f, _PackageRecords)]:
            handler.removeFilter(old)
        if progress:
            handler.addFilter(_PackageRecords())
