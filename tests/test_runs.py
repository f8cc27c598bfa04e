"""Run outputs: the metrics log (CSV tables, the source of plots) and the run's other loggers
(TorchRL's TensorBoard, W&B and MLflow loggers, ``experiment.loggers``).

The routing tests put TorchRL's own ``CSVLogger`` (no extra needed) behind every logger name;
the tests of the real services run where their extras are installed."""

from __future__ import annotations

import csv
import math
import time
from pathlib import Path

import pytest

from vdtn_marl import cli
from vdtn_marl.errors import ConfigError
from vdtn_marl.io import loggers as loggers_module
from vdtn_marl.io.loggers import DEFAULT_LOGGERS, LOGGERS, RunLoggers, check_loggers
from vdtn_marl.io.metrics import MetricsLog

SERVICES = [name for name, spec in LOGGERS.items() if spec.module is not None]


def _csv_rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture
def torchrl_csv_loggers(monkeypatch, tmp_path):
    """Every service logger is TorchRL's CSVLogger writing to ``tmp_path/torchrl/<name>``, and
    counts as installed. Returns the folder."""
    from torchrl.record.loggers import get_logger

    folder = tmp_path / "torchrl"

    def build(self, name):
        return get_logger("csv", str(folder), name)

    monkeypatch.setattr(RunLoggers, "_build", build)
    monkeypatch.setattr(loggers_module, "installed", lambda module: True)
    return folder


def _scalars(folder: Path, logger: str, key: str) -> list[tuple[int, float]]:
    """(step, value) rows TorchRL's CSV logger wrote for scalar ``key``."""
    path = folder / logger / "scalars" / f"{key}.csv"
    return [(int(s), float(v)) for s, v in (line.split(",") for line in path.read_text().split())]


# --- the CSV table -------------------------------------------------------------------------


def test_rows_with_different_keys_share_one_header_in_first_seen_order(tmp_path):
    log = MetricsLog(tmp_path)
    log.log({"iteration": 0, "stage": "pi_star"})
    log.log({"iteration": 1, "cost": 0.5})
    assert _csv_rows(tmp_path / "metrics.csv") == [
        {"iteration": "0", "stage": "pi_star", "cost": ""},
        {"iteration": "1", "stage": "", "cost": "0.5"},
    ]


def test_csv_is_the_default_and_opens_no_other_logger(tmp_path):
    assert DEFAULT_LOGGERS == ("csv",)
    loggers = RunLoggers(DEFAULT_LOGGERS, tmp_path, "run")
    log = MetricsLog(tmp_path, loggers=loggers)
    log.log({"cost": 0.5}, step=1, prefix="eval")
    loggers.close()
    assert loggers.names == () and loggers.opened == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["metrics.csv"]


# --- experiment.loggers ---------------------------------------------------------------------


@pytest.mark.parametrize("name", SERVICES)
def test_a_logger_that_is_not_installed_names_its_extra(name, monkeypatch):
    monkeypatch.setattr(loggers_module, "installed", lambda module: False)
    extra = LOGGERS[name].extra
    with pytest.raises(ConfigError, match=rf"experiment\.loggers.*vdtn-marl\[{extra}\]"):
        check_loggers(["csv", name])
    assert check_loggers(["csv"]) == ("csv",)  # csv needs nothing


@pytest.mark.parametrize(
    "value, fragment",
    [(["csv", "neptune"], "'neptune' is not a logger"), (["csv", "csv"], "names csv twice"),
     ("csv", "must be a list")],
)  # fmt: skip
def test_bad_logger_lists_name_the_key(value, fragment):
    with pytest.raises(ConfigError, match="experiment.loggers") as err:
        check_loggers(value)
    assert fragment in str(err.value)


def test_a_missing_logger_is_one_line_before_anything_is_written(tmp_path, monkeypatch, capsys):
    missing = SERVICES[-1]
    monkeypatch.setattr(
        loggers_module, "installed", lambda module: module != LOGGERS[missing].module
    )
    monkeypatch.chdir(tmp_path)
    assert cli.main(["jocc", "experiment=smoke", f"experiment.loggers=[csv,{missing}]"]) == 2
    (line,) = [x for x in capsys.readouterr().err.splitlines() if x.strip()]
    assert line.startswith("error: ") and "experiment.loggers" in line
    assert f"pip install 'vdtn-marl[{LOGGERS[missing].extra}]'" in line
    assert list(tmp_path.iterdir()) == []


# --- rows to scalars ------------------------------------------------------------------------


def test_rows_with_a_step_reach_every_logger_as_prefixed_scalars(tmp_path, torchrl_csv_loggers):
    loggers = RunLoggers(["csv", *SERVICES], tmp_path, "run")
    train = MetricsLog(tmp_path, loggers=loggers)
    evaluation = MetricsLog(tmp_path, filename="evaluation.csv", loggers=loggers)
    train.log({"iteration": 3, "stage": "rra", "done": True, "reward_mean": -0.5},
              step=3, prefix="rra", step_key="iteration")  # fmt: skip
    train.log({"iteration": 4, "reward_mean": -0.25, "kl": float("nan")},
              step=4, prefix="rra", step_key="iteration")  # fmt: skip
    evaluation.log({"jocc_iteration": 1, "control_cost": 2.5}, step=1, prefix="eval",
                   step_key="jocc_iteration")  # fmt: skip
    loggers.close()
    assert len(_csv_rows(tmp_path / "metrics.csv")) == 2  # the table keeps every row
    for name in SERVICES:
        assert _scalars(torchrl_csv_loggers, name, "rra/reward_mean") == [(3, -0.5), (4, -0.25)]
        assert _scalars(torchrl_csv_loggers, name, "eval/control_cost") == [(1, 2.5)]
        scalars = torchrl_csv_loggers / name / "scalars"
        written = {p.relative_to(scalars).with_suffix("").as_posix() for p in scalars.rglob("*.*")}
        # the step key, texts, bools and non-finite numbers are not scalars
        assert written == {"rra/reward_mean", "eval/control_cost"}, written


