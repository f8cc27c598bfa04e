"""Checkpoints: policies, critics, optimisers, config, RNG state and the run's position.

A checkpoint is one ``torch.save`` file written atomically. It is read back with
``weights_only=True`` (tensors and plain Python containers only: no code runs on load). A
truncated or foreign file, a newer format, or a config that changes the networks' shapes gives
a :class:`CheckpointError` naming the file and the problem.
"""

from __future__ import annotations

import io
import pickle
import zipfile
from pathlib import Path
from typing import Any

import torch

from vdtn_marl.runs import atomic_write_bytes

FORMAT = "vdtn-marl-checkpoint"
FORMAT_VERSION = 1

#: Config keys a checkpoint's networks depend on; resuming or evaluating with other values is
#: refused (everything else, e.g. budgets, may change between runs).
SHAPE_KEYS = (
    "scenario.num_vehicles",
    "scenario.num_subchannels",
    "scenario.model",
    "algo.name",
    "algo.share_params",
    "algo.depth",
    "algo.num_cells",
    "control.augmentation",
)


class CheckpointError(ValueError):
    """A checkpoint that cannot be used; the message names the file and the problem."""


def rng_state() -> dict[str, Any]:
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` (plus format tags) to ``path`` atomically."""
    buffer = io.BytesIO()
    torch.save({"format": FORMAT, "format_version": FORMAT_VERSION, **payload}, buffer)
    return atomic_write_bytes(path, buffer.getvalue())


def _lookup(config: dict[str, Any], dotted: str) -> Any:
    value: Any = config
    for part in dotted.split("."):
        if not isinstance(value, dict) or part not in value:
            return None
        value = value[part]
    return value


def load_checkpoint(path: str | Path, config: dict[str, Any] | None = None) -> dict[str, Any]:
    """Read a checkpoint; with ``config`` (nested dict) check the :data:`SHAPE_KEYS` match."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"checkpoint {str(path)!r} does not exist or is not a file")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except (RuntimeError, EOFError, pickle.UnpicklingError, zipfile.BadZipFile, OSError) as err:
        raise CheckpointError(
            f"checkpoint {str(path)!r} is truncated or not a vdtn-marl checkpoint ({err})"
        ) from err
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"checkpoint {str(path)!r} is not a vdtn-marl checkpoint")
    version = payload.get("format_version")
    if version != FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {str(path)!r} has format_version={version!r}; "
            f"this vdtn-marl reads format_version={FORMAT_VERSION}"
        )
    if config is not None:
        saved = payload.get("config", {})
        for key in SHAPE_KEYS:
            if _lookup(saved, key) != _lookup(config, key):
                raise CheckpointError(
                    f"checkpoint {str(path)!r} was written with {key}={_lookup(saved, key)!r}, "
                    f"but the config has {key}={_lookup(config, key)!r}"
                )
    return payload
