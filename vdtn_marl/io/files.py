"""The files of a run: their names, atomic writes, reading them back, and the run's lock.

Every file a run writes goes through :func:`atomic_write_bytes` (a temporary file in the same
directory, then ``os.replace``), so an interrupted run never leaves a half-written summary,
checkpoint or table.
"""

from __future__ import annotations

import contextlib
import csv
import json
import math
import os
import secrets
import shlex
import sys
import tempfile
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from vdtn_marl.errors import RunDirInUse, RunFileError, RunWriteError

METRICS_FILE = "metrics.csv"
EVALUATION_FILE = "evaluation.csv"
RAW_EVALUATION_FILE = "evaluation_raw.npz"  # arrays of the last evaluation, for plots
SUMMARY_FILE = "summary.json"
CONFIG_FILE = "config.yaml"
CHECKPOINT_DIR = "checkpoints"
#: Files and folders whose presence means a folder holds a run (finished or not).
RUN_OUTPUTS = (CONFIG_FILE, SUMMARY_FILE, METRICS_FILE, EVALUATION_FILE, CHECKPOINT_DIR)


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


_RUN_STAMP: list[str] = []  # this launch's, once drawn


def new_run_stamp() -> str:
    """Draw the stamp of a new launch (:func:`run_stamp`) and return it."""
    stamp = f"{time.strftime('%Y-%m-%d_%H-%M-%S')}_{secrets.token_hex(3)}"
    _RUN_STAMP[:] = [stamp]
    return stamp


def run_stamp() -> str:
    """The default name of a run's folder (``conf/config.yaml``: ``hydra.run.dir``): the
    launch's local time and 6 random hex digits, ``2026-12-07_10-31-05_4f2a9c``, the same
    every time one launch asks (its config checks and its run), so that two launches in one
    second get two folders. The command line draws a new one per launch (:func:`new_run_stamp`)."""
    return _RUN_STAMP[0] if _RUN_STAMP else new_run_stamp()


LOCK_FILE = ".lock"
_HELD_LOCKS: dict[Path, list] = {}  # run dir → [open lock file, depth]


def _same_file(handle: Any, path: Path) -> bool:
    """Whether ``handle`` is still the file at ``path`` (a holder removes the lock file when it
    lets go: a handle opened just before is then a file no other launcher sees)."""
    try:
        here, there = os.fstat(handle.fileno()), os.stat(path)
    except FileNotFoundError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


def lock_holder(run_dir: str | Path) -> str | None:
    """The pid of the live process that holds ``run_dir``'s lock (:func:`run_lock`), or None
    (no lock file, a lock file left by a process that is gone, or this process's own lock).
    Writes nothing."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        return None
    path = Path(run_dir).resolve() / LOCK_FILE
    if path.parent in _HELD_LOCKS:
        return None
    try:
        handle = open(path, encoding="utf-8")  # noqa: SIM115 - closed below
    except OSError:
        return None
    with handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError:
            return handle.read().strip() or "unknown"
    return None


@contextlib.contextmanager
def run_lock(run_dir: str | Path) -> Iterator[None]:
    """Hold ``run_dir``'s lock (an exclusive ``flock`` on ``run_dir/.lock``, released when the
    process ends however it ends): a second process that tries to run in the same folder gets
    :class:`~vdtn_marl.errors.RunDirInUse` (a :class:`RunFileError`) naming the folder and the
    holder's pid. The lock file is removed when the block ends (a process killed before leaves
    one that locks nothing), and the folder too where the block created it and it is still
    empty. Re-entrant in one process; a no-op where ``fcntl`` is missing (Windows)."""
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
    created = not key.exists()
    key.mkdir(parents=True, exist_ok=True)
    path = key / LOCK_FILE
    while True:
        handle = open(path, "a+", encoding="utf-8")  # noqa: SIM115 - held until exit
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.seek(0)
            holder = handle.read().strip() or "unknown"
            handle.close()
            raise RunDirInUse(
                f"{key} is in use by another run (pid {holder}): two launchers must not write "
                "into one run directory; wait for it to end or pick another directory"
            ) from None
        if _same_file(handle, path):
            break
        handle.close()  # its holder removed it as we opened it: lock the new one
    handle.seek(0)
    handle.truncate()
    handle.write(f"{os.getpid()}\n")
    handle.flush()
    _HELD_LOCKS[key] = [handle, 1]
    try:
        yield
    finally:
        del _HELD_LOCKS[key]
        path.unlink(missing_ok=True)  # while still held: no other launcher holds this file
        handle.close()  # releases the flock
        if created:
            with contextlib.suppress(OSError):  # not empty: a run's files are there
                key.rmdir()


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
