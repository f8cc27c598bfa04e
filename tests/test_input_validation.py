"""Bad or unusual input outside the Hydra schema: trace settings, trace files, model keyword
types, devices and the small command-line tools. Each error names the value and what is allowed.
"""

import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

import vdtn_marl
from vdtn_marl import cli
from vdtn_marl.data.profiles import load_train_eval_sources
from vdtn_marl.experiment.config import RunConfig, validate
from vdtn_marl.experiment.jocc import trace_sources
from vdtn_marl.sim.params import ConfigError
from vdtn_marl.sim.twin import resolve_device

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)


def _write_trace(path, duration_s=120.0, vehicles=("",)):
    """A ``time,speed`` CSV (one vehicle) of 0.1 s samples, speeds in m/s."""
    t = np.arange(0.0, duration_s + 1e-9, 0.1)
    v = 20.0 + 3.0 * np.sin(t / 7.0)
    rows = "\n".join(f"{a:.1f},{b:.4f}" for a, b in zip(t, v, strict=True))
    path.write_text("time,speed\n" + rows + "\n")
    return path


DEFAULT_TRACES = RunConfig().scenario.traces


def _cfg(**scenario):
    cfg = RunConfig()
    return replace(cfg, scenario=replace(cfg.scenario, **scenario))


# ------------------------------------------------------------------------------ trace files


def test_a_single_vehicle_csv_is_split_in_time(tmp_path):
    path = _write_trace(tmp_path / "drive.csv")
    train, evaluation = load_train_eval_sources("csv", path)
    (p_train,), (p_eval,) = train.profiles, evaluation.profiles
    assert p_train.time_s[-1] <= p_eval.time_s[0] + 1e-9  # evaluation follows training
    assert p_train.duration_s == pytest.approx(0.8 * 120.0, abs=0.1)
    assert p_eval.duration_s == pytest.approx(0.2 * 120.0, abs=0.1)
    assert "first 80% / last 20%" in evaluation.info.description
    # and a run config that names the file uses the same two parts (24 s of eval part hold one
    # disjoint window of episode + look-ahead: random windows)
    cfg = validate(_cfg(traces="csv", trace_path=str(path), eval_windows="random"))
    run_train, run_eval = trace_sources(cfg)
    assert run_train.profiles[0].duration_s == p_train.duration_s
    assert run_eval.profiles[0].duration_s == p_eval.duration_s


def test_a_file_whose_vehicles_fall_in_both_parts_keeps_the_id_split(monkeypatch):
    # us101/2 is an eval vehicle and us101/7 a training one (tests/data/test_data_profiles.py)
    from vdtn_marl.data import profiles as profiles_module
    from vdtn_marl.data.loaders import SpeedProfile

    t = np.arange(0.0, 60.0, 0.1)
    fake = [SpeedProfile(t, 20.0 + 0 * t, vid, "fake") for vid in ("us101/2", "us101/7")]
    monkeypatch.setitem(profiles_module.LOADERS, "csv", lambda path: list(fake))
    train, evaluation = load_train_eval_sources("csv", "unused.csv")
    assert [p.vehicle_id for p in train.profiles] == ["us101/7"]
    assert [p.vehicle_id for p in evaluation.profiles] == ["us101/2"]


