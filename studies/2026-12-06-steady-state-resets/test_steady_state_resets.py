"""steady_state_resets.py on a tiny JOCC run's checkpoint: all arms collect from
the same weights, the run, reset_first and separate arms from the checkpoint's persisting
scenarios, the fresh arm from a reset; the counts are those of the collections."""

import importlib.util
import json
from pathlib import Path

import pytest

from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RunConfig,
    ScenarioConfig,
)
from vdtn_marl.experiment.jocc import JointOptimisation

SCRIPT = Path(__file__).resolve().parent / "steady_state_resets.py"


def _script():
    spec = importlib.util.spec_from_file_location("steady_state_resets", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    run_dir = tmp_path_factory.mktemp("jocc")
    cfg = RunConfig(
        scenario=ScenarioConfig(episode_intervals=15),
        algo=AlgoConfig(
            num_envs=4,
            rollout_steps=10,
            rra_num_envs=4,
            rra_rollout_steps=50,
            minibatch_size=64,
            epochs=1,
        ),  # fmt: skip
        experiment=ExperimentConfig(
            jocc_iterations=2,
            control_iterations=2,
            rra_iterations=1,
            eval_episodes=2,
            eval_intervals=10,
            checkpoint_every=0,
        ),  # fmt: skip
        control=ControlConfig(warm_start="none"),
        progress=False,
    )
    JointOptimisation(cfg, run_dir).run()
    return run_dir / "checkpoints" / "last.pt"


def test_the_arms_collect_from_the_checkpoints_weights(checkpoint, tmp_path):
    out = tmp_path / "steady.json"
    script = _script()
    assert (
        script.main([str(checkpoint), "--iterations", "2", "--repeats", "2", "--out", str(out)])
        == 0
    )
    data = json.loads(out.read_text())
    assert data["rra_policy"] == "ActorPolicy"  # the RRA agents trained: π̃ runs under them
    assert data["pi_tilde_iteration"] == 4 and data["batch"] == [4]
    assert set(data["runs"]) == set(script.ARMS)
    for arm in script.ARMS:
        rows = data["runs"][arm]
        assert len(rows) == 4 and all(r["intervals"] == 10 for r in rows)
        if arm == "separate":  # one radio run more per interval at which some (not all) end
            extra = [r["reset_intervals"] - r["whole_batch_resets"] for r in rows]
        else:  # the ended scenarios start with the others' next interval: one run
            extra = [0] * len(rows)
        assert [r["radio_runs"] - r["intervals"] for r in rows] == extra
        assert all(r["reset_intervals"] <= r["reset_scenarios"] for r in rows)
        # each repeat starts from the same state: its collections are the same collections
        counts = [(r["radio_runs"], r["reset_scenarios"]) for r in rows]
        assert counts[:2] == counts[2:]
    # episodes of 15 intervals, 10 per collection: some scenarios restart in every arm
    for arm in script.ARMS:
        assert sum(r["reset_scenarios"] for r in data["runs"][arm]) > 0
    for ratio in ("fresh", "separate", "reset_first"):
        assert data[f"run_over_{ratio}_collect_s"] > 0


def test_refuses_a_missing_checkpoint_and_bad_counts(tmp_path, checkpoint, capsys):
    script = _script()
    with pytest.raises(SystemExit):
        script.parse_args([str(tmp_path / "none.pt")])
    assert "checkpoint" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        script.parse_args([str(checkpoint), "--repeats", "0"])
    assert "--repeats" in capsys.readouterr().err


def test_the_reset_first_arm_draws_the_new_episodes_before_the_interval():
    """Inside ``Counts(reset_first=True)`` a twin's restart is a reset drawn first and an
    interval start after it (the order before ``DigitalTwin.restart``); outside, the twin's own."""
    import copy

    import torch

    from vdtn_marl.sim.params import TwinParams
    from vdtn_marl.sim.twin import DigitalTwin

    own = DigitalTwin.restart
    twin = DigitalTwin(TwinParams.from_overrides(episode_intervals=5), batch_size=6, seed=2)
    mask = torch.tensor([True, False, False, True, False, False])
    reset_first, restarted = copy.deepcopy(twin), copy.deepcopy(twin)
    with _script().Counts(reset_first=True):
        reset_first.restart(mask)
    assert DigitalTwin.restart is own
    twin.reset(mask=mask, begin=False)
    twin.begin_interval()
    restarted.restart(mask)
    assert torch.equal(reset_first.tables.own_gain, twin.tables.own_gain)
    assert not torch.equal(restarted.tables.own_gain, twin.tables.own_gain)
