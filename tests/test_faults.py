"""Faults a run must survive without losing or corrupting anything: kill -9 in the middle of a
file write, a full disk, damaged files in a run being continued, two launchers in one run
directory, and environments driven at the edges of their physics."""

from __future__ import annotations

import csv
import errno
import json
import math
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

import vdtn_marl
from vdtn_marl.algos.checkpoint import load_checkpoint
from vdtn_marl.data.traces import TraceInfo
from vdtn_marl.errors import RunFileError, RunWriteError
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import LOCK_FILE, atomic_write_text, run_lock

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200", "OMP_NUM_THREADS": "1"}
RUN = [
    "jocc", "experiment=smoke", "experiment.control_iterations=3", "experiment.rra_iterations=3",
    "experiment.checkpoint_every=1", "progress=false",
]  # fmt: skip
linux_only = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs /proc")

# Runs the CLI with os.fsync patched: at the n-th write of the named file, after its data is
# in the temporary file and before os.replace, it leaves a marker and waits to be killed.
HANG_DURING_WRITE = r"""
import os, sys, time
from pathlib import Path
target, nth, marker = sys.argv[1], int(sys.argv[2]), sys.argv[3]
real, seen = os.fsync, [0]
def fsync(fd):
    real(fd)
    if Path(os.readlink(f"/proc/self/fd/{fd}")).name.startswith(f".{target}."):
        seen[0] += 1
        if seen[0] == nth:
            Path(marker).write_text("writing")
            time.sleep(120)
os.fsync = fsync
from vdtn_marl.cli import main
raise SystemExit(main(sys.argv[4:]))
"""


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    code = "from vdtn_marl.cli import main; raise SystemExit(main())"
    return subprocess.run(
        [sys.executable, "-c", code, *args], cwd=cwd, env=ENV, text=True, capture_output=True,
        timeout=300,
    )  # fmt: skip


def _assert_whole(run: Path) -> None:
    """Every file of the run that exists reads in full."""
    checkpoint = run / "checkpoints" / "last.pt"
    if checkpoint.exists():
        load_checkpoint(checkpoint)
    for name in ("metrics.csv", "evaluation.csv"):
        if (run / name).exists():
            with open(run / name, newline="", encoding="utf-8") as handle:
                rows = list(csv.DictReader(handle))
            assert all(None not in row and None not in row.values() for row in rows), name
    if (run / "summary.json").exists():
        assert isinstance(json.loads((run / "summary.json").read_text()), dict)


@linux_only
@pytest.mark.parametrize(
    "target, nth", [("last.pt", 2), ("metrics.csv", 3), ("evaluation.csv", 1), ("summary.json", 1)]
)
def test_kill_9_in_the_middle_of_a_write_loses_nothing(target, nth, tmp_path):
    run, marker = tmp_path / "run", tmp_path / "marker"
    proc = subprocess.Popen(
        [sys.executable, "-c", HANG_DURING_WRITE, target, str(nth), str(marker),
         *RUN, f"hydra.run.dir={run}"],
        cwd=tmp_path, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 240
    while not marker.exists():
        assert proc.poll() is None, proc.communicate()[1]
        assert time.monotonic() < deadline, "the write never came"
        time.sleep(0.05)
    proc.kill()  # SIGKILL, between the temporary file's last byte and its rename
    proc.wait(timeout=60)
    temporary = [*run.glob(f".{target}.*.tmp"), *(run / "checkpoints").glob(f".{target}.*.tmp")]
    assert temporary, "the kill did not land inside the write"
    _assert_whole(run)  # the file itself is its old version (or absent), never a part
    done = _cli(*RUN, f"hydra.run.dir={run}", "resume=true", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    _assert_whole(run)
    summary = json.loads((run / "summary.json").read_text())
    assert summary["resumed"] and summary["trainer_iterations"] == {
        "pi_star": 3, "pi_tilde": 3, "rra": 3,
    }  # fmt: skip
    assert not list(run.rglob("*.tmp")), "a temporary file was left behind"


def test_a_full_disk_is_one_clear_line_and_the_run_continues_after(tmp_path, monkeypatch, capsys):
    """The 6th file write fails with ENOSPC (as on a full disk): one line naming the file and
    how to continue, exit 1, every file whole, nothing temporary left; then the run continues
    to its end."""
    from vdtn_marl import cli
    from vdtn_marl.io import files as files_module

    real, calls = files_module.os.fsync, [0]

    def fsync(fd):
        calls[0] += 1
        if calls[0] == 6:
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd)

    monkeypatch.setattr(files_module.os, "fsync", fsync)
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run"
    with pytest.raises(SystemExit) as info:
        cli.main([*RUN, f"hydra.run.dir={run}"])
    assert info.value.code == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error")]
    assert len(err) == 1, err
    assert "cannot write " in err[0] and "No space left on device" in err[0], err
    assert "continue with: " in err[0] and "resume=true" in err[0], err
    _assert_whole(run)
    assert not list(run.rglob("*.tmp"))
    monkeypatch.setattr(files_module.os, "fsync", real)
    assert cli.main([*RUN, f"hydra.run.dir={run}", "resume=true"]) == 0
    _assert_whole(run)


def test_a_failed_write_keeps_the_previous_version(tmp_path, monkeypatch):
    from vdtn_marl.io import files as files_module

    path = atomic_write_text(tmp_path / "summary.json", '{"old": 1}\n')

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files_module.os, "fsync", full)
    with pytest.raises(RunWriteError, match="summary.json: No space left on device") as info:
        atomic_write_text(path, '{"new": 2}\n')
    assert info.value.errno == errno.ENOSPC and "previous version is intact" in str(info.value)
    assert path.read_text() == '{"old": 1}\n' and list(tmp_path.iterdir()) == [path]


