"""BenchMARL tasks of vdtn-marl: one import registers them (docs/integrations.md).

    import vdtn_marl.integrations.benchmarl            # registers the tasks
    python -m vdtn_marl.integrations benchmarl algorithm=mappo task=vdtn/control

Every single-clock face is a task of the environment ``vdtn``, built on its batched TorchRL
face (``vdtn_marl.make(id, batch_size=B)``: BenchMARL's ``n_envs_per_worker`` scenarios in one
``VDTNTorchRLEnv``, as BenchMARL's VMAS tasks are):

==========================  ===================================  =========  ==================
task                        environment id                       group      actions
==========================  ===================================  =========  ==================
``vdtn/control``            ``vdtn/platoon-control-v0``          vehicle    continuous (m/s²)
``vdtn/control_impaired``   ``vdtn/platoon-control-impaired-v1`` vehicle    continuous (m/s²)
``vdtn/rra``                ``vdtn/v2x-rra-v1``                  rra        discrete (M·P)
==========================  ===================================  =========  ==================

The joint environment (``vdtn/vdtn-joint-v1``) is not a task: its two groups act on two clocks
(vehicles every 50 subframes, RRA agents every subframe), while BenchMARL's algorithms step
every group together with one discount per step; asking for it (``task=vdtn/joint``,
:meth:`VDTNTask.from_env_id`) raises a :class:`~vdtn_marl.errors.ConfigError` naming the tasks
above. vdtn-marl's own JOCC loop trains the two groups on their own clocks.

What the import registers, each in the place BenchMARL reads:

- :class:`VDTNTask` in ``benchmarl.environments.tasks`` and its members in
  ``task_config_registry`` (``"vdtn/control"`` → ``VDTNTask.CONTROL``), which
  ``benchmarl.hydra_config.load_task_config_from_hydra`` looks tasks up in;
- the task YAMLs of this package's ``conf/task/vdtn/`` in Hydra's ``ConfigStore`` (group
  ``task/vdtn``), and their schemas (``vdtn_<task>_config``, group ``task``), which Hydra
  searches besides BenchMARL's own ``conf/`` (BenchMARL reads task YAML from its own package
  only; the ConfigStore is Hydra's way to add configs from another package);
- each schema as ``benchmarl.environments.vdtn.<task>.TaskConfig``, the module path where
  BenchMARL looks for a task's schema (its step 6 of "Creating a new task"), so that loading a
  task type-checks its config rather than warning that no schema was found.

``VDTNTask.CONTROL.get_from_yaml()`` reads this package's YAML (not BenchMARL's folder), and
``get_task({...})`` fills the keys it is not given from it.

What a task hands BenchMARL besides observations and actions (the batched face built with
``return_state=True, return_info=True``, :mod:`vdtn_marl.envs.torchrl`):

- ``state_spec``: ``"state"``, the twin's global state [3N] (positions, speeds, accelerations
  of all N vehicles, the PettingZoo faces' ``state()``). MAPPO's and MASAC's centralised
  critics and QMIX's mixer read it instead of the group's stacked observations.
- ``info_spec``: ``(group, "info")``, the domain metrics (|gap error|, |speed error|,
  collisions, CAM delivery, AoI, V2I throughput), which BenchMARL logs as
  ``collection/<group>/info/<key>``; in ``vdtn/rra`` (one step = one subframe) the interval
  metrics are averaged over the steps that close an interval (:meth:`VDTNClass.log_info`).
- ``has_render``: the control tasks draw scenario 0 (one frame per 50 ms step) for
  BenchMARL's evaluation video; ``vdtn/rra`` does not (one frame per 1 ms subframe, 50 per
  interval) and says so in a warning at the first evaluation.

``+task.env_kwargs.return_state=false`` gives the critic of earlier versions (observations
only), e.g. to rebuild a checkpoint trained before the state was handed over.
"""

from __future__ import annotations

import copy
import dataclasses
import importlib.util
import sys
import types
import warnings
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any

from vdtn_marl.envs.registration import make, spec
from vdtn_marl.errors import ConfigError, MissingExtraError

EXTRA_HINT = (
    "pip install 'vdtn-marl[benchmarl]' -c constraints-benchmarl.txt (BenchMARL 1.5.x requires "
    "torchrl<0.12; docs/integrations.md)"
)


