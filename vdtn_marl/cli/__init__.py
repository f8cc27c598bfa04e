"""The ``vdtn-marl`` command line: :mod:`.app` (the Hydra app, one command word per entry
point), :mod:`.prepass` (every job composed and validated before Hydra writes anything),
:mod:`.help` (help texts), :mod:`.errors` (one-line errors) and :mod:`.codes` (exit codes).
:func:`main` is the console script's entry point.

Importing this package imports neither Hydra nor torch: :func:`main` catches Ctrl-C before it
imports the app (about two thirds of a command's start-up), and the app's names load on first
use.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

from vdtn_marl._lazy import lazy_exports
from vdtn_marl.cli.codes import EXIT_CONFIG_ERROR, EXIT_INTERRUPTED, INTERRUPTED_BEFORE_START

#: the app's names, importable from here, loaded on first use (name → module)
_HOMES = dict.fromkeys(("SweepSummaryHint", "bench_main", "split_command"), "app")

__all__ = ["EXIT_CONFIG_ERROR", "EXIT_INTERRUPTED", "INTERRUPTED_BEFORE_START", *_HOMES, "main"]


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


__getattr__, __dir__ = lazy_exports(__name__, _HOMES)
