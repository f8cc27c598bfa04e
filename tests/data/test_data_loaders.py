"""Readers: NGSIM (plain, gz, zip), highD-style tracks, time,speed CSV, and malformed files."""

from __future__ import annotations

import gzip
import zipfile

import numpy as np
import pytest

from vdtn_marl.data import (
    TraceFormatError,
    load_highd,
    load_ngsim,
    load_time_speed_csv,
)
from vdtn_marl.data.loaders import file_stem

# Vehicle 7: frames 100..104 at 50, 51, 52, 53, 54 ft/s, written out of order; vehicle 3: 4 s.
NGSIM_ROWS = [
    (7, 102, 52.0),
    (7, 100, 50.0),
    (3, 10, 0.0),
    (7, 101, 51.0),
    (7, 103, 53.0),
    (7, 104, 54.0),
    (3, 50, 10.0),
]


def test_ngsim_units_order_and_ids(write_ngsim):
    path = write_ngsim("trajectories-0750am-0805am.csv", NGSIM_ROWS)
    profiles = {p.vehicle_id: p for p in load_ngsim(path)}
    assert set(profiles) == {"trajectories-0750am-0805am/7", "trajectories-0750am-0805am/3"}
    p7 = profiles["trajectories-0750am-0805am/7"]
    # hand-computed: 50 ft/s * 0.3048 m/ft = 15.24 m/s, +0.3048 m/s per frame
    np.testing.assert_allclose(p7.speed_mps, [15.24, 15.5448, 15.8496, 16.1544, 16.4592])
    np.testing.assert_allclose(p7.time_s, [0.0, 0.1, 0.2, 0.3, 0.4], atol=1e-12)
    p3 = profiles["trajectories-0750am-0805am/3"]
    np.testing.assert_allclose(p3.time_s, [0.0, 4.0])  # frames 10 -> 50 at 0.1 s
    np.testing.assert_allclose(p3.speed_mps, [0.0, 3.048])
    assert "NGSIM" in p7.source and "trajectories-0750am-0805am.csv" in p7.source


def test_ngsim_selection_by_id_and_criteria(write_ngsim):
    path = write_ngsim("ngsim.csv", NGSIM_ROWS)
    assert [p.vehicle_id for p in load_ngsim(path, vehicle_ids=[3])] == ["ngsim/3"]
    assert [p.vehicle_id for p in load_ngsim(path, vehicle_ids=["ngsim/7"])] == ["ngsim/7"]
    # vehicle 7 lasts 0.4 s, vehicle 3 lasts 4 s
    assert [p.vehicle_id for p in load_ngsim(path, min_duration_s=1.0)] == ["ngsim/3"]
    # mean speeds: vehicle 7 15.85 m/s, vehicle 3 1.524 m/s
    assert [p.vehicle_id for p in load_ngsim(path, speed_range_mps=(10, 20))] == ["ngsim/7"]
    assert load_ngsim(path, vehicle_ids=[99]) == []
    with pytest.raises(ValueError, match="speed_range_mps"):
        load_ngsim(path, speed_range_mps=(20, 10))


def test_ngsim_location_column_and_case_insensitive_header(write_ngsim):
    header = "vehicle_id,frame_id,V_VEL,Location"
    rows = ["1,5,10.0,us-101", "1,6,10.0,us-101", "1,5,20.0,i-80", "1,6,20.0,i-80"]
    path = write_ngsim("combined.csv", rows, header=header)
    profiles = {p.vehicle_id: p for p in load_ngsim(path, id_prefix="")}
    assert set(profiles) == {"us-101/1", "i-80/1"}
    np.testing.assert_allclose(profiles["i-80/1"].speed_mps, [6.096, 6.096])


def test_ngsim_gzip_and_zip_match_plain(write_ngsim, tmp_path):
    plain = write_ngsim("us101.csv", NGSIM_ROWS)
    text = plain.read_bytes()
    gz = tmp_path / "us101.csv.gz"
    gz.write_bytes(gzip.compress(text))
    zp = tmp_path / "us101.zip"
    with zipfile.ZipFile(zp, "w") as z:
        z.writestr("us101.csv", text)
    ref = load_ngsim(plain)
    for path in (gz, zp):
        got = load_ngsim(path)
        assert [p.vehicle_id for p in got] == [p.vehicle_id for p in ref]
        for a, b in zip(got, ref, strict=True):
            np.testing.assert_array_equal(a.speed_mps, b.speed_mps)
            np.testing.assert_array_equal(a.time_s, b.time_s)


