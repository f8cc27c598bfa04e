"""The bundled recorded drives (trace set ``cmap``): files, provenance, split by vehicle, and
the extraction rule of scripts/extract_recorded_drives.py."""

from __future__ import annotations

import importlib.util
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import torch

from vdtn_marl.data import (
    ProfileTraceSource,
    cmap,
    get_trace_source,
    load_time_speed_csv,
    trace_set_provenance,
    trace_source_names,
)
from vdtn_marl.data.profiles import split_key
from vdtn_marl.data.selection import named_sources, split_in_time

ROOT = Path(__file__).resolve().parents[2]
DRIVES = ROOT / "vdtn_marl" / "data" / "drives"
FILES = sorted(DRIVES.glob("cmap_*.csv"))


def test_cmap_is_registered_with_its_provenance():
    assert "cmap" in trace_source_names()
    entry = trace_set_provenance()["cmap"]
    assert entry["name"] == "cmap" and entry["synthetic"] is False
    for needle in ("Chicago", "Transportation Secure Data Center", "FASTSim 2.1.5"):
        assert needle in entry["source"], needle
    assert entry["license"].startswith("Apache License 2.0")
    assert "Alliance for Sustainable Energy" in entry["license"]
    assert get_trace_source("cmap").info == cmap.cmap_info()


def test_licence_and_notice_ship_with_the_files():
    assert "Apache License" in (DRIVES / "LICENSE").read_text()
    notice = (DRIVES / "NOTICE").read_text()
    assert "Copyright 2020 Alliance for Sustainable Energy, LLC" in notice
    readme = (DRIVES / "README.md").read_text()
    assert "Changes made to the FASTSim files" in readme and "fastsim-2.1.5" in readme
    size = sum(p.stat().st_size for p in DRIVES.iterdir())
    assert size < 3_000_000


def test_extracted_files_are_recorded_1hz_drives():
    assert len(FILES) == 22
    for path in FILES:
        (p,) = load_time_speed_csv(path)
        steps = np.diff(p.time_s)
        assert p.time_s[0] == 0.0 and np.all(steps >= 1.0), path.name
        assert np.all(steps == np.round(steps)), path.name  # whole seconds
        assert p.speed_mps.min() >= 0.0 and p.speed_mps.max() < 45.0, path.name


def test_cleaned_segments_are_physically_plausible():
    profiles = cmap.load_cmap_profiles()
    assert len(profiles) == 374
    assert sum(p.duration_s for p in profiles) == pytest.approx(234_330.0)
    assert len({split_key(p.vehicle_id) for p in profiles}) == 22
    for p in profiles:
        assert p.duration_s >= cmap.MIN_SEGMENT_S
        np.testing.assert_allclose(np.diff(p.time_s), 1.0)
        assert p.speed_mps.min() >= 0.0 and p.speed_mps.max() < 45.0
        accel = np.diff(p.speed_mps)  # m/s per 1 s step
        assert accel.min() >= -2.6 - 1e-9 and accel.max() <= 2.6 + 1e-9
    speeds = np.concatenate([p.speed_mps for p in profiles])
    assert 10.0 < speeds.mean() < 20.0  # mixed city and highway driving
    assert 0.2 < np.mean(speeds < 6.7) < 0.4
    x = get_trace_source("cmap").sample(64, 401, 0.05, torch.Generator().manual_seed(0))
    assert x.min() >= 0.0 and x.max() < 45.0 and (x.diff(dim=1).abs() <= 2.6 * 0.05 + 1e-5).all()


def test_runs_split_cmap_by_household_never_in_time():
    train, evaluation = named_sources("cmap")
    assert isinstance(train, ProfileTraceSource) and isinstance(evaluation, ProfileTraceSource)
    assert not split_in_time("cmap") and split_in_time("udds")
    vehicles = {
        part: {split_key(p.vehicle_id) for p in src.profiles}
        for part, src in (("train", train), ("eval", evaluation))
    }
    assert not vehicles["train"] & vehicles["eval"]
    assert len(vehicles["train"] | vehicles["eval"]) == 22
    assert (len(vehicles["train"]), len(vehicles["eval"])) == (17, 5)
    households = {part: {cmap.household(v) for v in ids} for part, ids in vehicles.items()}
    assert not households["train"] & households["eval"]
    assert households["eval"] == set(cmap.EVAL_HOUSEHOLDS)
    assert vehicles["eval"] == cmap.eval_vehicles()
    # whole segments, as bundled: nothing is cut in time
    every = {p.vehicle_id: p.duration_s for p in cmap.load_cmap_profiles()}
    for p in train.profiles + evaluation.profiles:
        assert every[p.vehicle_id] == p.duration_s
    assert len(train) + len(evaluation) == len(every)
    assert "part=eval, split by vehicle: 5 of 22 vehicles" in evaluation.info.description


