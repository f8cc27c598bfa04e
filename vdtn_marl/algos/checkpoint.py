"""Checkpoints: policies, critics, optimisers, config, RNG state and the run's position.

A checkpoint is one ``torch.save`` file written atomically. It is read back with
``weights_only=True`` (tensors and plain Python containers only: no code runs on load). A
truncated or foreign file, a newer format, or a config that changes the networks' shapes gives
a :class:`CheckpointError` naming the file and the problem.
"""

from __future__ import annotations

import io
import logging
import pickle
import struct
import zipfile
from pathlib import Path
from typing import Any

import torch

from vdtn_marl.core.reward import REWARD_KINDS as LEARNED_RRA
from vdtn_marl.errors import CheckpointError
from vdtn_marl.io.files import atomic_write_bytes

_log = logging.getLogger(__name__)

FORMAT = "vdtn-marl-checkpoint"
#: 2: a shared centralised critic has one output per agent (format 1 had one for all).
FORMAT_VERSION = 2

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


class ShapeMismatch(CheckpointError):
    """The config gives ``key`` another value than the checkpoint's run (``saved``)."""

    def __init__(self, path: Path, key: str, saved: Any, given: Any):
        super().__init__(
            f"checkpoint {str(path)!r} was written with {key}={saved!r}, "
            f"but the config has {key}={given!r}"
        )
        self.key, self.saved, self.given = key, saved, given


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
    written = atomic_write_bytes(path, buffer.getvalue())
    _log.info("checkpoint written: %s (%s)", written, describe(payload))
    return written


def trainer_iterations(payload: dict[str, Any]) -> dict[str, int]:
    """PPO iterations each trainer of a checkpoint has run (0: never trained)."""
    trainers = payload.get("trainers") or {}
    return {name: int(state.get("iteration", 0)) for name, state in trainers.items()}


def describe(payload: dict[str, Any]) -> str:
    """One line on where a checkpoint's run stands: task, JOCC iteration, next stage, and
    the PPO iterations of each trainer."""
    parts = [f"task={payload.get('task')}"]
    position = payload.get("position") or {}
    if "iteration" in position:
        where = f"JOCC iteration {position['iteration']}, next stage index {position.get('stage')}"
        parts.append(where)
    iterations = trainer_iterations(payload)
    if iterations:
        parts.append("PPO iterations " + ", ".join(f"{n}={i}" for n, i in iterations.items()))
    return "; ".join(parts)


_UNTRAINED = {
    "pi_star": "π* was never trained",
    "pi_tilde": "π̃ (control=learned) was never trained: its control metrics are those of its "
    "initial weights",
    "rra": "the RRA policy (rra={rra}) was never trained: a uniformly random allocation is "
    "scored in its place (pass rra=random, round_robin or greedy to evaluate a baseline)",
}


def untrained_policies(payload: dict[str, Any], config: dict[str, Any]) -> tuple[list[str], bool]:
    """Warnings for the learned policies an evaluation of ``payload`` under ``config`` (nested
    dict) would score although the checkpoint never trained them, and whether no trained
    policy would act at all (nothing of the checkpoint to evaluate).

    A ``task=control`` checkpoint is evaluated as its run evaluated it: π* on perfect
    observations. Otherwise π̃ acts when ``control.name`` is ``learned``, and the RRA agents
    when ``rra.name`` is a learned method (an untrained RRA policy is replaced by a uniformly
    random one, as during training)."""
    acting = ["pi_star"]
    if payload.get("task") != "control":
        acting = ["pi_tilde"] if _lookup(config, "control.name") == "learned" else []
        acting += ["rra"] if _lookup(config, "rra.name") in LEARNED_RRA else []
    iterations = trainer_iterations(payload)
    untrained = [name for name in acting if iterations.get(name, 0) == 0]
    rra = _lookup(config, "rra.name")
    warnings = [_UNTRAINED[name].format(rra=rra) for name in untrained]
    return warnings, bool(acting) and len(untrained) == len(acting)


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
    except _LOAD_ERRORS as err:
        # torch's own message is many lines and suggests weights_only=False (which would run
        # the file's code): name the file and the problem only.
        raise CheckpointError(_unreadable(path, err)) from err
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise CheckpointError(f"checkpoint {str(path)!r} is not a vdtn-marl checkpoint")
    version = payload.get("format_version")
    if version != FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint {str(path)!r} has format_version={version!r}; "
            f"this vdtn-marl reads format_version={FORMAT_VERSION} (the networks changed: "
            "train the run again with this version)"
        )
    if config is not None:
        saved = payload.get("config", {})
        for key in SHAPE_KEYS:
            if _lookup(saved, key) != _lookup(config, key):
                raise ShapeMismatch(path, key, _lookup(saved, key), _lookup(config, key))
    return payload


#: What ``torch.load(weights_only=True)`` raises on a file it cannot read. Besides a damaged
#: archive, a file that is not one (a config.yaml, a metrics.csv, any text) is read as a bare
#: pickle whose first bytes happen to be opcodes: the weights-only unpickler then fails with
#: whatever its stack or memo gives (``IndexError: pop from empty list``, ``KeyError: 101``,
#: a ``UnicodeDecodeError``, a ``struct.error``).
_LOAD_ERRORS = (
    RuntimeError,
    EOFError,
    pickle.UnpicklingError,
    zipfile.BadZipFile,
    OSError,
    KeyError,
    IndexError,
    ValueError,
    struct.error,
)

#: Start of a zip archive's first local file header, and that header's size in bytes.
_ZIP_MAGIC = b"PK\x03\x04"
_ZIP_HEADER = 30


def _unreadable(path: Path, err: BaseException) -> str:
    """Why torch cannot read ``path``, in one line: a damaged torch archive, one holding other
    objects than tensors and plain containers, another kind of file, or one the system does
    not let us read."""
    name = repr(str(path))
    try:
        with open(path, "rb") as handle:
            header = handle.read(_ZIP_HEADER)
            zipped = header[:4] == _ZIP_MAGIC  # the zip archive torch.save writes
            first = _first_zip_entry(handle, header) if zipped else None
    except OSError as exc:
        return f"checkpoint {name} cannot be read ({exc.strerror or exc})"
    if zipped and first is not None and not first.endswith(b"data.pkl"):
        # torch.save writes its pickle as the archive's first entry: this zip is another
        # kind (an evaluation_raw.npz, a zipped folder), whole or not
        return (
            f"checkpoint {name} is not a vdtn-marl checkpoint (a zip archive not written by "
            "torch.save)"
        )
    if zipped and isinstance(err, pickle.UnpicklingError):
        return (
            f"checkpoint {name} is not a vdtn-marl checkpoint (a torch file holding objects "
            "other than tensors and plain containers)"
        )
    if zipped:
        return f"checkpoint {name} is truncated or damaged (its torch archive cannot be read)"
    return f"checkpoint {name} is not a vdtn-marl checkpoint (not a file written by torch.save)"


def _first_zip_entry(handle: io.BufferedReader, header: bytes) -> bytes | None:
    """Name of the first entry of the zip archive whose first ``header`` bytes were read
    from ``handle`` (positioned just after them); None where the file ends before it."""
    if len(header) < _ZIP_HEADER:
        return None
    (length,) = struct.unpack("<H", header[26:28])  # file name length, in bytes
    entry = handle.read(length)  # the name follows the fixed-size header
    return entry if len(entry) == length else None
