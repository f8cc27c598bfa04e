"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-06-two-cores/test_two_cores.py``."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


two_cores = _script("two_cores.py")


def _arm(stage, arm, repeat, collect, update_1=0.5, update_2=0.4, frames=25_600):
    row = {
        "stage": stage,
        "arm": arm,
        "repeat": repeat,
        "frames_per_iteration": frames,
        "collect_s": list(collect),
        "peak_rss_mb": 500.0 if arm == "one" else 400.0,
    }
    if arm == "one":
        row["update_1_thread_s"] = [update_1] * len(collect)
        row["update_2_thread_s"] = [update_2] * len(collect)
    return row


def test_two_cores_pairs_the_arms_within_a_repeat_and_estimates_the_budget():
    runs = []
    for stage, one, shards in (
        ("pi_star", 0.2, 0.2),
        ("pi_tilde_random", 3.0, 2.0),
        ("pi_tilde_learned", 4.0, 2.0),
        ("rra", 1.0, 0.8),
    ):
        runs += [_arm(stage, "one", 0, [one] * 3), _arm(stage, "shards", 0, [shards] * 3)]
    # a slow repeat of both arms: paired, its ratio is the same 2.0
    runs += [
        _arm("pi_tilde_learned", "one", 1, [8.0, 8.0, 9.0]),
        _arm("pi_tilde_learned", "shards", 1, [4.0, 4.0, 3.0]),
    ]
    rows = {r["stage"]: r for r in two_cores.summarise(runs, list(two_cores.STAGES))}
    learned = rows["pi_tilde_learned"]
    assert learned["one_over_shards"] == pytest.approx(2.0)
    assert learned["one_over_shards_range"] == [2.0, 2.0]
    assert learned["update_1_over_2"] == pytest.approx(1.25)
    assert learned["peak_rss_mb_one"] == 500.0 and learned["peak_rss_mb_shards"] == 400.0
    sizes = {"control_iterations": 500, "rra_iterations": 300}
    est = two_cores.estimate(list(rows.values()), sizes)
    later_one = (500 * (0.2 + 0.5) + 500 * (learned["collect_one_s"] + 0.5) + 300 * 1.5) / 60
    later_two = (500 * (0.2 + 0.4) + 500 * (learned["collect_shards_s"] + 0.4) + 300 * 1.2) / 60
    assert est["later"]["one_min"] == pytest.approx(later_one)
    assert est["later"]["two_cores_min"] == pytest.approx(later_two)
    later_threads = (500 * 0.6 + 500 * (learned["collect_one_s"] + 0.4) + 300 * 1.4) / 60
    assert est["later"]["update_threads_min"] == pytest.approx(later_threads)
    assert est["first"]["one_over_two"] == pytest.approx(
        (500 * 0.7 + 500 * 3.5 + 300 * 1.5) / (500 * 0.6 + 500 * 2.4 + 300 * 1.2)
    )
    assert two_cores.estimate([rows["rra"]], sizes) is None  # stages missing: no estimate


@pytest.mark.parametrize(
    "argv, flag",
    [
        (["--stages", "pi_star,warp"], "--stages"),
        (["--shards", "1"], "--shards"),
        (["--iterations", "0"], "--iterations"),
    ],
)
def test_two_cores_refuses_bad_arguments(argv, flag, capsys):
    with pytest.raises(SystemExit) as refused:
        two_cores.parse_args(argv)
    assert flag in capsys.readouterr().err + str(refused.value.code)


def test_two_cores_summarise_refuses_a_file_that_is_not_its_results(tmp_path):
    bad = tmp_path / "other.json"
    bad.write_text(json.dumps({"runs": []}))
    with pytest.raises(SystemExit) as refused:
        two_cores.main(["--summarise", str(bad)])
    assert "--summarise" in str(refused.value.code) and "other.json" in str(refused.value.code)
