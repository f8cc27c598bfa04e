"""Helpers shared by the scripts in ``benchmarks/`` and ``studies/``: comma-separated option
lists that fail with a message naming the flag and the value, the provenance block of a results
JSON, means with their CIs, the description of a measured checkpoint's run and a console for tables.
(The loops of trained checkpoints come from
:func:`vdtn_marl.experiment.api.loaded_checkpoints`.)"""

from __future__ import annotations

import datetime as dt
import platform
import sys
from pathlib import Path

import torch
from rich.console import Console

from vdtn_marl import __version__
from vdtn_marl.io.files import script_command
from vdtn_marl.voi import mean_ci


def _parts(text: str) -> list[str]:
    return [part.strip() for part in text.split(",") if part.strip()]


def parse_names(
    flag: str, text: str, allowed: tuple[str, ...], allow_empty: bool = False
) -> list[str]:
    """Names out of ``allowed`` from ``"a,b"``; ``''`` gives ``[]`` only with ``allow_empty``."""
    names = _parts(text)
    if any(name not in allowed for name in names) or not (names or allow_empty):
        empty = " (or be '')" if allow_empty else ""
        raise SystemExit(f"{flag} {text!r} must list some of {', '.join(allowed)}{empty}")
    return names


def parse_seeds(flag: str, text: str) -> list[int]:
    """Distinct integer seeds from ``"0,1,2"`` (at least one)."""
    try:
        seeds = [int(part) for part in _parts(text)]
    except ValueError:
        raise SystemExit(f"{flag} {text!r} must be comma-separated integers") from None
    if not seeds or len(set(seeds)) != len(seeds):
        raise SystemExit(f"{flag} {text!r} must name at least one seed, each once")
    return seeds


def parse_numbers(flag: str, text: str, minimum: float = 0.0) -> list[float]:
    """Numbers ≥ ``minimum`` from ``"0,0.1"`` (at least one)."""
    try:
        values = [float(part) for part in _parts(text)]
    except ValueError:
        raise SystemExit(f"{flag} {text!r} must be comma-separated numbers") from None
    if not values or any(value < minimum for value in values):
        raise SystemExit(f"{flag} {text!r} must list numbers >= {minimum:g}")
    return values


def cpu_model(cpuinfo: str | Path = "/proc/cpuinfo") -> str:
    """The CPU's model name (Linux's ``/proc/cpuinfo``), else what :mod:`platform` knows
    (often only ``x86_64``): results JSONs record it, since speeds differ by machine."""
    try:
        for line in Path(cpuinfo).read_text(errors="replace").splitlines():
            key, _, value = line.partition(":")
            if key.strip() in ("model name", "Model", "Hardware") and value.strip():
                return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def provenance(benchmark: str) -> dict[str, str]:
    """Who wrote a results JSON: benchmark name, the command as typed, versions, date, machine
    and the torch threads in use."""
    return {
        "benchmark": benchmark,
        "command": script_command(),
        "vdtn_marl": __version__,
        "torch": torch.__version__,
        "written": dt.date.today().isoformat(),
        "machine": f"{platform.machine()}, {torch.get_num_threads()} torch thread(s)",
        "cpu": cpu_model(),
        "python": sys.version.split()[0],
    }


def ci_summary(samples: torch.Tensor) -> dict[str, float | int]:
    """Mean with its 95% Student-t CI over the finite samples, as a results JSON stores it
    (``n``: how many samples counted; NaNs where there are too few)."""
    finite = torch.as_tensor(samples, dtype=torch.float64).reshape(-1)
    finite = finite[torch.isfinite(finite)]
    if finite.numel() == 0:
        return {"mean": float("nan"), "low": float("nan"), "high": float("nan"), "n": 0}
    mean, low, high = mean_ci(finite)
    return {"mean": mean, "low": low, "high": high, "n": int(finite.numel())}


def checkpoint_run(path, cfg) -> dict:
    """What a results JSON says about a measured checkpoint: its path and its run's scenario,
    seed, RRA reward and κ1 (``cfg``: the run's :class:`~vdtn_marl.experiment.config.RunConfig`)."""
    return {
        "checkpoint": str(path),
        "scenario": cfg.scenario.name,
        "seed": cfg.seed,
        "rra_reward": cfg.rra.name,
        "kappa1": cfg.rra.kappa1,
    }


def table_console(file_width: int) -> Console:
    """A rich console for result tables: text stays as typed (no ``:name:`` emoji codes, so
    specs such as ``rollout:100:mc`` survive), and ``file_width`` columns when the output is
    a file or a pipe rather than a terminal."""
    console = Console(emoji=False)
    return console if console.is_terminal else Console(width=file_width, emoji=False)
