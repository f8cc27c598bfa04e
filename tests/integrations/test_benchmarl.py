"""The BenchMARL tasks (``vdtn_marl.integrations.benchmarl``).

Most tests need BenchMARL, which the main test set does not pin (it requires torchrl<0.12):
they run on the stack of ``constraints-benchmarl.txt`` (``scripts/benchmarl_check.sh`` builds
it and runs them), and are skipped elsewhere. Without BenchMARL, the import names the extra.
"""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import vdtn_marl

ROOT = Path(__file__).resolve().parents[2]


def single_clock_batched_ids() -> list[str]:
    """The registered PettingZoo ids with a batched face whose agents share one clock."""
    return [
        env_id
        for env_id in vdtn_marl.list_envs(api="pettingzoo")
        if vdtn_marl.spec(env_id).vector_entry_point and len(vdtn_marl.spec(env_id).clocks) == 1
    ]


def two_clock_ids() -> list[str]:
    return [i for i in vdtn_marl.list_envs() if len(vdtn_marl.spec(i).clocks) > 1]


def test_without_benchmarl_the_import_names_the_extra():
    code = (
        "import sys\n"
        "sys.modules['benchmarl'] = None  # as if it were not installed\n"
        "from vdtn_marl.errors import MissingExtraError\n"
        "try:\n"
        "    import vdtn_marl.integrations.benchmarl\n"
        "except MissingExtraError as exc:\n"
        "    print(exc.extra, '|', exc)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    extra, message = done.stdout.strip().split(" | ")
    assert extra == "benchmarl"
    assert "vdtn-marl[benchmarl]" in message and "torchrl<0.12" in message


def test_without_benchmarl_the_command_is_one_line_naming_the_extra():
    code = (
        "import sys\n"
        "sys.modules['benchmarl'] = None\n"
        "from vdtn_marl.integrations.__main__ import main\n"
        "sys.exit(main(['benchmarl', 'algorithm=mappo', 'task=vdtn/control']))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 1
    assert done.stderr.count("\n") == 1 and "vdtn-marl[benchmarl]" in done.stderr


# --- with BenchMARL ----------------------------------------------------------------------------
benchmarl_installed = pytest.mark.skipif(
    subprocess.run([sys.executable, "-c", "import benchmarl"], capture_output=True).returncode,
    reason="BenchMARL is not installed (the benchmarl extra, constraints-benchmarl.txt)",
)


@pytest.fixture(scope="module")
def vb():
    """The integration, imported. Importing BenchMARL (and our tasks) adds the config groups
    `task`, `algorithm` and `experiment` to Hydra's process-wide ConfigStore; they go when the
    module's tests end, as they would turn the plain `task=` key of vdtn-marl's own CLI into a
    group override for the tests that run later in this process."""
    from hydra.core.config_store import ConfigStore

    store = ConfigStore.instance().repo
    before = set(store)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import vdtn_marl.integrations.benchmarl as module
    yield module
    for group in set(store) - before:
        del store[group]


@benchmarl_installed
def test_every_single_clock_face_is_a_task(vb):
    ids = single_clock_batched_ids()
    assert ids
    tasks = {vb.VDTNTask.from_env_id(env_id) for env_id in ids}
    assert tasks == set(vb.VDTNTask)
    for task in vb.VDTNTask:
        assert vb.task_yaml(task.name.lower()).is_file()


@benchmarl_installed
def test_the_tasks_are_where_benchmarl_looks_them_up(vb):
    from benchmarl.environments import task_config_registry, tasks

    assert vb.VDTNTask in tasks
    for task in vb.VDTNTask:
        assert task_config_registry[f"vdtn/{task.name.lower()}"] is task


@benchmarl_installed
@pytest.mark.parametrize("env_id", two_clock_ids())
def test_a_two_clock_env_is_refused_naming_the_single_clock_tasks(vb, env_id):
    with pytest.raises(vdtn_marl.errors.ConfigError, match="not a BenchMARL task") as info:
        vb.VDTNTask.from_env_id(env_id)
    for task in vb.VDTNTask:
        assert f"vdtn/{task.name.lower()}" in str(info.value)
    for single in single_clock_batched_ids():
        assert single in str(info.value)


def compose(task: str, *overrides: str):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_module

    with initialize_config_module(config_module="benchmarl.conf", version_base=None):
        return hydra_compose(
            config_name="config", overrides=["algorithm=mappo", f"task={task}", *overrides]
        )


@benchmarl_installed
def test_task_joint_is_refused_through_hydra(vb):
    from benchmarl.hydra_config import load_task_config_from_hydra

    cfg = compose("vdtn/joint")
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # the refusal is the only message
        with pytest.raises(vdtn_marl.errors.ConfigError, match="vdtn/control.*vdtn/rra"):
            load_task_config_from_hydra(cfg.task, "vdtn/joint")


@benchmarl_installed
@pytest.mark.parametrize("name", ["control", "control_impaired", "rra"])
def test_hydra_composes_each_task_from_its_yaml_and_type_checks_it(vb, name):
    from benchmarl.hydra_config import load_task_config_from_hydra
    from hydra.errors import ConfigCompositionException

    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)  # e.g. "TaskConfig python dataclass not found"
        task = load_task_config_from_hydra(compose(f"vdtn/{name}").task, f"vdtn/{name}")
    assert isinstance(task, vb.VDTNClass) and task.config == vb.default_config(name)
    assert task == vb.VDTNTask[name.upper()].get_from_yaml()
    task = load_task_config_from_hydra(
        compose(f"vdtn/{name}", "task.num_vehicles=6", "+task.env_kwargs.traces=hwfet").task,
        f"vdtn/{name}",
    )
    assert task.config["num_vehicles"] == 6 and task.config["env_kwargs"] == {"traces": "hwfet"}
    with pytest.raises(ConfigCompositionException, match="num_vehicles"):
        compose(f"vdtn/{name}", "task.num_vehicles=many")


@benchmarl_installed
@pytest.mark.parametrize("name", ["control", "control_impaired", "rra"])
def test_task_builds_its_batched_face(vb, name):
    from torchrl.envs.utils import check_env_specs

    task = vb.VDTNTask[name.upper()].get_task({"num_vehicles": 5})
    env = task.get_env_fun(3, task.supports_continuous_actions(), 0, "cpu")()
    assert env.batch_size == (3,) and env.twin.params.platoon.num_vehicles == 5
    assert vdtn_marl.spec(task.env_id).vector_kwargs["mode"] == env.mode
    check_env_specs(env, seed=0)
    groups = task.group_map(env)
    assert set(groups) == set(task.observation_spec(env).keys()) == set(task.action_spec(env))
    assert all(len(agents) == 4 for agents in groups.values())
    per_interval = 1 if "max_cycles" in task.config else env.twin.subframes_per_interval
    horizon = task.config.get("max_cycles", task.config.get("episode_intervals"))
    assert task.max_steps(env) == horizon * per_interval
    assert task.supports_continuous_actions() != task.supports_discrete_actions()


@benchmarl_installed
def test_task_config_keys_are_checked(vb):
    with pytest.raises(vdtn_marl.errors.ConfigError, match="no key.*'kappa1'"):
        vb.VDTNTask.RRA.get_task({"kappa1": 0.7})  # model keys go in env_kwargs
    with pytest.raises(vdtn_marl.errors.ConfigError, match="env_kwargs sets.*num_vehicles"):
        vb.VDTNTask.RRA.get_task({"env_kwargs": {"num_vehicles": 3}}).env_kwargs()


@benchmarl_installed
def test_named_acting_parts_are_built(vb):
    from vdtn_marl.policies.rra import RoundRobinRRAPolicy

    env = vb.VDTNTask.CONTROL_IMPAIRED.get_task({"rra_policy": "round_robin"}).make_env(2, 0)
    assert isinstance(env.rra_policy, RoundRobinRRAPolicy)


@benchmarl_installed
@pytest.mark.parametrize("name", ["control", "control_impaired", "rra"])
def test_task_hands_over_the_global_state_and_the_domain_infos(vb, name):
    task = vb.VDTNTask[name.upper()].get_task({})
    env = task.get_env_fun(2, task.supports_continuous_actions(), 0, "cpu")()
    n = env.twin.params.platoon.num_vehicles
    assert list(task.state_spec(env).keys(True, True)) == ["state"]
    assert task.state_spec(env)["state"].shape == (3 * n,)  # unbatched, as BenchMARL reads it
    (group,) = task.group_map(env)
    observed = task.observation_spec(env)
    assert list(observed.keys(True, True)) == [(group, "observation")]  # what the actors read
    info = task.info_spec(env)
    keys = {key[-1] for key in info.keys(True, True)}
    assert {"gap_error_abs_m", "speed_error_abs_mps", "collided"} <= keys
    radio = {"cam_delivered", "aoi_ms", "v2i_throughput_mbps"}
    assert radio.issubset(keys) == (name != "control")
    rollout = env.rollout(3, break_when_any_done=False)
    assert set(rollout["next", group, "info"].keys()) == keys  # where BenchMARL's logger reads
    plain = vb.VDTNTask[name.upper()].get_task({"env_kwargs": {"return_state": False}})
    assert plain.state_spec(plain.get_env_fun(2, True, 0, "cpu")()) is None


@benchmarl_installed
def test_rra_interval_infos_are_logged_over_the_steps_that_close_an_interval(vb):
    task = vb.VDTNTask.RRA.get_task({"episode_intervals": 3})
    env = task.make_env(2, seed=0)
    rollout = env.rollout(150, break_when_any_done=False)  # 3 intervals of 50 subframes
    info = rollout["next", "rra", "info"]
    closing = info["closes_interval"] > 0
    assert int(closing.sum()) == 3 * 2 * env.num_links
    logged = vb.VDTNClass.log_info(rollout)
    delivered = info["cam_delivered"][closing].mean().item()
    assert logged["collection/rra/info/cam_delivered"] == pytest.approx(delivered)
    assert "collection/rra/info/aoi_ms" not in logged  # of each subframe: the plain mean
    assert vb.VDTNClass.log_info(task.make_env(2, seed=0).rollout(10)) == {}  # none closed


@benchmarl_installed
def test_the_control_tasks_render_and_rra_says_it_does_not(vb):
    for task in (vb.VDTNTask.CONTROL, vb.VDTNTask.CONTROL_IMPAIRED):
        env = task.get_task({"max_cycles": 3}).make_env(2, seed=0)
        env.rollout(2)
        assert task.get_task({}).has_render(env)
        frame = vb.VDTNClass.render_callback(None, env, None)  # BenchMARL's callback
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    rra = vb.VDTNTask.RRA.get_task({})
    with pytest.warns(UserWarning, match="vdtn/rra records no evaluation video.*render_mode"):
        assert not rra.has_render(rra.make_env(1, seed=0))


@benchmarl_installed
def test_mappos_centralised_critic_reads_the_global_state(vb, tmp_path):
    from benchmarl.algorithms import IppoConfig, MappoConfig
    from benchmarl.experiment import Experiment
    from benchmarl.models.mlp import MlpConfig

    def critic_inputs(algorithm, name):
        folder = tmp_path / f"{algorithm.__name__}_{name}"
        folder.mkdir()
        experiment = Experiment(
            task=vb.VDTNTask[name].get_task({}),
            algorithm_config=algorithm.get_from_yaml(),
            model_config=MlpConfig.get_from_yaml(),
            critic_model_config=MlpConfig.get_from_yaml(),
            seed=0,
            config=_one_iteration_config(folder, frames=40),
        )
        (group,) = experiment.group_map
        return experiment.losses[group].critic_network.in_keys, group

    for name in ("CONTROL", "RRA"):
        assert critic_inputs(MappoConfig, name)[0] == ["state"]
    inputs, group = critic_inputs(IppoConfig, "CONTROL")  # a decentralised critic: its own
    assert inputs == [(group, "observation")]


def _one_iteration_config(folder, frames: int):
    """BenchMARL's experiment config for one on-policy iteration of ``frames`` frames in 2
    scenarios, without loggers, rendering or evaluation, saving in ``folder``."""
    from benchmarl.experiment import ExperimentConfig

    config = ExperimentConfig.get_from_yaml()
    config.max_n_iters = 1
    config.loggers = []
    config.render = False
    config.evaluation = False
    config.save_folder = str(folder)
    config.on_policy_collected_frames_per_batch = frames
    config.on_policy_n_envs_per_worker = 2
    config.on_policy_n_minibatch_iters = 1
    config.on_policy_minibatch_size = frames // 2
    return config


@benchmarl_installed
@pytest.mark.slow
def test_benchmarl_trains_ippo_for_one_iteration_through_its_python_api(vb, tmp_path):
    from benchmarl.algorithms import IppoConfig
    from benchmarl.experiment import Experiment
    from benchmarl.models.mlp import MlpConfig

    config = _one_iteration_config(tmp_path, frames=40)
    experiment = Experiment(
        task=vb.VDTNTask.CONTROL_IMPAIRED.get_task({"max_cycles": 10}),
        algorithm_config=IppoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=config,
    )
    experiment.run()
    assert experiment.n_iters_performed == 1 and experiment.total_frames == 40


@benchmarl_installed
@pytest.mark.slow
def test_benchmarl_logs_the_domain_infos_of_a_mappo_iteration(vb, tmp_path):
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment
    from benchmarl.models.mlp import MlpConfig

    config = _one_iteration_config(tmp_path, frames=40)
    config.loggers = ["csv"]
    experiment = Experiment(
        task=vb.VDTNTask.CONTROL_IMPAIRED.get_task({"max_cycles": 10}),
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=config,
    )
    experiment.run()
    logged = {path.stem for path in tmp_path.rglob("*.csv")}  # "/" in a key becomes "_"
    for key in ("gap_error_abs_m", "cam_delivered", "aoi_ms", "v2i_throughput_mbps"):
        assert f"collection_vehicle_info_{key}" in logged, sorted(logged)


@benchmarl_installed
@pytest.mark.slow
def test_a_benchmarl_checkpoint_is_a_policy_of_the_benchmark(vb, tmp_path):
    """`rra.policy=<BenchMARL checkpoint>`: the trained weights act, deterministically, and
    nothing is written beside the checkpoint; a `vdtn-marl jocc` run takes it."""
    import json

    import torch
    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment
    from benchmarl.models.mlp import MlpConfig

    from vdtn_marl.algos.ppo import ActorPolicy
    from vdtn_marl.experiment.user_policy import load_policy
    from vdtn_marl.sim.params import TwinParams

    config = _one_iteration_config(tmp_path, frames=100)
    config.checkpoint_at_end = True
    experiment = Experiment(
        task=vb.VDTNTask.RRA.get_task({"episode_intervals": 1}),
        algorithm_config=MappoConfig.get_from_yaml(),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=0,
        config=config,
    )

    def weights(module) -> dict:  # tensordict 0.11 adds __batch_size, __device entries
        return {k: v.clone() for k, v in module.state_dict().items() if torch.is_tensor(v)}

    initial = weights(experiment.policy)
    experiment.run()
    (checkpoint,) = tmp_path.rglob("checkpoint_*.pt")
    listing = sorted(str(p) for p in tmp_path.rglob("*"))

    policy = load_policy("rra.policy", str(checkpoint), TwinParams(), seed=0)
    trained, loaded = weights(experiment.policy), weights(policy.actor)
    assert trained.keys() == loaded.keys()
    assert all(torch.equal(trained[k], loaded[k]) for k in trained)  # the trained weights ...
    assert any(not torch.equal(initial[k], trained[k]) for k in trained)  # ... not the initial
    observation = torch.randn(5, 3, experiment.observation_spec["rra", "observation"].shape[-1])
    assert torch.equal(policy(observation), ActorPolicy(experiment.policy, "rra")(observation))
    assert sorted(str(p) for p in tmp_path.rglob("*")) == listing

    run = subprocess.run(
        [sys.executable, "-m", "vdtn_marl.cli", "jocc", "experiment=smoke", "control=cacc",
         "rra=policy", f"rra.policy={checkpoint}", f"hydra.run.dir={tmp_path / 'run'}",
         "progress=false"],
        capture_output=True, text=True, cwd=tmp_path,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]
    summary = json.loads((tmp_path / "run" / "summary.json").read_text())
    assert summary["rra"] == "policy" and summary["config"]["rra"]["policy"] == str(checkpoint)
    assert sorted(str(p) for p in tmp_path.rglob("*") if "run" not in p.parts) == listing


@benchmarl_installed
def test_a_benchmarl_checkpoint_outside_its_folder_is_one_line(vb, tmp_path):
    import torch

    from vdtn_marl.errors import ConfigError
    from vdtn_marl.experiment.user_policy import check_policy

    lone = tmp_path / "checkpoint_100.pt"
    torch.save({"state": {"total_frames": 100}, "loss_rra": {}}, lone)
    with pytest.raises(ConfigError, match="rra.policy=.*config.pkl"):
        check_policy("rra.policy", str(lone))
