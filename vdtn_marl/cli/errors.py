"""Errors of the ``vdtn-marl`` command line: :class:`CLIError`, printed as one line (exit code
2). The one-line messages themselves come from :func:`vdtn_marl.experiment.compose.translate`
(exported here too), which the leaderboard shares."""

from vdtn_marl.experiment.compose import translate

__all__ = ["CLIError", "translate"]


class CLIError(Exception):
    """A bad command line or config: printed as one ``error: ...`` line, exit code 2."""
