"""Run outputs: atomic files, the metrics CSV (and TensorBoard when installed), progress bars,
and the run log.

Ctrl-C (:func:`graceful_interrupts`): the first SIGINT only sets a flag, which the training
loop reads at safe points (:func:`check_interrupt`, between PPO iterations and evaluation
intervals), so that it stops after saving a checkpoint and never inside a library call (where a
``KeyboardInterrupt`` can come out as another error); a second Ctrl-C stops at once.

Every file a run writes goes through :func:`atomic_write_bytes` (a temporary file in the same
directory, then ``os.replace``), so an interrupted run never leaves a half-written summary,
checkpoint or table.

The run log: the package logs with :mod:`logging` under ``vdtn_marl.*``, a few lines per stage
and checkpoint (:func:`logged_stage`, :func:`metrics_line`), never per PPO iteration. Inside
the CLI, Hydra sends them to the run's ``<command>.log``; :func:`keep_log_off_console` keeps
them off the terminal while progress bars show the same progress.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import logging
import math
import os
import shlex
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from vdtn_marl.errors import RunFileError, RunWriteError

METRICS_FILE = "metrics.csv"
EVALUATION_FILE = "evaluation.csv"
RAW_EVALUATION_FILE = "evaluation_raw.npz"  # arrays of the last evaluation, for plots
SUMMARY_FILE = "summary.json"
CONFIG_FILE = "config.yaml"
CHECKPOINT_DIR = "checkpoints"
#: Files and folders whose presence means a folder holds a run (finished or not).
RUN_OUTPUTS = (CONFIG_FILE, SUMMARY_FILE, METRICS_FILE, EVALUATION_FILE, CHECKPOINT_DIR)
#: Root of the package's loggers.
LOGGER = "vdtn_marl"

_log = logging.getLogger(__name__)


def run_outputs(run_dir: str | Path) -> list[str]:
    """The names of :data:`RUN_OUTPUTS` present in ``run_dir`` (empty: it holds no run)."""
    return [name for name in RUN_OUTPUTS if (Path(run_dir) / name).exists()]


#: Temporary files of :func:`atomic_write_bytes` (``.<name>.<random>.tmp``).
TEMP_PATTERN = ".*.tmp"


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + ``os.replace``): a reader, or a
    run killed at any point, sees the old file or the new one, never a part. An ``OSError``
    (no space left, say) comes out as :class:`RunWriteError` naming ``path``."""
    path = Path(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; give the usual file mode
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        kept = "its previous version is intact" if path.exists() else "nothing was written"
        raise RunWriteError(
            exc.errno, f"cannot write {path}: {exc.strerror or exc}; {kept}"
        ) from exc
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise
    return path


def remove_stale_temp_files(run_dir: str | Path) -> list[Path]:
    """Remove the temporary files a killed writer left in ``run_dir`` (and its checkpoint
    folder); returns them. Only call it while holding the run's lock (:func:`run_lock`)."""
    run_dir = Path(run_dir)
    stale = [*run_dir.glob(TEMP_PATTERN), *(run_dir / CHECKPOINT_DIR).glob(TEMP_PATTERN)]
    for path in stale:
        path.unlink(missing_ok=True)
    return stale


LOCK_FILE = ".lock"
_HELD_LOCKS: dict[Path, list] = {}  # run dir → [open lock file, depth]


@contextlib.contextmanager
def run_lock(run_dir: str | Path) -> Iterator[None]:
    """Hold ``run_dir``'s lock (an exclusive ``flock`` on ``run_dir/.lock``, released when the
    process ends however it ends): a second process that tries to run in the same folder gets
    :class:`RunFileError` naming the folder and the holder's pid. Re-entrant in one process;
    a no-op where ``fcntl`` is missing (Windows)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    key = Path(run_dir).resolve()
    held = _HELD_LOCKS.get(key)
    if held is not None:
        held[1] += 1
        try:
            yield
        finally:
            held[1] -= 1
        return
    key.mkdir(parents=True, exist_ok=True)
    handle = open(key / LOCK_FILE, "a+", encoding="utf-8")  # noqa: SIM115 - held until exit
    try:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        handle.seek(0)
        holder = handle.read().strip() or "unknown"
        handle.close()
        raise RunFileError(
            f"{key} is in use by another run (pid {holder}): two launchers must not write "
            "into one run directory; wait for it to end or pick another directory"
        ) from None
    handle.seek(0)
    handle.truncate()
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    _HELD_LOCKS[key] = [handle, 1]
    try:
        yield
    finally:
        del _HELD_LOCKS[key]
        handle.close()  # releases the flock


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def _json_safe(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json_safe(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy / torch scalars
        return _json_safe(value.item())
    return value


def script_command() -> str:
    """The running script's command line as a user would type it: ``python <argv...>``, shell-
    quoted, without the interpreter's path (which names one machine's environment)."""
    return "python " + shlex.join(sys.argv)


def atomic_write_json(path: str | Path, data: Any) -> Path:
    """JSON with non-finite floats written as ``null`` (strict JSON readers accept it)."""
    return atomic_write_text(path, json.dumps(_json_safe(data), indent=2, sort_keys=False) + "\n")


def read_json(path: str | Path) -> Any:
    with open(path, encoding="utf-8") as handle:
        return json.load(handle)


def read_csv_rows(path: str | Path) -> list[dict[str, str]]:
    """The rows of a run's CSV table (:class:`MetricsLog`); :class:`RunFileError` naming the
    file and the first bad row when it is not a whole table (binary, cut, fields that do not
    match the header)."""
    try:
        with open(path, newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            rows = list(reader)
            header = reader.fieldnames or []
    except (csv.Error, UnicodeDecodeError, ValueError) as exc:
        raise RunFileError(
            f"{path} is damaged ({exc}); restore it, or start the run again in another directory"
        ) from None
    for number, row in enumerate(rows, start=2):
        if None in row or any(value is None for value in row.values()) or "\0" in str(row):
            raise RunFileError(
                f"{path} is damaged: row {number} does not match its header of {len(header)} "
                "columns; restore it, or start the run again in another directory"
            )
    return rows


def check_summary_file(run_dir: str | Path) -> None:
    """A run being continued may hold ``summary.json`` (it ended before); one that is not
    valid JSON raises :class:`RunFileError` naming it."""
    path = Path(run_dir) / SUMMARY_FILE
    if not path.exists():
        return
    try:
        data = read_json(path)
    except (OSError, ValueError) as exc:
        raise RunFileError(
            f"{path} is damaged ({type(exc).__name__}: {exc}); remove it and continue the run: "
            "it is written again when the run ends"
        ) from None
    if not isinstance(data, dict):
        raise RunFileError(
            f"{path} is damaged (not a JSON object); remove it and continue the run: it is "
            "written again when the run ends"
        )


class MetricsLog:
    """Rows of metrics kept in memory and rewritten atomically as ``metrics.csv``.

    Rows may have different keys; the header is the union in first-seen order. TensorBoard
    scalars are written too when ``tensorboard`` is installed (``tensorboard=True``).
    """

    def __init__(
        self,
        run_dir: str | Path,
        tensorboard: bool = True,
        rows: Iterable = (),
        filename: str = METRICS_FILE,
    ):
        self.path = Path(run_dir) / filename
        self.rows: list[dict[str, Any]] = [dict(r) for r in rows]
        self._run_dir = Path(run_dir)
        self._tensorboard = tensorboard
        self._writer = None  # opened on the first scalar: a run that logs none has no folder

    def _scalar_writer(self):
        """The TensorBoard writer, opened on first use; None when tensorboard is off or not
        installed."""
        if self._writer is None and self._tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter
            except ImportError:  # tensorboard is optional
                self._tensorboard = False
                return None
            self._writer = SummaryWriter(log_dir=str(self._run_dir / "tensorboard"))
        return self._writer

    @classmethod
    def resume(
        cls,
        run_dir: str | Path,
        tensorboard: bool = True,
        filename: str = METRICS_FILE,
        expected_rows: int | None = None,
    ) -> MetricsLog:
        """Re-open a run's log, keeping the rows already written. A file that is not a whole
        CSV table, or that holds fewer than ``expected_rows`` rows (those a checkpoint
        counted), raises :class:`RunFileError` naming it."""
        path = Path(run_dir) / filename
        rows = read_csv_rows(path) if path.exists() else []
        if expected_rows is not None and len(rows) < expected_rows:
            state = f"holds {len(rows)} rows" if path.exists() else "is missing"
            raise RunFileError(
                f"{path} {state}, but the checkpoint counts {expected_rows}: the file was cut "
                "or edited; restore it, or start the run again in another directory"
            )
        return cls(run_dir, tensorboard=tensorboard, rows=rows, filename=filename)

    def log(self, row: Mapping[str, Any], step: int | None = None) -> None:
        self.rows.append(dict(row))
        scalars = {
            key: value
            for key, value in row.items()
            if isinstance(value, int | float) and not isinstance(value, bool)
        }
        writer = self._scalar_writer() if step is not None and scalars else None
        if writer is not None:
            for key, value in scalars.items():
                writer.add_scalar(key, value, step)
        self.flush()

    def truncate(self, keep: int) -> None:
        """Drop rows after the first ``keep`` (a resumed run rewrites what it repeats)."""
        self.rows = self.rows[:keep]
        self.flush()

    def flush(self) -> None:
        header: list[str] = []
        for row in self.rows:
            header.extend(k for k in row if k not in header)
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=header)
        writer.writeheader()
        writer.writerows(self.rows)
        atomic_write_text(self.path, buffer.getvalue())
        if self._writer is not None:
            self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()


def progress(total: int, description: str, enabled: bool = True):
    """A tqdm progress bar on the terminal (disabled when ``enabled`` is False)."""
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=description, disable=not enabled, dynamic_ncols=True, leave=True)


# --- Ctrl-C ----------------------------------------------------------------------------------


class _Interrupt:
    """The process's Ctrl-C state: whether a stop was asked for, and the hints of the
    :func:`graceful_interrupts` blocks in force (innermost last)."""

    requested = False
    hints: list = []


def interrupt_requested() -> bool:
    """Whether Ctrl-C was pressed inside :func:`graceful_interrupts` (and not yet acted on)."""
    return _Interrupt.requested


def check_interrupt() -> None:
    """Raise ``KeyboardInterrupt`` here, at a safe point, if Ctrl-C was pressed."""
    if _Interrupt.requested:
        _Interrupt.requested = False
        raise KeyboardInterrupt


def _on_sigint(signum: int, frame: Any) -> None:
    if not _Interrupt.requested:
        _Interrupt.requested = True
        print(
            "\nstopping at the next safe point (after saving a checkpoint); "
            "press Ctrl-C again to stop now",
            file=sys.stderr,
            flush=True,
        )
        return
    line = "interrupted again: stopped now"
    hint = next((h for h in reversed(_Interrupt.hints) if h is not None), None)
    if hint is not None:
        with contextlib.suppress(Exception):
            line = f"{line}; {hint()}"
    print(line, file=sys.stderr, flush=True)
    os._exit(130)


@contextlib.contextmanager
def graceful_interrupts(on_force: Any = None) -> Iterator[None]:
    """Inside, the first SIGINT sets the flag :func:`check_interrupt` reads (and says so on
    stderr), so that it never raises inside an import or a library call; a second one prints
    ``on_force()`` (a line: where the run can continue from; the innermost block's) and ends
    the process at once with exit code 130. Blocks nest: the outermost installs the handler
    and restores the previous one on exit; a Ctrl-C pressed in an outer block is still seen
    in an inner one. Outside the main thread, or where SIGINT is ignored, it changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if previous is signal.SIG_IGN:
        yield
        return
    outermost = previous is not _on_sigint
    if outermost:
        _Interrupt.requested = False
        signal.signal(signal.SIGINT, _on_sigint)
    _Interrupt.hints.append(on_force)
    try:
        yield
    finally:
        _Interrupt.hints.pop()
        if outermost:
            signal.signal(signal.SIGINT, previous)
            _Interrupt.requested = False


# --- the run log ---------------------------------------------------------------------------


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
