"""The command line's pre-pass: compose and validate every job before Hydra writes anything.

:func:`prevalidate` composes each job's config with Hydra's compose API (a ``-m`` sweep is expanded
as Hydra's basic sweeper does), converts it to a validated
:class:`~vdtn_marl.experiment.config.RunConfig` (:func:`to_run_config`: ranges, device, checkpoint)
or checks a benchmark (:func:`validate_bench`), and checks that the job's folder holds no run unless
``resume=true`` continues it. :func:`eval_overrides` recomposes the config of the run that wrote an
``eval`` checkpoint. Every problem is a :class:`~vdtn_marl.cli.errors.CLIError`.
"""

import argparse
import importlib
import importlib.util
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from vdtn_marl.cli.errors import CLIError, translate
from vdtn_marl.cli.help import EVAL_FRESH_KEYS, EVAL_OWN_KEYS, group_options, read_conf_yaml
from vdtn_marl.experiment.compose import (
    CONFIG_PACKAGE,
    checkpoint_file,
    checkpoint_problem,
    compose_config,
    job_config,
    to_run_config,
)

# Commands whose config is composed by Hydra, and the primary config of each.
HYDRA_COMMANDS = {"train": "config", "jocc": "config", "eval": "config", "bench": "bench"}


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
    "hydra_plugins.hydra_ray_launcher": (
        "pip install 'vdtn-marl[ray]', then pip install --no-deps 'hydra-ray-launcher==1.2.2' "
        "(docs/cli.md, section Ray)"
    ),
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