def test_highd_tracks(write_text):
    text = (
        "frame,id,x,y,width,height,xVelocity,yVelocity,xAcceleration,yAcceleration\n"
        "1,1,10.0,5.0,4.5,1.9,30.5,0.0,0.1,0.0\n"
        "2,1,11.2,5.0,4.5,1.9,30.6,0.0,0.1,0.0\n"
        "3,1,12.4,5.0,4.5,1.9,30.7,0.0,0.1,0.0\n"
        "1,2,400.0,20.0,4.5,1.9,-25.0,0.0,0.0,0.0\n"
        "2,2,399.0,20.0,4.5,1.9,-25.5,0.0,0.0,0.0\n"
    )
    path = write_text("01_tracks.csv", text)
    profiles = {p.vehicle_id: p for p in load_highd(path)}
    assert set(profiles) == {"01_tracks/1", "01_tracks/2"}
    np.testing.assert_allclose(profiles["01_tracks/1"].time_s, [0.0, 0.04, 0.08])
    np.testing.assert_allclose(profiles["01_tracks/1"].speed_mps, [30.5, 30.6, 30.7])
    np.testing.assert_allclose(profiles["01_tracks/2"].speed_mps, [25.0, 25.5])  # |xVelocity|
    slow = load_highd(path, frame_rate_hz=10.0, vehicle_ids=[1])
    np.testing.assert_allclose(slow[0].time_s, [0.0, 0.1, 0.2])


def test_time_speed_csv(write_text):
    path = write_text("drive.csv", "time,speed\n0.0,10.0\n0.5,10.5\n1.0,11.0\n1.0,11.0\n")
    (p,) = load_time_speed_csv(path)
    assert p.vehicle_id == "drive"
    np.testing.assert_allclose(p.time_s, [0.0, 0.5, 1.0, 1.0])  # repeats kept for preprocess
    np.testing.assert_allclose(p.speed_mps, [10.0, 10.5, 11.0, 11.0])
    path = write_text("units.csv", " Time_s , Speed_MPS ,note\n0,1,a\n1,2,b\n")
    (p,) = load_time_speed_csv(path, vehicle_id="x")
    assert p.vehicle_id == "x" and p.duration_s == 1.0


@pytest.mark.parametrize(
    ("header", "value", "mps"),
    [("speed_kmh", "90", 25.0), ("Speed_KPH", "36", 10.0), ("speed_mph", "56.7", 25.347168)],
)
def test_time_speed_csv_speed_units(write_text, header, value, mps):
    """The speed column's header names its unit; speeds come out in m/s (1 mph = 0.44704 m/s)."""
    (p,) = load_time_speed_csv(write_text("u.csv", f"time_s,{header}\n0,0\n1,{value}\n"))
    np.testing.assert_allclose(p.speed_mps, [0.0, mps], rtol=1e-12)
    assert p.source.endswith(("km/h)", "mph)"))


def test_time_speed_csv_needs_exactly_one_speed_column(write_text):
    path = write_text("two.csv", "time,speed,speed_kmh\n0,1,3.6\n")
    with pytest.raises(TraceFormatError, match=r"^two\.csv: more than one speed column; allowed"):
        load_time_speed_csv(path)


def test_file_stem():
    assert file_stem("a/01_tracks.csv.gz") == "01_tracks"
    assert file_stem("us101.zip") == "us101"
    assert file_stem("trace.CSV") == "trace"


# ---------------------------------------------------------------------------- malformed files


def _speed_rows(n: int, bad_row: int, bad_value: str) -> str:
    """A time,speed CSV with ``n`` data rows whose data row ``bad_row`` (1-based) has speed
    ``bad_value``."""
    rows = [f"{0.1 * i:.1f},{bad_value if i + 1 == bad_row else '12.5'}" for i in range(n)]
    return "time,speed\n" + "\n".join(rows) + "\n"


