"""A memo of π*'s warm start, shared by the runs that would compute the same one.

π*'s warm start (``control.warm_start=causal_mpc``: π* imitates the causal MPC,
:func:`~vdtn_marl.algos.imitation.distill_teacher`) is a pure function of what it reads: π*'s
trainer state (initial weights, observation scaling), the global RNG state it starts from (its
scaling rollout samples actions), the model, the leader traces, the trainer's seed and the
code. The cells of a leaderboard that share a scenario and a seed compute it again and again:
it is 40–60 % of a `reduced` cell. With ``warm_start_cache=DIR`` a run looks its warm start up
in ``DIR`` under a key hashed from all of those inputs (the package's whole source included, so
any code change misses) and, on a hit, loads π*'s trainer state and the RNG state the warm start
left behind instead of computing it: the run goes on bit for bit as if it had computed it. On a
miss it computes it and stores it (atomically; two processes that store the same key write the
same bytes). ``vdtn-marl bench`` sets ``DIR`` to ``<out_dir>/warm_starts`` unless
``share_warm_starts=false``.

Methods whose loops construct different trainers (a learned RRA policy or not) start the warm
start from different RNG states, so they get different keys: the memo never pairs runs that
would not have computed the same thing.
"""

from __future__ import annotations

import hashlib
import io
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from vdtn_marl.io.files import atomic_write_bytes

#: bump when the entry's layout changes
MEMO_FORMAT = 1
PACKAGE_ROOT = Path(__file__).resolve().parents[1]


def _update(h: hashlib._Hash, value: Any) -> None:
    """Feed a nested structure of tensors, arrays, numbers and strings to ``h`` in a fixed
    order (dict keys sorted), with type tags so that different structures cannot collide."""
    if isinstance(value, Mapping):
        h.update(b"{")
        for key in sorted(value, key=str):
            _update(h, str(key))
            _update(h, value[key])
        h.update(b"}")
    elif isinstance(value, list | tuple):
        h.update(b"[")
        for item in value:
            _update(h, item)
        h.update(b"]")
    elif isinstance(value, torch.Tensor):
        t = value.detach().cpu().contiguous()
        h.update(f"T{t.dtype}{tuple(t.shape)}".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    elif isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        h.update(f"A{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    elif isinstance(value, bytes):
        h.update(b"B" + value)
    else:
        h.update(f"{type(value).__name__}:{value!r}".encode())


def source_digest() -> str:
    """SHA-256 of the package's Python sources (paths and contents)."""
    h = hashlib.sha256()
    for path in sorted(PACKAGE_ROOT.rglob("*.py")):
        h.update(str(path.relative_to(PACKAGE_ROOT)).encode() + b"\0")
        h.update(path.read_bytes() + b"\0")
    return h.hexdigest()


def file_digest(path: str | Path | None) -> str | None:
    """SHA-256 of a file's bytes (a user's trace file), or None without one."""
    return None if path is None else hashlib.sha256(Path(path).read_bytes()).hexdigest()


def memo_key(**inputs: Any) -> str:
    """The key of a warm start computed from ``inputs`` (everything it reads)."""
    h = hashlib.sha256()
    _update(h, {"format": MEMO_FORMAT, "source": source_digest(), **inputs})
    return h.hexdigest()[:32]


def memo_path(directory: str | Path, key: str) -> Path:
    return Path(directory) / f"{key}.pt"


def load(directory: str | Path, key: str) -> dict[str, Any] | None:
    """The stored entry of ``key`` (``trainer``, ``rng``, ``stats``), or None."""
    path = memo_path(directory, key)
    if not path.is_file():
        return None
    try:
        entry = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # noqa: BLE001 - a damaged entry is a miss; it is written anew
        return None
    if not isinstance(entry, dict) or entry.get("format") != MEMO_FORMAT:
        return None
    return entry


def store(directory: str | Path, key: str, trainer: dict, rng: dict, stats: dict) -> Path:
    buffer = io.BytesIO()
    payload = {"format": MEMO_FORMAT, "trainer": trainer, "rng": rng, "stats": stats}
    torch.save(payload, buffer)
    return atomic_write_bytes(memo_path(directory, key), buffer.getvalue())
