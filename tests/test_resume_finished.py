"""``resume=true`` on a run that had ended leaves its results as they were, and a resumed run's
tables come back as the numbers that were logged (vdtn_marl.io.metrics.MetricsLog.resume)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from vdtn_marl.io.files import read_json
from vdtn_marl.io.metrics import MetricsLog, parse_cell

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    from vdtn_marl.experiment.config import (
        AlgoConfig,
        ControlConfig,
        ExperimentConfig,
        RunConfig,
        ScenarioConfig,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation

    cfg = RunConfig(
        scenario=ScenarioConfig(episode_intervals=40),
        control=ControlConfig(warm_start="none"),
        algo=AlgoConfig(num_envs=2, rollout_steps=8, rra_num_envs=2, rra_rollout_steps=16,
                        minibatch_size=16, epochs=1),
        experiment=ExperimentConfig(control_iterations=1, rra_iterations=1, eval_episodes=2,
                                    eval_intervals=5, checkpoint_every=0),
        progress=False,
    )  # fmt: skip
    run = tmp_path_factory.mktemp("finished")
    JointOptimisation(cfg, run).run()
    return cfg, run


def _numbers_only(value) -> bool:
    """No metric of a summary is text that reads as a number (``'0.0005'``, ``'nan'``)."""
    if isinstance(value, dict):
        return all(_numbers_only(v) for v in value.values())
    if isinstance(value, list):
        return all(_numbers_only(v) for v in value)
    parsed = parse_cell(value) if isinstance(value, str) else None
    return isinstance(parsed, bool) or not isinstance(parsed, int | float)


def test_resume_of_a_finished_run_leaves_its_summary_as_it_was(finished_run):
    from vdtn_marl.experiment.jocc import JointOptimisation

    cfg, run = finished_run
    before = (run / "summary.json").read_bytes()
    summary = JointOptimisation(dataclasses.replace(cfg, resume=True), run).run()
    assert (run / "summary.json").read_bytes() == before
    assert summary == read_json(run / "summary.json")
    assert _numbers_only(summary) and isinstance(summary["control_cost"], float)


def test_a_resumed_table_holds_the_numbers_that_were_logged(tmp_path):
    rows = [
        {"stage": "rra", "iteration": 3, "reward_mean": -0.25, "kl_approx": float("nan"),
         "best": True, "lr": 1e-05},
        {"stage": "control_perfect", "iteration": 4, "reward_mean": 2.0, "kl_approx": None,
         "best": False, "lr": 0.0003},
    ]  # fmt: skip
    log = MetricsLog(tmp_path)
    for row in rows:
        log.log(row)
    text = log.path.read_text()
    again = MetricsLog.resume(tmp_path, expected_rows=2)
    first, second = again.rows
    assert math.isnan(first["kl_approx"])
    assert {k: v for k, v in first.items() if k != "kl_approx"} == {
        k: v for k, v in rows[0].items() if k != "kl_approx"
    }
    assert second == rows[1]
    again.flush()  # read and rewritten: the same table
    assert again.path.read_text() == text
