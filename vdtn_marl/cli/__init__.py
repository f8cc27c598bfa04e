"""The ``vdtn-marl`` command line: :mod:`.app` (the Hydra app, one command word per entry
point), :mod:`.prepass` (every job composed and validated before Hydra writes anything),
:mod:`.help` (help texts) and :mod:`.errors` (one-line errors). ``main`` is the console
script's entry point.
"""

from vdtn_marl.cli.app import (
    EXIT_CONFIG_ERROR,
    EXIT_INTERRUPTED,
    SweepSummaryHint,
    bench_main,
    main,
    split_command,
)

__all__ = [
    "EXIT_CONFIG_ERROR",
    "EXIT_INTERRUPTED",
    "SweepSummaryHint",
    "bench_main",
    "main",
    "split_command",
]
