"""The examples run as their docstrings say, and stay short enough to read top to bottom."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)

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


def test_my_rra_runs_as_its_docstring_says(tmp_path, monkeypatch):
    """examples/my_rra.py: the `vdtn-marl jocc` line of its docstring runs, and the policy is
    the allocation it describes."""
    import json
    import shlex

    import torch

    from vdtn_marl import cli
    from vdtn_marl.experiment.user_policy import load_policy
    from vdtn_marl.sim.layout import RRAFeatureLayout
    from vdtn_marl.sim.params import TwinParams

    script = next(p for p in EXAMPLES if p.name == "my_rra.py")
    line = next(
        line.strip() for line in script.read_text().splitlines() if "vdtn-marl jocc" in line
    )
    argv = shlex.split(line.replace("examples/my_rra.py", str(script)))[1:]
    monkeypatch.chdir(tmp_path)
    assert cli.main([*argv, "hydra.run.dir=run", "progress=false"]) == 0
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["rra"] == "policy" and summary["cam_delivery_rate"] > 0

    params = TwinParams()
    policy = load_policy("rra.policy", f"{script}:make_policy", params, seed=0)
    layout = RRAFeatureLayout.from_radio(params.radio)
    observation = torch.zeros(2, 3, layout.dim)
    observation[0, :, layout.bits_left] = 1.0  # scenario 0: every CAM pending; 1: delivered
    actions = policy(observation)
    levels = params.radio.num_power_levels
    assert actions[0].tolist() == [0 * levels, 1 * levels, 2 * levels]  # own sub-channel, 23 dBm
    assert (actions[1] % levels == levels - 1).all()  # silent once delivered: "off"
