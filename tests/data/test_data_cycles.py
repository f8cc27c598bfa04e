"""Standard driving cycles through the optional fastsim package (real one if installed)."""

from __future__ import annotations

import sys
import types

import numpy as np
import pytest
import torch

from vdtn_marl.data import cycles, trace_source_names


@pytest.fixture
def fresh_cache():
    cycles._load_arrays.cache_clear()
    yield
    cycles._load_arrays.cache_clear()


def test_missing_package_says_how_to_install(monkeypatch, fresh_cache):
    monkeypatch.setitem(sys.modules, "fastsim", None)  # makes `import fastsim` fail
    with pytest.raises(ImportError, match=r"pip install 'vdtn-marl\[data\]'.*fastsim"):
        cycles.load_driving_cycle("udds")


def test_unknown_cycle():
    with pytest.raises(ValueError, match="driving cycle 'wltc9' is not known; known: udds, hwfet"):
        cycles.load_driving_cycle("wltc9")


def test_adapter_reads_the_package_resource(monkeypatch, fresh_cache):
    """Against a stand-in with fastsim 3's API: Cycle.from_resource(name).to_dict()."""
    asked = []

    class Cycle:
        @staticmethod
        def from_resource(name):
            asked.append(name)
            return types.SimpleNamespace(
                to_dict=lambda: {
                    "time_seconds": [0.0, 1.0, 2.0, 3.0],
                    "speed_meters_per_second": [0.0, 1.0, 2.5, 2.0],
                }
            )

    fake = types.ModuleType("fastsim")
    fake.Cycle = Cycle
    fake.__version__ = "9.9"
    monkeypatch.setitem(sys.modules, "fastsim", fake)
    p = cycles.load_driving_cycle("hwfet")
    assert asked == ["hwfet.csv"]
    np.testing.assert_allclose(p.speed_mps, [0.0, 1.0, 2.5, 2.0])
    assert p.vehicle_id == "hwfet" and "fastsim 9.9" in p.source
    src = cycles.driving_cycle_source("hwfet")
    assert src.info.name == "hwfet" and not src.info.synthetic
    x = src.sample(4, 21, 0.1, torch.Generator().manual_seed(0))  # 2 s windows of a 3 s cycle
    assert x.shape == (4, 21) and x.min() >= 0.0 and x.max() <= 2.5 + 1e-6


def test_registration_follows_availability():
    registered = {"udds", "hwfet"} & set(trace_source_names())
    assert registered == ({"udds", "hwfet"} if cycles.cycles_available() else set())


@pytest.mark.parametrize(
    ("name", "duration_s", "top_mps"), [("udds", 1369, 25.35), ("hwfet", 765, 26.78)]
)
def test_real_cycles(name, duration_s, top_mps, fresh_cache):
    pytest.importorskip("fastsim")
    p = cycles.load_driving_cycle(name)
    assert p.duration_s == pytest.approx(duration_s)
    assert p.speed_mps.max() == pytest.approx(top_mps, abs=0.01) and p.speed_mps.min() == 0.0
    assert np.abs(np.diff(p.speed_mps) / np.diff(p.time_s)).max() <= 2.6
    from vdtn_marl.data import get_trace_source

    x = get_trace_source(name).sample(8, 1200, 0.05, torch.Generator().manual_seed(0))
    assert x.shape == (8, 1200) and (x.diff(dim=1).abs() / 0.05 <= 2.6).all()