def _validate_bench(data: dict, check_runs: bool = True) -> None:
    from vdtn_marl import leaderboard
    from vdtn_marl.experiment import config

    bench_cfg = leaderboard.bench_config(data)
    config.validate_benchmark(bench_cfg)
    config.validate_device(bench_cfg.device)
    b = bench_cfg.benchmark
    _require_option("benchmark.experiment", b.experiment, "experiment")
    for scenario in b.scenarios:
        _require_option("benchmark.scenarios", scenario, "scenario")
    if not check_runs:
        return
    # Every scenario × method (and submission) must compose into a valid run (seeds only change
    # `seed`), and the methods of a scenario must share its held-out evaluation scenarios.
    composed = {}
    b = leaderboard.with_submissions(bench_cfg).benchmark
    for scenario in b.scenarios:
        for method in b.methods:
            overrides = [
                *leaderboard.cell_overrides(b, scenario, method),
                f"device={bench_cfg.device}",
            ]
            where = "submissions" if method in bench_cfg.submissions else "benchmark.methods"
            try:
                data = job_config(compose_config("config", overrides))
                to_run_config(data)
            except Exception as exc:
                raise CLIError(
                    f"{where}.{method}={list(b.methods[method])} on scenario "
                    f"{scenario}: {translate(exc, 'config', overrides)}"
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


def _check_run_dir(command: str, run_cfg: Any, data: dict, cfg: Any, job_num: int | None) -> Path:
    """A job never overwrites a run: its folder (``hydra.run.dir``, or for job ``job_num`` of a
    sweep ``hydra.sweep.dir/hydra.sweep.subdir``) must not be in use by a live run, and must
    hold none unless ``resume=true`` continues it (``train``/``jocc``; the config must then be
    the run's). Returns the job's folder."""
    from omegaconf import open_dict, read_write

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
    check_not_running(key, folder, job_dir, where)
    if run_cfg.resume and command != "eval":
        if job_num is None:
            _check_resume(run_cfg, data, cfg.hydra)
        return job_dir
    check_fresh(command, key, folder, job_dir, where)
    return job_dir


def check_not_running(key: str, folder: Path, job_dir: Path, where: str = "") -> None:
    """:class:`CLIError` if a live run holds ``job_dir``'s lock
    (:func:`~vdtn_marl.io.files.run_lock`)."""
    from vdtn_marl.io.files import lock_holder

    holder = lock_holder(job_dir)
    if holder is not None:
        raise CLIError(
            f"{key}={folder} is in use by a run still running{where} (pid {holder}); allowed: "
            f"another {key}, or resume=true once that run has ended"
        )


def check_fresh(command: str, key: str, folder: Path, job_dir: Path, where: str = "") -> None:
    """:class:`CLIError` if ``job_dir`` already holds a run (a job without ``resume=true``)."""
    from vdtn_marl.io.files import run_outputs

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

    from vdtn_marl.io.files import CONFIG_FILE
    from vdtn_marl.reporting.tables import flatten

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
    free = {"resume", "progress", "device", "warm_start_cache"}  # none changes a result
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

    from vdtn_marl.errors import ConfigError
    from vdtn_marl.experiment.compose import register_configs

    register_configs()
    with initialize_config_module(config_module=CONFIG_PACKAGE, version_base="1.3"):
        parser = OverridesParser.create(config_loader=GlobalHydra.instance().config_loader())
        try:
            parsed = parser.parse_overrides(overrides)
        except Exception as exc:
            raise CLIError(translate(exc, "config", overrides)) from exc
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
    from vdtn_marl.errors import ConfigError

    path = checkpoint_file(checkpoint, required=True)
    try:
        config = load_checkpoint(path).get("config")
    except CheckpointError as exc:
        raise ConfigError(checkpoint_problem(path, exc)) from exc
    return config if isinstance(config, dict) else None


def _run_overrides(saved: dict, parsed: Sequence[Any], extra: Sequence[str]) -> list[str]:
    """Overrides reproducing ``saved`` (a run's config) but for the keys ``parsed`` sets."""
    from vdtn_marl.reporting.tables import flatten

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
        return (
            top not in EVAL_FRESH_KEYS
            and key not in EVAL_OWN_KEYS
            and not any(key == k or key.startswith(k if k.endswith(".") else f"{k}.") for k in keys)
        )

    choices = [
        f"{group}={saved[group]['name']}"
        for group in _RUN_GROUPS
        if group not in {o.key_or_group for o in groups}
        and isinstance(saved.get(group), dict)
        and saved[group].get("name") in group_options(group)
    ]
    base = flatten(job_config(compose_config("config", [*choices, *extra])))
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


def prevalidate(
    command: str, hargs: argparse.Namespace, overrides: list[str]
) -> tuple[Path, bool] | None:
    """Compose and validate every job of the command line; raise :class:`CLIError`. Returns
    the folder of a single ``train``, ``jocc`` or ``eval`` run and whether the run continues
    one there (``resume=true``); None for a sweep, ``--cfg`` or ``bench``."""
    from hydra import initialize_config_module

    from vdtn_marl.experiment.compose import register_configs

    config_name = HYDRA_COMMANDS[command]
    register_configs()
    with initialize_config_module(config_module=CONFIG_PACKAGE, version_base="1.3"):
        try:
            jobs = _job_overrides(overrides, bool(hargs.multirun))
        except Exception as exc:
            raise CLIError(translate(exc, config_name, overrides)) from exc
        run = None
        for index, job in enumerate(jobs):
            shown = " ".join(o for o in job if not o.startswith(("hydra.", "hydra/")))
            where = f" (sweep job {index}: {shown})" if len(jobs) > 1 else ""
            try:
                cfg = compose_config(config_name, job)
            except Exception as exc:
                raise CLIError(f"{translate(exc, config_name, job)}{where}") from exc
            if index == 0 and hargs.multirun:
                _check_launcher(cfg.hydra)
            try:
                data = job_config(cfg)
                if config_name == "bench":
                    _validate_bench(data, check_runs=not hargs.cfg)
                else:
                    run_cfg = to_run_config(data, command)
                    if not hargs.cfg:
                        job_num = index if hargs.multirun else None
                        job_dir = _check_run_dir(command, run_cfg, data, cfg, job_num)
                        run = (job_dir, bool(run_cfg.resume) and command != "eval")
            except CLIError as exc:
                raise CLIError(f"{exc}{where}") from exc
            except Exception as exc:
                raise CLIError(f"{translate(exc, config_name, job)}{where}") from exc
    return None if hargs.multirun else run
