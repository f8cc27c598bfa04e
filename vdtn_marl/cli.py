"""The ``vdtn-marl`` command: a Hydra app with one command word per entry point.

    vdtn-marl [-m] COMMAND [GROUP=OPTION ...] [KEY=VALUE ...] [HYDRA FLAGS]

``train``, ``jocc`` and ``eval`` compose ``conf/config.yaml`` (schema
:class:`vdtn_marl.config.RunConfig`) and call :mod:`vdtn_marl.algos.api`; ``bench`` composes
``conf/bench.yaml`` (``bench summarize DIR`` tables a finished sweep); ``envs`` lists the
registry; ``rollout`` forwards to :mod:`vdtn_marl.rollout`.

How a Hydra command runs:

1. The command word is taken out of the arguments; Hydra's own argument parser reads the rest.
2. ``eval checkpoint=RUN``: the overrides that recompose the config of the checkpoint's run
   go before the user's (:func:`eval_overrides`), so eval uses the run's config and the
   command line changes it.
3. Pre-pass: every job's config is composed with Hydra's compose API (for ``-m``, one per
   combination of the sweep, expanded as Hydra's basic sweeper does), converted to a
   :class:`RunConfig`, and checked by :func:`vdtn_marl.config.validate` and
   :func:`vdtn_marl.config.validate_device`; the job's folder must not hold a run unless
   ``resume=true`` continues it. A bad config prints one line,
   ``error: KEY=VALUE ... allowed ...``, and exits with code 2 before anything is written.
4. Then the real ``@hydra.main`` app runs with the same arguments (so ``-m``, launchers,
   ``--cfg``, ``--info`` behave as in any Hydra app). Each job writes ``config.yaml`` (the
   resolved config) to its run directory and calls the entry point, which writes
   ``metrics.csv``, ``checkpoints/`` and ``summary.json`` there, and logs its stages to
   ``<command>.log``. Ctrl-C prints the command that continues the run and exits with 130.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib
import importlib.util
import json
import logging
import os
import re
import sys
import textwrap
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback

from vdtn_marl import __version__
from vdtn_marl.cli_help import (
    COMMANDS,
    CONFIG_PACKAGE,
    EVAL_FRESH_KEYS,
    PROG,
    command_help,
    group_options,
    read_conf_yaml,
    top_help,
)
from vdtn_marl.registry import EnvSpec, list_envs, spec

EXIT_CONFIG_ERROR = 2
EXIT_INTERRUPTED = 130  # the shell's code for Ctrl-C (128 + SIGINT)
# Commands whose config is composed by Hydra, and the primary config of each.
HYDRA_COMMANDS = {"train": "config", "jocc": "config", "eval": "config", "bench": "bench"}

# Hydra flags that take a value (the value is never the command word).
_VALUE_FLAGS = {
    "--cfg", "-c", "--package", "-p", "--config-path", "-cp", "--config-name", "-cn",
    "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc",
}  # fmt: skip
_INFO_CHOICES = {"all", "config", "defaults", "defaults-tree", "plugins", "searchpath"}
_SCHEMA_WARNING = "(?s).*is validated against ConfigStore schema with the same name"


# Our conf/hydra/launcher/*.yaml files carry the names of the launchers' own schemas; Hydra
# then checks them against those schemas and warns about it on every composition (also in the
# launchers' worker processes, which import this module to run a job).
warnings.filterwarnings("ignore", message=_SCHEMA_WARNING, category=UserWarning)


class CLIError(Exception):
    """A bad command line or config: printed as one ``error: ...`` line, exit code 2."""


# --- envs ----------------------------------------------------------------------------------

_COLUMNS = ("id", "agents", "clocks", "description", "data source")
_WRAP = {"agents": 34, "description": 44, "data source": 30}


def _format_clocks(clocks: dict[str, int]) -> str:
    return ", ".join(f"{kind}={period}ms" for kind, period in clocks.items()) or "-"


def _row(env: EnvSpec) -> dict[str, str]:
    return {
        "id": env.id,
        "agents": env.agents or "-",
        "clocks": _format_clocks(env.clocks),
        "description": env.description or "-",
        "data source": env.data_source or "-",
    }


def format_env_table(specs: Sequence[EnvSpec]) -> str:
    """Plain-text table of the given specs; ids are never wrapped."""
    rows = [_row(s) for s in specs]
    cells = [
        {c: (textwrap.wrap(r[c], _WRAP[c]) if c in _WRAP else [r[c]]) or [""] for c in _COLUMNS}
        for r in rows
    ]
    widths = {
        c: max([len(c)] + [len(line) for cell in cells for line in cell[c]]) for c in _COLUMNS
    }

    def line(values: dict[str, str]) -> str:
        return "  ".join(values[c].ljust(widths[c]) for c in _COLUMNS).rstrip()

    out = [line({c: c for c in _COLUMNS}), line({c: "-" * widths[c] for c in _COLUMNS})]
    for cell in cells:
        height = max(len(v) for v in cell.values())
        for i in range(height):
            out.append(line({c: cell[c][i] if i < len(cell[c]) else "" for c in _COLUMNS}))
    return "\n".join(out)


def _cmd_envs(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(
        prog=f"{PROG} envs",
        description="List the registered environments: id, agents, clocks (agent kind -> "
        "period in 1 ms subframes), description and data source.",
    )
    parser.add_argument("--json", action="store_true", help="print the specs as JSON")
    args = parser.parse_args(argv)
    specs = [spec(env_id) for env_id in list_envs()]
    try:
        if args.json:
            payload = [
                {
                    **{k: v for k, v in _row(s).items() if k != "clocks"},
                    "clocks": s.clocks,
                    "kwargs": s.kwargs,
                    "entry_point": s.entry_point
                    if isinstance(s.entry_point, str)
                    else f"{s.entry_point.__module__}:{s.entry_point.__qualname__}",
                }
                for s in specs
            ]
            print(json.dumps(payload, indent=2, default=repr))
        else:
            print(format_env_table(specs))
    except BrokenPipeError:  # e.g. `vdtn-marl envs | head`
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


# --- rollout -------------------------------------------------------------------------------


def _cmd_rollout(rest: list[str]) -> int:
    try:
        rollout = importlib.import_module("vdtn_marl.rollout")
    except ModuleNotFoundError as exc:
        if exc.name != "vdtn_marl.rollout":
            raise
        print(f"{PROG}: the rollout module (vdtn_marl.rollout) is not available", file=sys.stderr)
        return 1
    rc = rollout.main(rest)
    return rc if isinstance(rc, int) else 0


# --- bench summarize -----------------------------------------------------------------------


def _cmd_summarize(argv: list[str]) -> int:
    from vdtn_marl import results

    parser = argparse.ArgumentParser(
        prog=f"{PROG} bench summarize",
        description="Collect every job of a sweep into one table (CSV) and the κ1 Pareto plot.",
    )
    parser.add_argument("sweep_dir", help="a multirun directory (or any folder of run dirs)")
    parser.add_argument("--csv", help="table path (default: SWEEP_DIR/summary.csv)")
    parser.add_argument("--plot", help="plot path (default: SWEEP_DIR/pareto_kappa1.png)")
    parser.add_argument("--x", default=results.CONTROL_COST, help="summary key on the x axis")
    parser.add_argument("--y", default=results.V2I_THROUGHPUT, help="summary key on the y axis")
    args = parser.parse_args(argv)
    if not Path(args.sweep_dir).is_dir():
        print(f"error: {args.sweep_dir} is not a directory", file=sys.stderr)
        return EXIT_CONFIG_ERROR
    try:
        summary = results.summarize_sweep(args.sweep_dir, args.csv, args.plot, args.x, args.y)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    results.print_table(summary.table, title=f"{len(summary.table)} job(s) in {args.sweep_dir}")
    for note in summary.notes:
        print(f"warning: {note}", file=sys.stderr)
    print(f"table: {summary.csv_path}")
    if summary.plot_path is not None:
        print(f"plot:  {summary.plot_path}")
    return 0


# --- argument handling ---------------------------------------------------------------------


def split_command(argv: Sequence[str]) -> tuple[str | None, list[str]]:
    """Find the command word (the first bare word not a flag's value); return it and the rest."""
    skip = False
    for i, arg in enumerate(argv):
        if skip:
            skip = False
            continue
        if arg in _VALUE_FLAGS:
            skip = True
        elif arg in ("--info", "-i"):
            skip = i + 1 < len(argv) and argv[i + 1] in _INFO_CHOICES
        elif not arg.startswith("-") and "=" not in arg:
            return arg, [*argv[:i], *argv[i + 1 :]]
    return None, list(argv)


def _usage_error(message: str) -> None:
    print(f"usage: {PROG} [-m] COMMAND [OVERRIDES...]   ({PROG} --help)", file=sys.stderr)
    print(f"{PROG}: error: {message}", file=sys.stderr)
    raise SystemExit(EXIT_CONFIG_ERROR)


def _hydra_args(argv: list[str]) -> argparse.Namespace:
    from hydra._internal.utils import get_args_parser

    parser = get_args_parser()
    parser.prog = PROG
    # Intermixed: flags may stand between overrides (`jocc a=1 --cfg job b=2`).
    return parser.parse_intermixed_args(argv)


def _flag_args(argv: list[str], overrides: list[str]) -> list[str]:
    """``argv`` without the overrides (the positionals Hydra's parser collected), in order."""
    rest, pending = [], list(overrides)
    for arg in argv:
        if pending and arg == pending[0]:
            pending.pop(0)
        else:
            rest.append(arg)
    return rest


# --- pre-pass: compose and validate every job before Hydra writes anything ------------------


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


def _translate(exc: BaseException, config_name: str, overrides: Sequence[str]) -> str:
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


def _job_overrides(overrides: list[str], multirun: bool) -> list[list[str]]:
    """The overrides of every job: a sweep is expanded as Hydra's basic sweeper does."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser = OverridesParser.create(config_loader=GlobalHydra.instance().config_loader())
    parsed = parser.parse_overrides(overrides)
    if not multirun or not any(o.is_sweep_override() for o in parsed):
        return [overrides]
    sweeper = _choice_of(overrides, "hydra/sweeper")
    if sweeper not in (None, "basic"):
        # Another sweeper chooses values itself: check the config with its sweeps left out.
        return [[o.input_line for o in parsed if not o.is_sweep_override()]]
    return BasicSweeper.split_arguments(parsed, None)[0]


def _choice_of(overrides: Sequence[str], group: str) -> str | None:
    for item in overrides:
        if item.startswith(f"{group}="):
            return item.split("=", 1)[1]
    return None


# Launcher options of conf/hydra/launcher (and the plugins' own): the plugin each needs, and
# how to install it.
_LAUNCHERS = {
    "basic": None,
    "joblib": "hydra_plugins.hydra_joblib_launcher",
    "submitit_local": "hydra_plugins.hydra_submitit_launcher",
    "submitit_slurm": "hydra_plugins.hydra_submitit_launcher",
    "ray": "hydra_plugins.hydra_ray_launcher",
}
_LAUNCHER_PLUGINS = {
    "hydra_plugins.hydra_joblib_launcher": "hydra-joblib-launcher (pip install vdtn-marl)",
    "hydra_plugins.hydra_submitit_launcher": "pip install 'vdtn-marl[slurm]'",
    "hydra_plugins.hydra_ray_launcher": "see the README, section Command line > Ray",
}


def _installed(package: str) -> bool:
    try:
        return importlib.util.find_spec(package) is not None
    except (ImportError, ValueError):
        return False


def usable_launchers() -> list[str]:
    """The ``hydra/launcher`` options whose plugin is installed here."""
    return [name for name, plugin in _LAUNCHERS.items() if plugin is None or _installed(plugin)]


def _check_launcher(hydra_cfg: Any) -> None:
    target = str(hydra_cfg.launcher.get("_target_", ""))
    module = target.rpartition(".")[0]
    package = ".".join(module.split(".")[:2])
    if not _installed(package):
        choice = hydra_cfg.runtime.choices.get("hydra/launcher")
        hint = _LAUNCHER_PLUGINS.get(package, f"install the package that provides {target}")
        raise CLIError(
            f"hydra/launcher={choice} needs the plugin {package}, which is not installed; "
            f"{hint}; allowed here: {', '.join(usable_launchers())}"
        )


def _compose(config_name: str, overrides: list[str]) -> Any:
    from hydra import compose

    return compose(config_name=config_name, overrides=overrides, return_hydra_config=True)


def _job_config(cfg: Any) -> dict:
    """The composed config as plain data, without the ``hydra`` node."""
    from omegaconf import OmegaConf, open_dict

    if "hydra" in cfg:
        cfg = cfg.copy()
        with open_dict(cfg):
            del cfg["hydra"]
    return OmegaConf.to_container(cfg, resolve=True, throw_on_missing=True)


def to_run_config(data: dict, command: str = "jocc") -> Any:
    """Composed job config (plain data) -> validated :class:`RunConfig`: ranges, the device,
    and the checkpoint (required by ``eval``; a run directory stands for its last checkpoint,
    and ``data["checkpoint"]`` is updated to the file)."""
    from vdtn_marl import config

    data["checkpoint"] = _checkpoint_file(data.get("checkpoint"), required=command == "eval")
    run_cfg = config.validate(config.from_dict(data))
    config.validate_device(run_cfg.device)
    if run_cfg.checkpoint is not None:
        _check_checkpoint(run_cfg, command)
    return run_cfg


def _check_checkpoint(run_cfg: Any, command: str) -> None:
    """The checkpoint fits the config's networks; for ``eval``, it holds a trained policy."""
    from vdtn_marl.algos.checkpoint import (
        CheckpointError,
        ShapeMismatch,
        load_checkpoint,
        untrained_policies,
    )
    from vdtn_marl.config import ConfigError, to_dict

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
        raise ConfigError(_checkpoint_problem(run_cfg.checkpoint, exc)) from exc
    if command == "eval":
        warnings, nothing_trained = untrained_policies(payload, to_dict(run_cfg))
        if nothing_trained:
            raise ConfigError(
                f"{name} holds no trained policy to evaluate ({'; '.join(warnings)}); allowed: "
                "a checkpoint whose run trained the policies that act"
            )


def _checkpoint_problem(value: Any, exc: Exception) -> str:
    """A :class:`CheckpointError` as ``checkpoint=VALUE <problem>; allowed: ...``."""
    problem = str(exc)
    prefix = f"checkpoint {str(value)!r} "
    problem = problem[len(prefix) :] if problem.startswith(prefix) else f"cannot be used: {problem}"
    return f"checkpoint={value} {problem}; allowed: a checkpoint written by vdtn-marl"


def _checkpoint_file(value: Any, required: bool) -> Any:
    from vdtn_marl.config import ConfigError
    from vdtn_marl.runs import CHECKPOINT_DIR

    allowed = f"allowed: a run directory (with {CHECKPOINT_DIR}/last.pt) or a checkpoint file"
    if value is None:
        if required:
            raise ConfigError(f"checkpoint=None: eval needs the policies to evaluate; {allowed}")
        return None
    path = Path(str(value))
    if path.is_dir():
        if (path / CHECKPOINT_DIR / "last.pt").is_file():
            return str(path / CHECKPOINT_DIR / "last.pt")
        raise ConfigError(
            f"checkpoint={value} is a folder without {CHECKPOINT_DIR}/last.pt (no run saved a "
            f"checkpoint there); {allowed}"
        )
    if not path.is_file():
        raise ConfigError(f"checkpoint={value} does not exist; {allowed}")
    return str(path)


def _validate_bench(data: dict, check_runs: bool = True) -> None:
    from vdtn_marl import config, leaderboard

    bench_cfg = leaderboard.bench_config(data)
    config.validate_benchmark(bench_cfg)
    config.validate_device(bench_cfg.device)
    b = bench_cfg.benchmark
    _require_option("benchmark.experiment", b.experiment, "experiment")
    for scenario in b.scenarios:
        _require_option("benchmark.scenarios", scenario, "scenario")
    if not check_runs:
        return
    # Every scenario × method must compose into a valid run (seeds only change `seed`), and
    # the methods of a scenario must share its held-out evaluation scenarios.
    composed = {}
    for scenario in b.scenarios:
        for method in b.methods:
            overrides = [
                *leaderboard.cell_overrides(b, scenario, method),
                f"device={bench_cfg.device}",
            ]
            try:
                data = _job_config(_compose("config", overrides))
                to_run_config(data)
            except Exception as exc:
                raise CLIError(
                    f"benchmark.methods.{method}={list(b.methods[method])} on scenario "
                    f"{scenario}: {_translate(exc, 'config', overrides)}"
                ) from exc
            composed[leaderboard.Cell(scenario, method, 0, tuple(overrides))] = data
    try:
        leaderboard.check_eval_pairing(composed)
        leaderboard.check_out_dir(bench_cfg)
    except leaderboard.LeaderboardError as exc:
        raise CLIError(str(exc)) from exc


def _require_option(key: str, value: str, group: str) -> None:
    options = group_options(group)
    if value not in options:
        raise CLIError(f"{key}={value} is not a config of group {group!r}; allowed: "
                       f"{', '.join(options)}")  # fmt: skip


def _check_run_dir(command: str, run_cfg: Any, data: dict, cfg: Any, job_num: int | None) -> None:
    """A job never overwrites a run: its folder (``hydra.run.dir``, or for job ``job_num`` of a
    sweep ``hydra.sweep.dir/hydra.sweep.subdir``) must hold none, unless ``resume=true``
    continues it (``train``/``jocc``; the config must then be the run's)."""
    from omegaconf import open_dict, read_write

    from vdtn_marl.runs import run_outputs

    if run_cfg.resume and command != "eval":
        if job_num is None:
            _check_resume(run_cfg, data, cfg.hydra)
        return
    if job_num is None:
        key, folder = "hydra.run.dir", Path(str(cfg.hydra.run.dir))
        job_dir, where = folder, ""
    else:
        cfg = cfg.copy()
        with read_write(cfg), open_dict(cfg):
            cfg.hydra.job.num = job_num
            key, folder = "hydra.sweep.dir", Path(str(cfg.hydra.sweep.dir))
            job_dir = folder / str(cfg.hydra.sweep.subdir)
        where = f" in {job_dir}"
    found = run_outputs(job_dir)
    if found:
        allowed = (
            f"another {key}"
            if command == "eval"
            else f"resume=true to continue it, or another {key}"
        )
        raise CLIError(
            f"{key}={folder} already holds a run{where} ({', '.join(found)}); allowed: {allowed}"
        )


def _check_resume(run_cfg: Any, data: dict, hydra_cfg: Any) -> None:
    """resume=true: the run directory must hold a run whose config matches this one."""
    import yaml

    from vdtn_marl.results import flatten
    from vdtn_marl.runs import CONFIG_FILE

    run_dir = Path(str(hydra_cfg.run.dir))
    old_file = run_dir / CONFIG_FILE
    if not old_file.is_file():
        raise CLIError(
            f"resume=true but hydra.run.dir={run_dir} holds no run ({CONFIG_FILE} is missing); "
            "allowed: hydra.run.dir=<the directory of the run to continue>"
        )
    with open(old_file, encoding="utf-8") as handle:
        old = flatten(yaml.safe_load(handle) or {})
    new = flatten(data)
    free = {"resume", "progress", "device"}
    # Keys the old run does not have (added to the schema since) are not compared.
    for key in sorted(set(old) & set(new)):
        if key not in free and old[key] != new[key]:
            raise CLIError(
                f"resume=true but {key}={new.get(key)!r} differs from the run's "
                f"{old_file} ({key}={old.get(key)!r}); allowed: the run's own value"
            )


# --- eval: the config of the checkpoint's run ----------------------------------------------

_RUN_GROUPS = ("scenario", "algo", "control", "rra", "experiment")


def eval_overrides(overrides: list[str], extra: Sequence[str] = ()) -> list[str]:
    """``eval checkpoint=RUN ...``: the overrides that recompose the config of the checkpoint's
    run (its group options, then every key whose value differs from theirs), followed by
    ``overrides``; entries of the run's that an override sets are left out, so the command
    line wins. ``extra``: overrides for composing only (``hydra.searchpath``).

    Without ``checkpoint=`` (or a checkpoint without a config) ``overrides`` is returned
    as it is. Raises :class:`CLIError` for a bad checkpoint or a sweep over checkpoints."""
    from hydra import initialize_config_module
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    from vdtn_marl.config import ConfigError, register_configs

    register_configs()
    with initialize_config_module(config_module=CONFIG_PACKAGE, version_base="1.3"):
        parser = OverridesParser.create(config_loader=GlobalHydra.instance().config_loader())
        try:
            parsed = parser.parse_overrides(overrides)
        except Exception as exc:
            raise CLIError(_translate(exc, "config", overrides)) from exc
        given = [o for o in parsed if o.key_or_group == "checkpoint" and not o.is_delete()]
        if not given:
            return overrides
        if given[-1].is_sweep_override():
            raise CLIError(
                f"{given[-1].input_line} is a sweep; eval takes the config of one run, so "
                "allowed: one checkpoint per command (run eval once per run)"
            )
        try:
            saved = _run_config_of(given[-1].value())
        except ConfigError as exc:
            raise CLIError(str(exc)) from exc
        if saved is None:
            return overrides
        return [*_run_overrides(saved, parsed, extra), *overrides]


def _run_config_of(checkpoint: Any) -> dict | None:
    """The config (nested dict) stored in ``checkpoint`` (a run directory or a file)."""
    from vdtn_marl.algos.checkpoint import CheckpointError, load_checkpoint
    from vdtn_marl.config import ConfigError

    path = _checkpoint_file(checkpoint, required=True)
    try:
        config = load_checkpoint(path).get("config")
    except CheckpointError as exc:
        raise ConfigError(_checkpoint_problem(path, exc)) from exc
    return config if isinstance(config, dict) else None


def _run_overrides(saved: dict, parsed: Sequence[Any], extra: Sequence[str]) -> list[str]:
    """Overrides reproducing ``saved`` (a run's config) but for the keys ``parsed`` sets."""
    from vdtn_marl.results import flatten

    groups = [o for o in parsed if o.key_or_group in _RUN_GROUPS]
    keys = [o.key_or_group for o in parsed if o.key_or_group not in _RUN_GROUPS]
    # A group option replaces the run's: the keys of the group, and for `experiment` (whose
    # options set keys across groups) the keys that the run's option and the new one set.
    keys += [f"{o.key_or_group}." for o in groups]
    for o in groups:
        if o.key_or_group == "experiment" and not o.is_delete():
            options = o.sweep_string_iterator() if o.is_sweep_override() else [str(o.value())]
            for option in [*options, saved.get("experiment", {}).get("name")]:
                data = read_conf_yaml("experiment", f"{option}.yaml")
                keys += list(flatten({k: v for k, v in data.items() if k != "defaults"}))

    def kept(key: str) -> bool:
        top = key.split(".")[0]
        return top not in EVAL_FRESH_KEYS and not any(
            key == k or key.startswith(k if k.endswith(".") else f"{k}.") for k in keys
        )

    choices = [
        f"{group}={saved[group]['name']}"
        for group in _RUN_GROUPS
        if group not in {o.key_or_group for o in groups}
        and isinstance(saved.get(group), dict)
        and saved[group].get("name") in group_options(group)
    ]
    base = flatten(_job_config(_compose("config", [*choices, *extra])))
    values = []
    for key, value in flatten(saved).items():
        if not kept(key):
            continue
        if key in base:
            if base[key] != value:
                values.append(f"{key}={_hydra_value(value)}")
        elif key.startswith("scenario.model."):  # a model parameter the scenario does not set
            values.append(f"+{key}={_hydra_value(value)}")
    return [*choices, *values]


def _hydra_value(value: Any) -> str:
    """``value`` in Hydra's override grammar (strings quoted)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ",".join(_hydra_value(v) for v in value) + "]"
    return "'" + str(value).replace("'", "\\'") + "'"


def prevalidate(command: str, hargs: argparse.Namespace, overrides: list[str]) -> None:
    """Compose and validate every job of the command line; raise :class:`CLIError`."""
    from hydra import initialize_config_module

    from vdtn_marl.config import register_configs

    config_name = HYDRA_COMMANDS[command]
    warnings.filterwarnings("ignore", message=_SCHEMA_WARNING, category=UserWarning)
    register_configs()
    with initialize_config_module(config_module=CONFIG_PACKAGE, version_base="1.3"):
        try:
            jobs = _job_overrides(overrides, bool(hargs.multirun))
        except Exception as exc:
            raise CLIError(_translate(exc, config_name, overrides)) from exc
        for index, job in enumerate(jobs):
            shown = " ".join(o for o in job if not o.startswith(("hydra.", "hydra/")))
            where = f" (sweep job {index}: {shown})" if len(jobs) > 1 else ""
            try:
                cfg = _compose(config_name, job)
            except Exception as exc:
                raise CLIError(f"{_translate(exc, config_name, job)}{where}") from exc
            if index == 0 and hargs.multirun:
                _check_launcher(cfg.hydra)
            try:
                data = _job_config(cfg)
                if config_name == "bench":
                    _validate_bench(data, check_runs=not hargs.cfg)
                else:
                    run_cfg = to_run_config(data, command)
                    if not hargs.cfg:
                        job_num = index if hargs.multirun else None
                        _check_run_dir(command, run_cfg, data, cfg, job_num)
            except CLIError as exc:
                raise CLIError(f"{exc}{where}") from exc
            except Exception as exc:
                raise CLIError(f"{_translate(exc, config_name, job)}{where}") from exc


# --- the Hydra jobs --------------------------------------------------------------------------


def run_job(command: str, cfg: Any) -> dict:
    """One job inside Hydra: validate, write config.yaml, call the entry point, print results."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from omegaconf import OmegaConf

    from vdtn_marl import results
    from vdtn_marl.algos import api
    from vdtn_marl.runs import CONFIG_FILE, atomic_write_text, keep_log_off_console

    data = _job_config(cfg)
    run_cfg = to_run_config(data, command)
    keep_log_off_console(run_cfg.progress)
    run_dir = Path(HydraConfig.get().runtime.output_dir)
    atomic_write_text(run_dir / CONFIG_FILE, OmegaConf.to_yaml(OmegaConf.create(data)))
    entry: Callable[..., dict] = {"train": api.train, "jocc": api.jocc, "eval": api.evaluate}[
        command
    ]
    try:
        summary = entry(run_cfg, run_dir)
    except KeyboardInterrupt:
        print(interrupted_message(command, run_dir), file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None
    if HydraConfig.get().mode == RunMode.MULTIRUN:
        print(f"job {HydraConfig.get().job.num} done: {run_dir}")
        return summary
    if isinstance(summary, dict) and summary:
        results.print_summary(summary, title=f"{command} summary")
    print(f"run directory: {run_dir}")
    plots = sorted(str(p) for p in run_dir.rglob("*.png"))
    if plots:
        print("plots: " + ", ".join(plots))
    return summary


def interrupted_message(command: str, run_dir: Path) -> str:
    """One line after Ctrl-C: the last checkpoint and the command that continues the run."""
    import shlex

    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from vdtn_marl.runs import CHECKPOINT_DIR

    hydra_cfg = HydraConfig.get()
    if command == "eval":
        return (
            f"interrupted; eval writes summary.json only when it ends, so {run_dir} holds no "
            "result: run the command again with another hydra.run.dir"
        )
    checkpoint = run_dir / CHECKPOINT_DIR / "last.pt"
    where = (
        f"the last checkpoint is {checkpoint}"
        if checkpoint.is_file()
        else "no checkpoint was written yet (the run starts over)"
    )
    if hydra_cfg.mode == RunMode.MULTIRUN:
        return (
            f"interrupted; {where}; continue the sweep with the same command plus resume=true "
            f"hydra.sweep.dir={hydra_cfg.sweep.dir}"
        )
    task = [o for o in hydra_cfg.overrides.task if not o.startswith(("resume=", "+resume="))]
    again = shlex.join([PROG, command, *task, "resume=true", f"hydra.run.dir={run_dir}"])
    return f"interrupted; {where}; continue with: {again}"


class SweepSummaryHint(Callback):
    """Hydra callback (conf/config.yaml): after a sweep, say how to table its results."""

    def on_multirun_end(self, config: Any, **kwargs: Any) -> None:
        sweep_dir = config.hydra.sweep.dir
        print(f"sweep done: {sweep_dir}")
        print(f"table and κ1 Pareto plot: {PROG} bench summarize {sweep_dir}")


def _train_job(cfg: Any) -> dict:
    return run_job("train", cfg)


def _jocc_job(cfg: Any) -> dict:
    return run_job("jocc", cfg)


def _eval_job(cfg: Any) -> dict:
    return run_job("eval", cfg)


def _bench_job(cfg: Any) -> None:
    """``vdtn-marl bench benchmark=NAME``: run or resume the grid, then write the report."""
    import shlex

    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode

    from vdtn_marl import config, leaderboard
    from vdtn_marl.runs import keep_log_off_console

    hydra_cfg = HydraConfig.get()
    bench_cfg = config.validate_benchmark(leaderboard.bench_config(_job_config(cfg)))
    keep_log_off_console(bench_cfg.progress)
    multirun = hydra_cfg.mode == RunMode.MULTIRUN
    # a sweep's job: its own overrides, as one command would set them
    command = shlex.join([PROG, "bench", *hydra_cfg.overrides.task])
    try:
        result = leaderboard.run_benchmark(bench_cfg, command=command)
    except leaderboard.LeaderboardError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_CONFIG_ERROR) from None
    total = len(leaderboard.plan(bench_cfg))
    print(
        f"{bench_cfg.benchmark.name} v{bench_cfg.benchmark.version}: {len(result.ran)} cell(s) "
        f"run now, {len(result.done) - len(result.ran)} already complete, "
        f"{len(result.failed)} failed, {len(result.pending)} of {total} still missing; "
        f"runs in {bench_cfg.out_dir}"
    )
    for cell, error in result.failed:
        print(f"failed: {cell.name}: {error}", file=sys.stderr)
    if result.report:
        if not multirun:
            leaderboard.print_leaderboard(result.report["json"])
        print(f"report: {result.report['markdown']}")
    if result.failed and not multirun:
        raise SystemExit(1)


_JOBS = {"train": _train_job, "jocc": _jocc_job, "eval": _eval_job, "bench": _bench_job}


def _launch(command: str, hydra_argv: list[str]) -> int:
    """Run the ``@hydra.main`` app of ``command`` with ``hydra_argv`` as its command line."""
    import hydra

    from vdtn_marl.config import register_configs

    register_configs()
    app = hydra.main(
        config_path=f"pkg://{CONFIG_PACKAGE}",
        config_name=HYDRA_COMMANDS[command],
        version_base="1.3",
    )(_JOBS[command])
    saved = sys.argv
    sys.argv = [PROG, *hydra_argv]
    try:
        with _logging_restored():
            app()
    finally:
        sys.argv = saved
    return 0


@contextlib.contextmanager
def _logging_restored() -> Iterator[None]:
    """Give the root logger its handlers and level back after Hydra's job logging (whose
    handlers write to the run's log file and to the stdout of the moment), closing Hydra's:
    a caller in the same process (tests, scripts) logs as before."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    try:
        yield
    finally:
        for handler in [h for h in root.handlers if h not in handlers]:
            root.removeHandler(handler)
            handler.close()
        for handler in handlers:
            if handler not in root.handlers:
                root.addHandler(handler)
        root.setLevel(level)


def _cmd_hydra(command: str, argv: list[str]) -> int:
    if command == "bench" and argv and argv[0] == "summarize":
        return _cmd_summarize(argv[1:])
    if any(a in ("-h", "--help") for a in argv):
        print(command_help(command))
        return 0
    hargs = _hydra_args(argv)
    if hargs.config_name or hargs.config_path:
        _usage_error("--config-name/--config-path are not supported; the command word picks "
                     "the config (use --config-dir DIR to add your own config files)")  # fmt: skip
    modes = [hargs.run, hargs.multirun, hargs.cfg, hargs.info, hargs.shell_completion]
    if sum(bool(m) for m in modes) > 1:
        _usage_error("only one of --run, -m/--multirun, --cfg, --info, --shell-completion")
    # --config-dir for the pre-pass, which composes through the compose API.
    searchpath = (
        [f"hydra.searchpath=[file://{Path(hargs.config_dir).resolve()}]"]
        if hargs.config_dir
        else []
    )
    passthrough = (
        hargs.hydra_help or hargs.info or hargs.shell_completion or hargs.experimental_rerun
    )
    try:
        user = list(hargs.overrides)
        if command == "eval" and not passthrough:
            user = eval_overrides(user, searchpath)
        overrides = [*user, f"hydra.job.name={command}"]
        if not passthrough:
            prevalidate(command, hargs, [*overrides, *searchpath])
    except CLIError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_CONFIG_ERROR
    except KeyboardInterrupt:
        print("interrupted before the run started; nothing was written", file=sys.stderr)
        return EXIT_INTERRUPTED
    try:
        # Flags first, then the overrides: the order Hydra's own parser accepts.
        return _launch(command, [*_flag_args(argv, list(hargs.overrides)), *overrides])
    except KeyboardInterrupt:  # outside a job's entry point (which says more; see run_job)
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    warnings.filterwarnings("ignore", message=_SCHEMA_WARNING, category=UserWarning)
    if args and args[0] == "rollout":  # forwards everything after it untouched
        return _cmd_rollout(args[1:])
    if args and args[0] == "--version":
        print(f"{PROG} {__version__}")
        return 0
    if args and args[0] in ("-h", "--help"):
        print(top_help())
        return 0
    command, rest = split_command(args)
    if command is None:
        _usage_error(f"a command is required ({', '.join(COMMANDS)})")
    if command not in COMMANDS:
        _usage_error(f"unknown command {command!r}; choose one of {', '.join(COMMANDS)}")
    if command == "envs":
        return _cmd_envs(rest)
    if command == "rollout":
        return _cmd_rollout(rest)
    return _cmd_hydra(command, rest)


if __name__ == "__main__":
    raise SystemExit(main())
