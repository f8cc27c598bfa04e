"""Ctrl-C at safe points.

Inside :func:`graceful_interrupts` the first SIGINT only sets a flag, which the training loop
reads at safe points (:func:`check_interrupt`, between PPO iterations and evaluation
intervals), so that it stops after saving a checkpoint and never inside a library call (where a
``KeyboardInterrupt`` can come out as another error); a second Ctrl-C stops at once.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from typing import Any


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
