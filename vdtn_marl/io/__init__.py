"""What a run reads and writes, and how it talks to the terminal: the files of a run, written
atomically, and its lock (:mod:`.files`), the metrics log (:mod:`.metrics`), Ctrl-C at safe
points (:mod:`.interrupts`), the run log and the progress bars (:mod:`.log`).

The bottom of the house beside ``data/``: it imports nothing of the package but its errors, so
every room may use it. Every name is importable from :mod:`vdtn_marl.io`; modules of the
package import from the module that defines it.
"""

from vdtn_marl.io.files import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    EVALUATION_FILE,
    LOCK_FILE,
    METRICS_FILE,
    RAW_EVALUATION_FILE,
    RUN_OUTPUTS,
    SUMMARY_FILE,
    TEMP_PATTERN,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    check_summary_file,
    read_csv_rows,
    read_json,
    remove_stale_temp_files,
    run_lock,
    run_outputs,
    script_command,
)
from vdtn_marl.io.interrupts import check_interrupt, graceful_interrupts, interrupt_requested
from vdtn_marl.io.log import LOGGER, keep_log_off_console, logged_stage, metrics_line, progress
from vdtn_marl.io.metrics import MetricsLog

__all__ = [
    "CHECKPOINT_DIR",
    "CONFIG_FILE",
    "EVALUATION_FILE",
    "LOCK_FILE",
    "LOGGER",
    "METRICS_FILE",
    "MetricsLog",
    "RAW_EVALUATION_FILE",
    "RUN_OUTPUTS",
    "SUMMARY_FILE",
    "TEMP_PATTERN",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "check_interrupt",
    "check_summary_file",
    "graceful_interrupts",
    "interrupt_requested",
    "keep_log_off_console",
    "logged_stage",
    "metrics_line",
    "progress",
    "read_csv_rows",
    "read_json",
    "remove_stale_temp_files",
    "run_lock",
    "run_outputs",
    "script_command",
]
