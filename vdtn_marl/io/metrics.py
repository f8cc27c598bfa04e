"""The metrics log of a run: rows of metrics rewritten atomically as a CSV table
(``metrics.csv``, ``evaluation.csv``), and TensorBoard scalars when it is installed."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from vdtn_marl.errors import RunFileError
from vdtn_marl.io.files import METRICS_FILE, atomic_write_text, read_csv_rows


class MetricsLog:
    """Rows of metrics kept in memory and rewritten atomically as ``metrics.csv``.

    Rows may have different keys; the header is the union in first-seen order. TensorBoard
    scalars are written too when ``tensorboard`` is installed (``tensorboard=True``).
    """

    def __init__(
        self,
        run_dir: str | Path,
        tensorboard: bool = True,
        rows: Iterable = (),
        filename: str = METRICS_FILE,
    ):
        self.path = Path(run_dir) / filename
        self.rows: list[dict[str, Any]] = [dict(r) for r in rows]
        self._run_dir = Path(run_dir)
        self._tensorboard = tensorboard
        self._writer = None  # opened on the first scalar: a run that logs none has no folder

    def _scalar_writer(self):
        """The TensorBoard writer, opened on first use; None when tensorboard is off or not
        installed."""
        if self._writer is None and self._tensorboard:
            try:
                from torch.utils.tensorboard import SummaryWriter
            except ImportError:  # tensorboard is optional
                self._tensorboard = False
                return None
            self._writer = SummaryWriter(log_dir=str(self._run_dir / "tensorboard"))
        return self._writer

    @classmethod
    def resume(
        cls,
        run_dir: str | Path,
        tensorboard: bool = True,
        filename: str = METRICS_FILE,
        expected_rows: int | None = None,
    ) -> MetricsLog:
        """Re-open a run's log, keeping the rows already written. A file that is not a whole
        CSV table, or that holds fewer than ``expected_rows`` rows (those a checkpoint
        counted), raises :class:`RunFileError` naming it."""
        path = Path(run_dir) / filename
        rows = read_csv_rows(path) if path.exists() else []
        if expected_rows is not None and len(rows) < expected_rows:
            state = f"holds {len(rows)} rows" if path.exists() else "is missing"
            raise RunFileError(
                f"{path} {state}, but the checkpoint counts {expected_rows}: the file was cut "
                "or edited; restore it, or start the run again in another directory"
            )
        return cls(run_dir, tensorboard=tensorboard, rows=rows, filename=filename)

    def log(self, row: Mapping[str, Any], step: int | None = None) -> None:
        self.rows.append(dict(row))
        scalars = {
            key: value
            for key, value in row.items()
            if isinstance(value, int | float) and not isinstance(value, bool)
        }
        writer = self._scalar_writer() if step is not None and scalars else None
        if writer is not None:
            for key, value in scalars.items():
                writer.add_scalar(key, value, step)
        self.flush()

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
        if self._writer is not None:
            self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
