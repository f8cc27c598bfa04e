"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-01-delivery-vs-speed/test_delivery_vs_speed.py``."""

import importlib.util
import json
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_delivery_vs_speed_shows_the_breakpoint_cliff(tmp_path):
    """Liang's path loss drops 16.5 dB at the 6.67 m breakpoint, so greedy RRA delivers every
    CAM just above 6.7 m/s and clearly fewer just below it."""
    module = _script("delivery_vs_speed.py")
    out = tmp_path / "speed.json"
    args = ["--speeds", "6.5,7.5", "--rra", "greedy", "--episodes", "8", "--intervals", "40"]
    args += ["--v2v-pathloss-form", "liang"]  # the form with the cliff (the default has none)
    assert module.main([*args, "--output", str(out)]) == 0
    below, above = json.loads(out.read_text())["rows"]
    assert below["v2v_distance_m"] < 6.67 < above["v2v_distance_m"]
    assert below["v2v_pathloss_db"] - above["v2v_pathloss_db"] > 15.0
    assert above["cam_delivery_rate"] == 1.0
    assert below["cam_delivery_rate"] < 0.9
