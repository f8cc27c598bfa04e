"""Hydra composition and validation of a job's config, used by the command line and the
leaderboard alike (so both check a run the same way, and neither imports the other).

:func:`hydra_compose` readies Hydra's compose API over the package's configs,
:func:`compose_config` + :func:`job_config` compose a job as plain data, :func:`to_run_config`
validates it into a :class:`~vdtn_marl.experiment.config.RunConfig` (ranges, device,
checkpoint), and :func:`translate` turns a composition or validation error into one line that
names the key, the value given and what is allowed (``KEY=VALUE ... allowed: ...``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import re
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

#: The package holding the Hydra configs (``vdtn_marl/conf``).
CONFIG_PACKAGE = "vdtn_marl.conf"

#: Hydra's warning about our ``conf/hydra/launcher/*.yaml``, which carry the names of the
#: launchers' own schemas: Hydra checks them against those schemas and warns on every
#: composition. Nothing for a user to act on, so it is not shown.
SCHEMA_WARNING = "(?s).*is validated against ConfigStore schema with the same name"


#: The resolver of the default run folder's name (``conf/config.yaml``: ``hydra.run.dir``).
RUN_STAMP_RESOLVER = "run_stamp"


def register_configs() -> None:
    """The schemas in Hydra's ConfigStore
    (:func:`vdtn_marl.experiment.config.register_configs`) and the resolver
    ``${run_stamp:}`` (:func:`vdtn_marl.io.files.run_stamp`) the configs use."""
    from omegaconf import OmegaConf

    from vdtn_marl.experiment import config
    from vdtn_marl.io.files import run_stamp

    config.register_configs()
    if not OmegaConf.has_resolver(RUN_STAMP_RESOLVER):
        OmegaConf.register_new_resolver(RUN_STAMP_RESOLVER, run_stamp)


@contextlib.contextmanager
def hydra_compose() -> Iterator[None]:
    """Hydra's compose API: inside a Hydra app it is ready; elsewhere initialise it here."""
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra

    if GlobalHydra.instance().is_initialized():
        yield
        return
    register_configs()
    with initialize_config_module(config_module=CONFIG_PACKAGE, version_base="1.3"):
        yield


def compose_config(config_name: str, overrides: list[str]) -> Any:
    import warnings

    from hydra import compose

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=SCHEMA_WARNING, category=UserWarning)
        return compose(config_name=config_name, overrides=overrides, return_hydra_config=True)


def job_config(cfg: Any) -> dict:
    """The composed config as plain data, without the ``hydra`` node."""
    from omegaconf import OmegaConf, open_dict

    if "hydra" in cfg:
        cfg = cfg.copy()
        with open_dict(cfg):
            del cfg["hydra"]
    return OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)


def to_run_config(data: dict, command: str = "jocc") -> Any:
    """Composed job config (plain data) -> validated :class:`RunConfig`: ranges, the device,
    and the checkpoint (a run directory stands for its last checkpoint, and
    ``data["checkpoint"]`` is updated to the file; ``eval`` without one scores fixed policies:
    :func:`~vdtn_marl.experiment.config.check_fixed_policies`)."""
    from vdtn_marl.experiment import config

    data["checkpoint"] = checkpoint_file(data.get("checkpoint"), required=False)
    run_cfg = config.validate(config.from_dict(data))
    config.validate_device(run_cfg.device)
    if run_cfg.checkpoint is not None:
        _check_checkpoint(run_cfg, command)
    elif run_cfg.control.pi_star is not None:  # a checkpoint's π* wins (eval, resume)
        data["control"]["pi_star"] = checkpoint_file(
            run_cfg.control.pi_star, required=False, key="control.pi_star"
        )
        run_cfg.control.pi_star = data["control"]["pi_star"]
        check_pi_star(run_cfg)
    elif command == "eval":
        config.check_fixed_policies(run_cfg)
    _build_user_policies(run_cfg)
    return run_cfg


def _build_user_policies(run_cfg: Any) -> None:
    """``rra=policy``, ``control=policy``: the policy is built and called once on an observation
    of the run's model here (:func:`~vdtn_marl.experiment.user_policy.probe_policy`), so that
    one that fails, is of the other task or for another number of agents, or returns what the
    run cannot use is one line before anything is written."""
    from vdtn_marl.experiment.user_policy import probe_policy

    for key, section in (("control.policy", run_cfg.control), ("rra.policy", run_cfg.rra)):
        if section.name == "policy":
            probe_policy(key, section.policy, run_cfg.twin_params(), run_cfg.seed)


