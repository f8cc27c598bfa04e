"""What a user's trace file is told about: repeated timestamps (named, or refused when their
speeds disagree), km/h read as m/s (a warning) and acceleration clipped by pre-processing
(one warning from the library, none extra on the CLI's path)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from vdtn_marl.data.loaders import load_highd, load_ngsim, load_time_speed_csv
from vdtn_marl.data.profiles import load_trace_source, load_train_eval_sources
from vdtn_marl.data.selection import check_trace_settings, file_sources
from vdtn_marl.errors import ConfigError, TraceFormatError

DATA_LOGGERS = ("vdtn_marl.data.loaders", "vdtn_marl.data.profiles")


def _warnings(caplog) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if r.levelno == logging.WARNING and r.name in DATA_LOGGERS
    ]


def _csv(path, times, speeds, header="time,speed"):
    rows = "\n".join(f"{t:g},{v:g}" for t, v in zip(times, speeds, strict=True))
    path.write_text(f"{header}\n{rows}\n")
    return path


def _drive(duration_s=120.0, dt=0.5):
    t = np.arange(0.0, duration_s + 1e-9, dt)
    return t, 15.0 + 2.0 * np.sin(t / 9.0)


# ------------------------------------------------------------------- repeated timestamps


def test_repeated_times_with_the_same_speed_are_named_in_one_warning(tmp_path, caplog):
    t, v = _drive()
    # data rows 4 and 9 repeat rows 3 and 8 (a speed 0.2 m/s apart is rounding)
    t = np.insert(t, [3, 7], [t[2], t[6]])
    v = np.insert(v, [3, 7], [v[2] + 0.2, v[6]])
    path = _csv(tmp_path / "drive.csv", t, v)
    caplog.set_level(logging.WARNING)
    (profile,) = load_time_speed_csv(path)
    assert len(profile) == len(t)  # the reader keeps them for pre-processing to drop
    (line,) = _warnings(caplog)
    assert line.startswith("drive.csv: rows 4 and 9 repeat the time of the row before")
    assert "drops them" in line and "\n" not in line
    # the library's loaders say it once per read, and pre-processing drops exactly those
    caplog.clear()
    source = load_trace_source("csv", path)
    assert len(_warnings(caplog)) == 1
    assert source.preprocessing["input_points"] == len(t)


def test_the_list_of_repeated_rows_is_capped(tmp_path, caplog):
    t, v = _drive()
    t, v = np.repeat(t[:30], 2), np.repeat(v[:30], 2)  # every time twice
    path = _csv(tmp_path / "twice.csv", np.r_[t, _drive()[0][30:]], np.r_[v, _drive()[1][30:]])
    caplog.set_level(logging.WARNING)
    load_time_speed_csv(path)
    (line,) = _warnings(caplog)
    assert "rows 2, 4, 6, 8, 10, 12, 14, 16, 18, 20 and 20 more repeat" in line


def test_repeated_times_with_different_speeds_are_refused(tmp_path, caplog):
    t, v = _drive()
    t = np.insert(t, 5, t[4])
    v = np.insert(v, 5, v[4] + 3.0)  # same time, 3 m/s apart
    path = _csv(tmp_path / "conflict.csv", t, v)
    caplog.set_level(logging.WARNING)
    with pytest.raises(TraceFormatError) as err:
        load_time_speed_csv(path)
    message = str(err.value)
    assert message.startswith(f"conflict.csv: rows 5 and 6 share the time {t[4]:g} s")
    assert f"{v[4]:.4g} and {v[5]:.4g} m/s, 3 m/s apart" in message
    assert "allowed: rows repeating a time may differ by at most 0.5 m/s" in message
    assert "\n" not in message and not _warnings(caplog)
    # the CLI's check: one line naming the setting, before anything is written
    with pytest.raises(ConfigError, match=r"^scenario\.trace_path=.*rows 5 and 6 share"):
        check_trace_settings("csv", str(path))


def test_conflicting_repeats_are_shown_in_the_file_unit(tmp_path):
    t, v = _drive()
    kmh = np.round(v * 3.6)
    t, kmh = np.insert(t, 2, t[1]), np.insert(kmh, 2, kmh[1] + 11.0)
    path = _csv(tmp_path / "kmh.csv", t, kmh, header="time,speed_kmh")
    with pytest.raises(TraceFormatError, match=rf"{kmh[1]:g} and {kmh[2]:g} km/h, 3.06 m/s"):
        load_time_speed_csv(path)


def test_ngsim_and_highd_repeated_frames_name_the_vehicle(write_ngsim, write_text):
    rows = [(3, f, 40.0) for f in range(1, 11)] + [(3, 5, 50.0), (7, 1, 30.0), (7, 2, 30.0)]
    path = write_ngsim("ngsim.csv", rows)
    with pytest.raises(TraceFormatError, match=r"vehicle 3, rows 5 and 11 share .*40 and 50 ft/s"):
        load_ngsim(path)
    assert [p.vehicle_id for p in load_ngsim(path, vehicle_ids=[7])] == ["ngsim/7"]
    text = "frame,id,xVelocity\n1,1,30.0\n2,1,30.5\n2,1,-20.0\n"
    with pytest.raises(TraceFormatError, match=r"vehicle 1, rows 2 and 3 share .*30.5 and 20 m/s"):
        load_highd(write_text("01_tracks.csv", text))


# --------------------------------------------------------------------- km/h read as m/s


def test_city_speeds_in_kmh_in_an_mps_column_draw_a_warning(tmp_path, caplog):
    t = np.arange(0.0, 120.0 + 1e-9, 1.0)
    city_kmh = np.round(43.5 + 14.5 * np.sin(t / 10.0))  # 29 to 58 km/h
    caplog.set_level(logging.WARNING)
    load_time_speed_csv(_csv(tmp_path / "city.csv", t, city_kmh, header="time,speed_mps"))
    (line,) = _warnings(caplog)
    assert line.startswith("city.csv: column 'speed_mps' is read as m/s, but its speeds reach 58")
    assert "they look like km/h" in line and "name the column speed_kmh" in line
    # the same numbers under their unit, and a motorway drive in m/s, say nothing
    caplog.clear()
    load_time_speed_csv(_csv(tmp_path / "city_kmh.csv", t, city_kmh, header="time,speed_kmh"))
    load_time_speed_csv(_csv(tmp_path / "motorway.csv", t, 33.0 + 5.0 * np.sin(t / 10.0)))
    assert _warnings(caplog) == []


# --------------------------------------------------------------- clipped hard braking


def _braking(path):
    """120 s at 15 m/s, then a stop at -5 m/s² (beyond the followers' -2.6), then away."""
    t = np.arange(0.0, 240.0 + 1e-9, 0.1)
    v = np.where(t < 100, 15.0, np.clip(15.0 - 5.0 * (t - 100.0), 0.0, None))
    v = np.where(t >= 110, np.minimum(1.0 * (t - 110.0), 15.0), v)
    return _csv(path, np.round(t, 1), np.round(v, 4))


def test_load_trace_source_warns_once_of_clipped_braking(tmp_path, caplog):
    path = _braking(tmp_path / "brake.csv")
    caplog.set_level(logging.WARNING)
    source = load_trace_source("csv", path, part="train")
    clipped = source.preprocessing["accel_points_clipped"]
    assert clipped > 0
    (line,) = _warnings(caplog)
    assert line.startswith(f"{path}: pre-processing clipped the acceleration of {clipped} of ")
    assert "5.00 m/s² became 2.60 m/s²" in line
    assert "preprocess_kw={'clip_accel_mps2': None} keeps the recorded ones" in line
    # one file read for both parts: one warning
    caplog.clear()
    load_train_eval_sources("csv", path)
    assert len(_warnings(caplog)) == 1
    # the recorded acceleration, kept on request, and a gentle drive: nothing to say
    caplog.clear()
    load_trace_source("csv", path, preprocess_kw={"clip_accel_mps2": None})
    load_trace_source("csv", _csv(tmp_path / "gentle.csv", *_drive()))
    assert _warnings(caplog) == []


def test_the_cli_path_leaves_the_clipping_warning_to_the_run(tmp_path, caplog):
    # the run warns itself, naming scenario.trace_accel_clip (selection.preprocessing_note)
    path = _braking(tmp_path / "brake.csv")
    caplog.set_level(logging.WARNING)
    train, _ = file_sources("csv", str(path))
    assert train.preprocessing["accel_points_clipped"] > 0
    assert _warnings(caplog) == []


def test_a_run_reading_a_file_twice_warns_of_it_once(tmp_path, caplog):
    # a run checks its file with the default band and may train with none (trace_accel_clip)
    t, v = _drive()
    path = _csv(tmp_path / "again.csv", np.insert(t, 3, t[2]), np.insert(v, 3, v[2]))
    caplog.set_level(logging.WARNING)
    file_sources("csv", str(path))
    file_sources("csv", str(path), clip_accel_mps2=None)
    assert len(_warnings(caplog)) == 1