def test_loggers_open_on_the_first_scalar(tmp_path, torchrl_csv_loggers):
    loggers = RunLoggers(SERVICES, tmp_path, "run")
    log = MetricsLog(tmp_path, loggers=loggers)
    log.log({"iteration": 0, "stage": "pi_star"})  # no step: the table only
    log.log({"stage": "pi_star"}, step=0, prefix="pi_star")  # no number
    assert loggers.opened == [] and not torchrl_csv_loggers.exists()
    log.log({"reward_mean": 1.0}, step=1, prefix="pi_star")
    assert len(loggers.opened) == len(SERVICES)
    loggers.close()
    assert loggers.opened == []


@pytest.mark.slow
def test_a_jocc_run_sends_each_stage_and_evaluation_to_the_loggers(tmp_path, torchrl_csv_loggers):
    from vdtn_marl.experiment.config import (
        AlgoConfig,
        ControlConfig,
        ExperimentConfig,
        RunConfig,
        validate,
    )
    from vdtn_marl.experiment.jocc import JointOptimisation

    experiment = ExperimentConfig(
        jocc_iterations=1, control_iterations=2, rra_iterations=1, eval_episodes=2,
        eval_intervals=5, checkpoint_every=0, loggers=["csv", SERVICES[0]],
    )  # fmt: skip
    algo = AlgoConfig(num_envs=2, rra_num_envs=2, rollout_steps=8, rra_rollout_steps=16,
                      epochs=1, minibatch_size=16)  # fmt: skip
    cfg = validate(RunConfig(experiment=experiment, algo=algo, progress=False,
                             control=ControlConfig(warm_start="none")))  # fmt: skip
    summary = JointOptimisation(cfg, tmp_path / "run").run()
    rows = _csv_rows(tmp_path / "run" / "metrics.csv")
    for stage in {r["stage"] for r in rows}:
        mine = [r for r in rows if r["stage"] == stage]
        logged = _scalars(torchrl_csv_loggers, SERVICES[0], f"{stage}/reward_mean")
        assert logged == [(int(r["iteration"]), float(r["reward_mean"])) for r in mine], stage
    (row,) = _csv_rows(tmp_path / "run" / "evaluation.csv")
    cost = _scalars(torchrl_csv_loggers, SERVICES[0], "eval/control_cost")
    assert cost == [(int(row["jocc_iteration"]), pytest.approx(summary["control_cost"]))]


# --- the services themselves (where their extras are installed) -----------------------------


def _log_two_rows(run_dir: Path, names) -> None:
    loggers = RunLoggers(names, run_dir, "test run", hparams={"seed": 3, "rra.kappa1": 0.5})
    log = MetricsLog(run_dir, loggers=loggers)
    log.log({"iteration": 1, "reward_mean": -0.5}, step=1, prefix="rra", step_key="iteration")
    log.log({"iteration": 2, "reward_mean": -0.25}, step=2, prefix="rra", step_key="iteration")
    loggers.close()


def test_tensorboard_events_hold_the_rows(tmp_path):
    pytest.importorskip("tensorboard")
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    _log_two_rows(tmp_path, ["csv", "tensorboard"])
    (events,) = (tmp_path / "tensorboard").rglob("events.out.tfevents.*")
    acc = EventAccumulator(str(events.parent))
    acc.Reload()
    got = [(e.step, e.value) for e in acc.Scalars("rra/reward_mean")]
    assert got == [(1, -0.5), (2, -0.25)]


def test_wandb_offline_writes_the_run_without_a_network(tmp_path, monkeypatch):
    pytest.importorskip("wandb")
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("HTTPS_PROXY", "http://127.0.0.1:9")  # any network use would fail
    _log_two_rows(tmp_path, ["csv", "wandb"])
    (run,) = (tmp_path / "wandb").glob("offline-run-*/run-*.wandb")
    # the run's record (protobuf, read by `wandb sync`) holds the scalars, name and config;
    # wandb's writer process may still be flushing it when `finish()` returns (wandb 0.31:
    # about 1 first run in 15), so the test waits for it, up to 30 s
    wanted = (b"rra/reward_mean", b"-0.25", b"-0.5", b"test run", b"rra.kappa1")
    deadline = time.monotonic() + 30.0
    record = run.read_bytes()
    while not all(w in record for w in wanted) and time.monotonic() < deadline:
        time.sleep(0.2)
        record = run.read_bytes()
    for expected in wanted:
        assert expected in record, expected


def test_mlflow_keeps_the_metric_history_in_the_runs_sqlite_store(tmp_path, monkeypatch):
    pytest.importorskip("mlflow")
    from mlflow.tracking import MlflowClient

    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    _log_two_rows(tmp_path, ["csv", "mlflow"])
    client = MlflowClient(tracking_uri=f"sqlite:///{tmp_path / loggers_module.MLFLOW_DB}")
    experiment = client.get_experiment_by_name(loggers_module.PROJECT)
    (run,) = client.search_runs([experiment.experiment_id])
    history = client.get_metric_history(run.info.run_id, "rra/reward_mean")
    assert [(m.step, m.value) for m in history] == [(1, -0.5), (2, -0.25)]
    assert run.data.params["rra.kappa1"] == "0.5" and run.info.run_name == "test run"
    assert not math.isnan(run.data.metrics["rra/reward_mean"])