def _check_checkpoint(run_cfg: Any, command: str) -> None:
    """The checkpoint fits the config's networks; for ``eval``, it holds a trained policy."""
    from vdtn_marl.algos.checkpoint import (
        CheckpointError,
        ShapeMismatch,
        load_checkpoint,
        untrained_policies,
    )
    from vdtn_marl.errors import ConfigError
    from vdtn_marl.experiment.config import to_dict

    name = f"checkpoint={run_cfg.checkpoint}"
    try:
        payload = load_checkpoint(run_cfg.checkpoint, to_dict(run_cfg))
    except ShapeMismatch as exc:
        raise ConfigError(
            f"{exc.key}={exc.given!r} does not fit {name}, whose networks were built with "
            f"{exc.key}={exc.saved!r}; allowed: {exc.key}={exc.saved!r}, the value of the "
            "checkpoint's run"
        ) from exc
    except CheckpointError as exc:
        raise ConfigError(checkpoint_problem(run_cfg.checkpoint, exc)) from exc
    if command == "eval":
        warnings, nothing_trained = untrained_policies(payload, to_dict(run_cfg))
        if nothing_trained:
            raise ConfigError(
                f"{name} holds no trained policy to evaluate ({'; '.join(warnings)}); allowed: "
                "a checkpoint whose run trained the policies that act"
            )


def checkpoint_problem(value: Any, exc: Exception) -> str:
    """A :class:`CheckpointError` as ``checkpoint=VALUE <problem>; allowed: ...``."""
    problem = str(exc)
    prefix = f"checkpoint {str(value)!r} "
    problem = problem[len(prefix) :] if problem.startswith(prefix) else f"cannot be used: {problem}"
    return f"checkpoint={value} {problem}; allowed: a checkpoint written by vdtn-marl"


def checkpoint_file(value: Any, required: bool, key: str = "checkpoint") -> Any:
    """The file a ``checkpoint`` (or other ``key``) value names (a run directory stands for
    its ``checkpoints/last.pt``); ``None`` when none is given and none is ``required``."""
    from vdtn_marl.errors import ConfigError
    from vdtn_marl.io.files import CHECKPOINT_DIR

    allowed = f"allowed: a run directory (with {CHECKPOINT_DIR}/last.pt) or a checkpoint file"
    if value is None:
        if required:
            raise ConfigError(f"{key}=None: eval needs the policies to evaluate; {allowed}")
        return None
    path = Path(str(value))
    if path.is_dir():
        if (path / CHECKPOINT_DIR / "last.pt").is_file():
            return str(path / CHECKPOINT_DIR / "last.pt")
        raise ConfigError(
            f"{key}={value} is a folder without {CHECKPOINT_DIR}/last.pt (no run saved a "
            f"checkpoint there); {allowed}"
        )
    if not path.is_file():
        raise ConfigError(f"{key}={value} does not exist; {allowed}")
    return str(path)


def check_pi_star(run_cfg: Any) -> None:
    """``control.pi_star``: a checkpoint holding a π* trained on this run's scenario, with
    networks this config builds."""
    from vdtn_marl.algos.checkpoint import SHAPE_KEYS, CheckpointError, load_checkpoint
    from vdtn_marl.errors import ConfigError
    from vdtn_marl.experiment.config import to_dict
    from vdtn_marl.reporting.tables import flatten

    name = f"control.pi_star={run_cfg.control.pi_star}"
    mine = to_dict(run_cfg)
    try:
        payload = load_checkpoint(run_cfg.control.pi_star)
    except CheckpointError as exc:
        raise ConfigError(
            f"{name} cannot be used ({exc}); allowed: a vdtn-marl checkpoint"
        ) from exc
    saved, given = flatten(payload.get("config", {})), flatten(mine)
    for key in SHAPE_KEYS:  # π* sees perfect observations: control.augmentation is π̃'s
        if not key.startswith("control.") and saved.get(key) != given.get(key):
            raise ConfigError(
                f"{key}={given.get(key)!r} does not fit {name}, whose π* was built with "
                f"{key}={saved.get(key)!r}; allowed: {key}={saved.get(key)!r}"
            )
    state = payload.get("trainers", {}).get("pi_star")
    position = payload.get("position", {})
    if state is None or not (state.get("iteration") or position.get("warm_start")):
        raise ConfigError(
            f"{name} holds no trained π* (no PPO iteration, no warm start); allowed: the "
            "checkpoint of a run that trained π* (vdtn-marl train task=control)"
        )
    theirs = flatten({"scenario": payload.get("config", {}).get("scenario", {})})
    ours = flatten({"scenario": mine["scenario"]})
    for key in sorted(set(theirs) | set(ours)):
        if theirs.get(key) != ours.get(key):
            raise ConfigError(
                f"{key}={ours.get(key)!r} but {name} trained π* with {key}={theirs.get(key)!r}; "
                "allowed: a π* trained on this run's scenario"
            )


def _one_line(text: str) -> str:
    return re.sub(r"\s+", " ", str(text)).strip()


def _override_values(overrides: Sequence[str]) -> dict[str, str]:
    values = {}
    for item in overrides:
        key, sep, value = item.partition("=")
        if sep:
            values[key.lstrip("+~")] = value
    return values


