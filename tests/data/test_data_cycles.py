"""The bundled EPA driving cycles: the files match the EPA's published figures, and they work
as trace sets."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vdtn_marl.data import cycles, get_trace_source, trace_source_names
from vdtn_marl.data.loaders import MPH_TO_MPS


def test_unknown_cycle():
    with pytest.raises(ValueError, match="driving cycle 'wltc9' is not known; known: udds, hwfet"):
        cycles.load_driving_cycle("wltc9")


def test_cycles_are_registered_and_real():
    assert {"udds", "hwfet"} <= set(trace_source_names())
    for name in cycles.CYCLES:
        info = get_trace_source(name).info
        assert info.name == name and not info.synthetic and "public domain" in info.license


@pytest.mark.parametrize("name", sorted(cycles.CYCLES))
def test_bundled_cycle_matches_the_epa_figures(name):
    """Duration, distance, average and top speed as the EPA publishes them for the schedule
    (rounded as published), 1 s steps, starting and ending at rest."""
    published = cycles.CYCLES[name]
    p = cycles.load_driving_cycle(name)
    assert p.vehicle_id == name and "bundled" in p.source
    np.testing.assert_array_equal(np.diff(p.time_s), 1.0)
    assert p.time_s[0] == 0.0 and p.duration_s == published.duration_s
    assert p.speed_mps[0] == 0.0 and p.speed_mps[-1] == 0.0
    distance_mi = np.trapezoid(p.speed_mps, p.time_s) / (MPH_TO_MPS * 3600.0)
    assert distance_mi == pytest.approx(published.distance_mi, abs=0.005)
    average_mph = distance_mi * 3600.0 / published.duration_s
    assert average_mph == pytest.approx(published.average_speed_mph, abs=0.05)
    assert p.speed_mps.max() / MPH_TO_MPS == pytest.approx(published.max_speed_mph, abs=1e-9)
    # speeds are the EPA's 0.1 mph steps, converted at exactly 0.44704 m/s per mph
    tenths = p.speed_mps / MPH_TO_MPS * 10.0
    np.testing.assert_allclose(tenths, np.round(tenths), atol=1e-9)
    assert np.abs(np.diff(p.speed_mps)).max() <= 1.5  # EPA schedules stay within ±1.5 m/s²


def test_profile_is_a_fresh_copy():
    first = cycles.load_driving_cycle("udds")
    first.speed_mps[:] = -1.0
    assert cycles.load_driving_cycle("udds").speed_mps.min() == 0.0


@pytest.mark.parametrize("name", sorted(cycles.CYCLES))
def test_cycle_windows_sample_within_the_cycle(name):
    x = get_trace_source(name).sample(8, 1200, 0.05, torch.Generator().manual_seed(0))
    top = cycles.CYCLES[name].max_speed_mph * MPH_TO_MPS
    assert x.shape == (8, 1200) and x.min() >= 0.0 and x.max() <= top + 1e-4
    assert (x.diff(dim=1).abs() / 0.05 <= 2.6).all()
