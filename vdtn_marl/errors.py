"""The exceptions of vdtn-marl, in one place at the bottom of the package (it imports nothing
of ours, so every layer may raise them). Each message names the bad value and what is allowed.

The modules that raised them first still export them (``vdtn_marl.sim.params.ConfigError``,
``vdtn_marl.algos.checkpoint.CheckpointError``, ...): the same classes, not copies.
"""

from __future__ import annotations

from pathlib import Path


class ConfigError(ValueError):
    """A parameter value outside its allowed range; the message names key, value and range."""


class TraceFormatError(ValueError):
    """A trace file that cannot be read as the format it claims.

    ``row`` is the 1-based data row (header excluded), or ``None`` for problems with the file
    as a whole (a missing column, no data rows).
    """

    def __init__(self, path: str | Path, row: int | None, problem: str) -> None:
        self.path = Path(path)
        self.row = row
        self.problem = problem
        where = f"{self.path.name} row {row}" if row is not None else self.path.name
        super().__init__(f"{where}: {problem}")


class CheckpointError(ValueError):
    """A checkpoint that cannot be used; the message names the file and the problem."""


class RunFileError(ValueError):
    """A file of a run (metrics, evaluation, summary) that cannot be used to continue it; the
    message names the file, the problem and what to do."""


class RunDirInUse(RunFileError):
    """Another live process holds the run directory's lock (:func:`vdtn_marl.io.files.run_lock`)."""


class RunWriteError(OSError):
    """A run's file could not be written (a full disk, say); the previous version of the file,
    if any, is intact. The message names the file and the cause."""


class PolicyError(RuntimeError):
    """A policy of the user's own (``rra.policy``, ``control.policy``) that raised, or returned
    what the run cannot use, during a run; the message names the policy, the call and the
    problem (``problem``: the problem alone, with the allowed values)."""

    def __init__(self, message: str, problem: str = "") -> None:
        super().__init__(message)
        self.problem = problem or message


class UnknownEnvError(KeyError):
    """Raised for an id that is not registered; the message lists the known ids."""

    def __str__(self) -> str:  # KeyError would repr() the message
        return str(self.args[0]) if self.args else ""


class DeprecatedEnvError(UnknownEnvError):
    """Raised for an id that a newer version supersedes (Gymnasium's ``DeprecatedEnv``).

    A subclass of :class:`UnknownEnvError`, so code that handles unknown ids handles it too;
    the message names the new id, what changed, and how to get the old behaviour.
    """


class LeaderboardError(Exception):
    """A benchmark that cannot run or resume as asked; the message says why and what to do."""


class MissingExtraError(ImportError):
    """An optional library is missing (or does not import); the message names the extra that
    installs the tested versions (``pip install 'vdtn-marl[EXTRA]'``)."""

    def __init__(self, message: str, extra: str) -> None:
        super().__init__(message)
        self.extra = extra
