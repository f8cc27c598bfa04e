"""Entry points of the training code, called by the CLI (``vdtn-marl train|jocc|eval``).

Each takes a :class:`~vdtn_marl.experiment.config.RunConfig` (validated here) and a run
directory, writes its outputs there atomically (``metrics.csv``, ``evaluation.csv``,
``checkpoints/``, ``summary.json``) and returns the summary dict it wrote. ``cfg.resume``
continues an interrupted run from its last checkpoint. Each logs (logger
``vdtn_marl.experiment.api``) one line when it starts and one with its wall time and main
metrics when it ends.

Scripts get one more: :func:`loaded_checkpoints` (the loops of trained checkpoints, for the
scripts in ``benchmarks/`` and ``studies/``).
"""

from __future__ import annotations

import logging
import tempfile
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

from vdtn_marl.algos.checkpoint import load_checkpoint, untrained_policies
from vdtn_marl.errors import CheckpointError, ConfigError
from vdtn_marl.experiment.config import RunConfig, check_fixed_policies, to_dict, validate
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import SUMMARY_FILE, atomic_write_json
from vdtn_marl.io.log import metrics_line
from vdtn_marl.reporting.tables import TABLE_METRICS

_log = logging.getLogger(__name__)


def _start(cfg: RunConfig, run_dir: str | Path, task: str) -> JointOptimisation:
    loop = JointOptimisation(validate(cfg), run_dir, task=task)
    if cfg.checkpoint and not (cfg.resume and loop.checkpoint_path.exists()):
        loop.load_policies(load_checkpoint(cfg.checkpoint, to_dict(cfg)))
    return loop


def _run(cfg: RunConfig, run_dir: str | Path, task: str) -> dict:
    """Run (or continue) ``task`` in ``run_dir``, logging its start and end."""
    began = time.perf_counter()
    loop = _start(cfg, run_dir, task)
    continues = cfg.resume and loop.checkpoint_path.exists()
    _log.info(
        "%s seed=%d in %s: scenario=%s algo=%s control=%s rra=%s experiment=%s, "
        "%d JOCC iteration(s) (%s)",
        task, cfg.seed, Path(run_dir).resolve(), cfg.scenario.name, cfg.algo.name,
        cfg.control.name, cfg.rra.name, cfg.experiment.name, cfg.experiment.jocc_iterations,
        f"continuing from {loop.checkpoint_path}" if continues else "from the start",
    )  # fmt: skip
    summary = loop.run()
    _log.info(
        "%s done in %.1f s: %s", task, time.perf_counter() - began,
        metrics_line(summary, TABLE_METRICS),
    )  # fmt: skip
    return summary