def _import_benchmarl():
    if importlib.util.find_spec("benchmarl") is None:
        raise MissingExtraError(f"BenchMARL is not installed: {EXTRA_HINT}", "benchmarl")
    try:
        import benchmarl
        from benchmarl import environments
        from benchmarl.environments.common import Task, TaskClass
    except ImportError as exc:  # e.g. BenchMARL 1.5.1 on torchrl 0.14
        raise MissingExtraError(
            f"BenchMARL is installed but does not import ({type(exc).__name__}: {exc}); "
            f"install the tested versions: {EXTRA_HINT}",
            "benchmarl",
        ) from exc
    return benchmarl, environments, Task, TaskClass


_benchmarl, _environments, Task, TaskClass = _import_benchmarl()

ENV_NAME = "vdtn"
"""The environment name of the tasks (``task=vdtn/<task>``)."""

CONF_DIR = Path(__file__).resolve().parent / "conf"
"""This package's BenchMARL config tree: ``task/vdtn/<task>.yaml``."""

#: task name (lower case, as in ``task=vdtn/<name>``) → the registered environment id it runs.
TASK_ENV_IDS: dict[str, str] = {
    "control": "vdtn/platoon-control-v0",
    "control_impaired": "vdtn/platoon-control-impaired-v1",
    "rra": "vdtn/v2x-rra-v1",
}


# --- schemas: types only; the values live in the YAMLs (BenchMARL's convention) -------------
@dataclass
class ControlTaskConfig:
    max_cycles: int = MISSING
    num_vehicles: int = MISSING
    env_kwargs: dict[str, Any] = MISSING


@dataclass
class ControlImpairedTaskConfig(ControlTaskConfig):
    rra_policy: str = MISSING


@dataclass
class RRATaskConfig:
    episode_intervals: int = MISSING
    num_vehicles: int = MISSING
    reward: str = MISSING
    control: str = MISSING
    env_kwargs: dict[str, Any] = MISSING


#: Tasks whose evaluation video BenchMARL records (:meth:`VDTNClass.has_render`): one frame
#: per step, and one step of ``vdtn/rra`` is one 1 ms subframe.
RENDERED_TASKS = ("control", "control_impaired")

NO_VIDEO_WARNING = (
    "task vdtn/rra records no evaluation video, whatever experiment.render says: one step is "
    "one 1 ms subframe, so an episode of K intervals would be K x 50 frames. Draw the platoon "
    "and its links with vdtn_marl.make('vdtn/v2x-rra-v1', render_mode='rgb_array') "
    "(docs/integrations.md)"
)

TASK_CONFIGS: dict[str, type] = {
    "control": ControlTaskConfig,
    "control_impaired": ControlImpairedTaskConfig,
    "rra": RRATaskConfig,
}
"""task name → its schema (a dataclass of the keys of ``conf/task/vdtn/<name>.yaml``)."""


def _single_clock_tasks() -> str:
    return ", ".join(f"{ENV_NAME}/{name} ({env_id})" for name, env_id in TASK_ENV_IDS.items())


def refusal(what: str) -> ConfigError:
    """The error for a two-clock environment asked for as a BenchMARL task."""
    return ConfigError(
        f"{what} is not a BenchMARL task: its vehicles act every control interval and its RRA "
        "agents every subframe, and BenchMARL steps all groups together with one discount; use "
        f"a single-clock task: {_single_clock_tasks()}"
    )


def task_yaml(name: str) -> Path:
    """The YAML of task ``name`` (``conf/task/vdtn/<name>.yaml``)."""
    return CONF_DIR / "task" / ENV_NAME / f"{name}.yaml"


def default_config(name: str) -> dict[str, Any]:
    """The values of task ``name``'s YAML (without Hydra's ``defaults`` list)."""
    from benchmarl.utils import _read_yaml_config

    return _read_yaml_config(str(task_yaml(name)))