def test_negative_speed_names_file_and_row(write_text):
    path = write_text("traces.csv", _speed_rows(20, 17, "-3.2"))
    with pytest.raises(TraceFormatError) as err:
        load_time_speed_csv(path)
    assert str(err.value).startswith("traces.csv row 17: speed -3.2 m/s is negative")
    assert err.value.row == 17 and err.value.path.name == "traces.csv"


def test_kmh_mixup_is_rejected(write_text):
    path = write_text("kmh.csv", _speed_rows(5, 4, "95.0"))
    # 95 km/h in a column said to hold m/s: the hint says how to name the unit
    match = r"kmh\.csv row 4: speed 95 m/s is above 70 m/s .*name the speed column by its unit"
    with pytest.raises(TraceFormatError, match=match):
        load_time_speed_csv(path)


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        ("abc", "value 'abc' in column 'speed' is not a finite number"),
        ("", "missing value in column 'speed'"),
        ("inf", "value 'inf' in column 'speed' is not a finite number"),
    ],
)
def test_non_numeric_speed(write_text, value, expected):
    path = write_text("bad.csv", _speed_rows(6, 3, value))
    with pytest.raises(TraceFormatError, match=rf"^bad\.csv row 3: {expected}"):
        load_time_speed_csv(path)


def test_non_monotone_time(write_text):
    path = write_text("t.csv", "time,speed\n0.0,1\n0.1,1\n0.3,1\n0.2,1\n0.4,1\n")
    with pytest.raises(TraceFormatError, match=r"^t\.csv row 4: time 0\.2 s is earlier"):
        load_time_speed_csv(path)


def test_missing_columns(write_text, write_ngsim):
    path = write_text("nospeed.csv", "time,velocity\n0,1\n")
    with pytest.raises(TraceFormatError, match=r"^nospeed\.csv: missing column 'speed'") as err:
        load_time_speed_csv(path)
    assert err.value.row is None and "time, velocity" in str(err.value)
    path = write_ngsim("novel.csv", ["1,2,3"], header="Vehicle_ID,Frame_ID,v_Acc")
    with pytest.raises(TraceFormatError, match=r"^novel\.csv: missing column 'v_Vel'"):
        load_ngsim(path)
    path = write_text("01_tracks.csv", "frame,id,yVelocity\n1,1,0\n")
    with pytest.raises(TraceFormatError, match=r"^01_tracks\.csv: missing column 'xVelocity'"):
        load_highd(path)


def test_empty_file_and_header_only(write_text):
    with pytest.raises(TraceFormatError, match=r"^empty\.csv: "):
        load_time_speed_csv(write_text("empty.csv", ""))
    with pytest.raises(TraceFormatError, match=r"^head\.csv: no data rows"):
        load_time_speed_csv(write_text("head.csv", "time,speed\n"))


def test_ngsim_malformed_rows(write_ngsim):
    rows = [(1, 1, 30.0), (1, 2, 30.0), (1, "x3", 30.0)]
    with pytest.raises(TraceFormatError, match=r"^n1\.csv row 3: value 'x3' in column 'Frame_ID'"):
        load_ngsim(write_ngsim("n1.csv", rows))
    # 300 ft/s = 91.44 m/s: impossible, probably not ft/s at all
    rows = [(1, 1, 30.0), (1, 2, 300.0)]
    with pytest.raises(TraceFormatError, match=r"^n2\.csv row 2: speed 91\.44 m/s is above 70"):
        load_ngsim(write_ngsim("n2.csv", rows))
    rows = [(1, 1, 30.0), (1, 2, 30.0), (1, 3, -1.0)]
    with pytest.raises(TraceFormatError, match=r"^n3\.csv row 3: speed -0\.3048 m/s is negative"):
        load_ngsim(write_ngsim("n3.csv", rows))


def test_highd_malformed_row(write_text):
    path = write_text("02_tracks.csv", "frame,id,xVelocity\n1,1,30\n2,1,3O.1\n")
    with pytest.raises(TraceFormatError, match=r"^02_tracks\.csv row 2: value '3O\.1'"):
        load_highd(path)
    path = write_text("03_tracks.csv", "frame,id,xVelocity\n1,1,30\n2,1,-250\n")
    with pytest.raises(TraceFormatError, match=r"^03_tracks\.csv row 2: speed 250 m/s is above"):
        load_highd(path)


def test_trace_format_error_is_value_error():
    assert issubclass(TraceFormatError, ValueError)
