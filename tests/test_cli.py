"""The Hydra CLI, driven as users drive it: `vdtn-marl ...` in a subprocess.

Bad configs are checked in-process through ``cli.main`` as well (same code path, without paying
torch's import time once per case) and, for a few cases, in a subprocess for the real exit
code and stderr.

The tests named ``*_real`` run the real entry points of ``vdtn_marl.experiment.api`` (a smoke
`train` then `eval`, a two-job joblib sweep, and a two-job Ray sweep where the Ray plugin is
installed: scripts/ray_check.sh). The tests named ``*_fake_entry_points`` check CLI
plumbing that does not depend on training (the submitit launcher) with a fake ``api``
installed by a ``sitecustomize`` module on PYTHONPATH, so that launcher worker processes see it
too; that keeps them fast. The resume test patches ``api.jocc`` in-process.
"""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from vdtn_marl import cli
from vdtn_marl.cli import help as cli_help
from vdtn_marl.cli import prepass as cli_prepass
from vdtn_marl.experiment import config

# Our conf/hydra/launcher/*.yaml carry the launchers' schema names (see vdtn_marl/cli/app.py).
pytestmark = [
    pytest.mark.slow,  # runs of the CLI or of training (the fast loop skips them)
    pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema"),
]

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = Path(sys.executable).with_name("vdtn-marl")
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


FAKE_API = '''
import os
import sys

if os.environ.get("VDTN_MARL_FAKE_API"):
    import importlib.abc
    import importlib.util

    def _patch(api):
        from pathlib import Path

        from vdtn_marl.io.files import CHECKPOINT_DIR, SUMMARY_FILE, atomic_write_json
        from vdtn_marl.io.metrics import MetricsLog

        def _fake(cfg, run_dir):
            run_dir = Path(run_dir)
            log = MetricsLog(run_dir)
            log.log({"iteration": 0, "kappa1": cfg.rra.kappa1})
            (run_dir / CHECKPOINT_DIR).mkdir(exist_ok=True)
            summary = {
                "control_cost": 1.0 + cfg.rra.kappa1,
                "v2i_throughput_mbps_per_link": 0.5 + cfg.rra.kappa1,
                "resumed": cfg.resume,
            }
            atomic_write_json(run_dir / SUMMARY_FILE, summary)
            return summary

        api.train = api.jocc = api.evaluate = _fake

    class _PatchApi(importlib.abc.MetaPathFinder):
        """Patch vdtn_marl.experiment.api right after it is imported (only processes using it)."""

        def find_spec(self, name, path, target=None):
            if name != "vdtn_marl.experiment.api":
                return None
            sys.meta_path.remove(self)
            spec = importlib.util.find_spec(name)
            run = spec.loader.exec_module

            def exec_module(module):
                run(module)
                _patch(module)

            spec.loader.exec_module = exec_module
            return spec

    sys.meta_path.insert(0, _PatchApi())
'''