class VDTNClass(TaskClass):
    """How BenchMARL builds a vdtn-marl task: the batched face of its environment id.

    ``config`` may give only some keys of the task's YAML; the others keep the YAML's values.
    A key that is not in the YAML raises a :class:`ConfigError` naming the allowed keys."""

    def __init__(self, name: str, config: dict[str, Any] | None):
        key = name.lower()
        if key not in TASK_ENV_IDS:
            raise refusal(f"task {ENV_NAME}/{key}")
        allowed = [f.name for f in dataclasses.fields(TASK_CONFIGS[key])]
        unknown = sorted(set(config or {}) - set(allowed))
        if unknown:
            raise ConfigError(
                f"task {ENV_NAME}/{key} has no key(s) {unknown}; keys: {allowed} (any other "
                "keyword of the environment goes in env_kwargs)"
            )
        super().__init__(name, {**default_config(key), **copy.deepcopy(dict(config or {}))})
        self.key = key
        self.env_id = TASK_ENV_IDS[key]

    def env_kwargs(self) -> dict[str, Any]:
        """The keyword arguments of ``vdtn_marl.make(env_id, batch_size=B, ...)``, except the
        acting parts given by name (``rra_policy``, ``control``)."""
        config = dict(self.config)
        extra = dict(config.pop("env_kwargs", None) or {})
        config.pop("rra_policy", None)
        config.pop("control", None)
        clash = sorted(set(extra) & set(config))
        if clash:
            raise ConfigError(
                f"env_kwargs sets {clash}, which task {ENV_NAME}/{self.key} sets as its own keys"
            )
        return {**config, **extra}

    def make_env(self, num_envs: int, seed: int | None = None, device: str = "cpu"):
        """The batched environment of ``num_envs`` scenarios (what :meth:`get_env_fun`'s
        function returns)."""
        from vdtn_marl.policies import make_control_baseline, make_rra_baseline

        handed_over = {"return_state": True, "return_info": True, **self.env_kwargs()}
        env = make(self.env_id, batch_size=num_envs, seed=seed, device=device, **handed_over)
        if "rra_policy" in self.config:
            env.rra_policy = make_rra_baseline(self.config["rra_policy"], env.twin, seed)
        if "control" in self.config:
            env.control_module = make_control_baseline(self.config["control"], env.twin)
        return env

    # --- BenchMARL's TaskClass interface ---------------------------------------------------
    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None, device):
        return lambda: self.make_env(num_envs, seed, device)

    def supports_continuous_actions(self) -> bool:
        return self.key != "rra"

    def supports_discrete_actions(self) -> bool:
        return self.key == "rra"

    def max_steps(self, env) -> int:
        if "max_cycles" in self.config:
            return int(self.config["max_cycles"])
        return int(self.config["episode_intervals"]) * _subframes_per_interval(env)

    def has_render(self, env) -> bool:
        """Whether BenchMARL's evaluation video records this task: the control tasks (scenario
        0, one frame per control interval); ``vdtn/rra`` warns instead (BenchMARL asks at
        every evaluation, before it reads ``experiment.render``: once per process)."""
        if self.key in RENDERED_TASKS:
            return True
        warnings.warn(NO_VIDEO_WARNING, UserWarning, stacklevel=2)
        return False

    def group_map(self, env) -> dict[str, list[str]]:
        return env.group_map

    def observation_spec(self, env):
        """Each group's ``observation`` only (what the policies read)."""
        spec = env.full_observation_spec_unbatched.clone()
        for key in list(spec.keys()):
            if key not in self.group_map(env):
                del spec[key]  # "state": the critics' (state_spec)
        for group in self.group_map(env):
            for key in list(spec[group].keys()):
                if key != "observation":
                    del spec[group, key]
        return spec

    def info_spec(self, env):
        """Each group's ``info`` (None for an environment built without infos)."""
        from torchrl.data import Composite

        spec = env.full_observation_spec_unbatched
        groups = [g for g in self.group_map(env) if "info" in spec[g].keys()]
        if not groups:
            return None
        return Composite(
            {g: Composite(info=spec[g, "info"].clone(), shape=spec[g].shape) for g in groups}
        )

    def state_spec(self, env):
        """``"state"``, the twin's global state [3N] (None for an environment built
        without it)."""
        from torchrl.data import Composite

        spec = env.full_observation_spec_unbatched
        if "state" not in spec.keys():
            return None
        return Composite(state=spec["state"].clone())

    @staticmethod
    def log_info(batch) -> dict[str, float]:
        """For a group whose steps are subframes (``closes_interval`` in its infos): the mean of
        each interval metric over the steps that close an interval, where it is that
        interval's, under the key of BenchMARL's plain mean over steps (which it replaces)."""
        from vdtn_marl.envs.torchrl import RRA_SUBFRAME_INFO_KEYS

        logged = {}
        following = batch.get("next", None)
        for group, entries in following.items() if following is not None else ():
            info = entries.get("info", None) if hasattr(entries, "keys") else None
            if info is None or "closes_interval" not in info.keys():
                continue
            closing = info.get("closes_interval") > 0
            if not bool(closing.any()):
                continue
            of_subframe = RRA_SUBFRAME_INFO_KEYS if group == "rra" else ("closes_interval",)
            for key, value in info.items():
                if key not in of_subframe:
                    logged[f"collection/{group}/info/{key}"] = value[closing].float().mean().item()
        return logged

    def action_spec(self, env):
        return env.full_action_spec_unbatched.clone()

    def action_mask_spec(self, env):
        return None

    @staticmethod
    def env_name() -> str:
        return ENV_NAME


