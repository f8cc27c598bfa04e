"""The ``vdtn-marl`` command: a Hydra app with one command word per entry point.

    vdtn-marl [-m] COMMAND [GROUP=OPTION ...] [KEY=VALUE ...] [HYDRA FLAGS]

``train``, ``jocc`` and ``eval`` compose ``conf/config.yaml`` (schema
:class:`vdtn_marl.experiment.config.RunConfig`) and call :mod:`vdtn_marl.experiment.api`;
``bench`` composes ``conf/bench.yaml`` (``bench summarize DIR`` tables a finished sweep);
``envs`` lists the registry; ``rollout`` forwards to :mod:`vdtn_marl.cli.rollout`.

How a Hydra command runs:

1. The command word is taken out of the arguments; Hydra's own argument parser reads the rest.
2. ``eval checkpoint=RUN``: the overrides that recompose the config of the checkpoint's run
   go before the user's (:func:`vdtn_marl.cli.prepass.eval_overrides`), so eval uses the
   run's config and the command line changes it.
3. Pre-pass (:mod:`vdtn_marl.cli.prepass`): every job's config is composed with Hydra's
   compose API (for ``-m``, one per combination of the sweep, expanded as Hydra's basic
   sweeper does), converted to a :class:`RunConfig`, and checked by
   :func:`vdtn_marl.experiment.config.validate` and
   :func:`vdtn_marl.experiment.config.validate_device`; the job's
   folder must not hold a run unless ``resume=true`` continues it. A bad config prints one
   line, ``error: KEY=VALUE ... allowed ...`` (:mod:`vdtn_marl.cli.errors`), and exits with
   code 2 before anything is written.
4. Then the real ``@hydra.main`` app runs with the same arguments (so ``-m``, launchers,
   ``--cfg``, ``--info`` behave as in any Hydra app). Each job writes ``config.yaml`` (the
   resolved config) to its run directory and calls the entry point, which writes
   ``metrics.csv``, ``checkpoints/`` and ``summary.json`` there, and logs its stages to
   ``<command>.log``. Ctrl-C prints the command that continues the run and exits with 130.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import importlib.util
import json
import logging
import os
import sys
import textwrap
import warnings
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback

from vdtn_marl import __version__
from vdtn_marl.cli.codes import EXIT_CONFIG_ERROR, EXIT_INTERRUPTED, INTERRUPTED_BEFORE_START
from vdtn_marl.cli.errors import CLIError
from vdtn_marl.cli.help import (
    COMMANDS,
    CONFIG_PACKAGE,
    PROG,
    command_help,
    top_help,
)
from vdtn_marl.cli.prepass import (
    HYDRA_COMMANDS,
    check_fresh,
    eval_overrides,
    job_config,
    prevalidate,
    to_run_config,
)
from vdtn_marl.envs.registration import EnvSpec, list_envs, spec
from vdtn_marl.experiment.compose import SCHEMA_WARNING

# Hydra flags that take a value (the value is never the command word).
_VALUE_FLAGS = {
    "--cfg", "-c", "--package", "-p", "--config-path", "-cp", "--config-name", "-cn",
    "--config-dir", "-cd", "--experimental-rerun", "--shell-completion", "-sc",
}  # fmt: skip
_INFO_CHOICES = {"all", "config", "defaults", "defaults-tree", "plugins", "searchpath"}


# Our conf/hydra/launcher/*.yaml files carry the names of the launchers' own schemas; Hydra
# then checks them against those schemas and warns about it on every composition (also in the
# launchers' worker processes, which import this module to run a job).
warnings.filterwarnings("ignore", message=SCHEMA_WARNING, category=UserWarning)


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
                    "api": s.api,
                    "batched": s.vector_entry_point is not None,
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
        rollout = importlib.import_module("vdtn_marl.cli.rollout")
    except ModuleNotFoundError as exc:
        if exc.name != "vdtn_marl.cli.rollout":
            raise
        print(
            f"{PROG}: the rollout module (vdtn_marl.cli.rollout) is not available",
            file=sys.stderr,
        )
        return 1
    rc = rollout.main(rest)
    return rc if isinstance(rc, int) else 0


# --- bench summarize -----------------------------------------------------------------------


def _cmd_summarize(argv: list[str]) -> int:
    from vdtn_marl.reporting import sweep, tables

    parser = argparse.ArgumentParser(
        prog=f"{PROG} bench summarize",
        description="Collect every job of a sweep into one table (CSV) and the κ1 Pareto plot.",
    )
    parser.add_argument("sweep_dir", help="a multirun directory (or any folder of run dirs)")
    parser.add_argument("--csv", help="table path (default: SWEEP_DIR/summary.csv)")
    parser.add_argument("--plot", help="plot path (default: SWEEP_DIR/pareto_kappa1.png)")
    parser.add_argument("--x", default=tables.CONTROL_COST, help="summary key on the x axis")
    parser.add_argument("--y", default=tables.V2I_THROUGHPUT, help="summary key on the y axis")
    args = parser.parse_args(argv)
    if not Path(args.sweep_dir).is_dir():
        print(f"error: {args.sweep_dir} is not a directory", file=sys.stderr)
        return EXIT_CONFIG_ERROR
    try:
        summary = sweep.summarize_sweep(args.sweep_dir, args.csv, args.plot, args.x, args.y)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    tables.print_table(summary.table, title=f"{len(summary.table)} job(s) in {args.sweep_dir}")
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


# --- the Hydra jobs --------------------------------------------------------------------------


def run_job(command: str, cfg: Any) -> dict:
    """One job inside Hydra: validate, write config.yaml, call the entry point, print results."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.types import RunMode
    from omegaconf import OmegaConf

    from vdtn_marl.algos.checkpoint import CheckpointError
    from vdtn_marl.errors import PolicyError, RunFileError, RunWriteError
    from vdtn_marl.experiment import api
    from vdtn_marl.experiment.reference import REFERENCE_WARNING, row_problems
    from vdtn_marl.io.files import CONFIG_FILE, atomic_write_text, run_lock
    from vdtn_marl.io.interrupts import check_interrupt, graceful_interrupts
    from vdtn_marl.io.log import keep_log_off_console
    from vdtn_marl.reporting.tables import print_summary

    run_dir = Path(HydraConfig.get().runtime.output_dir)
    try:  # Ctrl-C from here on stops at a safe point of the run (vdtn_marl.io.interrupts)
        with (
            graceful_interrupts(lambda: interrupted_message(command, run_dir)),
            run_lock(run_dir),  # before anything is written: a second launcher is refused
        ):
            data = job_config(cfg)
            run_cfg = to_run_config(data, command)
            keep_log_off_console(run_cfg.progress)
            atomic_write_text(run_dir / CONFIG_FILE, OmegaConf.to_yaml(OmegaConf.create(data)))
            entry: Callable[..., dict] = {
                "train": api.train, "jocc": api.jocc, "eval": api.evaluate,
            }[command]  # fmt: skip
            check_interrupt()
            summary = entry(run_cfg, run_dir)
    except KeyboardInterrupt:
        print(interrupted_message(command, run_dir), file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None
    except (RunFileError, CheckpointError) as exc:  # a run folder that cannot be continued
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_CONFIG_ERROR) from None
    except RunWriteError as exc:  # a full disk, say: every file is whole (io/files.py)
        hint = interrupted_message(command, run_dir).removeprefix("interrupted; ")
        print(f"error: {exc.strerror}; {hint}", file=sys.stderr)
        raise SystemExit(1) from None
    except PolicyError as exc:  # the user's policy failed during the run: it names the call
        hint = interrupted_message(command, run_dir).removeprefix("interrupted; ")
        print(f"error: {exc}; {hint}", file=sys.stderr)
        raise SystemExit(1) from None
    problems = row_problems(summary) if isinstance(summary, dict) else ""
    notes = summary.get("notes", []) if isinstance(summary, dict) else []  # eval without π*
    if HydraConfig.get().mode == RunMode.MULTIRUN:
        print(f"job {HydraConfig.get().job.num} done: {run_dir}")
        if problems:
            print(f"warning: job {HydraConfig.get().job.num}: {REFERENCE_WARNING}{problems}")
        for note in notes:
            print(f"note: job {HydraConfig.get().job.num}: {note}")
        return summary
    if isinstance(summary, dict) and summary:
        print_summary(summary, title=f"{command} summary")
    for note in notes:
        print(f"note: {note}")
    if problems:
        print(f"warning: {REFERENCE_WARNING}{problems}", file=sys.stderr)
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

    from vdtn_marl.io.files import CHECKPOINT_DIR

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

    from vdtn_marl import leaderboard
    from vdtn_marl.experiment import config
    from vdtn_marl.io.interrupts import graceful_interrupts
    from vdtn_marl.io.log import keep_log_off_console

    hydra_cfg = HydraConfig.get()
    bench_cfg = config.validate_benchmark(leaderboard.bench_config(job_config(cfg)))
    keep_log_off_console(bench_cfg.progress)
    multirun = hydra_cfg.mode == RunMode.MULTIRUN
    # a sweep's job: its own overrides, as one command would set them
    command = shlex.join([PROG, "bench", *hydra_cfg.overrides.task])
    again = f"complete cells are kept; run {command} again to continue"
    try:
        with graceful_interrupts(lambda: again):
            result = leaderboard.run_benchmark(bench_cfg, command=command)
    except leaderboard.LeaderboardError as exc:
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_CONFIG_ERROR) from None
    except KeyboardInterrupt:
        print(f"interrupted; {again}", file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None
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

    from vdtn_marl.experiment.compose import register_configs

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
    from vdtn_marl.io.interrupts import graceful_interrupts

    before = INTERRUPTED_BEFORE_START
    # From here Ctrl-C only sets a flag, read at safe points (vdtn_marl.io.interrupts): never inside
    # the imports and config checks below, where Python could swallow it or turn it into
    # another error.
    with graceful_interrupts(lambda: before):
        return _cmd_hydra_run(command, argv, hargs, searchpath, passthrough, before)


def _cmd_hydra_run(command, argv, hargs, searchpath, passthrough, before: str) -> int:
    from vdtn_marl.errors import RunFileError
    from vdtn_marl.io.files import new_run_stamp, run_lock
    from vdtn_marl.io.interrupts import check_interrupt

    new_run_stamp()  # the default run folder's name: one per launch (conf/config.yaml)
    run = None
    try:
        user = list(hargs.overrides)
        if command == "eval" and not passthrough:
            user = eval_overrides(user, searchpath)
        overrides = [*user, f"hydra.job.name={command}"]
        if not passthrough:
            run = prevalidate(command, hargs, [*overrides, *searchpath])
        check_interrupt()
    except CLIError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_CONFIG_ERROR
    except KeyboardInterrupt:
        print(before, file=sys.stderr)
        return EXIT_INTERRUPTED
    with contextlib.ExitStack() as stack:
        if run is not None:
            # Held from before Hydra writes .hydra/ and the job's log: a launcher that loses
            # the race for the folder touches nothing in it.
            run_dir, resume = run
            try:
                stack.enter_context(run_lock(run_dir))
                if not resume:  # free at the pre-pass; a launcher that won it may have ended
                    check_fresh(command, "hydra.run.dir", run_dir, run_dir)
            except (RunFileError, CLIError) as exc:
                print(f"error: {exc}", file=sys.stderr)
                return EXIT_CONFIG_ERROR
        return _launch_job(command, argv, hargs, overrides)


def _launch_job(command: str, argv: list[str], hargs: argparse.Namespace, overrides) -> int:
    try:
        # Flags first, then the overrides: the order Hydra's own parser accepts.
        return _launch(command, [*_flag_args(argv, list(hargs.overrides)), *overrides])
    except KeyboardInterrupt:  # outside a job's entry point (which says more; see run_job)
        print(
            "interrupted while Hydra started or ended the job, outside the run: run the command "
            "again (add resume=true if the run directory holds a checkpoint)",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED


def main(argv: Sequence[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    warnings.filterwarnings("ignore", message=SCHEMA_WARNING, category=UserWarning)
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


def bench_main(argv: Sequence[str] | None = None) -> int:
    """``vdtn-marl bench ARGS`` (for ``python -m vdtn_marl.leaderboard`` and
    ``benchmarks/leaderboard.py``)."""
    return main(["bench", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":
    raise SystemExit(main())
