"""π* trained once per scenario and seed and shared by the cells of a benchmark
(``benchmark.pi_star``, ``control.pi_star``), and π*'s stage ended at its plateau
(``control.pi_star_patience``)."""

from __future__ import annotations

import csv
import hashlib
import itertools
from pathlib import Path

import pytest

from vdtn_marl import leaderboard
from vdtn_marl.algos.ppo import PPOTrainer
from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment import api, config
from vdtn_marl.experiment.compose import compose_config, hydra_compose, job_config, to_run_config
from vdtn_marl.io.files import SUMMARY_FILE, read_json

pytestmark = pytest.mark.slow  # each test trains or runs a small grid


def _compose(*overrides: str, command: str = "jocc"):
    with hydra_compose():
        data = job_config(
            compose_config("config", ["experiment=smoke", "progress=false", *overrides])
        )
        return to_run_config(data, command)


def _train_pi_star(run_dir: Path, *overrides: str) -> Path:
    cfg = _compose("task=control", *overrides, command="train")
    api.train(cfg, run_dir)
    return run_dir / "checkpoints" / "last.pt"


def _stages(run_dir: Path) -> set[str]:
    """The stages that trained in a run (a run that trains nothing writes no metrics.csv)."""
    if not (run_dir / "metrics.csv").is_file():
        return set()
    with open(run_dir / "metrics.csv", newline="", encoding="utf-8") as f:
        return {row["stage"] for row in csv.DictReader(f)}


@pytest.fixture(scope="module")
def pi_star_run(tmp_path_factory) -> Path:
    return _train_pi_star(
        tmp_path_factory.mktemp("pi_star") / "run", "experiment.control_iterations=2"
    )


def test_a_run_with_control_pi_star_loads_it_and_trains_no_pi_star(pi_star_run, tmp_path):
    summary = api.jocc(
        _compose(f"control.pi_star={pi_star_run.parent.parent}", "rra=greedy"), tmp_path
    )
    source = summary["pi_star_source"]
    assert source["checkpoint"] == str(pi_star_run)
    assert source["sha256"] == hashlib.sha256(pi_star_run.read_bytes()).hexdigest()
    assert source["ppo_iterations"] == 2 == summary["trainer_iterations"]["pi_star"]
    assert "control_perfect" not in _stages(tmp_path) and "control_impaired" in _stages(tmp_path)
    shared = read_json(pi_star_run.parent.parent / SUMMARY_FILE)
    # the same π* on the same held-out scenarios: the same control cost, to the bit (in
    # task=control π* is what is evaluated)
    assert summary["optimal_control_cost"] == shared["control_cost"]
    # its start's score came with it: the reference check still compares π* with its start
    assert summary["pi_star_minus_start"] is not None


def test_control_pi_star_refuses_what_does_not_fit(pi_star_run, tmp_path):
    with pytest.raises(ConfigError, match="control.pi_star"):
        _compose(f"control.pi_star={tmp_path / 'nothing.pt'}")
    with pytest.raises(ConfigError, match="scenario.num_vehicles"):
        _compose(f"control.pi_star={pi_star_run}", "scenario=platoon8")
    with pytest.raises(ConfigError, match="algo.num_cells"):
        _compose(f"control.pi_star={pi_star_run}", "algo.num_cells=32")


def test_pi_star_patience_ends_the_stage_at_its_plateau(tmp_path, monkeypatch):
    """Validation returns that fall after the start's: with patience 2 the stage ends after the
    second validation that misses the best, and keeps the best (the start)."""
    scores = itertools.count()
    monkeypatch.setattr(PPOTrainer, "validation_return", lambda self: -float(next(scores)))
    summary = api.train(
        _compose(
            "task=control", "experiment.control_iterations=20", "control.pi_star_patience=2",
            "control.pi_star_validate_every=1", command="train",
        ),
        tmp_path,
    )  # fmt: skip
    assert summary["trainer_iterations"]["pi_star"] == 2
    assert summary["plateaus"]["control_perfect"] == {
        "stopped_at": 2,
        "budget_end": 20,
        "patience": 2,
    }
    assert summary["selected_iterations"]["control_perfect"] == -1  # the start
    with pytest.raises(ConfigError, match="control.pi_star_patience"):
        _compose("control.pi_star_patience=2", "control.pi_star_validate_every=0")


def _bench(out_dir: Path, **benchmark) -> config.BenchConfig:
    defaults = dict(
        name="shared", version="0.1", experiment="smoke", scenarios=["platoon4"], seeds=[0],
        methods={"greedy": ["rra=greedy"], "random": ["rra=random", "control=cacc"]},
        pi_star=["experiment.control_iterations=2"],
    )  # fmt: skip
    b = config.BenchmarkConfig(**{**defaults, **benchmark})
    return config.BenchConfig(benchmark=b, out_dir=str(out_dir), progress=False, report=False)


def test_benchmark_cells_share_one_pi_star_per_scenario_and_seed(tmp_path):
    first = _bench(tmp_path)
    first.cells = ["*/pi_star/*"]  # the shared π* alone, before any cell
    alone = leaderboard.run_benchmark(first, command="test")
    assert not alone.ran and len(alone.pending) == 2
    assert (tmp_path / "platoon4" / "pi_star" / "seed0" / SUMMARY_FILE).is_file()
    result = leaderboard.run_benchmark(_bench(tmp_path), command="test")
    assert len(result.ran) == 2 and not result.failed
    shared = tmp_path / "platoon4" / "pi_star" / "seed0"
    checkpoint = shared / "checkpoints" / "last.pt"
    digest = hashlib.sha256(checkpoint.read_bytes()).hexdigest()
    costs = set()
    for cell in result.ran:
        summary = read_json(cell.directory(tmp_path) / SUMMARY_FILE)
        assert summary["pi_star_source"]["sha256"] == digest
        assert "control_perfect" not in _stages(cell.directory(tmp_path))
        costs.add(summary["optimal_control_cost"])
    assert len(costs) == 1  # one π*, one set of held-out scenarios
    # a rerun finds every cell and π* done, and trains nothing; its report lists the π*
    before = checkpoint.stat().st_mtime_ns
    cfg = _bench(tmp_path)
    cfg.report = True
    again = leaderboard.run_benchmark(cfg, command="test")
    assert not again.ran and checkpoint.stat().st_mtime_ns == before
    report = read_json(again.report["json"])
    [row] = report["shared_pi_star"]
    assert (row["scenario"], row["seed"], row["ppo_iterations"]) == ("platoon4", 0, 2)
    assert row["control_cost"] == read_json(shared / SUMMARY_FILE)["control_cost"]
    assert "## The shared π*" in again.report["markdown"].read_text(encoding="utf-8")


def test_benchmark_pi_star_refuses_methods_that_set_pi_star(tmp_path):
    with pytest.raises(ConfigError, match="control.pi_star"):
        config.validate_benchmark(_bench(tmp_path, methods={"m": ["control.pi_star_patience=3"]}))
    with pytest.raises(ConfigError, match="benchmark.methods.pi_star"):
        config.validate_benchmark(_bench(tmp_path, methods={"pi_star": ["rra=greedy"]}))
