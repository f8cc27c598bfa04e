"""The Quick-start rollout runs and reports finite, physically plausible numbers."""

import math
import sys

import pytest

from vdtn_marl.cli.rollout import main, print_table, run


def test_rollout_reports_every_metric():
    results = run(intervals=3, seed=0, kappa1=0.5, device="cpu")
    assert results["control intervals"] == 3 and isinstance(results["control intervals"], int)
    assert 0.5 < results["V2I throughput per link (Mbps)"] < 5.0
    assert 0.0 <= results["CAM delivery rate"] <= 1.0
    assert results["mean IVoI per interval"] <= 1e-6 or math.isnan(
        results["mean IVoI per interval"]
    )


def test_rollout_cli_prints_table(capsys):
    assert main(["--intervals", "2", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "V2I throughput per link (Mbps)" in out and "CAM delivery rate" in out


def _row(out: str, key: str) -> str:
    (line,) = [line for line in out.splitlines() if key in line]
    return line


def test_rollout_cli_prints_counts_as_integers(capsys):
    assert main(["--intervals", "2", "--seed", "1"]) == 0
    line = _row(capsys.readouterr().out, "control intervals")
    assert line.rstrip(" │|").split()[-1] == "2", line


@pytest.mark.parametrize("rich", [True, False])
def test_rollout_table_formats_counts_and_measurements(rich, capsys, monkeypatch):
    if not rich:  # the plain fallback when rich is not installed
        monkeypatch.setitem(sys.modules, "rich.console", None)
    print_table({"control intervals": 40, "CAM delivery rate": 0.5}, "title")
    out = capsys.readouterr().out
    assert "40.000" not in out and _row(out, "control intervals").rstrip(" │|").endswith(" 40")
    assert "0.500" in _row(out, "CAM delivery rate")