def _schema_field(root: type, path: str) -> tuple[type | None, str | None]:
    """(dataclass holding the last key of ``path``, the key's type as text) or (None, None)."""
    import typing

    cls: Any = root
    parts = path.split(".")
    for i, part in enumerate(parts):
        if not dataclasses.is_dataclass(cls):
            return None, None
        hints = typing.get_type_hints(cls)
        if part not in hints:
            return cls, None
        hint = hints[part]
        if i == len(parts) - 1:
            name = hint.__name__ if isinstance(hint, type) else str(hint).replace("typing.", "")
            return cls, name
        cls = hint
    return None, None


def _schema_root(config_name: str) -> type:
    from vdtn_marl.experiment import config

    return config.RunConfig if config_name == "config" else config.BenchConfig


def translate(exc: BaseException, config_name: str, overrides: Sequence[str]) -> str:
    """One line for a composition or validation error, naming key, value and what is allowed."""
    from hydra.errors import MissingConfigException, OverrideParseException
    from omegaconf.errors import ConfigKeyError, OmegaConfBaseException, ValidationError

    from vdtn_marl.errors import ConfigError

    values = _override_values(overrides)
    if isinstance(exc, ConfigError):
        match = re.match(r"unknown key '([\w.]+)'; known: (.*)", str(exc))
        if match:  # from_dict: a key added with +KEY=VALUE
            key = match.group(1)
            where = key.rpartition(".")[0] or "the root config"
            return (
                f"{key}={values.get(key, '?')} is not a known key; allowed keys of {where}: "
                f"{match.group(2)}"
            )
        return _scenario_key(str(exc), values)
    if isinstance(exc, OverrideParseException):
        return (
            f"{exc.override} cannot be parsed ({_one_line(exc.message).split(' See ')[0]}); "
            "allowed: KEY=VALUE, GROUP=OPTION, +KEY=VALUE, ~KEY, and for -m sweeps KEY=A,B,C "
            "(https://hydra.cc/docs/advanced/override_grammar/basic/)"
        )
    if isinstance(exc, MissingConfigException):
        missing = exc.missing_cfg_file or ""
        group, _, option = missing.rpartition("/")
        if group and exc.options is not None:
            return (
                f"{group}={option} is not a config of group {group!r}; allowed: "
                f"{', '.join(exc.options)}"
            )
        return _one_line(exc)
    cause: BaseException | None = exc
    while cause is not None and not isinstance(cause, OmegaConfBaseException):
        cause = cause.__cause__ or cause.__context__
    if isinstance(cause, OmegaConfBaseException):
        key = getattr(cause, "full_key", None) or ""
        value = values.get(key, getattr(cause, "value", None))
        parent, type_text = _schema_field(_schema_root(config_name), key) if key else (None, None)
        if isinstance(cause, ValidationError) and type_text:
            return f"{key}={value} has the wrong type; allowed: a value of type {type_text}"
        if isinstance(cause, ConfigKeyError | AttributeError) or "not in struct" in str(cause):
            if parent is not None and type_text is None:
                known = ", ".join(f.name for f in dataclasses.fields(parent))
                where = key.rpartition(".")[0] or "the root config"
                return f"{key}={value} is not a known key; allowed keys of {where}: {known}"
            if key.startswith("scenario.model."):
                return (
                    f"{key}={value} is not set by default; add a model parameter with a "
                    f"leading +: +{key}={value}; allowed: {', '.join(_model_parameters())}"
                )
            return f"{key}={value} is not in the config; add a new key with +{key}={value}"
        first = str(cause).splitlines()[0]
        return f"{key}={value}: {first}" if key else _one_line(first)
    message = _one_line(exc)
    match = re.search(r"Ambiguous value for argument '([^']+)'", message)
    if match:
        return (
            f"{match.group(1)} is a sweep; allowed without -m: one value per key (add -m, "
            "--multirun, to run one job per value)"
        )
    return message


def _model_parameters() -> list[str]:
    """Keys allowed under ``scenario.model`` (TwinParams keys the scenario does not set)."""
    from vdtn_marl.sim.params import PlatoonParams, RadioParams

    names = {f.name for cls in (PlatoonParams, RadioParams) for f in dataclasses.fields(cls)}
    return sorted(names - set(_SCENARIO_KEYS) - {"scenario_topology"})  # a scenario's own


_SCENARIO_KEYS = (
    "num_vehicles",
    "num_subchannels",
    "subchannel_bandwidth_hz",
    "cam_size_bits",
    "episode_intervals",
)


def _scenario_key(message: str, values: dict[str, str]) -> str:
    """The simulator's own errors name bare model keys; give them their config path."""
    match = re.match(r"(\w+)=", message)
    if match and match.group(1) in _SCENARIO_KEYS:
        return f"scenario.{message}"
    if match and match.group(1) in _model_parameters():
        return f"scenario.model.{message}"
    match = re.match(r"unknown model parameter '(\w+)'", message)
    if match:
        key = f"scenario.model.{match.group(1)}"
        return (
            f"{key}={values.get(key, '?')} is not a model parameter; allowed: "
            f"{', '.join(_model_parameters())}"
        )
    return message
