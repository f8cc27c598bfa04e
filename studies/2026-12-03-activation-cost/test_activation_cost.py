"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-03-activation-cost/test_activation_cost.py``."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


activation = _script("activation_cost.py")


def test_activation_ratios_are_tanhs_time_over_the_others_in_the_same_repeat():
    runs = [
        {"part": "k", "name": "tanh", "repeat": 0, "us": 100.0},
        {"part": "k", "name": "tanh_sigmoid", "repeat": 0, "us": 25.0},
        {"part": "k", "name": "tanh", "repeat": 1, "us": 300.0},  # a slow repeat for both
        {"part": "k", "name": "tanh_sigmoid", "repeat": 1, "us": 100.0},
        {"part": "k", "name": "tanh", "repeat": 2, "us": 120.0},
        {"part": "k", "name": "tanh_sigmoid", "repeat": 2, "us": 60.0},
    ]
    rows = {r["name"]: r for r in activation._ratio_rows(runs, "us")}
    assert rows["tanh"]["tanh_over_this"] == 1.0
    assert rows["tanh_sigmoid"]["tanh_over_this"] == 3.0  # median of 4, 3, 2
    assert rows["tanh_sigmoid"]["us"] == 60.0 and rows["tanh_sigmoid"]["runs"] == 3


def test_activation_cost_refuses_bad_arguments(capsys):
    with pytest.raises(SystemExit) as refused:
        activation.parse_args(["--stages", "pi_star,warp"])
    assert "--stages" in capsys.readouterr().err + str(refused.value.code)
    assert activation.parse_args(["--stages", "none"]).stages == []
