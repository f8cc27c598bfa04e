"""The CLI without Hydra: `envs` table, `rollout` forwarding, help, usage errors."""

from __future__ import annotations

import json
import sys
import types

import pytest

import vdtn_marl
from vdtn_marl import cli

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)

BUILTIN_IDS = tuple(env_id for env_id in vdtn_marl.list_envs() if env_id.startswith("vdtn/"))
"""Every built-in id, from the registry (tests/test_registry.py pins the list itself)."""


def test_envs_prints_table_with_builtin_ids(capsys):
    assert cli.main(["envs"]) == 0
    out = capsys.readouterr().out
    header = out.splitlines()[0]
    for column in ("id", "agents", "clocks", "description", "data source"):
        assert column in header
    for env_id in BUILTIN_IDS:
        assert env_id in out
    assert "vehicle=50ms, rra=1ms" in out


def test_envs_json(capsys):
    assert cli.main(["envs", "--json"]) == 0
    rows = {row["id"]: row for row in json.loads(capsys.readouterr().out)}
    assert set(BUILTIN_IDS) <= set(rows)
    assert rows["vdtn/vdtn-joint-v1"]["clocks"] == {"vehicle": 50, "rra": 1}
    assert rows["vdtn/platoon-control-impaired-v1"]["kwargs"] == {"impaired": True}


def test_rollout_forwards_all_arguments(monkeypatch):
    seen = []
    fake = types.ModuleType("vdtn_marl.cli.rollout")
    fake.main = lambda argv: seen.append(list(argv)) or 0
    monkeypatch.setitem(sys.modules, "vdtn_marl.cli.rollout", fake)
    assert cli.main(["rollout", "--env", "vdtn/v2x-rra-v1", "--help"]) == 0
    assert seen == [["--env", "vdtn/v2x-rra-v1", "--help"]]


@pytest.mark.parametrize("argv", [["no-such-command"], []])
def test_unknown_or_missing_command_is_usage_error(argv, capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(argv)
    assert info.value.code == 2
    assert "usage:" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv,command,rest",
    [
        (["jocc", "seed=1"], "jocc", ["seed=1"]),
        (["-m", "jocc", "seed=0,1"], "jocc", ["-m", "seed=0,1"]),
        (["--cfg", "job", "train", "task=rra"], "train", ["--cfg", "job", "task=rra"]),
        (["-m", "rra.kappa1=0,1", "jocc"], "jocc", ["-m", "rra.kappa1=0,1"]),
        (["--info", "defaults", "eval"], "eval", ["--info", "defaults"]),
        (["-m"], None, ["-m"]),
    ],
)
def test_split_command_finds_the_command_word_among_hydra_flags(argv, command, rest):
    assert cli.split_command(argv) == (command, rest)


def test_help_needs_no_command(capsys):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "commands:" in out and "config groups" in out and "platoon4*" in out