@pytest.mark.parametrize(
    "scenario, fragment",
    [
        (dict(traces="foo"), "scenario.traces='foo' is not a known trace set"),
        (dict(traces="csv"), "scenario.traces='csv' reads a file"),
        (
            dict(trace_path="drive.csv"),
            f"scenario.traces={RunConfig().scenario.traces!r} cannot read",
        ),
        (dict(traces="csv", trace_path="no/such.csv"), "scenario.trace_path='no/such.csv'"),
        (dict(traces="csv", trace_path="bad.csv"), "bad.csv row 3: time 1 s is earlier"),
        (dict(traces="ngsim", trace_path="drive.csv"), "(ngsim)"),
        (dict(traces="csv", trace_path="one.csv"), "one.csv is too short: its longest drive"),
    ],
)
def test_bad_trace_settings_are_config_errors(scenario, fragment, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _write_trace(tmp_path / "drive.csv")
    (tmp_path / "one.csv").write_text("time,speed\n0,10\n")
    (tmp_path / "bad.csv").write_text("time,speed\n0,10\n2,10\n1,10\n")
    with pytest.raises(ConfigError) as info:
        validate(_cfg(**scenario))
    assert fragment in str(info.value)


def test_a_trace_file_too_short_for_a_scenario_is_refused_before_anything_runs(
    tmp_path, monkeypatch, capsys
):
    """32 s of one drive: its eval part (the last 20 %, 6.4 s) cannot hold the 20 s of an
    episode and the look-ahead; the message says how long the file must be and why."""
    path = _write_trace(tmp_path / "short.csv", duration_s=32.0)
    with pytest.raises(ConfigError) as info:
        validate(_cfg(traces="csv", trace_path=str(path), eval_windows="random"))
    message = str(info.value)
    assert message.startswith(f"scenario.trace_path={str(path)!r}") and "\n" not in message
    for part in ("eval part", "6.4 s", "20 s", "look-ahead", "at least 100 s"):
        assert part in message, message
    # a shorter episode does not rescue it: the 10 s look-ahead alone needs a 50 s file
    with pytest.raises(ConfigError, match="scenario.trace_path"):
        validate(_cfg(traces="csv", trace_path=str(path), episode_intervals=20))
    validate(_cfg(traces="csv", trace_path=str(_write_trace(tmp_path / "ok.csv", 100.0)),
                  eval_windows="random"))  # fmt: skip
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    monkeypatch.chdir(tmp_path / "out")
    assert cli.main(["jocc", "scenario.traces=csv", f"scenario.trace_path={path}"]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and "at least 100 s" in lines[0], lines
    assert list((tmp_path / "out").iterdir()) == []


def test_a_recorded_part_without_a_long_enough_profile_is_refused(monkeypatch):
    from vdtn_marl.data import profiles as profiles_module
    from vdtn_marl.data.loaders import SpeedProfile

    long_t, short_t = np.arange(0.0, 60.0, 0.1), np.arange(0.0, 12.0, 0.1)
    fake = [  # us101/2 evaluates, us101/7 trains (split by vehicle)
        SpeedProfile(short_t, 20.0 + 0 * short_t, "us101/2", "fake"),
        SpeedProfile(long_t, 20.0 + 0 * long_t, "us101/7", "fake"),
    ]
    monkeypatch.setitem(profiles_module.LOADERS, "csv", lambda path: list(fake))
    with pytest.raises(ConfigError) as info:
        validate(_cfg(traces="csv", trace_path=__file__, eval_windows="random"))
    assert "no profile of its eval part" in str(info.value), info.value
    assert "the longest 11.9 s" in str(info.value), info.value


@pytest.mark.parametrize(
    "overrides, key",
    [
        (["scenario.traces=foo"], "scenario.traces='foo'"),
        (["scenario.traces=csv", "scenario.trace_path=no_such.csv"], "scenario.trace_path"),
        (["train", "task=rra", "rra=greedy"], "task=rra"),
    ],
)
def test_cli_refuses_bad_traces_and_tasks_in_one_line_and_writes_nothing(
    overrides, key, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    command = overrides[0] if overrides[0] == "train" else "jocc"
    rest = overrides[1:] if command == "train" else overrides
    assert cli.main([command, *rest]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and key in lines[0], lines
    assert list(tmp_path.iterdir()) == []


def test_task_rra_needs_a_learned_rra_method():
    cfg = RunConfig(task="rra")
    from vdtn_marl.policies.registry import RRA_BASELINES

    for name in RRA_BASELINES:
        with pytest.raises(ConfigError, match=f"rra={name} has nothing to learn"):
            validate(replace(cfg, rra=replace(cfg.rra, name=name)))
    validate(replace(cfg, rra=replace(cfg.rra, name="drra")))
    validate(replace(cfg, task="control", rra=replace(cfg.rra, name="greedy")))


# ------------------------------------------------------------------ model keywords, devices


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(num_vehicles=4.5), "num_vehicles=4.5 must be an integer"),
        (dict(num_vehicles="4"), "num_vehicles='4' must be an integer"),
        (dict(num_vehicles=True), "num_vehicles=True must be an integer"),
        (dict(carrier_ghz="2"), "carrier_ghz='2' must be a number"),
        (dict(v2v_power_levels_dbm=[23, "x"]), "v2v_power_levels_dbm=(23, 'x') must be"),
        (dict(episode_intervals=None), "episode_intervals=None must be an integer"),
        (dict(kappa1="a"), "kappa1='a' must be a number in [0, 1]"),
        (dict(device="foo"), "device='foo' is not a torch device"),
        (dict(device="mps"), "device='mps' is not supported"),
    ],
)
def test_make_names_the_bad_keyword(kwargs, message):
    with pytest.raises(ConfigError) as info:
        vdtn_marl.make("vdtn/vdtn-joint-v1", **kwargs)
    assert message in str(info.value)


def test_make_accepts_numpy_scalars():
    env = vdtn_marl.make(
        "vdtn/platoon-control-v0", num_vehicles=np.int64(5), driveline_lag_s=np.float32(0.2)
    )
    assert env.twin.num_followers == 4


def test_resolve_device_names_cpu_or_the_missing_cuda():
    assert resolve_device("cpu").type == "cpu"
    import torch

    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="device='cuda' is not available.*allowed: cpu"):
            resolve_device("cuda")


