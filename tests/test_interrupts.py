"""Ctrl-C with real signals: a run stops at a safe point with exit code 130 and a one-line hint,
never a traceback, wherever the signal lands; the hint's command continues the run; a second
Ctrl-C stops at once (vdtn_marl.io.interrupts.graceful_interrupts)."""

from __future__ import annotations

import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [
    pytest.mark.slow,  # runs of the CLI or of training (the fast loop skips them)
    pytest.mark.skipif(os.name != "posix", reason="POSIX signals"),
]

SCRIPT = Path(sys.executable).with_name("vdtn-marl")
ENV = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200", "OMP_NUM_THREADS": "1"}


def _command() -> list[str]:
    if SCRIPT.exists():
        return [str(SCRIPT)]
    return [sys.executable, "-c", "from vdtn_marl.cli import main; raise SystemExit(main())"]


def _start(run: Path, iterations: int) -> subprocess.Popen:
    args = [
        "jocc", "experiment=smoke", f"experiment.control_iterations={iterations}",
        f"experiment.rra_iterations={iterations}", "progress=false", f"hydra.run.dir={run}",
    ]  # fmt: skip
    return subprocess.Popen(
        [*_command(), *args], cwd=run.parent, env=ENV, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE,
    )  # fmt: skip


def _last_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    return lines[-1] if lines else ""


def _interrupt(proc: subprocess.Popen, delay: float) -> tuple[int, str]:
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=180)
    return proc.returncode, err


@pytest.mark.parametrize("delay", [1.0, 2.0, 3.0, 4.5, 6.0, 8.0, 11.0])
def test_ctrl_c_anywhere_exits_130_with_one_hint(delay, tmp_path):
    """From the command's first step (its config checks) to the middle of training (the run
    would last minutes), whichever phase the signal lands in: exit 130, no traceback, the last
    line says what to do. (Before that, in the interpreter's start-up and the import of
    ``vdtn_marl.cli``, about 0.1 s on a quiet machine, Python's own KeyboardInterrupt applies,
    as for any Python program.)"""
    run = tmp_path / "run"
    code, err = _interrupt(_start(run, iterations=400), delay)
    assert code == 130, err
    assert "Traceback" not in err and "RuntimeError" not in err, err
    last = _last_line(err)
    assert last.startswith("interrupted"), err
    checkpoint = run / "checkpoints" / "last.pt"
    if checkpoint.is_file():  # stopped at a safe point after saving: the hint names it
        assert f"the last checkpoint is {checkpoint}" in last and "continue with: " in last, err
        assert not list(checkpoint.parent.glob("*.tmp*")), "a half-written checkpoint is left"


def test_ctrl_c_while_the_app_is_imported_exits_130_with_one_line(tmp_path):
    """The console script catches Ctrl-C before it imports the app (Hydra, torch: most of a
    command's start-up): a SIGINT that lands inside that import, here sent by an import hook
    when Hydra is first imported, ends the command with 130 and one line, no traceback."""
    code = (
        "import os, signal, sys, time\n"
        "class Hook:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'hydra':\n"
        "            os.kill(os.getpid(), signal.SIGINT)\n"
        "            time.sleep(0.2)\n"
        "        return None\n"
        "from vdtn_marl.cli import main\n"
        "assert 'hydra' not in sys.modules, 'vdtn_marl.cli imports Hydra before main() runs'\n"
        "sys.meta_path.insert(0, Hook())\n"
        "raise SystemExit(main(['jocc', 'experiment=smoke', 'hydra.run.dir=run']))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], cwd=tmp_path, env=ENV, text=True, capture_output=True,
        timeout=120,
    )  # fmt: skip
    assert done.returncode == 130, done.stderr
    assert "Traceback" not in done.stderr, done.stderr
    assert _last_line(done.stderr) == "interrupted before the run started; nothing was written"
    assert not (tmp_path / "run").exists()


