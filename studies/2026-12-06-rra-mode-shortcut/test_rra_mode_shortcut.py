"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-06-rra-mode-shortcut/test_rra_mode_shortcut.py``."""

import importlib.util
import json
from pathlib import Path

import pytest
import torch

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_rra_mode_shortcut_refuses_batch_sizes_that_do_not_divide_the_frames(capsys):
    module = _script("rra_mode_shortcut.py")
    with pytest.raises(SystemExit):
        module.parse_args(["--batch-sizes", "3", "--frames", "16"])
    assert "--batch-sizes" in capsys.readouterr().err


def test_rra_mode_shortcut_reference_arm_computes_the_probabilities_every_call():
    """The reference arm turns the shortcut and the binding off, and restores both."""
    from vdtn_marl.algos import networks
    from vdtn_marl.algos.ppo import ActorPolicy

    module = _script("rra_mode_shortcut.py")
    separated = torch.tensor([[0.0, 3.0, -1.0]])
    assert networks.mode_shortcut(separated) is not None
    shipped_bound = ActorPolicy.bound
    with module.reference():
        assert networks.mode_shortcut(separated) is None
        assert ActorPolicy.bound(policy := object()) is policy
    assert networks.mode_shortcut(separated) is not None
    assert ActorPolicy.bound is shipped_bound


@pytest.mark.slow
def test_rra_mode_shortcut_times_both_arms_on_the_same_iterations(tmp_path):
    module = _script("rra_mode_shortcut.py")
    out = tmp_path / "m.json"
    argv = ["--batch-sizes", "8", "--frames", "16", "--repeats", "2", "--out", str(out)]
    assert module.main(argv) == 0
    (row,) = json.loads(out.read_text())["rows"]
    assert len(row["reference"]) == len(row["shipped"]) == 2
    assert row["actions_bit_identical"] is True
    # the shipped arm's calls: 50 subframes of 2 intervals per iteration at least
    assert row["mode_calls"] >= 2 * 2 * 50 and 0 <= row["long_way_calls"] <= row["mode_calls"]
    assert row["reference_over_shipped"] > 0
