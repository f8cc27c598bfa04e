"""ivoi_estimator_error.py: the td IVoI against a reference on the acting system's states, on a tiny JOCC run's checkpoint."""

import json

import pytest
import torch
from test_ivoi_signal import _load, checkpoint  # noqa: F401  (the tiny run's fixture)


def test_error_statistics_by_hand():
    module = _load("ivoi_estimator_error")
    reference = torch.tensor([0.0, 1.0, 2.0, 3.0], dtype=torch.float64)
    exact = module.error_stats(reference.clone(), reference)
    assert exact["bias"] == 0.0 and exact["rmse"] == 0.0
    assert exact["correlation"] == pytest.approx(1.0) and exact["explained"] == pytest.approx(1.0)
    shifted = module.error_stats(reference + 1.0, reference)  # biased, perfectly correlated
    assert shifted["bias"] == pytest.approx(1.0) and shifted["rmse"] == pytest.approx(1.0)
    assert shifted["correlation"] == pytest.approx(1.0)
    assert shifted["explained"] == pytest.approx(1.0 - 1.0 / float(reference.var()))
    flipped = module.error_stats(-reference, reference)
    assert flipped["correlation"] == pytest.approx(-1.0) and flipped["explained"] < 0


def test_measures_td_against_the_reference_on_the_same_intervals(checkpoint, tmp_path):  # noqa: F811
    module = _load("ivoi_estimator_error")
    out = tmp_path / "error.json"
    args = [str(checkpoint), "--rra", "learned,random", "--episodes", "2"]
    assert module.main([*args, "--reference", "rollout:3:mc", "--output", str(out)]) == 0
    data = json.loads(out.read_text())
    (run,) = data["runs"]
    assert [row["rra"] for row in run["rows"]] == ["jocc (learned)", "random"]
    for row in run["rows"]:
        counted = row["all"]["n"] + row["collision_intervals"]["n"]
        assert counted == 2 * 20 * 3  # scenarios × intervals × followers
        assert row["delivered"].get("n", 0) + row["lost"].get("n", 0) == row["all"]["n"]
        assert row["all"]["rmse"] >= abs(row["all"]["bias"])
    # a run without rra.value_fit: its td reads π*'s critic, the same as --td-value pi_star
    both = tmp_path / "both.json"
    argv = [*args, "--reference", "rollout:3:mc", "--td-value", "run,pi_star"]
    assert module.main([*argv, "--output", str(both)]) == 0
    rows = json.loads(both.read_text())["runs"][0]["rows"]
    assert [row["td_value"] for row in rows] == ["π*'s critic"] * 4
    assert rows[0]["all"] == rows[2]["all"] and rows[1]["all"] == rows[3]["all"]


def test_a_reference_the_signal_script_refuses_is_refused(checkpoint):  # noqa: F811
    module = _load("ivoi_estimator_error")
    with pytest.raises(SystemExit, match="--estimators"):
        module.main([str(checkpoint), "--reference", "rollout:0"])