def test_the_hint_continues_an_interrupted_run_to_its_end(tmp_path):
    run = tmp_path / "run"
    proc = _start(run, iterations=12)
    deadline = time.monotonic() + 120
    while not (run / "metrics.csv").is_file():  # training has begun
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()[1]
        time.sleep(0.05)
    code, err = _interrupt(proc, 0.5)
    assert code == 130, err
    last = _last_line(err)
    assert "continue with: " in last, err
    again = shlex.split(last.split("continue with: ")[1])
    assert again[0] == "vdtn-marl" and "resume=true" in again
    done = subprocess.run(
        [*_command(), *again[1:]], cwd=tmp_path, env=ENV, text=True, capture_output=True,
        timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert (run / "summary.json").is_file()


def test_a_second_ctrl_c_stops_at_once_with_the_hint():
    code = (
        "import os, signal, time\n"
        "from vdtn_marl.io.interrupts import graceful_interrupts, interrupt_requested\n"
        "with graceful_interrupts(lambda: 'HINT'):\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "    time.sleep(0.2)\n"
        "    assert interrupt_requested()\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "    time.sleep(5)\n"
        "print('not stopped')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], env=ENV, text=True, capture_output=True, timeout=60
    )
    assert done.returncode == 130, done.stderr
    assert "not stopped" not in done.stdout
    assert "press Ctrl-C again to stop now" in done.stderr
    assert _last_line(done.stderr) == "interrupted again: stopped now; HINT"


def test_outside_the_handler_ctrl_c_is_an_ordinary_keyboard_interrupt():
    from vdtn_marl.io.interrupts import check_interrupt, graceful_interrupts, interrupt_requested

    before = signal.getsignal(signal.SIGINT)
    with graceful_interrupts():
        assert signal.getsignal(signal.SIGINT) is not before
        signal.raise_signal(signal.SIGINT)  # handled: sets the flag only
        assert interrupt_requested()
        with pytest.raises(KeyboardInterrupt):
            check_interrupt()
        assert not interrupt_requested()
    assert signal.getsignal(signal.SIGINT) is before


def test_nested_blocks_keep_a_ctrl_c_of_the_outer_one():
    """The CLI's block covers the config checks, the job's block the run: a Ctrl-C pressed
    before the job starts is still seen (and acted on) inside it."""
    from vdtn_marl.io.interrupts import check_interrupt, graceful_interrupts, interrupt_requested

    before = signal.getsignal(signal.SIGINT)
    with graceful_interrupts(lambda: "outer"):
        signal.raise_signal(signal.SIGINT)
        with graceful_interrupts(lambda: "inner"):
            assert interrupt_requested()
            with pytest.raises(KeyboardInterrupt):
                check_interrupt()
        assert signal.getsignal(signal.SIGINT) is not before  # still the outer block's
    assert signal.getsignal(signal.SIGINT) is before and not interrupt_requested()


# --- SIGTERM (kill, timeout, SLURM, Kubernetes) stops as Ctrl-C does --------------------------


def test_sigterm_sets_the_flag_like_ctrl_c():
    code = (
        "import os, signal, time\n"
        "from vdtn_marl.io.interrupts import graceful_interrupts, interrupt_requested\n"
        "with graceful_interrupts(lambda: 'HINT'):\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(0.2)\n"
        "    print('flag', interrupt_requested(), flush=True)\n"
        "    os.kill(os.getpid(), signal.SIGTERM)\n"
        "    time.sleep(5)\n"
        "print('not stopped')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], env=ENV, text=True, capture_output=True, timeout=60
    )
    assert done.returncode == 130, done.stderr
    assert done.stdout.split() == ["flag", "True"]
    assert "SIGTERM: stopping at the next safe point" in done.stderr
    assert _last_line(done.stderr) == "interrupted again: stopped now; HINT"


def test_sigterm_during_training_keeps_a_checkpoint_and_says_how_to_continue(tmp_path):
    run = tmp_path / "run"
    proc = _start(run, iterations=400)
    deadline = time.monotonic() + 120
    while not (run / "metrics.csv").is_file():  # training has begun
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()[1]
        time.sleep(0.05)
    time.sleep(0.5)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=180)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "leaked" not in err, err
    checkpoint = run / "checkpoints" / "last.pt"
    last = _last_line(err)
    assert checkpoint.is_file() and f"the last checkpoint is {checkpoint}" in last, err
    assert "continue with: " in last and "resume=true" in last, err