def run_cli(*args: str, cwd: Path, env: dict | None = None, timeout: float = 240):
    if SCRIPT.exists():
        command = [str(SCRIPT)]
    else:  # not `-m vdtn_marl.cli`: launchers pickle the jobs' functions by module name
        command = [sys.executable, "-c", "from vdtn_marl.cli import main; raise SystemExit(main())"]
    full_env = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200", **(env or {})}
    return subprocess.run(
        [*command, *args],
        cwd=cwd,
        env=full_env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.fixture
def fake_env(tmp_path_factory) -> dict:
    """Environment under which every process of the CLI uses the fake entry points."""
    folder = tmp_path_factory.mktemp("fake_api")
    (folder / "sitecustomize.py").write_text(FAKE_API)
    path = os.pathsep.join(filter(None, [str(folder), os.environ.get("PYTHONPATH")]))
    return {"PYTHONPATH": path, "VDTN_MARL_FAKE_API": "1"}


def _only_entry(path: Path) -> Path:
    entries = list(path.iterdir())
    assert len(entries) == 1, entries
    return entries[0]


# --- envs, help, --cfg ---------------------------------------------------------------------


def test_envs_lists_registry_with_agents_clocks_descriptions(tmp_path):
    result = run_cli("envs", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    for env_id in ("vdtn/platoon-control-v0", "vdtn/v2x-rra-v1", "vdtn/vdtn-joint-v1"):
        assert env_id in result.stdout
    assert "vehicle=50ms, rra=1ms" in result.stdout
    assert "description" in result.stdout.splitlines()[0]
    assert list(tmp_path.iterdir()) == []


def test_top_level_help_lists_commands_and_groups(tmp_path):
    result = run_cli("--help", cwd=tmp_path)
    assert result.returncode == 0
    for word in ("train", "jocc", "eval", "bench", "envs", "scenario", "platoon4_1mhz",
                 "round_robin", "hydra/launcher", "--cfg job", "-m"):  # fmt: skip
        assert word in result.stdout


@pytest.mark.parametrize("command", ["train", "jocc", "eval"])
def test_command_help_explains_groups_and_common_overrides(command, tmp_path):
    result = run_cli(command, "--help", cwd=tmp_path)
    assert result.returncode == 0
    assert f"usage: vdtn-marl [-m] {command}" in result.stdout
    assert "config groups" in result.stdout and "platoon4*" in result.stdout
    assert "most used keys" in result.stdout and "seed=" in result.stdout
    if command == "jocc":
        assert "rra.kappa1=" in result.stdout and "[default: 0.5]" in result.stdout
    assert list(tmp_path.iterdir()) == []


def test_bench_help_explains_summarize(tmp_path):
    result = run_cli("bench", "--help", cwd=tmp_path)
    assert result.returncode == 0
    assert "bench summarize SWEEP_DIR" in result.stdout
    assert "leaderboard" in result.stdout


def test_version(tmp_path):
    result = run_cli("--version", cwd=tmp_path)
    assert result.returncode == 0
    assert result.stdout.startswith("vdtn-marl ")


def test_cfg_job_prints_resolved_config_and_writes_nothing(tmp_path):
    result = run_cli(
        "jocc", "--cfg", "job", "experiment=smoke", "rra.kappa1=0.25", "scenario=platoon8",
        cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    cfg = yaml.safe_load(result.stdout)
    assert cfg["rra"]["kappa1"] == 0.25 and cfg["rra"]["kappa2"] is None
    assert cfg["scenario"]["num_vehicles"] == 8
    assert cfg["experiment"]["name"] == "smoke" and cfg["algo"]["num_envs"] == 2
    assert list(tmp_path.iterdir()) == []


# --- validation: one line, exit 2, nothing written -----------------------------------------

BAD_CONFIGS = [
    # (overrides, key the message must name)
    (["rra.kappa1=0.3", "rra.kappa2=0.3"], "rra.kappa2=0.3"),
    (["rra.kappa1=1.5"], "rra.kappa1=1.5"),
    (["rra.kappa1=-0.1"], "rra.kappa1=-0.1"),
    (["rra.kappa1=0", "rra.kappa2=1.2"], "rra.kappa2=1.2"),
    (["experiment.jocc_iterations=0"], "experiment.jocc_iterations=0"),
    (["experiment.control_iterations=-5"], "experiment.control_iterations=-5"),
    (["experiment.eval_episodes=0"], "experiment.eval_episodes=0"),
    (["algo.num_envs=0"], "algo.num_envs=0"),
    (["algo.lr_schedule=cosine"], "algo.lr_schedule='cosine'"),
    (["algo.activation=relu"], "algo.activation='relu'"),
    (["algo.validate_every=-1"], "algo.validate_every=-1"),
    (["algo.update_threads=-1"], "algo.update_threads=-1"),
    (["algo.collector_workers=-1"], "algo.collector_workers=-1"),
    (["algo.collector_workers=3"], "algo.collector_workers=3"),
    (["algo.rra_lmbda=1.5"], "algo.rra_lmbda=1.5"),
    (["algo.rra_burn_in_intervals=200"], "algo.rra_burn_in_intervals=200"),
    (["rra.rollout_intervals=0"], "rra.rollout_intervals=0"),
    (["rra.ivoi_baseline=best"], "rra.ivoi_baseline='best'"),
    (["rra.ivoi_baseline=cam_lost"], "rra.ivoi_baseline='cam_lost' needs rra.ivoi_estimator"),
    (["scenario.foo=1"], "scenario.foo=1"),
    (["+scenario.foo=1"], "scenario.foo=1"),
    (["+scenario.model.foo=1"], "scenario.model.foo=1"),
    (["scenario.num_vehicles=1"], "scenario.num_vehicles=1"),
    (["scenario.subchannel_bandwidth_hz=0"], "scenario.subchannel_bandwidth_hz"),
    (["scenario=platoon99"], "scenario=platoon99"),
    (
        ["scenario=platoon4_noise90", "scenario.model.noise_power_override_dbm=5"],
        "noise_power_override_dbm=5",
    ),
    (["seed=abc"], "seed=abc"),
    (["rra.kappa1=high"], "rra.kappa1=high"),
    (["algo.num_envs=2.5"], "algo.num_envs=2.5"),
    (["task=nope"], "task='nope'"),
    (["control.warm_start=teacher"], "control.warm_start='teacher'"),
    (["control.pi_star_critic_warmup=-1"], "control.pi_star_critic_warmup=-1"),
    (["control.pi_star_validate_every=-2"], "control.pi_star_validate_every=-2"),
    (["rra.warm_start=random"], "rra.warm_start='random'"),
    (["rra.validate_every=-1"], "rra.validate_every=-1"),
    (["rra.term_scales=auto"], "rra.term_scales='auto'"),
    (["rra=drra", "rra.term_scales=spread"], "rra.term_scales='spread'"),
    (["control=oracle", "control.mpc_iterations=0"], "control.mpc_iterations=0"),
    (["control.mpc_iterations=50"], "control.mpc_iterations=50"),  # control=learned
    (["algo.validation_scenarios=0"], "algo.validation_scenarios=0"),
    (["rra.kappa1=0,1"], "rra.kappa1=0,1"),
]


def _assert_one_line_error(stderr: str, key: str) -> None:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: "), stderr
    assert key in lines[0], stderr
    # ... and says what is allowed (validate's wording: allowed / must / choose / outside).
    assert any(w in lines[0] for w in ("allowed", "must", "choose", "outside")), stderr


@pytest.mark.parametrize("overrides,key", BAD_CONFIGS, ids=[" ".join(o) for o, _ in BAD_CONFIGS])
def test_bad_config_is_one_line_exit_2_and_writes_nothing(
    overrides, key, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["jocc", *overrides]) == 2
    _assert_one_line_error(capsys.readouterr().err, key)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "overrides,key",
    [([], "checkpoint=None"), (["checkpoint=no/such/run"], "checkpoint=no/such/run")],
)
def test_eval_needs_an_existing_checkpoint(overrides, key, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["eval", *overrides]) == 2
    _assert_one_line_error(capsys.readouterr().err, key)
    assert list(tmp_path.iterdir()) == []


def test_bad_sweep_job_is_rejected_before_any_job_runs(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["-m", "jocc", "rra.kappa1=0,0.5,1.5", "seed=0,1"]) == 2
    err = capsys.readouterr().err
    _assert_one_line_error(err, "rra.kappa1=1.5")
    assert "sweep job" in err
    assert list(tmp_path.iterdir()) == []


def test_missing_launcher_plugin_is_a_config_error(tmp_path, monkeypatch, capsys):
    if importlib.util.find_spec("hydra_plugins.hydra_ray_launcher") is not None:
        pytest.skip("the Ray launcher plugin is installed here")
    monkeypatch.chdir(tmp_path)
    assert cli.main(["-m", "jocc", "rra.kappa1=0,1", "hydra/launcher=ray"]) == 2
    _assert_one_line_error(capsys.readouterr().err, "hydra/launcher=ray")
    assert list(tmp_path.iterdir()) == []


def test_unavailable_cuda_device_is_rejected(tmp_path, monkeypatch, capsys):
    import torch

    if torch.cuda.is_available():
        device = f"cuda:{torch.cuda.device_count()}"  # one past the last device
    else:
        device = "cuda"
    monkeypatch.chdir(tmp_path)
    assert cli.main(["train", f"device={device}"]) == 2
    _assert_one_line_error(capsys.readouterr().err, f"device='{device}'")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "overrides,key",
    [
        (["rra.kappa1=0.7", "rra.kappa2=0.7"], "rra.kappa1=0.7 + rra.kappa2=0.7"),
        (["device=cuda:7"], "device="),
        (["scenario.bogus=3"], "scenario.bogus=3"),
    ],
)
def test_bad_config_subprocess_exit_code_and_stderr(overrides, key, tmp_path):
    import torch

    if "device=cuda:7" in overrides and torch.cuda.device_count() > 7:
        pytest.skip("this machine has 8 or more GPUs")
    result = run_cli("train", *overrides, cwd=tmp_path)
    assert result.returncode == 2, result.stdout + result.stderr
    _assert_one_line_error(result.stderr, key)
    assert result.stdout == ""
    assert list(tmp_path.iterdir()) == [], "a rejected config must write nothing"


def test_unknown_command_is_usage_error(tmp_path):
    result = run_cli("fly", cwd=tmp_path)
    assert result.returncode == 2
    assert "unknown command 'fly'" in result.stderr


# --- every shipped config composes into a valid run ----------------------------------------


def _prevalidate(command: str, overrides: list[str]) -> None:
    hargs = cli.app._hydra_args(overrides)
    cli.app.prevalidate(command, hargs, [*hargs.overrides, f"hydra.job.name={command}"])


#: what an option needs besides itself: the user's own policy names one (control=policy, rra=policy)
USER_POLICIES = """
from vdtn_marl.policies import CACCController, make_rra_baseline



def control(params, seed):
    return CACCController(params.platoon)


def rra(params, seed):
    return make_rra_baseline("greedy", params, seed)
"""


@pytest.mark.parametrize("group", ["scenario", "algo", "control", "rra", "experiment"])
def test_every_group_option_composes_and_validates(group, tmp_path):
    options = cli_help.group_options(group)
    assert options, group
    (tmp_path / "user_policies.py").write_text(USER_POLICIES)
    for option in options:
        needs = [f"{group}.policy={tmp_path / 'user_policies.py'}:{group}"] * (option == "policy")
        _prevalidate("jocc", [f"{group}={option}", *needs])


def test_group_options_as_documented():
    assert set(cli_help.group_options("scenario")) == {
        "platoon4",
        "platoon8",
        "platoon16",
        "platoon4_1mhz",
        "platoon4_noise90",
        "two_platoons",
    }
    assert set(cli_help.group_options("algo")) == {"mappo", "ippo"}
    # one YAML per learned-RRA reward and per registered baseline, and no other
    assert set(cli_help.group_options("rra")) == set(config.RRA_METHODS)
    assert {"jocc", "drra", "throughput", "random", "round_robin", "greedy"} <= set(
        config.RRA_METHODS
    )
    assert set(cli_help.group_options("control")) == set(config.CONTROLS)
    assert set(cli_help.group_options("experiment")) == {"smoke", "default", "paper"}
    launchers = set(cli_help.group_options("hydra/launcher"))
    assert {"basic", "joblib", "submitit_slurm", "ray"} <= launchers


def test_scenarios_match_the_case_study(tmp_path, monkeypatch, capsys):
    from hydra import compose, initialize_config_module

    from vdtn_marl.experiment.config import ScenarioConfig, register_configs
    from vdtn_marl.scenarios import scenario_params

    register_configs()
    with initialize_config_module(config_module="vdtn_marl.conf", version_base="1.3"):
        base = compose("config", ["scenario=platoon4"]).scenario
        wide = compose("config", ["scenario=platoon4_1mhz"]).scenario
        assert (base.num_vehicles, base.num_subchannels) == (4, 4)
        assert base.subchannel_bandwidth_hz == 180e3
        assert wide.subchannel_bandwidth_hz == 1e6 and wide.num_vehicles == 4
        assert compose("config", ["scenario=platoon16"]).scenario.num_vehicles == 16
        noisy = compose("config", ["scenario=platoon4_noise90"]).scenario
        assert noisy.subchannel_bandwidth_hz == 180e3 and noisy.num_vehicles == 4
        assert dict(noisy.model) == {"noise_power_override_dbm": -90.0}
        kwargs = ScenarioConfig(model=dict(noisy.model)).model_kwargs()
        assert scenario_params(**kwargs).radio.noise_power_dbm == -90.0
        assert compose("config", ["rra=throughput"]).rra.kappa1 == 1.0


BENCHMARKS = sorted(p.stem for p in (ROOT / "conf" / "benchmark").glob("*.yaml"))


def test_every_benchmark_config_is_tested():
    assert {"smoke", "reduced", "leaderboard", "sensitivity"} <= set(BENCHMARKS)
    assert cli_help.group_options("benchmark") == BENCHMARKS


@pytest.mark.parametrize("benchmark", BENCHMARKS)
def test_benchmark_configs_are_valid(benchmark):
    """Every shipped benchmark composes, validates and composes every cell into a valid run."""
    _prevalidate("bench", [f"benchmark={benchmark}"])


def test_benchmark_cfg_job_shows_version(tmp_path):
    result = run_cli("bench", "benchmark=leaderboard", "--cfg", "job", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    bench = yaml.safe_load(result.stdout)["benchmark"]
    assert bench["version"] and bench["scenarios"] and bench["methods"] and bench["seeds"]
    assert list(tmp_path.iterdir()) == []


# --- runs and sweeps with fake entry points (CLI plumbing) ---------------------------------


def test_resume_reuses_the_run_dir(tmp_path, monkeypatch, capsys):
    """In-process, with a fake entry point: resume=true reruns the job in the same dir."""
    from vdtn_marl.experiment import api

    calls = []

    def fake_jocc(cfg, run_dir):
        calls.append((cfg.resume, Path(run_dir)))
        summary = {"control_cost": 1.0, "v2i_throughput_mbps_per_link": 2.0}
        (Path(run_dir) / "summary.json").write_text(json.dumps(summary))
        return summary

    monkeypatch.setattr(api, "jocc", fake_jocc)
    monkeypatch.chdir(tmp_path)
    run_dir = tmp_path / "run"
    assert cli.main(["jocc", "experiment=smoke", f"hydra.run.dir={run_dir}"]) == 0
    assert cli.main(["jocc", "experiment=smoke", f"hydra.run.dir={run_dir}", "resume=true"]) == 0
    assert calls == [(False, run_dir), (True, run_dir)]
    assert yaml.safe_load((run_dir / "config.yaml").read_text())["resume"] is True
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    assert "run directory:" in capsys.readouterr().out


def test_resume_with_another_config_or_no_run_is_rejected(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    run_dir = tmp_path / "old"
    assert cli.main(["jocc", f"hydra.run.dir={run_dir}", "resume=true"]) == 2
    _assert_one_line_error(capsys.readouterr().err, "resume=true")
    assert list(tmp_path.iterdir()) == []
    run_dir.mkdir()
    (run_dir / "config.yaml").write_text(
        yaml.safe_dump({"rra": {"kappa1": 0.5}, "seed": 0, "resume": False})
    )
    assert cli.main(["jocc", f"hydra.run.dir={run_dir}", "resume=true", "rra.kappa1=0.7"]) == 2
    err = capsys.readouterr().err
    assert "rra.kappa1=0.7" in err and "allowed" in err
    assert sorted(p.name for p in run_dir.iterdir()) == ["config.yaml"]


def _check_sweep(tmp_path: Path, result, kappas: list[float]) -> Path:
    assert result.returncode == 0, result.stdout + result.stderr
    sweep_dir = _only_entry(tmp_path / "multirun" / "jocc")
    jobs = sorted(p for p in sweep_dir.iterdir() if p.is_dir() and (p / ".hydra").is_dir())
    assert [p.name for p in jobs] == [str(i) for i in range(len(kappas))]
    seen = []
    for job in jobs:
        assert (job / "summary.json").is_file() and (job / "metrics.csv").is_file()
        seen.append(yaml.safe_load((job / "config.yaml").read_text())["rra"]["kappa1"])
        assert yaml.safe_load((job / ".hydra" / "overrides.yaml").read_text())
    assert sorted(seen) == sorted(kappas)
    assert "bench summarize" in result.stdout
    return sweep_dir


@pytest.mark.skipif(
    importlib.util.find_spec("hydra_plugins.hydra_submitit_launcher") is None,
    reason="hydra-submitit-launcher is not installed (pip install 'vdtn-marl[slurm]')",
)
def test_submitit_local_sweep_fake_entry_points(tmp_path, fake_env):
    """The submitit plugin (SLURM launcher) runs our jobs through its local executor."""
    result = run_cli(
        "-m", "jocc", "rra.kappa1=0,1", "experiment=smoke", "hydra/launcher=submitit_local",
        "hydra.launcher.timeout_min=5", cwd=tmp_path, env=fake_env,
    )  # fmt: skip
    _check_sweep(tmp_path, result, [0, 1])


# --- runs and sweeps with the real entry points --------------------------------------------


@pytest.mark.skipif(
    importlib.util.find_spec("hydra_plugins.hydra_ray_launcher") is None,
    reason="hydra-ray-launcher is not installed (scripts/ray_check.sh; docs/cli.md, Ray)",
)
def test_ray_sweep_two_jobs_real(tmp_path):
    """Two smoke JOCC jobs, each a Ray task of a local instance (scripts/ray_check.sh)."""
    result = run_cli(
        "-m", "jocc", "rra.kappa1=0,1", "experiment=smoke", "hydra/launcher=ray",
        "+hydra.launcher.ray.init.num_cpus=2", "+hydra.launcher.ray.init.include_dashboard=false",
        "+hydra.launcher.ray.init._node_ip_address=127.0.0.1",
        cwd=tmp_path, env={"RAY_ADDRESS": "", "OMP_NUM_THREADS": "1"}, timeout=600,
    )  # fmt: skip
    sweep_dir = _check_sweep(tmp_path, result, [0, 1])
    assert "Ray Launcher is launching 2 jobs" in result.stdout + result.stderr
    for job in ("0", "1"):
        summary = json.loads((sweep_dir / job / "summary.json").read_text())
        assert summary["control_cost"] > 0 and summary["v2i_throughput_mbps_per_link"] > 0
        assert 0.0 <= summary["cam_delivery_rate"] <= 1.0


def test_train_smoke_then_eval_real(tmp_path):
    result = run_cli("train", "experiment=smoke", "rra.kappa1=0.25", cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    run_dir = _only_entry(tmp_path / "outputs" / "train")
    for name in ("config.yaml", "metrics.csv", "checkpoints", "summary.json", ".hydra"):
        assert (run_dir / name).exists(), name
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert config["rra"]["kappa1"] == 0.25 and config["experiment"]["name"] == "smoke"
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["task"] == "control" and "kappa1" not in summary  # π* only: no RRA reward
    assert f"run directory: {run_dir.resolve()}" in result.stdout
    assert "control_cost" in result.stdout  # the summary table

    # eval takes the run directory for its checkpoints/last.pt
    result = run_cli("eval", f"checkpoint={run_dir}", "experiment=smoke", "rra=random",
                     "hydra.run.dir=eval_run", cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    config = yaml.safe_load((tmp_path / "eval_run" / "config.yaml").read_text())
    assert config["checkpoint"] == str(run_dir / "checkpoints" / "last.pt")
    assert (tmp_path / "eval_run" / "summary.json").is_file()


def test_joblib_sweep_two_jobs_real(tmp_path):
    result = run_cli(
        "-m", "jocc", "rra.kappa1=0,1", "experiment=smoke", "hydra/launcher=joblib",
        "hydra.launcher.n_jobs=2", cwd=tmp_path, env={"OMP_NUM_THREADS": "1"},
    )  # fmt: skip
    sweep_dir = _check_sweep(tmp_path, result, [0, 1])
    assert "Joblib.Parallel(n_jobs=2" in result.stdout + result.stderr

    summary = run_cli("bench", "summarize", str(sweep_dir), cwd=tmp_path)
    assert summary.returncode == 0, summary.stderr
    with open(sweep_dir / "summary.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert sorted(float(r["rra.kappa1"]) for r in rows) == [0.0, 1.0]
    assert all(float(r["control_cost"]) >= 0 for r in rows)
    assert (sweep_dir / "pareto_kappa1.png").read_bytes()[:8] == PNG_MAGIC


# --- bench summarize -----------------------------------------------------------------------


def _fake_sweep(root: Path, with_metrics: bool = True) -> Path:
    """A sweep dir as Hydra lays it out: κ1 ∈ {0, 0.5, 1} × seeds {0, 1}, plus a failed job."""
    sweep = root / "multirun" / "jocc" / "2026-01-01_00-00-00"
    job = 0
    for kappa1 in (0.0, 0.5, 1.0):
        for seed in (0, 1):
            job_dir = sweep / str(job)
            (job_dir / ".hydra").mkdir(parents=True)
            overrides = [f"rra.kappa1={kappa1}", f"seed={seed}"]
            (job_dir / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(overrides))
            config = {"rra": {"name": "jocc", "kappa1": kappa1, "kappa2": None}, "seed": seed}
            (job_dir / "config.yaml").write_text(yaml.safe_dump(config))
            summary = {"cam_delivery_rate": 0.9 + 0.01 * seed}
            if with_metrics:
                summary["control_cost"] = 2.0 - kappa1 + 0.05 * seed
                summary["v2i_throughput_mbps_per_link"] = 0.6 + 0.8 * kappa1 + 0.01 * seed
            (job_dir / "summary.json").write_text(json.dumps(summary))
            job += 1
    (sweep / str(job) / ".hydra").mkdir(parents=True)  # a job that never wrote its summary
    (sweep / "multirun.yaml").write_text("{}\n")
    return sweep


def test_bench_summarize_writes_table_and_pareto_plot(tmp_path):
    sweep = _fake_sweep(tmp_path)
    result = run_cli("bench", "summarize", str(sweep), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    with open(sweep / "summary.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == 6
    row = next(r for r in rows if r["run"] == "2")  # κ1 = 0.5, seed 0
    assert float(row["rra.kappa1"]) == 0.5 and float(row["rra.kappa2"]) == 0.5
    assert float(row["control_cost"]) == pytest.approx(1.5)
    assert row["overrides"] == "rra.kappa1=0.5 seed=0"
    png = (sweep / "pareto_kappa1.png").read_bytes()
    assert png[:8] == PNG_MAGIC and len(png) > 5000
    assert "V2I Mbps/link" in result.stdout and "control cost" in result.stdout  # the table
    assert "1 job(s) have no summary.json" in result.stderr and "6" in result.stderr


def test_bench_summarize_without_pareto_keys_explains_and_keeps_table(tmp_path):
    sweep = _fake_sweep(tmp_path, with_metrics=False)
    result = run_cli("bench", "summarize", str(sweep), "--csv", str(tmp_path / "t.csv"),
                     cwd=tmp_path)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "t.csv").stat().st_size > 0
    assert not (sweep / "pareto_kappa1.png").exists()
    assert "no Pareto plot" in result.stderr and "'control_cost'" in result.stderr
    assert "cam_delivery_rate" in result.stderr  # the keys that were found


def test_bench_summarize_of_empty_or_missing_dir_fails_clearly(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    result = run_cli("bench", "summarize", str(empty), cwd=tmp_path)
    assert result.returncode == 1 and "no summary.json" in result.stderr
    result = run_cli("bench", "summarize", str(tmp_path / "nope"), cwd=tmp_path)
    assert result.returncode == 2 and "not a directory" in result.stderr


def test_bench_summarize_lists_jobs_in_job_number_order(tmp_path):
    """Hydra numbers a sweep's jobs 0..N-1: job 10 comes after job 9, not after job 1."""
    from vdtn_marl.reporting.sweep import summarize_sweep
    from vdtn_marl.reporting.tables import find_jobs

    sweep = tmp_path / "sweep"
    for job in range(12):
        (sweep / str(job) / ".hydra").mkdir(parents=True)
        (sweep / str(job) / "summary.json").write_text(json.dumps({"control_cost": job}))
    (sweep / "12" / ".hydra").mkdir(parents=True)  # not finished: named in the note
    (sweep / "13" / ".hydra").mkdir(parents=True)
    expected = [str(job) for job in range(12)]
    assert [p.name for p in find_jobs(sweep)] == [*expected, "12", "13"]
    summary = summarize_sweep(sweep)  # no throughput key: the table only, no plot
    assert list(summary.table["run"]) == expected
    with open(summary.csv_path, newline="") as handle:
        assert [row["run"] for row in csv.DictReader(handle)] == expected
    assert summary.missing == ["12", "13"]


def test_pareto_mask():
    from vdtn_marl.reporting.plots import pareto_mask

    # (cost, throughput): the second point is beaten by the first on both.
    assert pareto_mask([1.0, 2.0, 3.0, 0.5], [1.0, 0.5, 2.0, 0.2]) == [True, False, True, True]


def test_default_config_mirrors_the_dataclass_defaults():
    """conf/ with its default options composes to RunConfig() exactly (no silent drift)."""
    from hydra import compose, initialize_config_module

    from vdtn_marl.experiment.config import RunConfig, register_configs, to_dict
    from vdtn_marl.reporting.tables import flatten

    register_configs()
    with initialize_config_module(config_module="vdtn_marl.conf", version_base="1.3"):
        composed = flatten(cli_prepass.job_config(compose("config")))
    expected = flatten(to_dict(RunConfig()))
    assert composed == expected
