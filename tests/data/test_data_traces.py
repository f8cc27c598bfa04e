"""The built-in synthetic and constant trace sources (vdtn_marl.data.traces)."""

from __future__ import annotations

import pytest
import torch

from vdtn_marl.data import (
    ConstantSpeedTraceSource,
    SyntheticTraceSource,
    TraceSource,
    get_trace_source,
    trace_source_names,
)

DT = 0.05


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def test_synthetic_is_seed_reproducible():
    src = SyntheticTraceSource()
    a = src.sample(16, 400, DT, _gen(11))
    b = src.sample(16, 400, DT, _gen(11))
    c = src.sample(16, 400, DT, _gen(12))
    assert a.shape == (16, 400) and a.dtype == torch.float32
    assert torch.equal(a, b) and not torch.equal(a, c)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_synthetic_stays_in_speed_band_and_actuator_bounds(seed):
    src = SyntheticTraceSource()
    x = src.sample(64, 2400, DT, _gen(seed))  # 2 min at the twin's control step
    assert torch.isfinite(x).all()
    assert x.min() >= src.speed_min_mps and x.max() <= src.speed_max_mps
    accel = x.diff(dim=1) / DT
    assert accel.abs().max() <= 2.6
    assert accel.min() >= -src.brake_max_mps2 - 1e-3 and accel.max() <= src.accel_max_mps2 + 1e-3
    # it is not a constant: events reach well beyond the jitter
    assert accel.abs().max() > 1.0 and (x.max(dim=1).values - x.min(dim=1).values).mean() > 1.0


def test_synthetic_custom_band_and_bad_sizes():
    src = SyntheticTraceSource(speed_min_mps=5.0, speed_max_mps=8.0, event_rate_hz=1.0)
    x = src.sample(8, 1000, 0.1, _gen(0))
    assert x.min() >= 5.0 and x.max() <= 8.0
    with pytest.raises(ValueError, match="num_points=1"):
        src.sample(1, 1, 0.1, _gen(0))


def test_constant_and_registry():
    x = ConstantSpeedTraceSource(speed_mps=12.0).sample(3, 5, DT, _gen(0))
    torch.testing.assert_close(x, torch.full((3, 5), 12.0))
    assert {"synthetic", "constant"} <= set(trace_source_names())
    assert isinstance(get_trace_source("synthetic"), TraceSource)
    with pytest.raises(ValueError, match="traces='nope' is not a known trace set"):
        get_trace_source("nope")


@pytest.mark.parametrize(
    "kwargs", [{}, {"speed_min_mps": 5.0, "speed_max_mps": 8.0, "event_rate_hz": 3.0}]
)
@pytest.mark.parametrize("num_traces", [1, 5, 64])
def test_synthetic_numpy_and_torch_passes_agree_bit_for_bit(kwargs, num_traces):
    """On the CPU the sequential pass runs on NumPy arrays; on other devices on torch tensors.
    Both must give the same float32 speeds from the same draws."""
    src = SyntheticTraceSource(**kwargs)
    cpu = src.sample(num_traces, 1201, DT, _gen(3))  # the NumPy pass
    # the torch pass on the same draws: rebuild them with the same generator
    calls = []
    original = src._pass

    def spy(xp, *args):
        calls.append(args)
        return original(xp, *args)

    object.__setattr__(src, "_pass", spy)
    again = src.sample(num_traces, 1201, DT, _gen(3))
    assert torch.equal(cpu, again) and len(calls) == 1
    start, event_start, event_accel, event_steps, noise, decay, gain, dt = calls[0]
    drawn = (start, event_start, event_accel, event_steps, noise)
    on_torch = original(torch, *(torch.from_numpy(a) for a in drawn), decay, gain, dt)
    assert on_torch.dtype == torch.float32
    assert torch.equal(on_torch.T, cpu)
    # events happen, so the comparison covers the plateau and band logic
    assert (cpu.diff(dim=1).abs() / DT).max() > 1.0