# --- damaged files in a run being continued ---------------------------------------------------


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    from vdtn_marl.experiment.config import (
        AlgoConfig,
        ControlConfig,
        ExperimentConfig,
        RunConfig,
        ScenarioConfig,
    )

    cfg = RunConfig(  # a tiny run that writes every file (2 checkpoints per stage)
        scenario=ScenarioConfig(episode_intervals=40),
        control=ControlConfig(warm_start="none"),
        algo=AlgoConfig(num_envs=4, rollout_steps=10, rra_num_envs=4, rra_rollout_steps=50,
                        minibatch_size=64, epochs=1),
        experiment=ExperimentConfig(control_iterations=2, rra_iterations=2, eval_episodes=2,
                                    eval_intervals=10, checkpoint_every=1),
        progress=False,
    )  # fmt: skip
    run = tmp_path_factory.mktemp("finished")
    JointOptimisation(cfg, run).run()
    return cfg, run


def _copy_run(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


@pytest.mark.parametrize(
    "name, damage, fragment",
    [
        ("metrics.csv", lambda text: text[: len(text) // 2], "metrics.csv"),
        ("metrics.csv", lambda text: text.splitlines()[0] + "\n", "metrics.csv holds 0 rows"),
        ("metrics.csv", lambda text: "\x00\x01binary\x00" * 20, "metrics.csv (is damaged|holds 0)"),
        ("evaluation.csv", lambda text: "", "evaluation.csv holds 0 rows"),
        ("summary.json", lambda text: text[: len(text) // 3], "summary.json is damaged"),
        ("summary.json", lambda text: "[1, 2]", "summary.json is damaged"),
    ],
)
def test_a_damaged_file_in_a_run_being_continued_is_named(
    name, damage, fragment, finished_run, tmp_path
):
    cfg, src = finished_run
    run = _copy_run(src, tmp_path / "run")
    path = run / name
    path.write_text(damage(path.read_text()))
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    with pytest.raises(RunFileError, match=fragment) as info:
        JointOptimisation(replace(cfg, resume=True), run).run()
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    after = {p: p.read_bytes() for p in run.rglob("*") if p.is_file() and p.name != LOCK_FILE}
    assert after == {p: b for p, b in before.items() if p.name != LOCK_FILE}  # nothing written


@pytest.mark.parametrize("name", ["metrics.csv", "checkpoints/last.pt"])
def test_a_damaged_file_on_resume_is_one_line_from_the_cli(name, tmp_path, monkeypatch, capsys):
    from vdtn_marl import cli

    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run"
    assert cli.main([*RUN, f"hydra.run.dir={run}"]) == 0
    path = run / name
    if name.endswith(".csv"):
        path.write_text("not,a\n1,2,3,4\n")
    else:
        path.write_bytes(path.read_bytes()[:200])  # a checkpoint cut short
    capsys.readouterr()
    with pytest.raises(SystemExit) as info:
        cli.main([*RUN, f"hydra.run.dir={run}", "resume=true"])
    assert info.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert lines == [line for line in lines if line.startswith("error: ")] and len(lines) == 1
    assert str(path) in lines[0] and "Traceback" not in lines[0]


# --- two launchers in one run directory --------------------------------------------------------


def test_a_second_launcher_into_a_running_directory_refuses(tmp_path):
    run = tmp_path / "run"
    first = subprocess.Popen(
        [sys.executable, "-c", "from vdtn_marl.cli import main; raise SystemExit(main())",
         "jocc", "experiment=smoke", "experiment.control_iterations=300", "progress=false",
         f"hydra.run.dir={run}"],
        cwd=tmp_path, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 120
        while not (run / "metrics.csv").exists():
            assert first.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        config = (run / "config.yaml").read_bytes()
        second = _cli(
            "jocc", "experiment=smoke", "experiment.control_iterations=300", "progress=false",
            f"hydra.run.dir={run}", "resume=true", cwd=tmp_path,
        )  # fmt: skip
        assert second.returncode == 2, second.stderr
        last = [line for line in second.stderr.splitlines() if line.strip()][-1]
        assert last.startswith("error: ") and f"pid {first.pid}" in last and str(run) in last
        assert (run / "config.yaml").read_bytes() == config
        assert first.poll() is None  # the first run goes on
    finally:
        first.kill()
        first.wait(timeout=60)


def test_the_run_lock_is_reentrant_in_a_process_and_released_after(tmp_path):
    with run_lock(tmp_path), run_lock(tmp_path):
        pid = (tmp_path / LOCK_FILE).read_text().strip()
        assert pid == str(os.getpid())
    code = (
        "import sys; from vdtn_marl.io.files import run_lock\n"
        "with run_lock(sys.argv[1]): print('got it')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path)], env=ENV, text=True, capture_output=True
    )
    assert done.returncode == 0 and "got it" in done.stdout, done.stderr


# --- environments at the edges of their physics ----------------------------------------------


class _StepTraces:
    """Leader speed profiles that jump between 0 and 40 m/s every 20 points, or stay at 0."""

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.info = TraceInfo(name=f"edge-{kind}", description=kind, synthetic=True, source="")

    def sample(self, num_traces, num_points, dt_s, generator):
        if self.kind == "stopped":
            return torch.zeros(num_traces, num_points)
        square = (torch.arange(num_points) // 20) % 2 == 1
        return (40.0 * square.to(torch.get_default_dtype())).expand(num_traces, -1).clone()


def _finite(value) -> bool:
    if isinstance(value, dict):
        return all(_finite(v) for v in value.values())
    if isinstance(value, bool | str) or value is None:
        return True
    return bool(np.all(np.isfinite(np.asarray(value, dtype=np.float64))))


@pytest.mark.parametrize(
    "env_id", [i for i in vdtn_marl.list_envs(api="pettingzoo") if i.startswith("vdtn/")]
)
@pytest.mark.parametrize(
    "kind, vehicles, shadow_db",
    [("steps", 4, 30.0), ("stopped", 4, 30.0), ("steps", 64, 3.0), ("stopped", 64, 0.0)],
)
def test_environments_stay_finite_at_the_edges(env_id, kind, vehicles, shadow_db):
    """Leader steps 0 → 40 → 0 m/s, a leader stopped from t = 0, 64 vehicles, the widest
    shadowing allowed: every observation, reward and info is finite, through collisions."""
    env = vdtn_marl.make(
        env_id, seed=0, traces=_StepTraces(kind), num_vehicles=vehicles,
        v2v_shadow_std_db=shadow_db, v2i_shadow_std_db=shadow_db,
    )  # fmt: skip
    obs, infos = env.reset(seed=0)
    rng = np.random.default_rng(0)
    steps = 0
    for _ in range(3 if vehicles == 64 else 12):  # episodes, each to its end or a cut-off
        done = False
        while not done and steps < (150 if vehicles == 64 else 600):
            actions = {a: env.action_space(a).sample() for a in env.agents}
            for a in actions:  # the extremes of the action range, half the time
                if env.action_space(a).shape == (1,) and rng.random() < 0.5:
                    actions[a] = env.action_space(a).high.copy() * rng.choice([-1.0, 1.0])
            obs, rewards, terminated, truncated, infos = env.step(actions)
            steps += 1
            assert all(_finite(o) for o in obs.values()), (env_id, steps)
            assert all(math.isfinite(r) for r in rewards.values()), (env_id, steps, rewards)
            assert all(_finite(i) for i in infos.values()), (env_id, steps, infos)
            done = any(terminated.values()) or any(truncated.values())
        obs, infos = env.reset()
        assert all(_finite(o) for o in obs.values())
