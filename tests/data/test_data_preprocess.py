"""Preprocessing: smoothing against a known truth, duplicates, gaps, clipping, resampling."""

from __future__ import annotations

import numpy as np
import pytest

from vdtn_marl.data import PreprocessReport, SpeedProfile, limit_acceleration, preprocess

DT = 0.1
WIDE = (-100.0, 100.0)  # acceleration bounds that never bind, to test smoothing alone


def _truth(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Speed 20 + 3 sin(2πt/20) m/s and its exact acceleration (m/s²)."""
    w = 2 * np.pi / 20.0
    return 20.0 + 3.0 * np.sin(w * t), 3.0 * w * np.cos(w * t)


def _noisy(seed: int = 0, noise_mps: float = 0.3, duration_s: float = 60.0) -> SpeedProfile:
    t = DT * np.arange(int(duration_s / DT) + 1)
    v, _ = _truth(t)
    rng = np.random.default_rng(seed)
    return SpeedProfile(t, v + noise_mps * rng.standard_normal(t.shape), "noisy", "test")


def _rms_accel_error(p: SpeedProfile) -> float:
    """RMS of (finite-difference acceleration − true acceleration at step midpoints), m/s²."""
    a = np.diff(p.speed_mps) / np.diff(p.time_s)
    _, a_true = _truth(0.5 * (p.time_s[1:] + p.time_s[:-1]))
    inner = slice(10, -10)  # ignore the filters' edge handling
    return float(np.sqrt(np.mean((a - a_true)[inner] ** 2)))


@pytest.mark.parametrize("smoothing", ["savgol", "ema"])
def test_smoothing_reduces_acceleration_noise(smoothing):
    raw = _noisy()
    (cleaned,), report = preprocess(raw, smoothing=smoothing, clip_accel_mps2=WIDE)
    (unsmoothed,), _ = preprocess(raw, smoothing="none", clip_accel_mps2=WIDE)
    raw_err = _rms_accel_error(unsmoothed)
    err = _rms_accel_error(cleaned)
    assert raw_err > 3.0  # 0.3 m/s white noise differenced at 0.1 s: ~4.2 m/s² rms
    assert err < 0.2 * raw_err, (smoothing, err, raw_err)
    # the smoother removes roughly the noise, not the signal
    assert 0.2 < report.smoothing_rms_change_mps < 0.4
    truth, _ = _truth(cleaned.time_s)
    assert np.sqrt(np.mean((cleaned.speed_mps - truth) ** 2)) < 0.15


def test_no_smoothing_changes_nothing_on_a_clean_grid():
    t = DT * np.arange(101)
    v, _ = _truth(t)
    (out,), report = preprocess(SpeedProfile(t, v, "clean", "test"), smoothing="none")
    np.testing.assert_allclose(out.speed_mps, v)
    assert report.smoothing_rms_change_mps == 0.0
    assert report.accel_points_clipped == 0 and report.speed_points_clipped == 0


def test_duplicates_dropped_and_reported():
    t = np.array([0.0, 0.1, 0.1, 0.2, 0.3, 0.3, 0.3, 0.4] + list(0.5 + DT * np.arange(60)))
    v = np.full_like(t, 15.0)
    v[2] = 99.0  # a repeated timestamp: the first sample is kept
    (out,), report = preprocess(SpeedProfile(t, v, "dup", "t"), smoothing="none")
    assert report.duplicates_dropped == 3
    assert report.input_points == len(t) and report.output_points == len(t) - 3
    np.testing.assert_allclose(out.speed_mps, 15.0)


def test_short_gap_interpolated_long_gap_split():
    t = DT * np.arange(200)
    t = np.delete(t, [50, 51])  # a 0.3 s gap: two lost frames
    t[120:] += 10.0  # a 10.1 s gap
    v = 10.0 + 0.1 * t  # 0.1 m/s², well inside all bounds
    segs, report = preprocess(
        SpeedProfile(t, v, "veh", "t"), smoothing="none", max_gap_s=1.0, min_segment_s=1.0
    )
    assert report.gaps_interpolated == 1 and report.gaps_split == 1
    assert [s.vehicle_id for s in segs] == ["veh#0", "veh#1"] == report.segments
    first, second = segs
    np.testing.assert_allclose(np.diff(first.time_s), DT)  # lost frames are back on the grid
    # sample 120 (t = 12.2 s once two frames are gone) and after were shifted by 10 s
    np.testing.assert_allclose(first.time_s[[0, -1]], [0.0, 12.1], atol=1e-9)
    np.testing.assert_allclose(first.speed_mps[51], 10.0 + 0.1 * 5.1)  # interpolated linearly
    np.testing.assert_allclose(second.time_s[0], 22.2)
    np.testing.assert_allclose(second.speed_mps, 10.0 + 0.1 * second.time_s)


def test_short_segments_dropped():
    t = np.concatenate([DT * np.arange(20), 10.0 + DT * np.arange(100)])  # 1.9 s then 9.9 s
    segs, report = preprocess(SpeedProfile(t, np.full_like(t, 5.0), "v", "t"), min_segment_s=5.0)
    assert report.segments_dropped == 1 and report.gaps_split == 1
    assert len(segs) == 1 and segs[0].time_s[0] == pytest.approx(10.0)


def test_resample_to_requested_step():
    t = DT * np.arange(101)
    (out,), report = preprocess(SpeedProfile(t, 2.0 * t, "v", "t"), smoothing="none", dt_s=0.25)
    np.testing.assert_allclose(out.time_s, 0.25 * np.arange(41))
    np.testing.assert_allclose(out.speed_mps, 0.5 * np.arange(41))
    assert report.dt_s == 0.25 and report.nominal_dt_s == pytest.approx(DT)


def test_speed_and_acceleration_clipped():
    # standing, then an impossible jump to 20 m/s, then an impossible stop
    t = DT * np.arange(300)
    v = np.where((t >= 5.0) & (t < 20.0), 20.0, 0.0)
    (out,), report = preprocess(SpeedProfile(t, v, "jump", "t"), smoothing="savgol")
    a = np.diff(out.speed_mps) / DT
    assert a.max() <= 2.6 + 1e-9 and a.min() >= -2.6 - 1e-9
    assert out.speed_mps.min() >= 0.0
    assert report.accel_points_clipped > 10
    assert report.speed_points_clipped > 0  # savgol overshoots below 0 next to the steps
    # reaches cruise ~7.7 s after the jump (2.6 m/s² from rest); savgol rings ~1 m/s at steps
    assert out.speed_mps[150:200].mean() == pytest.approx(20.0, abs=0.5)
    # the savgol window (2 s) reaches 1 s ahead of the jump at 5 s, not further
    assert out.speed_mps[:40].max() < 1e-6 and out.speed_mps[49] > 0.5


def test_limit_acceleration():
    v = np.array([0.0, 10.0, 10.0, 0.0, 0.0])
    out, n = limit_acceleration(v, 1.0, (-3.0, 2.0))
    np.testing.assert_allclose(out, [0.0, 2.0, 4.0, 1.0, 0.0])
    assert n == 3
    same, n = limit_acceleration(np.array([1.0, 1.5, 1.0]), 1.0, (-1.0, 1.0))
    np.testing.assert_allclose(same, [1.0, 1.5, 1.0]) and n == 0


def test_report_type_and_argument_checks():
    p = _noisy(duration_s=10.0)
    _, report = preprocess(p)
    assert isinstance(report, PreprocessReport) and report.smoothing == "savgol"
    with pytest.raises(ValueError, match="smoothing='median'"):
        preprocess(p, smoothing="median")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"clip_accel_mps2=\(1\.0, 2\.0\)"):
        preprocess(p, clip_accel_mps2=(1.0, 2.0))
    with pytest.raises(ValueError, match="window_s=0"):
        preprocess(p, window_s=0)
    backwards = SpeedProfile(np.array([0.0, 1.0, 0.5]), np.ones(3), "b", "t")
    with pytest.raises(ValueError, match="non-decreasing"):
        preprocess(backwards)


def test_tiny_profiles():
    segs, report = preprocess(SpeedProfile(np.array([0.0]), np.array([3.0]), "one", "t"))
    assert segs == [] and report.output_points == 0
    t = DT * np.arange(8)  # shorter than the savgol window: the window shrinks
    segs, _ = preprocess(SpeedProfile(t, 5.0 + t, "short", "t"), min_segment_s=0.5)
    assert len(segs) == 1 and len(segs[0]) == 8
