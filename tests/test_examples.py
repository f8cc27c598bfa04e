"""The examples run as their docstrings say, and stay short enough to read top to bottom."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.py"))
MAX_LINES = 200


def test_there_are_examples():
    assert EXAMPLES


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_an_example_is_short(path):
    assert len(path.read_text(encoding="utf-8").splitlines()) <= MAX_LINES


def test_train_pi_star_torchrl_runs_and_compares_with_cacc(tmp_path):
    script = next(p for p in EXAMPLES if p.name == "train_pi_star_torchrl.py")
    args = ["--iterations", "2", "--num-envs", "4", "--steps", "20", "--eval-episodes", "4"]
    result = subprocess.run(
        [sys.executable, str(script), *args, "--validate-every", "1", "--device", "cpu"],
        cwd=tmp_path, capture_output=True, text=True, timeout=600,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    rows = re.findall(r"^\s+(\d+)\s+(-?\d\.\d{4})\s", result.stdout, flags=re.M)
    assert [int(i) for i, _ in rows] == [0, 1]  # one line per iteration
    scores = dict(re.findall(r"^\s+(pi_star|cacc)\b.*?(-?\d+\.\d{4})", result.stdout, flags=re.M))
    assert set(scores) == {"pi_star", "cacc"}
    assert all(math.isfinite(float(v)) and float(v) <= 0.0 for v in scores.values())
