"""The CLI around runs: `eval` reuses the checkpoint's run config and names untrained policies,
a run folder is never overwritten, Ctrl-C says how to continue, checkpoint and launcher errors
are one line, the run log is written, help tells what each command writes.

Checkpoints are real (``JointOptimisation.save`` of a loop built from a Hydra-composed config,
no training: trainer iteration counts are set by hand where a test needs a "trained" policy).
Entry points are faked where the test is about the CLI only, so every test takes seconds.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import shlex
from pathlib import Path

import pytest
import yaml

from vdtn_marl import cli
from vdtn_marl.cli import help as cli_help
from vdtn_marl.cli import prepass as cli_prepass

pytestmark = [
    pytest.mark.slow,  # runs of the CLI or of training (the fast loop skips them)
    pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema"),
]


def _compose(overrides: list[str]) -> dict:
    from hydra import initialize_config_module

    from vdtn_marl.experiment.config import register_configs

    register_configs()
    with initialize_config_module(config_module=cli_help.CONFIG_PACKAGE, version_base="1.3"):
        return cli_prepass.job_config(cli_prepass.compose_config("config", overrides))


def _make_run(run_dir: Path, overrides: list[str], task: str = "jocc", trained=()) -> dict:
    """A run folder as `vdtn-marl` leaves it: config.yaml and checkpoints/last.pt of a loop
    built from ``overrides`` whose trainers ``trained`` count one PPO iteration."""
    from vdtn_marl.experiment.jocc import JointOptimisation

    data = _compose(overrides)
    run_cfg = cli_prepass.to_run_config(dict(data), task)
    loop = JointOptimisation(run_cfg, run_dir, task=task)
    for name, trainer in loop.trainers().items():
        trainer.iteration = int(name in trained)
    loop.save()
    (run_dir / "config.yaml").write_text(yaml.safe_dump(data))
    return data


def _one_line(err: str, *fragments: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    for fragment in fragments:
        assert fragment in lines[0], err
    return lines[0]


def _fake_entry(monkeypatch, name: str, calls: list) -> None:
    from vdtn_marl.experiment import api

    def fake(cfg, run_dir):
        calls.append(cfg)
        summary = {"control_cost": 1.0}
        (Path(run_dir) / "summary.json").write_text(json.dumps(summary))
        return summary

    monkeypatch.setattr(api, name, fake)


def _listing(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in folder.rglob("*")}


TRAINED = ("pi_star", "pi_tilde", "rra")
PLATOON8 = ["experiment=smoke", "scenario=platoon8", "algo=ippo", "seed=3"]


# --- 1. eval composes its config from the checkpoint's run ----------------------------------


def test_eval_takes_the_run_config_and_the_command_line_on_top(tmp_path, monkeypatch):
    run = tmp_path / "run"
    _make_run(run, PLATOON8, trained=TRAINED)
    calls = []
    _fake_entry(monkeypatch, "evaluate", calls)
    monkeypatch.chdir(tmp_path)
    argv = ["eval", f"checkpoint={run}", "experiment.eval_episodes=3", "hydra.run.dir=ev"]
    assert cli.main(argv) == 0
    (cfg,) = calls
    assert (cfg.scenario.name, cfg.scenario.num_vehicles, cfg.algo.name) == ("platoon8", 8, "ippo")
    assert cfg.experiment.name == "smoke" and cfg.experiment.eval_intervals == 5
    assert cfg.experiment.eval_episodes == 3 and cfg.seed == 3
    assert cfg.checkpoint == str(run / "checkpoints" / "last.pt")
    saved = yaml.safe_load((tmp_path / "ev" / "config.yaml").read_text())
    assert saved["scenario"]["num_vehicles"] == 8 and saved["experiment"]["eval_episodes"] == 3


@pytest.mark.parametrize(
    "overrides",
    [
        [*PLATOON8, "rra.kappa1=0.7", "+scenario.model.carrier_ghz=5.9", "algo.lr=1e-05"],
        ["experiment=smoke", "control=oracle", "rra=greedy", "scenario=platoon4_1mhz"],
    ],
    ids=["platoon8-ippo-tweaked", "oracle-greedy-cell"],
)
def test_eval_overrides_recompose_the_run_config_exactly(overrides, tmp_path):
    run = tmp_path / "run"
    data = _make_run(run, overrides, trained=TRAINED)
    composed = _compose(cli_prepass.eval_overrides([f"checkpoint={run}"]))
    for key in cli_help.EVAL_FRESH_KEYS:
        data.pop(key), composed.pop(key)
    assert composed == data


def test_eval_group_option_on_the_command_line_replaces_the_runs(tmp_path, monkeypatch):
    run = tmp_path / "run"
    _make_run(run, [*PLATOON8, "rra.kappa1=0.7"], trained=TRAINED)
    calls = []
    _fake_entry(monkeypatch, "evaluate", calls)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", f"checkpoint={run}", "rra=round_robin", "experiment=default"]) == 0
    (cfg,) = calls
    assert cfg.rra.name == "round_robin" and cfg.rra.kappa1 == 0.5  # the option's, not 0.7
    assert cfg.experiment.name == "default" and cfg.algo.num_envs != 2  # default budgets
    assert cfg.scenario.num_vehicles == 8 and cfg.algo.name == "ippo"  # still the run's


@pytest.mark.parametrize(
    "override,key",
    [("scenario.num_vehicles=4", "scenario.num_vehicles=4"), ("algo=mappo", "algo.name='mappo'")],
)
def test_eval_override_that_contradicts_the_checkpoint_is_one_line(
    override, key, tmp_path, monkeypatch, capsys
):
    run = tmp_path / "run"
    _make_run(run, PLATOON8, trained=TRAINED)
    monkeypatch.chdir(tmp_path)
    before = _listing(tmp_path)
    assert cli.main(["eval", f"checkpoint={run}", override]) == 2
    _one_line(capsys.readouterr().err, key, "does not fit", "allowed")
    assert _listing(tmp_path) == before


def test_eval_sweep_over_checkpoints_is_refused(tmp_path, monkeypatch, capsys):
    run = tmp_path / "run"
    _make_run(run, ["experiment=smoke"], trained=TRAINED)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["-m", "eval", f"checkpoint={run},{run}"]) == 2
    _one_line(capsys.readouterr().err, "is a sweep", "allowed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


# --- 2. untrained policies ------------------------------------------------------------------


def test_untrained_policies_of_a_checkpoint():
    from vdtn_marl.algos.checkpoint import untrained_policies

    def payload(task, **iterations):
        return {"task": task, "trainers": {n: {"iteration": i} for n, i in iterations.items()}}

    learned = {"control": {"name": "learned"}, "rra": {"name": "jocc"}}
    baselines = {"control": {"name": "cacc"}, "rra": {"name": "greedy"}}
    assert untrained_policies(payload("control", pi_star=3, pi_tilde=0, rra=0), learned) == (
        [],
        False,
    )
    warnings, none = untrained_policies(payload("control_impaired", pi_star=3, pi_tilde=3), learned)
    assert none is False and len(warnings) == 1 and "RRA policy (rra=jocc)" in warnings[0]
    warnings, none = untrained_policies(payload("jocc", pi_star=3, pi_tilde=0, rra=0), learned)
    assert none is True and "π̃" in warnings[0] and "rra=jocc" in warnings[1]
    assert untrained_policies(payload("jocc", pi_star=3), baselines) == ([], False)


@pytest.fixture
def eval_run(tmp_path, monkeypatch):
    """Run `vdtn-marl eval checkpoint=RUN` (real api.evaluate, smoke budgets) in tmp_path."""
    monkeypatch.chdir(tmp_path)

    def run(task: str, trained: tuple[str, ...], *extra: str) -> dict:
        _make_run(tmp_path / "run", ["experiment=smoke", "progress=false"], task, trained)
        argv = ["eval", "checkpoint=run", "hydra.run.dir=ev", "progress=false", *extra]
        assert cli.main(argv) == 0
        return json.loads((tmp_path / "ev" / "summary.json").read_text())

    return run


def test_eval_of_a_control_checkpoint_scores_pi_star(eval_run):
    summary = eval_run("control", ("pi_star",))
    assert summary["checkpoint_task"] == "control" and summary["warnings"] == []
    assert "cacc_control_cost" in summary  # π* against CACC, as `train task=control` evaluates
    assert "cam_delivery_rate" not in summary  # not the (untrained) π̃ under an RRA policy
    assert "kappa1" not in summary and "kappa2" not in summary  # no RRA reward was used


def test_eval_warns_about_an_untrained_rra_policy(eval_run, tmp_path, capsys):
    summary = eval_run("control_impaired", ("pi_star", "pi_tilde"))
    (warning,) = summary["warnings"]
    assert "RRA policy (rra=jocc) was never trained" in warning
    assert warning in capsys.readouterr().out  # logged on the console (WARNING) ...
    assert warning in (tmp_path / "ev" / "eval.log").read_text()  # ... and in the run log


def test_eval_of_a_checkpoint_without_trained_acting_policies_is_refused(
    tmp_path, monkeypatch, capsys
):
    _make_run(tmp_path / "run", ["experiment=smoke"], "jocc", ("pi_star",))
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", "checkpoint=run"]) == 2
    _one_line(capsys.readouterr().err, "checkpoint=run/checkpoints/last.pt", "no trained policy")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    # baselines by name are a meaningful evaluation of the same checkpoint
    _fake_entry(monkeypatch, "evaluate", calls := [])
    baselines = ["control=cacc", "control.augmentation=true", "rra=greedy"]
    assert cli.main(["eval", "checkpoint=run", *baselines]) == 0 and calls


def test_eval_video_draws_every_interval_of_the_first_scenario_and_moves_no_result(
    tmp_path, monkeypatch
):
    iio = pytest.importorskip("imageio.v3")
    _make_run(tmp_path / "run", ["experiment=smoke", "progress=false"], "jocc", TRAINED)
    monkeypatch.chdir(tmp_path)
    common = ["eval", "checkpoint=run", "progress=false"]
    assert cli.main([*common, "hydra.run.dir=plain"]) == 0
    assert cli.main([*common, "hydra.run.dir=filmed", "video=true"]) == 0
    plain, filmed = (
        json.loads((tmp_path / d / "summary.json").read_text()) for d in ("plain", "filmed")
    )
    path = tmp_path / "filmed" / "episode.gif"
    assert filmed["videos"] == {"episode": str(path.resolve())} and "videos" not in plain
    frames = iio.imread(path, index=None)
    assert frames.shape[0] == filmed["config"]["experiment"]["eval_intervals"] == 5
    assert frames.shape[-1] in (3, 4) and frames.std() > 0
    assert not list((tmp_path / "plain").glob("episode.*"))
    for key in ("control_cost", "cam_delivery_rate", "aoi_ms_mean", "evoi"):
        assert filmed[key] == plain[key], key


def test_best_and_worst_scenarios_are_drawn_from_a_second_identical_run(tmp_path, monkeypatch):
    """video_scenarios=best_worst: the scenarios of the highest and lowest control return of
    the acting system, each drawn as scenario 0 of a one-scenario view of the batch."""
    import torch

    from vdtn_marl.experiment import evaluate as evaluate_module
    from vdtn_marl.experiment.jocc import JointOptimisation

    iio = pytest.importorskip("imageio.v3")
    data = _make_run(tmp_path / "run", ["experiment=smoke", "experiment.eval_episodes=4"],
                     "jocc", TRAINED)  # fmt: skip
    from vdtn_marl.envs import render

    drawn, indices = [], []
    real_render, real_twin = evaluate_module._render, render.render_twin

    def spy_index(twin, record, index, batch):
        indices.append(index)
        return real_render(twin, record, index, batch)

    def spy(twin, record=None):  # what the renderer sees as its scenario 0
        drawn.append((int(twin.interval[0]), twin.platoon.position_m[0].clone()))
        return real_twin(twin, record)

    monkeypatch.setattr(evaluate_module, "_render", spy_index)
    monkeypatch.setattr(render, "render_twin", spy)
    loop = JointOptimisation.from_checkpoint(tmp_path / "run/checkpoints/last.pt", tmp_path / "e")
    loop.cfg.video, loop.cfg.video_scenarios = True, "best_worst"
    loop.evaluate()
    returns = loop._last_results[1].returns
    best, worst = int(returns.argmax()), int(returns.argmin())
    assert best != worst and sorted(loop.videos) == ["episode_best", "episode_worst"]
    intervals = data["experiment"]["eval_intervals"]
    assert indices == [best, worst] * intervals
    # what the view shows is that scenario's state: the twin's own row, not row 0
    twin_rows = {}

    def rows(twin, record):
        twin_rows.setdefault(int(twin.interval[0]), twin.platoon.position_m.clone())

    from vdtn_marl.algos.evaluate import evaluate_system

    params = loop.params
    acting = loop.control_policy(), loop.rra_policy()
    evaluate_system(
        params, *acting, perfect=False, episodes=4, intervals=intervals,
        seed=evaluate_module.EVAL_SEED_OFFSET + loop.cfg.seed, gamma=loop.cfg.algo.gamma,
        device=loop.device, trace_source=loop.eval_traces, ivoi_estimator=loop.estimator,
        completion=loop.completion, on_interval=rows,
    )  # fmt: skip
    for index, (interval, position) in zip(indices, drawn, strict=True):
        torch.testing.assert_close(position, twin_rows[interval][index])
    frames = iio.imread(loop.videos["episode_best"], index=None)
    assert frames.shape[0] == intervals


def test_eval_video_without_its_library_is_one_line(tmp_path, monkeypatch, capsys):
    from vdtn_marl.io import video

    _make_run(tmp_path / "run", ["experiment=smoke"], "jocc", TRAINED)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(video, "installed", lambda module: module != "imageio_ffmpeg")
    assert cli.main(["eval", "checkpoint=run", "video=true", "video_format=mp4"]) == 2
    _one_line(capsys.readouterr().err, "video_format=mp4", "pip install 'vdtn-marl[video]'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


# --- 3. a run folder is never overwritten ---------------------------------------------------


@pytest.mark.parametrize("command", ["jocc", "train"])
def test_rerun_into_a_run_folder_without_resume_is_refused(command, tmp_path, monkeypatch, capsys):
    calls = []
    _fake_entry(monkeypatch, command, calls)
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run"
    assert cli.main([command, "experiment=smoke", f"hydra.run.dir={run}"]) == 0
    before = _listing(tmp_path)
    capsys.readouterr()
    assert cli.main([command, "experiment=smoke", "seed=3", f"hydra.run.dir={run}"]) == 2
    _one_line(capsys.readouterr().err, f"hydra.run.dir={run}", "already holds a run",
              "resume=true", "another hydra.run.dir")  # fmt: skip
    assert _listing(tmp_path) == before and len(calls) == 1
    assert cli.main([command, "experiment=smoke", f"hydra.run.dir={run}", "resume=true"]) == 0


def test_eval_into_a_run_folder_is_refused(tmp_path, monkeypatch, capsys):
    run = tmp_path / "run"
    _make_run(run, ["experiment=smoke"], trained=TRAINED)
    monkeypatch.chdir(tmp_path)
    before = _listing(tmp_path)
    assert cli.main(["eval", f"checkpoint={run}", f"hydra.run.dir={run}"]) == 2
    line = _one_line(capsys.readouterr().err, "already holds a run", "another hydra.run.dir")
    assert "resume" not in line
    assert _listing(tmp_path) == before


def test_sweeps_into_new_folders_run_and_a_used_sweep_folder_is_refused(
    tmp_path, monkeypatch, capsys
):
    calls = []
    _fake_entry(monkeypatch, "jocc", calls)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["-m", "jocc", "experiment=smoke", "rra.kappa1=0,1"]) == 0  # default dirs
    sweep = next((tmp_path / "multirun" / "jocc").iterdir())
    assert len(calls) == 2 and (sweep / "1" / "summary.json").is_file()
    capsys.readouterr()
    argv = ["-m", "jocc", "experiment=smoke", "rra.kappa1=0,1", f"hydra.sweep.dir={sweep}"]
    assert cli.main(argv) == 2
    _one_line(capsys.readouterr().err, f"hydra.sweep.dir={sweep}", f"{sweep / '0'}", "resume=true")
    assert cli.main([*argv, "resume=true"]) == 0 and len(calls) == 4


# --- 4. Ctrl-C ------------------------------------------------------------------------------


def test_ctrl_c_prints_how_to_continue_and_exits_130(tmp_path, monkeypatch, capsys):
    from vdtn_marl.algos.checkpoint import save_checkpoint
    from vdtn_marl.experiment import api

    def interrupted(cfg, run_dir):
        save_checkpoint(Path(run_dir) / "checkpoints" / "last.pt", {"task": "jocc"})
        raise KeyboardInterrupt

    monkeypatch.setattr(api, "jocc", interrupted)
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run"
    try:
        with pytest.raises(SystemExit) as info:
            cli.main(["jocc", "experiment=smoke", "seed=2", f"hydra.run.dir={run}"])
    except KeyboardInterrupt:
        pytest.fail("the KeyboardInterrupt went through the CLI")
    assert info.value.code == 130
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert f"the last checkpoint is {run / 'checkpoints' / 'last.pt'}" in lines[0]
    command = lines[0].split("continue with: ")[1]
    assert command.startswith("vdtn-marl jocc ")
    # ... and the command it gives continues the run
    calls = []
    _fake_entry(monkeypatch, "jocc", calls)
    assert cli.main(shlex.split(command)[1:]) == 0
    (cfg,) = calls
    assert cfg.resume and cfg.seed == 2 and cfg.experiment.name == "smoke"


# --- 5. checkpoint errors -------------------------------------------------------------------


def test_a_file_that_is_not_a_checkpoint_is_one_line(tmp_path, monkeypatch, capsys):
    from vdtn_marl.algos.checkpoint import CheckpointError, load_checkpoint

    fake = tmp_path / "run" / "checkpoints" / "last.pt"
    fake.parent.mkdir(parents=True)
    fake.write_text('{"not": "a checkpoint"}')
    with pytest.raises(CheckpointError) as info:
        load_checkpoint(fake)
    assert "\n" not in str(info.value) and "weights_only" not in str(info.value)
    assert "not a vdtn-marl checkpoint" in str(info.value) and str(fake) in str(info.value)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", "checkpoint=run"]) == 2
    line = _one_line(capsys.readouterr().err, "checkpoint=run/checkpoints/last.pt", "allowed")
    assert "weights_only" not in line


@pytest.mark.parametrize("name", ["config.yaml", "hello.txt"])
def test_eval_of_a_text_file_is_one_line(name, tmp_path, monkeypatch, capsys):
    # both start with a pickle opcode: torch's unpickler fails with KeyError / IndexError
    path = tmp_path / name
    path.write_text("hello" if name == "hello.txt" else "(algo:\n  name: mappo\n")
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", f"checkpoint={path}", "hydra.run.dir=ev"]) == 2
    err = capsys.readouterr().err
    _one_line(err, f"checkpoint={path}", "not a vdtn-marl checkpoint")
    assert "Traceback" not in err


def test_a_checkpoint_the_system_will_not_let_us_read_is_one_line(tmp_path, monkeypatch):
    import builtins

    from vdtn_marl.algos import checkpoint

    path = tmp_path / "last.pt"
    path.write_bytes(b"PK\x03\x04 whatever")

    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(checkpoint.torch, "load", refuse)
    monkeypatch.setattr(builtins, "open", refuse)
    with pytest.raises(checkpoint.CheckpointError, match="cannot be read \\(Permission denied\\)"):
        checkpoint.load_checkpoint(path)


def test_a_run_folder_without_a_checkpoint_is_named_as_such(tmp_path, monkeypatch, capsys):
    (tmp_path / "run").mkdir()
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", "checkpoint=run"]) == 2
    line = _one_line(capsys.readouterr().err, "checkpoint=run", "without checkpoints/last.pt")
    assert "does not exist" not in line


# --- 6. launchers ---------------------------------------------------------------------------


@pytest.mark.skipif(
    importlib.util.find_spec("hydra_plugins.hydra_submitit_launcher") is None,
    reason="hydra-submitit-launcher is not installed (pip install 'vdtn-marl[slurm]')",
)
def test_missing_launcher_lists_the_installed_ones(tmp_path, monkeypatch, capsys):
    real = importlib.util.find_spec

    def find_spec(name, *args, **kwargs):  # as if Ray's plugin were not installed
        if name.startswith("hydra_plugins.hydra_ray_launcher"):
            return None
        return real(name, *args, **kwargs)

    monkeypatch.setattr(importlib.util, "find_spec", find_spec)
    monkeypatch.chdir(tmp_path)
    assert cli.main(["-m", "jocc", "rra.kappa1=0,1", "hydra/launcher=ray"]) == 2
    line = _one_line(capsys.readouterr().err, "hydra/launcher=ray")
    allowed = line.split("allowed here: ")[1].split(", ")
    assert allowed == ["basic", "joblib", "submitit_local", "submitit_slurm"]
    assert list(tmp_path.iterdir()) == []


# --- 7. the run log -------------------------------------------------------------------------


class _FakeLoop:
    """Stands in for JointOptimisation: one checkpoint write, one summary (no training)."""

    def __init__(self, cfg, run_dir, task):
        self.checkpoint_path = Path(run_dir) / "checkpoints" / "last.pt"

    def run(self):
        from vdtn_marl.algos.checkpoint import save_checkpoint

        payload = {"task": "jocc", "position": {"iteration": 1, "stage": 0}}
        save_checkpoint(
            self.checkpoint_path, {**payload, "trainers": {"pi_star": {"iteration": 4}}}
        )
        return {"control_cost": 0.25, "v2i_throughput_mbps_per_link": 1.5}


@pytest.mark.parametrize("progress", [True, False])
def test_the_run_log_has_start_checkpoints_and_final_metrics(
    progress, tmp_path, monkeypatch, capsys
):
    from vdtn_marl.experiment import api

    monkeypatch.setattr(api, "JointOptimisation", _FakeLoop)
    monkeypatch.chdir(tmp_path)
    argv = ["jocc", "experiment=smoke", "hydra.run.dir=run", f"progress={progress}"]
    assert cli.main(argv) == 0
    log = (tmp_path / "run" / "jocc.log").read_text()
    assert "jocc seed=0 in" in log and "scenario=platoon4" in log
    assert "checkpoint written:" in log and "pi_star=4" in log
    assert "jocc done in" in log and "control_cost=0.25" in log
    # with progress bars the terminal shows the bars, not the log; without, the log
    assert ("checkpoint written:" in capsys.readouterr().out) is not progress


def test_logged_stage_logs_start_and_end_with_wall_time(caplog):
    from vdtn_marl.io.log import logged_stage

    with caplog.at_level(logging.INFO, logger="vdtn_marl"):
        with logged_stage("control_perfect", "π* for 4 PPO iterations", 2):
            pass
    first, last = (r.getMessage() for r in caplog.records)
    assert first == "JOCC iteration 2, stage control_perfect: π* for 4 PPO iterations"
    assert last.startswith("JOCC iteration 2, stage control_perfect done in ")


# --- 8. help --------------------------------------------------------------------------------


def test_help_lists_what_each_command_writes():
    outputs = {c: cli_help.command_help(c).split("outputs:")[1].split("hydra flags")[0] for c in
               ("eval", "jocc")}  # fmt: skip
    assert "metrics.csv" not in outputs["eval"] and "checkpoints" not in outputs["eval"]
    assert "summary.json" in outputs["eval"] and "eval.log" in outputs["eval"]
    assert "metrics.csv" in outputs["jocc"] and "checkpoints/last.pt" in outputs["jocc"]
