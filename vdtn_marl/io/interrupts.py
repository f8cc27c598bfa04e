"""Ctrl-C and SIGTERM at safe points.

Inside :func:`graceful_interrupts` the first SIGINT (Ctrl-C) or SIGTERM (what ``kill``,
``timeout``, SLURM and Kubernetes send) only sets a flag, which the training loop reads at safe
points (:func:`check_interrupt`, between PPO iterations and evaluation intervals), so that it
stops after saving a checkpoint and never inside a library call (where a ``KeyboardInterrupt``
can come out as another error); both end the command the same way (exit code 130, the line
that continues the run). A second signal stops at once.
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


#: The signals :func:`graceful_interrupts` handles: Ctrl-C, and the polite stop of schedulers
#: (SLURM, Kubernetes) and ``timeout``.
SIGNALS = (signal.SIGINT, signal.SIGTERM)


def _on_signal(signum: int, frame: Any) -> None:
    if not _Interrupt.requested:
        _Interrupt.requested = True
        stopping = "stopping at the next safe point (after saving a checkpoint)"
        if signum == signal.SIGINT:
            line = f"{stopping}; press Ctrl-C again to stop now"
        else:
            name = signal.Signals(signum).name
            line = f"{name}: {stopping}; a second {name} or Ctrl-C stops now"
        print(f"\n{line}", file=sys.stderr, flush=True)
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
    """Inside, the first SIGINT or SIGTERM sets the flag :func:`check_interrupt` reads (and
    says so on stderr), so that it never raises inside an import or a library call; a second
    one prints ``on_force()`` (a line: where the run can continue from; the innermost block's)
    and ends the process at once with exit code 130. Blocks nest: the outermost installs the
    handler and restores the previous one on exit; a signal received in an outer block is
    still seen in an inner one. Outside the main thread it changes nothing, and a signal that
    is ignored (SIGINT of a job started with ``&``, say) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {signum: signal.getsignal(signum) for signum in SIGNALS}
    installed = [
        signum
        for signum, handler in previous.items()
        if handler is not signal.SIG_IGN and handler is not _on_signal
    ]
    if not any(handler is _on_signal for handler in previous.values()):
        _Interrupt.requested = False  # the outermost block
    for signum in installed:
        signal.signal(signum, _on_signal)
    _Interrupt.hints.append(on_force)
    try:
        yield
    finally:
        _Interrupt.hints.pop()
        for signum in installed:
            signal.signal(signum, previous[signum])
        if installed and not any(h is _on_signal for h in map(signal.getsignal, SIGNALS)):
            _Interrupt.requested = False