def train(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Train one group (``cfg.task``): ``control`` trains π* on perfect observations;
    ``control_impaired`` trains π* and then π̃ under the configured RRA policy; ``rra`` trains
    π* (for v*) and then the RRA agents with π̃ (or the control baseline) as control module.
    ``cfg.checkpoint`` starts from the policies of an earlier run."""
    return _run(cfg, run_dir, cfg.task)


def jocc(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Run ``cfg.experiment.jocc_iterations`` iterations of joint optimisation (JOCC)."""
    return _run(cfg, run_dir, "jocc")


def evaluate(cfg: RunConfig, run_dir: str | Path) -> dict:
    """Evaluate the policies in ``cfg.checkpoint`` on the held-out scenarios, as the
    checkpoint's run evaluated them: a ``task=control`` checkpoint scores π* on perfect
    observations (against CACC); any other scores the acting system, control and RRA as
    configured (learned policies from the checkpoint, baselines by name).

    The learned policies that act but were never trained are named in ``summary["warnings"]``
    (and logged); a checkpoint none of whose acting policies was trained is refused
    (:class:`ConfigError`).

    Without ``cfg.checkpoint``, fixed policies (a control baseline or ``control=policy`` with an
    RRA baseline or ``rra=policy``) are scored on impaired observations: with no trained π*
    there is no EVoI and no IVoI (``evoi`` and ``ivoi_sum`` are None in the summary, and
    ``notes`` says why); learned ones are refused (:class:`ConfigError`)."""
    if not cfg.checkpoint:
        return _evaluate_fixed(cfg, run_dir)
    began = time.perf_counter()
    payload = load_checkpoint(cfg.checkpoint, to_dict(cfg))
    warnings, nothing_trained = untrained_policies(payload, to_dict(cfg))
    if nothing_trained:
        raise ConfigError(
            f"checkpoint={cfg.checkpoint} holds no trained policy to evaluate: "
            + "; ".join(warnings)
        )
    task = payload.get("task") or "jocc"
    _log.info(
        "eval of %s (task=%s) in %s: %d episode(s) of %d interval(s), seed=%d",
        cfg.checkpoint, task, Path(run_dir).resolve(), cfg.experiment.eval_episodes,
        cfg.experiment.eval_intervals, cfg.seed,
    )  # fmt: skip
    for warning in warnings:
        _log.warning(warning)
    loop = JointOptimisation(validate(cfg), run_dir, task=task)
    loop.load_policies(payload)
    loop.position["iteration"] = int(payload["position"]["iteration"])
    # the reference comparators its run scored (π*'s start among them), where the scenarios
    # are the same (JointOptimisation.reference_memo)
    loop.position["reference"] = payload["position"].get("reference")
    row = loop.evaluate()
    summary = loop.summary(row["eval_seconds"], resumed=False)
    summary["checkpoint"] = str(Path(cfg.checkpoint).resolve())
    summary["checkpoint_task"] = task
    summary["task"] = "eval"
    summary["warnings"] = warnings
    return _write_eval(loop, summary, began)


#: ``notes`` of an ``eval`` of fixed policies (one line, also printed under its table).
NO_PI_STAR_NOTE = (
    "no trained π* (eval without a checkpoint): EVoI and IVoI are not computed; the "
    "metrics are those of the fixed policies"
)


def _evaluate_fixed(cfg: RunConfig, run_dir: str | Path) -> dict:
    """``eval`` without a checkpoint: the fixed policies of ``cfg`` on the held-out
    scenarios, without π* (see :func:`evaluate`)."""
    check_fixed_policies(validate(cfg))
    began = time.perf_counter()
    _log.info(
        "eval of control=%s rra=%s (no checkpoint) in %s: %d episode(s) of %d interval(s), "
        "seed=%d", cfg.control.name, cfg.rra.name, Path(run_dir).resolve(),
        cfg.experiment.eval_episodes, cfg.experiment.eval_intervals, cfg.seed,
    )  # fmt: skip
    loop = JointOptimisation(cfg, run_dir, task="jocc")
    row = loop.evaluate(pi_star=False)
    summary = loop.summary(row["eval_seconds"], resumed=False)
    for key in ("kappa1", "kappa2"):  # the weights of an RRA reward that nothing learns from
        summary.pop(key, None)
    summary.update(checkpoint=None, task="eval", evoi=None, ivoi_sum=None, warnings=[])
    summary["notes"] = [NO_PI_STAR_NOTE]
    _log.info(NO_PI_STAR_NOTE)
    return _write_eval(loop, summary, began)


def _write_eval(loop: JointOptimisation, summary: dict, began: float) -> dict:
    """Write an ``eval``'s ``evaluation_raw.npz`` and ``summary.json``; log its end."""
    loop.write_raw_evaluation()
    atomic_write_json(loop.run_dir / SUMMARY_FILE, summary)
    loop.loggers.close()
    _log.info(
        "eval done in %.1f s: %s", time.perf_counter() - began,
        metrics_line(summary, TABLE_METRICS),
    )  # fmt: skip
    return summary


def loaded_checkpoints(
    paths: Sequence[str | Path], scratch_prefix: str, console: Any = None
) -> Iterator[tuple[str | Path, JointOptimisation]]:
    """Yield (path, JOCC loop with every trainer loaded) per checkpoint, one after the other;
    the loops write to a scratch directory removed at the end (nothing lands next to the
    checkpoints). A bad checkpoint stops the script with its error. ``console``: a rich
    console that names each checkpoint's run."""
    with tempfile.TemporaryDirectory(prefix=scratch_prefix) as scratch:
        for number, path in enumerate(paths):
            try:
                loop = JointOptimisation.from_checkpoint(
                    path, Path(scratch) / f"run{number}", needs_pi_tilde=True
                )
            except CheckpointError as err:
                raise SystemExit(str(err)) from err
            if console is not None:
                console.print(f"[bold]{path}[/]: {loop.cfg.scenario.name}, seed {loop.cfg.seed}")
            yield path, loop
