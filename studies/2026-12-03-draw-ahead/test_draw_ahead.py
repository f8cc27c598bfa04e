"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-03-draw-ahead/test_draw_ahead.py``."""

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


draw_ahead = _script("draw_ahead.py")


def _pair(stage, pair, ahead, at_start):
    common = {"stage": stage, "pair": pair}
    return [
        {**common, "setting": "ahead", "wall_s": ahead, "cpu_s": ahead + 1},
        {**common, "setting": "at_start", "wall_s": at_start, "cpu_s": at_start},
    ]


def test_draw_ahead_ratios_are_paired_and_the_iteration_adds_each_budget():
    runs = [
        *_pair("pi_star", 0, 1.0, 1.0),
        *_pair("pi_tilde_random", 0, 2.0, 2.4),
        *_pair("pi_tilde_learned", 0, 4.0, 5.0),
        *_pair("pi_tilde_learned", 1, 8.0, 8.8),  # a slow pair: its own ratio, 1.1
        *_pair("pi_tilde_learned", 2, 4.0, 6.0),
        *_pair("rra", 0, 3.0, 3.0),
    ]
    rows = {r["stage"]: r for r in draw_ahead.summarise(runs)}
    learned = rows["pi_tilde_learned"]
    assert learned["at_start_over_ahead"] == pytest.approx(1.25)  # median of 1.25, 1.1, 1.5
    assert (learned["ratio_min"], learned["ratio_max"], learned["pairs"]) == (1.1, 1.5, 3)
    assert learned["wall_s_ahead"] == 4.0 and learned["cpu_s_ahead"] == 5.0
    minutes = draw_ahead.iteration_minutes(
        list(rows.values()), {"control_iterations": 500, "rra_iterations": 300}
    )
    assert minutes["first_ahead"] == pytest.approx((500 * 1.0 + 500 * 2.0 + 300 * 3.0) / 60)
    assert minutes["later_at_start"] == pytest.approx((500 * 1.0 + 500 * 6.0 + 300 * 3.0) / 60)
    partial = draw_ahead.iteration_minutes([rows["rra"]], {"control_iterations": 1})
    assert partial == {}  # stages missing: no estimate


def test_draw_ahead_refuses_bad_arguments(capsys):
    with pytest.raises(SystemExit) as refused:
        draw_ahead.parse_args(["--stages", "pi_star,warp"])
    assert "--stages" in capsys.readouterr().err + str(refused.value.code)
    with pytest.raises(SystemExit):
        draw_ahead.parse_args(["--repeats", "0"])
    assert "--repeats" in capsys.readouterr().err
