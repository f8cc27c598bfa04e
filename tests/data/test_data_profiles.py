"""ProfileTraceSource sampling, the train/eval split, and file-backed trace sources."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vdtn_marl.data import (
    SPLIT_VERSION,
    NGSIMTraceSource,
    ProfileTraceSource,
    SpeedProfile,
    TraceSource,
    get_trace_source,
    load_trace_source,
    load_train_eval_sources,
    split,
)
from vdtn_marl.data.profiles import is_eval, split_key


def _ramp(vid: str, duration_s: float = 100.0, v0: float = 10.0, slope: float = 0.1):
    t = np.arange(0.0, duration_s + 1e-9, 1.0)  # 1 s samples, linear speed
    return SpeedProfile(t + 1000.0, v0 + slope * t, vid, "ramp")  # times need not start at 0


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


# ---------------------------------------------------------------------------------- split


def test_split_disjoint_complete_and_stable():
    profiles = [_ramp(f"us101/{i}") for i in range(1, 200)]
    train, evl = split(profiles, "train"), split(profiles, "eval")
    ids_t, ids_e = {p.vehicle_id for p in train}, {p.vehicle_id for p in evl}
    assert not ids_t & ids_e
    assert ids_t | ids_e == {p.vehicle_id for p in profiles}
    assert [p.vehicle_id for p in split(profiles, "eval")] == [p.vehicle_id for p in evl]
    assert [p.vehicle_id for p in split(list(reversed(profiles)), "eval")] == sorted(
        ids_e, key=lambda v: -int(v.split("/")[1])
    )
    # a profile's part does not depend on which other profiles are present
    assert [p.vehicle_id for p in split(profiles[:30], "eval")] == [
        v for v in (p.vehicle_id for p in evl) if int(v.split("/")[1]) <= 30
    ]
    assert len(split(profiles, "all")) == len(profiles)
    with pytest.raises(ValueError, match="part='test'"):
        split(profiles, "test")  # type: ignore[arg-type]


def test_split_rule_v1_known_answers():
    # Pinned: if these change, the rule changed and SPLIT_VERSION must be bumped.
    assert SPLIT_VERSION == "1"
    evl = [f"us101/{i}" for i in range(1, 40) if is_eval(f"us101/{i}")]
    assert evl == ["us101/2", "us101/4", "us101/21"]
    share = np.mean([is_eval(f"v{i}") for i in range(10000)])
    assert 0.18 < share < 0.22


def test_split_keeps_segments_of_a_vehicle_together():
    assert split_key("us101/7#3") == "us101/7" and split_key("a#b") == "a#b"
    segs = [_ramp(f"us101/7#{k}") for k in range(5)] + [_ramp(f"us101/2#{k}") for k in range(5)]
    # us101/2 is eval and us101/7 is train (see above): all five segments follow their vehicle
    assert [p.vehicle_id for p in split(segs, "eval")] == [f"us101/2#{k}" for k in range(5)]
    assert [p.vehicle_id for p in split(segs, "train")] == [f"us101/7#{k}" for k in range(5)]


# ---------------------------------------------------------------------- ProfileTraceSource


def test_sample_shape_dtype_and_protocol():
    src = ProfileTraceSource([_ramp("a"), _ramp("b", v0=20.0)])
    assert isinstance(src, TraceSource)
    assert get_trace_source(src) is src
    x = src.sample(6, 201, 0.05, _gen(0))
    assert x.shape == (6, 201) and x.dtype == torch.float32
    assert torch.isfinite(x).all() and (x >= 0).all()
    assert src.info.synthetic is False and src.info.source == "ramp"


def test_sample_is_seed_reproducible():
    src = ProfileTraceSource([_ramp(f"v{i}", v0=5.0 + i) for i in range(10)])
    a = src.sample(8, 100, 0.1, _gen(7))
    b = src.sample(8, 100, 0.1, _gen(7))
    c = src.sample(8, 100, 0.1, _gen(8))
    assert torch.equal(a, b)
    assert not torch.equal(a, c)


def test_sample_interpolates_on_the_requested_grid():
    # speed 10 + 0.1 t: any window on a dt grid is linear with step 0.1·dt and lies in range
    src = ProfileTraceSource([_ramp("a")])
    x = src.sample(16, 401, 0.05, _gen(3)).double()
    steps = x.diff(dim=1)
    torch.testing.assert_close(steps, torch.full_like(steps, 0.005), atol=2e-5, rtol=0)
    assert x.min() >= 10.0 - 1e-4 and x.max() <= 20.0 + 1e-4
    starts = x[:, 0]
    assert starts.max() - starts.min() > 1.0  # random offsets, not always the profile start


def test_only_profiles_long_enough_are_used():
    long, short = _ramp("long", 100.0, v0=20.0, slope=0.0), _ramp("short", 5.0, v0=5.0, slope=0.0)
    src = ProfileTraceSource([short, long])
    x = src.sample(32, 201, 0.1, _gen(0))  # 20 s: only "long" fits
    torch.testing.assert_close(x, torch.full_like(x, 20.0))


def test_too_short_raises_or_reflects():
    src = ProfileTraceSource([_ramp("tiny", 5.0)])
    with pytest.raises(ValueError, match=r"no profile covers 10 s .*'tiny'.* lasts 5 s"):
        src.sample(2, 101, 0.1, _gen(0))
    refl = ProfileTraceSource([_ramp("tiny", 5.0)], too_short="reflect")
    x = refl.sample(4, 101, 0.1, _gen(0)).double()
    assert x.min() >= 10.0 - 1e-5 and x.max() <= 10.5 + 1e-5
    # forward then backward: speed stays continuous, each step is ±0.01 m/s (or 0 at a turn)
    assert (x.diff(dim=1).abs() <= 0.01 + 1e-5).all()
    assert (x.diff(dim=1) < -0.005).any() and (x.diff(dim=1) > 0.005).any()


def test_bad_profiles_and_arguments():
    with pytest.raises(ValueError, match="at least one profile"):
        ProfileTraceSource([SpeedProfile(np.zeros(1), np.zeros(1), "x", "t")])
    dup = SpeedProfile(np.array([0.0, 1.0, 1.0]), np.ones(3), "dup", "t")
    with pytest.raises(ValueError, match="'dup' needs strictly increasing times"):
        ProfileTraceSource([dup])
    with pytest.raises(ValueError, match="too_short='loop'"):
        ProfileTraceSource([_ramp("a")], too_short="loop")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="num_points=1"):
        ProfileTraceSource([_ramp("a")]).sample(1, 1, 0.1, _gen(0))


# ------------------------------------------------------------------ sources built from files


def _ngsim_file(write_ngsim, n_vehicles: int = 20, seconds: int = 40):
    rows = []
    for vid in range(1, n_vehicles + 1):
        for frame in range(10 * seconds + 1):
            rows.append((vid, 1000 + frame, 40.0 + vid + 5.0 * np.sin(frame / 50.0)))
    return write_ngsim("trajectories-0400-0415.csv", rows)


def test_ngsim_trace_source_end_to_end(write_ngsim):
    path = _ngsim_file(write_ngsim)
    train = NGSIMTraceSource(path, part="train", min_duration_s=30.0)
    evl = NGSIMTraceSource(path, part="eval", min_duration_s=30.0)
    ids_t = {p.vehicle_id for p in train.profiles}
    ids_e = {p.vehicle_id for p in evl.profiles}
    assert ids_t and ids_e and not ids_t & ids_e and len(ids_t | ids_e) == 20
    assert ids_e == {"trajectories-0400-0415/13", "trajectories-0400-0415/14"}
    assert train.info.name == "ngsim" and "trajectories-0400-0415.csv" in train.info.source
    x = train.sample(5, 600, 0.05, _gen(1))  # 30 s windows at the twin's 50 ms step
    assert x.shape == (5, 600)
    # v_Vel between 36 and 65 ft/s: 10.97 .. 19.81 m/s after conversion
    assert x.min() > 10.9 and x.max() < 19.9
    assert (x.diff(dim=1).abs() / 0.05 <= 2.6 + 1e-4).all()
    one = NGSIMTraceSource(path, vehicle_ids=[3])
    assert [p.vehicle_id for p in one.profiles] == ["trajectories-0400-0415/3"]


def test_load_trace_source_kinds(write_text, write_ngsim):
    path = write_text(
        "drive.csv", "time,speed\n" + "".join(f"{t},{15 + 0.01 * t}\n" for t in range(61))
    )
    src = load_trace_source("csv", path)
    assert src.info.name == "csv:drive.csv" and len(src) == 1
    x = src.sample(3, 101, 0.5, _gen(0))
    assert x.shape == (3, 101) and (x >= 15.0 - 1e-4).all() and (x <= 15.6 + 1e-4).all()
    with pytest.raises(ValueError, match="kind='ngsimm'"):
        load_trace_source("ngsimm", path)
    with pytest.raises(ValueError, match="min_duration_s=60.0"):
        load_trace_source("ngsim", _ngsim_file(write_ngsim, 2, 10), min_duration_s=60.0)


def test_selection_keywords_work_for_every_format_and_unknown_ones_are_named(write_text):
    path = write_text(
        "drive.csv", "time,speed\n" + "".join(f"{t},{15 + 0.01 * t}\n" for t in range(61))
    )
    assert len(load_trace_source("csv", path, min_duration_s=60, speed_range_mps=(5, 30))) == 1
    with pytest.raises(ValueError, match="min_duration_s=61"):
        load_trace_source("csv", path, min_duration_s=61)
    with pytest.raises(ValueError, match=r"^frame_rate_hz=25 is not a keyword of the 'csv' "):
        load_trace_source("csv", path, frame_rate_hz=25)


def test_one_drive_splits_in_time_through_the_python_api_as_on_the_cli(write_text):
    """A file whose profiles all land in one part of the id split (one drive) is split in time
    by load_trace_source(part=...) exactly as by load_train_eval_sources (the CLI's path)."""
    path = write_text(
        "drive.csv", "time,speed\n" + "".join(f"{t},{15 + 0.01 * t}\n" for t in range(101))
    )
    train, evaluation = load_train_eval_sources("csv", path)
    for part, expected in (("train", train), ("eval", evaluation)):
        src = load_trace_source("csv", path, part=part)
        (profile,) = src.profiles
        (same,) = expected.profiles
        np.testing.assert_array_equal(profile.time_s, same.time_s)
        assert profile.vehicle_id == f"drive@{part}" and "first 80%" in src.info.description
    (head,), (tail,) = train.profiles, evaluation.profiles
    assert head.time_s[-1] == tail.time_s[0] == pytest.approx(80.0)
    assert load_trace_source("csv", path, part="all").profiles[0].duration_s == 100.0
