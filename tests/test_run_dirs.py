"""A run's folder: two launchers never share one (the one that loses touches nothing, a live
run is named as running), default folder names of two launches never collide, and no lock
file stays behind once a run has ended, however it ended (vdtn_marl.io.files.run_lock)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from vdtn_marl import cli
from vdtn_marl.io.files import LOCK_FILE, lock_holder, new_run_stamp, run_lock, run_stamp

pytestmark = [
    pytest.mark.slow,  # runs of the CLI or of training (the fast loop skips them)
    pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema"),
    pytest.mark.skipif(os.name != "posix", reason="flock"),
]

ENV = {**os.environ, "PYTHONUNBUFFERED": "1", "OMP_NUM_THREADS": "1"}
# Holds the lock of the folder argv[1] (as a live run does) until its stdin closes.
HOLD_LOCK = (
    "import sys; from vdtn_marl.io.files import run_lock\n"
    "with run_lock(sys.argv[1]):\n"
    "    print('held', flush=True)\n"
    "    sys.stdin.read()\n"
)


@pytest.fixture
def live_run(tmp_path):
    """A folder whose lock another process holds; yields (folder, that process)."""
    run = tmp_path / "run"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLD_LOCK, str(run)], env=ENV, text=True,
        stdin=subprocess.PIPE, stdout=subprocess.PIPE,
    )  # fmt: skip
    try:
        assert holder.stdout.readline().strip() == "held"
        yield run, holder
    finally:
        holder.stdin.close()
        holder.wait(timeout=60)


def _fake_entry(monkeypatch, name: str, calls: list, fail: bool = False) -> None:
    from vdtn_marl.experiment import api

    def fake(cfg, run_dir):
        calls.append(Path(run_dir))
        if fail:
            raise RuntimeError("the entry point failed")
        summary = {"control_cost": 1.0}
        (Path(run_dir) / "summary.json").write_text(json.dumps(summary))
        return summary

    monkeypatch.setattr(api, name, fake)


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    return lines[0]


def test_a_launch_that_loses_the_race_for_a_folder_touches_nothing(live_run, monkeypatch, capsys):
    """Both launches found the folder free; the first holds it now and has written Hydra's
    files: the second writes none of its own (not .hydra/config.yaml, not overrides.yaml)."""
    run, holder = live_run
    (run / ".hydra").mkdir()
    (run / ".hydra" / "config.yaml").write_text("seed: 0\n")
    (run / ".hydra" / "overrides.yaml").write_text("- seed=0\n")
    before = _files(run)
    calls = []
    _fake_entry(monkeypatch, "jocc", calls)
    monkeypatch.chdir(run.parent)
    assert cli.main(["jocc", "experiment=smoke", "seed=3", f"hydra.run.dir={run}"]) == 2
    line = _error_line(capsys.readouterr().err)
    assert str(run) in line and f"pid {holder.pid}" in line
    assert _files(run) == before and not calls


@pytest.mark.parametrize("resume", [False, True])
def test_a_live_run_is_reported_as_running(resume, live_run, monkeypatch, capsys):
    run, holder = live_run
    (run / "config.yaml").write_text("seed: 0\n")
    before = _files(run)
    monkeypatch.chdir(run.parent)
    args = ["jocc", "experiment=smoke", f"hydra.run.dir={run}", *(["resume=true"] * resume)]
    assert cli.main(args) == 2
    line = _error_line(capsys.readouterr().err)
    assert "still running" in line and f"pid {holder.pid}" in line
    assert "allowed: resume=true" not in line and "to continue it" not in line
    assert _files(run) == before


def test_two_default_launches_in_one_second_get_two_folders(tmp_path, monkeypatch, capsys):
    calls = []
    _fake_entry(monkeypatch, "jocc", calls)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("vdtn_marl.io.files.time.strftime", lambda pattern: "2026-12-07_10-00-00")
    assert cli.main(["jocc", "experiment=smoke"]) == 0
    assert cli.main(["jocc", "experiment=smoke"]) == 0
    assert len(calls) == 2 and calls[0] != calls[1]
    assert all(p.parent == tmp_path / "outputs" / "jocc" for p in calls)
    assert all(p.name.startswith("2026-12-07_10-00-00_") for p in calls)


def test_a_launch_keeps_one_stamp_until_the_next():
    stamp = new_run_stamp()
    assert run_stamp() == stamp == run_stamp()
    assert new_run_stamp() != stamp


@pytest.mark.parametrize("fail", [False, True])
def test_no_lock_file_stays_after_a_run(fail, tmp_path, monkeypatch):
    calls = []
    _fake_entry(monkeypatch, "jocc", calls, fail=fail)
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run"
    if fail:
        with pytest.raises(SystemExit) as info:  # Hydra reports the error and exits with 1
            cli.main(["jocc", "experiment=smoke", f"hydra.run.dir={run}"])
        assert info.value.code == 1
    else:
        assert cli.main(["jocc", "experiment=smoke", f"hydra.run.dir={run}"]) == 0
    assert calls and not (run / LOCK_FILE).exists()


def test_a_lock_file_left_by_a_killed_run_names_no_holder(tmp_path):
    (tmp_path / LOCK_FILE).write_text("999999\n")  # its process is gone: it locks nothing
    assert lock_holder(tmp_path) is None
    with run_lock(tmp_path):
        assert (tmp_path / LOCK_FILE).read_text().strip() == str(os.getpid())
    assert not (tmp_path / LOCK_FILE).exists()