def test_eval_households_follow_the_documented_rule():
    """Households ranked by kept duration, longest first; every fourth from the second."""
    duration: dict[str, float] = defaultdict(float)
    for p in cmap.load_cmap_profiles():
        duration[cmap.household(p.vehicle_id)] += p.duration_s
    ranked = sorted(duration, key=lambda h: -duration[h])
    assert len(ranked) == 18
    assert sorted(ranked[1::4]) == sorted(cmap.EVAL_HOUSEHOLDS)
    with pytest.raises(ValueError, match="not a cmap vehicle id"):
        cmap.household("udds")


# ------------------------------------------------------------------ extraction rule


def _extractor():
    path = ROOT / "scripts" / "extract_recorded_drives.py"
    spec = importlib.util.spec_from_file_location("extract_recorded_drives", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def _fake_wheel(root: Path) -> None:
    """An unpacked wheel with one vehicle: a drive with a 30 s unrecorded stop, a GPS loss
    while moving, a 10 s tail, and one sample outside the trip."""
    info = root / "fastsim-2.1.5.dist-info"
    (info / "license_files").mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fastsim\nVersion: 2.1.5\n")
    (info / "license_files" / "LICENSE").write_text("Apache License\n")
    (info / "license_files" / "NOTICE").write_text("Copyright 2020 Alliance\n")
    vehicle = root / "fastsim" / "resources" / "cycles" / "cmap_subset" / "1000_2"
    vehicle.mkdir(parents=True)
    rows = []

    def add(second: int, mph: float) -> None:
        rows.append(f"2007-05-01 08:{second // 60:02d}:{second % 60:02d},0,1,{mph},0.0")

    for s in range(0, 40):  # 0 -> 20 mph -> rest at s = 39
        add(s, 20.0 * np.sin(np.pi * s / 39.0) if s < 39 else 0.0)
    for s in range(70, 121):  # after 30 s unrecorded at rest, away to 30 mph, still moving
        add(s, min(30.0, (s - 70) * 2.0))
    for s in range(130, 141):  # GPS back after 9 s lost: a 10 s tail, too short
        add(s, 30.0)
    add(200, 5.0)  # outside the trip
    header = "timestamp,cycle_sec,timestep,speed_mph,accel_meters_ps\n"
    (vehicle / "2007-05-01.csv").write_text(header + "\n".join(rows) + "\n")
    (vehicle / "trips.csv").write_text(
        "sampno,vehno,trip_id,start_ts,end_ts\n1000,2,1,2007-05-01 08:00:00,2007-05-01 08:02:20\n"
    )


def test_extractor_rule_on_a_small_drive(tmp_path):
    extractor = _extractor()
    _fake_wheel(tmp_path / "wheel")
    out = tmp_path / "drives"
    assert extractor.main([str(tmp_path / "wheel"), str(out)]) == 0
    (p,) = load_time_speed_csv(out / "cmap_1000_2.csv")
    # one segment, 0..120 s at 1 s, the stop filled with standstill; the tail dropped
    np.testing.assert_array_equal(p.time_s, np.arange(0.0, 121.0))
    np.testing.assert_array_equal(p.speed_mps[39:70], 0.0)
    assert p.speed_mps.max() == pytest.approx(30.0 * 0.44704, abs=0.005)
    assert p.speed_mps[20] == pytest.approx(20.0 * np.sin(np.pi * 20 / 39) * 0.44704, abs=0.005)
    assert (out / "LICENSE").read_text() == "Apache License\n"
    assert (out / "NOTICE").read_text() == "Copyright 2020 Alliance\n"
    readme = (out / "README.md").read_text()
    assert (
        "| 1000_2 | 2007-05-01 08:00:00 | 1 | 1 | 1 | 120 | 103 | 1 | 1 (30) | 0 | 1 | 1 |"
        in readme
    )
