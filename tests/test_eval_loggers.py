"""``vdtn-marl eval`` of a run trained with online loggers (W&B, MLflow) needs none of them: eval
does not take the run's loggers, and a logger that cannot open is one warning line, never a
lost result (vdtn_marl.io.loggers.RunLoggers)."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import pytest
import yaml

from vdtn_marl import cli
from vdtn_marl.cli import prepass as cli_prepass
from vdtn_marl.io.files import LOCK_FILE
from vdtn_marl.io.loggers import RunLoggers
from vdtn_marl.io.metrics import MetricsLog

pytestmark = [
    pytest.mark.slow,  # runs of the CLI or of training (the fast loop skips them)
    pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema"),
]


def _run_with_wandb(run_dir: Path) -> None:
    """A run folder as a run with ``experiment.loggers=[csv,wandb]`` leaves it (its
    checkpoint's config and config.yaml), every policy trained one PPO iteration."""
    from hydra import initialize_config_module

    from vdtn_marl.algos.checkpoint import save_checkpoint
    from vdtn_marl.experiment import checkpoint
    from vdtn_marl.experiment.compose import CONFIG_PACKAGE, register_configs
    from vdtn_marl.experiment.jocc import JointOptimisation

    register_configs()
    with initialize_config_module(config_module=CONFIG_PACKAGE, version_base="1.3"):
        composed = cli_prepass.compose_config("config", ["experiment=smoke", "progress=false"])
        data = cli_prepass.job_config(composed)
    loop = JointOptimisation(cli_prepass.to_run_config(dict(data)), run_dir)
    for trainer in loop.trainers().values():
        trainer.iteration = 1
    payload = checkpoint.payload(loop)
    payload["config"]["experiment"]["loggers"] = ["csv", "wandb"]
    save_checkpoint(loop.checkpoint_path, payload)
    data["experiment"]["loggers"] = ["csv", "wandb"]
    (run_dir / "config.yaml").write_text(yaml.safe_dump(data))


def test_eval_of_a_run_trained_with_wandb_needs_no_wandb(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("WANDB_API_KEY", raising=False)
    _run_with_wandb(tmp_path / "run")
    assert cli.main(["eval", "checkpoint=run", "hydra.run.dir=ev", "progress=false"]) == 0
    summary = json.loads((tmp_path / "ev" / "summary.json").read_text())
    assert summary["config"]["experiment"]["loggers"] == ["csv"]
    assert not (tmp_path / "ev" / "wandb").exists() and not (tmp_path / "ev" / LOCK_FILE).exists()


def test_a_logger_that_cannot_open_is_one_warning_and_the_table_is_kept(
    tmp_path, monkeypatch, caplog
):
    monkeypatch.setattr("vdtn_marl.io.loggers.installed", lambda module: True)

    def no_login(self, name):
        raise RuntimeError("api_key not configured (no-tty). call wandb.login(key=[your_api_key])")

    monkeypatch.setattr(RunLoggers, "_build", no_login)
    loggers = RunLoggers(["csv", "wandb"], tmp_path, "test run")
    log = MetricsLog(tmp_path, loggers=loggers)
    with caplog.at_level(logging.WARNING, logger="vdtn_marl.io.loggers"):
        log.log({"iteration": 1, "reward_mean": -0.5}, step=1, prefix="rra", step_key="iteration")
        log.log({"iteration": 2, "reward_mean": -0.25}, step=2, prefix="rra", step_key="iteration")
    loggers.close()
    (record,) = caplog.records
    assert "logger wandb did not open" in record.getMessage()
    assert "api_key not configured" in record.getMessage() and "\n" not in record.getMessage()
    assert len(MetricsLog.resume(tmp_path).rows) == 2
