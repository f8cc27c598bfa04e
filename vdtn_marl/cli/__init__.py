"""The ``vdtn-marl`` command line: :mod:`.app` (the Hydra app, one command word per entry
point), :mod:`.prepass` (every job composed and validated before Hydra writes anything),
:mod:`.help` (help texts) and :mod:`.errors` (one-line errors). :func:`main` is the console
script's entry point.

Importing this package imports neither Hydra nor torch: :func:`main` catches Ctrl-C before it
imports the app (about two thirds of a command's start-up), and the app's names load on first
use.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence

EXIT_CONFIG_ERROR = 2
EXIT_INTERRUPTED = 130  # the shell's code for Ctrl-C (128 + SIGINT)

#: the app's names, importable from here, loaded on first use
_APP_NAMES = ("SweepSummaryHint", "bench_main", "split_command")
#: the line a Ctrl-C before a run started ends with
INTERRUPTED_BEFORE_START = "interrupted before the run started; nothing was written"

__all__ = ["EXIT_CONFIG_ERROR", "EXIT_INTERRUPTED", "INTERRUPTED_BEFORE_START", *_APP_NAMES, "main"]


def main(argv: Sequence[str] | None = None) -> int:
    """``vdtn-marl ARGS``. A Ctrl-C while the command's modules load stops it with exit code
    130 and one line, as in the rest of the command (:mod:`vdtn_marl.io.interrupts`), instead
    of a ``KeyboardInterrupt`` traceback from inside an import."""
    from vdtn_marl.io.interrupts import check_interrupt, graceful_interrupts

    try:
        with graceful_interrupts(lambda: INTERRUPTED_BEFORE_START):
            from vdtn_marl.cli.app import main as app_main

            check_interrupt()
    except KeyboardInterrupt:
        print(INTERRUPTED_BEFORE_START, file=sys.stderr)
        return EXIT_INTERRUPTED
    return app_main(argv)


def __getattr__(name: str):
    if name not in _APP_NAMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f"{__name__}.app"), name)


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_APP_NAMES))
