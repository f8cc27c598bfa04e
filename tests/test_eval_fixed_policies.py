"""`vdtn-marl eval` of fixed policies (no checkpoint, so no π* and no EVoI), several of them in
one process (`-m`), the per-scenario metrics of ``evaluation_raw.npz``, and the user's policy
spec at the top of ``summary.json``. Smoke budgets: each evaluation takes well under a second.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from vdtn_marl import cli
from vdtn_marl.algos.evaluate import PER_SCENARIO_METRICS, evaluate_system
from vdtn_marl.experiment.config import FIXED_CONTROLS, FIXED_RRA
from vdtn_marl.policies import CACCController, make_rra_baseline
from vdtn_marl.sim.params import TwinParams

pytestmark = [
    pytest.mark.slow,  # runs of the CLI or of training (the fast loop skips them)
    pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema"),
]

SMOKE = ("experiment=smoke", "progress=false")
#: the radio's metrics, absent where the radio is off (π* on perfect observations)
RADIO_METRICS = ("cam_delivery_rate", "v2i_throughput_mbps_per_link", "aoi_ms_mean")


def _eval(run_dir: Path, *overrides: str) -> dict:
    assert cli.main(["eval", f"hydra.run.dir={run_dir}", *SMOKE, *overrides]) == 0
    return json.loads((run_dir / "summary.json").read_text())


# --- item 3: eval of fixed policies ----------------------------------------------------------


def test_eval_scores_fixed_policies_without_a_checkpoint_and_says_there_is_no_evoi(
    tmp_path, capsys
):
    summary = _eval(tmp_path / "ev", "control=cacc", "rra=greedy")
    out = capsys.readouterr().out
    assert summary["task"] == "eval" and summary["checkpoint"] is None
    assert (summary["control"], summary["rra"]) == ("cacc", "greedy")
    assert math.isfinite(summary["control_cost"]) and 0.0 <= summary["cam_delivery_rate"] <= 1.0
    # no π*: EVoI and IVoI are null, nothing of π*'s is reported, and one line says so
    assert summary["evoi"] is None and summary["ivoi_sum"] is None
    for key in ("evoi_ci_low", "optimal_control_cost", "reference_ok", "kappa1"):
        assert key not in summary, key
    (note,) = summary["notes"]
    assert "EVoI" in note and "π*" in note
    assert [line for line in out.splitlines() if line.startswith("note:")] == [f"note: {note}"]
    with open(tmp_path / "ev" / "evaluation.csv", encoding="utf-8") as handle:
        (row,) = list(csv.DictReader(handle))
    assert "evoi" not in row and "ivoi_sum" not in row and float(row["control_cost"]) >= 0.0


@pytest.mark.parametrize(
    "overrides,named",
    [
        (["control=learned", "rra=greedy"], "control=learned is learned"),
        (["control=cacc", "rra=jocc"], "rra=jocc is learned"),
        ([], "control=learned and rra=jocc are learned"),
    ],
    ids=["learned-control", "learned-rra", "defaults"],
)
def test_eval_without_a_checkpoint_refuses_learned_policies_in_one_line(
    overrides, named, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", *SMOKE, *overrides]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: checkpoint=None"), lines
    assert named in lines[0]
    assert f"control={'|'.join(FIXED_CONTROLS)}" in lines[0]
    assert f"rra={'|'.join(FIXED_RRA)}" in lines[0]
    assert list(tmp_path.iterdir()) == []


def test_eval_sweeps_fixed_policies_and_seeds_in_one_process(tmp_path):
    sweep = tmp_path / "sweep"
    argv = [
        "-m",
        "eval",
        "control=cacc",
        "rra=greedy,silent",
        "seed=0,1",
        f"hydra.sweep.dir={sweep}",
    ]
    assert cli.main([*argv, *SMOKE]) == 0
    jobs = {}
    for number in range(4):
        summary = json.loads((sweep / str(number) / "summary.json").read_text())
        jobs[summary["rra"], summary["seed"]] = summary
        assert summary["evoi"] is None
    assert set(jobs) == {("greedy", 0), ("greedy", 1), ("silent", 0), ("silent", 1)}
    # the silent RRA delivers no CAM; the greedy one does, on the same scenarios
    assert jobs["silent", 0]["cam_delivery_rate"] == 0.0 < jobs["greedy", 0]["cam_delivery_rate"]


# --- item 5: per-scenario metrics and the user's policy spec ---------------------------------


def _scenarios(params: TwinParams, **kwargs):
    common = dict(episodes=3, intervals=6, seed=11)
    return evaluate_system(params, CACCController(params.platoon), **kwargs, **common)


def test_per_scenario_metrics_make_up_the_pooled_ones():
    params = TwinParams()
    rra = make_rra_baseline("random", params, 0)
    result = _scenarios(params, rra=rra, perfect=False)
    per = result.per_scenario
    assert set(per) == set(PER_SCENARIO_METRICS)
    assert all(value.shape == (3,) for value in per.values())
    assert float(per["collided"].mean()) == result.metrics["collision_rate"] == 0.0
    # no collision: every scenario counts every interval, so the pooled mean is their mean
    for key in PER_SCENARIO_METRICS:
        if key != "collided":
            assert float(per[key].mean()) == pytest.approx(result.metrics[key], rel=1e-9), key
    assert len(set(per["cam_delivery_rate"].tolist())) > 1  # the scenarios differ
    perfect = _scenarios(params, perfect=True)  # no radio: no radio metrics
    assert set(perfect.per_scenario) == set(PER_SCENARIO_METRICS) - set(RADIO_METRICS)


def test_evaluation_raw_holds_each_scenarios_metrics(tmp_path):
    _eval(tmp_path / "a", "control=cacc", "rra=greedy", "seed=4")
    _eval(tmp_path / "b", "control=cacc", "rra=silent", "seed=4")
    raw = {name: np.load(tmp_path / name / "evaluation_raw.npz") for name in "ab"}
    episodes = 2  # experiment=smoke
    for data in raw.values():
        for key in PER_SCENARIO_METRICS:
            assert data[f"scenario_{key}"].shape == (episodes,), key
        assert "optimal_returns" not in data.files  # no π* scored
        assert not any(name.startswith("optimal_") for name in data.files)
    # runs of one seed share their held-out scenarios: they pair scenario by scenario
    assert int(raw["a"]["scenario_seed"]) == int(raw["b"]["scenario_seed"])
    delivered = raw["a"]["scenario_cam_delivery_rate"] - raw["b"]["scenario_cam_delivery_rate"]
    assert (delivered > 0).all()
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert raw["a"]["scenario_cam_delivery_rate"].mean() == pytest.approx(
        summary["cam_delivery_rate"]
    )


def test_evaluation_raw_holds_pi_stars_scenarios_where_there_is_one(tmp_path):
    from vdtn_marl.experiment.outputs import write_raw_evaluation

    params = TwinParams()
    rra = make_rra_baseline("greedy", params, 0)
    acting = _scenarios(params, rra=rra, perfect=False, record_traces=True)
    optimal = _scenarios(params, perfect=True)
    write_raw_evaluation(tmp_path, params, optimal, acting, scenario_seed=11)
    data = np.load(tmp_path / "evaluation_raw.npz")
    assert int(data["scenario_seed"]) == 11
    np.testing.assert_array_equal(data["optimal_returns"], optimal.returns.numpy())
    for key in PER_SCENARIO_METRICS:
        np.testing.assert_array_equal(data[f"scenario_{key}"], acting.per_scenario[key].numpy())
        assert (f"optimal_scenario_{key}" in data.files) == (key not in RADIO_METRICS), key
    np.testing.assert_array_equal(
        data["optimal_scenario_control_cost"], optimal.per_scenario["control_cost"].numpy()
    )
    assert data["gap_error_abs_m"].shape == (6, 3)  # scenario 0's traces are kept beside them


POLICY = """
from vdtn_marl.policies import make_rra_baseline



def greedy(params, seed):
    return make_rra_baseline("greedy", params, seed)
"""


def test_summary_names_the_users_policy_spec_at_its_top(tmp_path, monkeypatch):
    (tmp_path / "mine.py").write_text(POLICY)
    monkeypatch.chdir(tmp_path)
    spec = "mine.py:greedy"
    summary = _eval(tmp_path / "ev", "control=cacc", "rra=policy", f"rra.policy={spec}")
    assert list(summary)[:3] == ["vdtn_marl_version", "task", "user_policies"]
    assert summary["user_policies"] == {"rra.policy": spec}
    # the same results as the greedy baseline it builds
    baseline = _eval(tmp_path / "baseline", "control=cacc", "rra=greedy")
    assert summary["control_cost"] == baseline["control_cost"]
    assert "user_policies" not in baseline


def test_run_summary_names_a_control_policy_spec():
    from vdtn_marl.experiment.config import RunConfig
    from vdtn_marl.experiment.evaluate import user_policy_specs

    cfg = RunConfig()
    assert user_policy_specs(cfg) == {}
    cfg.control.name, cfg.control.policy = "policy", "runs/bc/actor.pt"
    assert user_policy_specs(cfg) == {"control.policy": "runs/bc/actor.pt"}