# ---------------------------------------------------------------------- small CLI tools


@pytest.mark.parametrize(
    "argv, fragment",
    [(["--kappa1", "2"], "kappa1=2.0 is outside"), (["--device", "foo"], "device='foo'")],
)
def test_rollout_tool_rejects_bad_flags_in_one_line(argv, fragment, capsys):
    from vdtn_marl.cli.rollout import main

    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err


def test_jocc_module_rejects_a_bad_kappa1_before_writing(tmp_path, capsys):
    from vdtn_marl.experiment.jocc import main

    with pytest.raises(SystemExit) as info:
        main(["--kappa1", "2", "--run-dir", str(tmp_path / "run")])
    assert info.value.code == 2
    assert "rra.kappa1=2.0 is outside" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("module", ["vdtn_marl.experiment.jocc"])
def test_python_m_jocc_keeps_its_flags(module, tmp_path):
    """``python -m vdtn_marl.experiment.jocc`` parses its flags."""
    run = tmp_path / "run"
    done = subprocess.run(
        [sys.executable, "-m", module, "--kappa1", "2", "--run-dir", str(run)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2, done.stderr
    assert "rra.kappa1=2.0 is outside" in done.stderr and "Traceback" not in done.stderr
    assert not run.exists()


def test_jocc_module_refuses_a_run_dir_that_holds_a_run(tmp_path, capsys, monkeypatch):
    from vdtn_marl.experiment import jocc

    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    files = {"summary.json": '{"control_cost": 1.0}', "config.yaml": "seed: 0\n"}
    files["metrics.csv"] = "iteration,control_cost\n0,1.0\n"
    files["checkpoints/last.pt"] = "a finished run's checkpoint"
    for name, text in files.items():
        (run / name).write_text(text)

    def fail(*args, **kwargs):
        raise AssertionError("training started")

    monkeypatch.setattr(jocc, "JointOptimisation", fail)
    assert jocc.main(["--run-dir", str(run)]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: --run-dir={run} already holds a run (config.yaml")
    assert "allowed: --resume to continue it, or another --run-dir" in lines[0]
    assert {name: (run / name).read_text() for name in files} == files
    assert sorted(p.name for p in run.rglob("*")) == sorted(
        ["checkpoints", "last.pt", "summary.json", "config.yaml", "metrics.csv"]
    )

    # --resume continues it: the loop is built (and resumes from checkpoints/last.pt itself)
    calls = []

    class Resumed:
        def __init__(self, cfg, run_dir):
            calls.append((cfg.resume, run_dir))

        def run(self):
            return {"control_cost": 1.0}

    monkeypatch.setattr(jocc, "JointOptimisation", Resumed)
    assert jocc.main(["--run-dir", str(run), "--resume"]) == 0
    assert calls == [(True, str(run))]


def test_a_recorded_trace_set_trains_and_evaluates_on_different_stretches(monkeypatch):
    """A named recorded set is one drive (a driving cycle): without a split, evaluation windows
    would be cut from the stretch that training drew from."""
    from vdtn_marl.data import traces as traces_module
    from vdtn_marl.data.loaders import SpeedProfile
    from vdtn_marl.data.profiles import ProfileTraceSource

    t = np.arange(0.0, 300.0, 0.1)
    drive = SpeedProfile(t, 20.0 + np.sin(t / 10.0), "drive", "recorded")
    monkeypatch.setitem(traces_module._TRACE_SOURCES, "drive", lambda: ProfileTraceSource([drive]))
    cfg = validate(_cfg(traces="drive", eval_windows="random"))  # 60 s held out: 2 windows
    train, evaluation = trace_sources(cfg)
    (p_train,), (p_eval,) = train.profiles, evaluation.profiles
    assert p_train.time_s[-1] <= p_eval.time_s[0] + 1e-9
    assert p_train.duration_s == pytest.approx(0.8 * drive.duration_s, abs=0.1)
    assert "part=eval" in evaluation.info.description
    # generated sets are drawn afresh for every seed: one name serves both
    assert trace_sources(validate(_cfg(traces="synthetic"))) == ("synthetic", "synthetic")


def _write_braking_trace(path):
    """240 s at 15 m/s with a stop at −5 m/s² at t = 100 s (beyond the followers' −2.6)."""
    t = np.arange(0.0, 240.0 + 1e-9, 0.1)
    v = np.where(t < 100, 15.0, np.clip(15.0 - 5.0 * (t - 100.0), 0.0, None))
    v = np.where(t >= 110, np.minimum(1.0 * (t - 110.0), 15.0), v)
    rows = "\n".join(f"{a:.1f},{b:.4f}" for a, b in zip(t, v, strict=True))
    path.write_text("time,speed\n" + rows + "\n")
    return path


def test_hard_braking_in_a_trace_file_is_reported_and_can_be_kept(tmp_path):
    from vdtn_marl.data.selection import preprocessing_note

    path = _write_braking_trace(tmp_path / "brake.csv")
    cfg = validate(_cfg(traces="csv", trace_path=str(path), eval_windows="random"))
    train, evaluation = trace_sources(cfg)
    report = train.preprocessing
    assert report == evaluation.preprocessing  # one file, one report
    assert report["accel_points_clipped"] > 0 and report["clip_accel_mps2"] == [-2.6, 2.6]
    assert report["accel_min_before_mps2"] == pytest.approx(-5.0, abs=0.01)
    assert report["accel_min_after_mps2"] == pytest.approx(-2.6, abs=1e-6)
    assert min(np.diff(p.speed_mps).min() / 0.1 for p in train.profiles) >= -2.6 - 1e-9
    note = preprocessing_note(train, cfg.scenario.trace_path)
    assert note.startswith(f"scenario.trace_path={str(path)!r}") and "\n" not in note
    assert "5.00 m/s² became 2.60 m/s²" in note and "scenario.trace_accel_clip=none" in note
    # the leader's recorded deceleration, kept on request
    kept = validate(_cfg(traces="csv", trace_path=str(path), eval_windows="random",
                         trace_accel_clip="none"))  # fmt: skip
    train, _ = trace_sources(kept)
    assert train.preprocessing["accel_points_clipped"] == 0
    assert train.preprocessing["clip_accel_mps2"] is None
    assert min(np.diff(p.speed_mps).min() / 0.1 for p in train.profiles) < -4.5
    assert preprocessing_note(train, kept.scenario.trace_path) is None
    # a file that needs no clipping says nothing
    smooth = validate(_cfg(traces="csv", trace_path=str(_write_trace(tmp_path / "ok.csv", 120.0)),
                           eval_windows="random"))  # fmt: skip
    assert preprocessing_note(trace_sources(smooth)[0], smooth.scenario.trace_path) is None


@pytest.mark.parametrize(
    "scenario, key",
    [
        (dict(trace_accel_clip="bogus"), "scenario.trace_accel_clip='bogus' is not allowed"),
        (dict(trace_accel_clip="none"), "scenario.trace_accel_clip='none' applies to a trace"),
    ],
)
def test_bad_trace_accel_clip_is_one_line(scenario, key):
    with pytest.raises(ConfigError, match=key):
        validate(_cfg(**scenario))
