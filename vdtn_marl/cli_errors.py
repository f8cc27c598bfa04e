"""Errors of the ``vdtn-marl`` command line: :class:`CLIError` and :func:`translate`, which
turns a Hydra composition or config validation error into one line that names the key, the
value given and what is allowed (``error: KEY=VALUE ... allowed: ...``, exit code 2)."""

import dataclasses
import re
from collections.abc import Sequence
from typing import Any


class CLIError(Exception):
    """A bad command line or config: printed as one ``error: ...`` line, exit code 2."""


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
    from vdtn_marl import config

    return config.RunConfig if config_name == "config" else config.BenchConfig


def translate(exc: BaseException, config_name: str, overrides: Sequence[str]) -> str:
    """One line for a composition or validation error, naming key, value and what is allowed."""
    from hydra.errors import MissingConfigException, OverrideParseException
    from omegaconf.errors import ConfigKeyError, OmegaConfBaseException, ValidationError

    from vdtn_marl.config import ConfigError

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
    return sorted(names - set(_SCENARIO_KEYS))


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