def _subframes_per_interval(env) -> int:
    base = getattr(env, "base_env", env)  # BenchMARL hands over a TransformedEnv
    return int(base.twin.subframes_per_interval)


class VDTNTask(Task):
    """The vdtn-marl tasks (an enum, as BenchMARL's ``VmasTask``); configs in
    ``conf/task/vdtn/<name>.yaml`` of this package."""

    CONTROL = None
    CONTROL_IMPAIRED = None
    RRA = None

    @staticmethod
    def associated_class():
        return VDTNClass

    def get_from_yaml(self, path: str | None = None):
        """The task with the config of ``path`` (default: this package's YAML of the task)."""
        return super().get_from_yaml(str(task_yaml(self.name.lower())) if path is None else path)

    @classmethod
    def from_env_id(cls, env_id: str) -> VDTNTask:
        """The task that runs the registered environment ``env_id``; a :class:`ConfigError`
        for an environment with two clocks and for one no task runs."""
        env_spec = spec(env_id)
        if len(env_spec.clocks) > 1:
            raise refusal(env_id)
        for name, task_env_id in TASK_ENV_IDS.items():
            if task_env_id == env_id:
                return cls[name.upper()]
        raise ConfigError(f"no BenchMARL task runs {env_id!r}; tasks: {_single_clock_tasks()}")


@dataclass
class _RefusedConfig:
    """The (empty) schema of a refused name, so that BenchMARL reaches the refusal silently."""


class _RefusedTask:
    """What ``task_config_registry["vdtn/joint"]`` holds: asking for it raises."""

    def __init__(self, what: str):
        self.what = what

    def get_task(self, config=None):
        raise refusal(self.what)

    get_from_yaml = get_task


REFUSED = {"joint": "vdtn/vdtn-joint-v1 (task vdtn/joint)"}
"""Names under ``task=vdtn/`` that are refused, with what they would have run."""


def _register() -> None:
    from hydra.core.config_store import ConfigStore
    from omegaconf import OmegaConf

    if VDTNTask not in _environments.tasks:
        _environments.tasks.append(VDTNTask)
    for task in VDTNTask:
        _environments.task_config_registry[f"{ENV_NAME}/{task.name.lower()}"] = task
    for name, what in REFUSED.items():
        _environments.task_config_registry[f"{ENV_NAME}/{name}"] = _RefusedTask(what)

    package = types.ModuleType(f"benchmarl.environments.{ENV_NAME}")
    package.__path__ = []  # a namespace for the schema modules below
    sys.modules.setdefault(package.__name__, package)
    store = ConfigStore.instance()
    for name, schema in TASK_CONFIGS.items():
        module = types.ModuleType(f"{package.__name__}.{name}")
        module.TaskConfig = schema
        sys.modules.setdefault(module.__name__, module)
        store.store(name=f"{ENV_NAME}_{name}_config", group="task", node=schema)
        store.store(name=name, group=f"task/{ENV_NAME}", node=OmegaConf.load(task_yaml(name)))
        _environments._task_class_registry[f"{ENV_NAME}_{name}"] = schema
    for name in REFUSED:
        module = types.ModuleType(f"{package.__name__}.{name}")
        module.TaskConfig = _RefusedConfig
        sys.modules.setdefault(module.__name__, module)
        store.store(name=name, group=f"task/{ENV_NAME}", node={})


_register()


def run() -> None:
    """BenchMARL's ``benchmarl/run.py`` (its Hydra app: configs from BenchMARL's ``conf/`` and
    the ``vdtn`` tasks of this package), with the command line of this process."""
    from benchmarl.run import hydra_experiment

    hydra_experiment()


__all__ = [
    "CONF_DIR",
    "ENV_NAME",
    "TASK_CONFIGS",
    "TASK_ENV_IDS",
    "VDTNClass",
    "VDTNTask",
    "default_config",
    "refusal",
    "run",
    "task_yaml",
]
