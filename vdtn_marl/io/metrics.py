"""The metrics log of a run: rows of metrics rewritten atomically as a CSV table
(``metrics.csv``, ``evaluation.csv``), the source of the run's plots, and the same rows as
scalars to the run's other loggers (:mod:`.loggers`: TensorBoard, W&B, MLflow)."""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from vdtn_marl.errors import RunFileError
from vdtn_marl.io.files import METRICS_FILE, atomic_write_text, read_csv_rows
from vdtn_marl.io.loggers import RunLoggers

#: A cell of a table that :class:`csv.DictWriter` wrote from a number (``nan``, ``inf`` too).
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*(e[-+]?\d+)?|\.\d+(e[-+]?\d+)?|nan|inf)", re.IGNORECASE)
_INTEGER = re.compile(r"[-+]?\d+")


def parse_cell(text: str) -> Any:
    """A cell of a run's table as the value that was logged: an int, a float (``nan`` too), a
    bool, None (an empty cell: the row had no such key) or the text itself. ``str`` of each
    gives the cell back, so a table read and rewritten is the same."""
    if text == "":
        return None
    if text in ("True", "False"):
        return text == "True"
    if _INTEGER.fullmatch(text):
        return int(text)
    if _NUMBER.fullmatch(text):
        return float(text)
    return text


class MetricsLog:
    """Rows of metrics kept in memory and rewritten atomically as ``metrics.csv``.

    Rows may have different keys; the header is the union in first-seen order. With
    ``loggers`` (shared by the logs of a run), a row logged with a ``step`` goes to them too,
    its numbers as the scalars ``<prefix>/<key>``.
    """

    def __init__(
        self,
        run_dir: str | Path,
        rows: Iterable = (),
        filename: str = METRICS_FILE,
        loggers: RunLoggers | None = None,
    ):
        self.path = Path(run_dir) / filename
        self.rows: list[dict[str, Any]] = [dict(r) for r in rows]
        self.loggers = loggers

    @classmethod
    def resume(
        cls,
        run_dir: str | Path,
        filename: str = METRICS_FILE,
        expected_rows: int | None = None,
        loggers: RunLoggers | None = None,
    ) -> MetricsLog:
        """Re-open a run's log, keeping the rows already written (their numbers as numbers,
        :func:`parse_cell`). A file that is not a whole CSV table, or that holds fewer than
        ``expected_rows`` rows (those a checkpoint counted), raises :class:`RunFileError`
        naming it."""
        path = Path(run_dir) / filename
        text_rows = read_csv_rows(path) if path.exists() else []
        rows = [{k: parse_cell(v) for k, v in row.items()} for row in text_rows]
        if expected_rows is not None and len(rows) < expected_rows:
            state = f"holds {len(rows)} rows" if path.exists() else "is missing"
            raise RunFileError(
                f"{path} {state}, but the checkpoint counts {expected_rows}: the file was cut "
                "or edited; restore it, or start the run again in another directory"
            )
        return cls(run_dir, rows=rows, filename=filename, loggers=loggers)

    def log(
        self,
        row: Mapping[str, Any],
        step: int | None = None,
        prefix: str = "",
        step_key: str | None = None,
    ) -> None:
        """Append ``row`` and rewrite the table; with a ``step``, send its numbers (but
        ``step_key``, the one that holds the step) to the loggers as ``<prefix>/<key>``."""
        self.rows.append(dict(row))
        self.flush()
        if self.loggers is not None and step is not None:
            self.loggers.log(row, step, prefix, skip=step_key)

    def truncate(self, keep: int) -> None:
        """Drop rows after the first ``keep`` (a resumed run rewrites what it repeats)."""
        self.rows = self.rows[:keep]
        self.flush()

    def flush(self) -> None:
        header: list[str] = []
        for row in self.rows:
            header.extend(k for k in row if k not in header)
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=header)
        writer.writeheader()
        writer.writerows(self.rows)
        atomic_write_text(self.path, buffer.getvalue())
