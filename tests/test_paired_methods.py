"""benchmarks/paired_methods.py: paired differences by seed from a report's runs table."""

import csv
import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "paired_methods.py"


def _script():
    spec = importlib.util.spec_from_file_location("paired_methods", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _write_runs(path: Path) -> None:
    metrics = [m for m, _ in _script().METRICS]
    rows = []
    for seed in range(4):  # "a" = "b" + seed + 1 on every metric; "b" lacks seed 3
        for method, value in (("a", 2.0 * seed + 1.0), ("b", 1.0 * seed)):
            if method == "b" and seed == 3:
                continue
            rows.append({"scenario": "s1", "method": method, "seed": seed,
                         **dict.fromkeys(metrics, value)})  # fmt: skip
    rows.append({"scenario": "s2", "method": "a", "seed": 0, **dict.fromkeys(metrics, 9.0)})
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def test_pairs_by_the_seeds_both_methods_have(tmp_path):
    runs = tmp_path / "leaderboard_runs.csv"
    _write_runs(runs)
    out = tmp_path / "paired.json"
    argv = [str(runs), "--scenario", "s1", "--pairs", "a:b", "--output", str(out)]
    assert _script().main(argv) == 0
    data = json.loads(out.read_text())
    for metric in data["metrics"]:
        stat = data["pairs"]["a - b"][metric]
        assert stat["seeds"] == [0, 1, 2] and stat["n"] == 3
        assert stat["mean"] == pytest.approx(2.0)  # differences 1, 2, 3
        assert stat["low"] < 2.0 < stat["high"]


@pytest.mark.parametrize("pairs", ["a:c", "a-b", "a:a", ","])
def test_a_bad_pair_is_refused_naming_the_flag(tmp_path, pairs, capsys):
    runs = tmp_path / "leaderboard_runs.csv"
    _write_runs(runs)
    with pytest.raises(SystemExit) as exc:
        _script().main([str(runs), "--scenario", "s1", "--pairs", pairs])
    assert "--pairs" in f"{exc.value}{capsys.readouterr().err}"
