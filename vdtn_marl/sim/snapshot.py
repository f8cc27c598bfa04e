"""Snapshots of simulation objects as plain containers of tensors, and their restoration.

:func:`export_state` walks an object's attributes (and those of the objects it holds) and
returns nested dicts and lists of tensors, numbers and strings: what ``torch.save`` writes and
``torch.load(weights_only=True)`` reads back without running code. :func:`import_state` writes
such a snapshot back into an object of the same construction (built with the same config), in
place. Together they let a trainer keep its environments running across PPO iterations and
still resume a run bit for bit: the twin's state, its random generator, a completion filter's
state and a random policy's generator all travel in the checkpoint.

Not exported: ``torch.nn.Module`` instances (the trainers save the weights), functions, enum
members (settings, not state), and objects already visited (shared references are written
once). Frozen dataclasses come back as new instances (``dataclasses.replace``).
"""

from __future__ import annotations

import dataclasses
import enum
import types
from typing import Any

import numpy as np
import torch

_SKIPPED = {"__skipped__": True}
_LEAVES = (bool, int, float, str, type(None))


def _skip(value: Any) -> bool:
    return isinstance(
        value,
        torch.nn.Module | types.FunctionType | types.MethodType | type | enum.Enum,
    )


def export_state(obj: Any, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    """The state of ``obj`` (an object with attributes) as plain containers; attribute names
    in ``skip`` are left out at the top level."""
    seen: set[int] = set()
    return {
        key: _export(value, seen)
        for key, value in vars(obj).items()
        if key not in skip and not _skip(value)
    }


def _export(value: Any, seen: set[int]) -> Any:
    if isinstance(value, torch.Tensor):
        return value.detach().clone()
    if isinstance(value, _LEAVES):
        return value
    if isinstance(value, torch.device):
        return {"__device__": str(value)}
    if isinstance(value, np.ndarray):
        return {"__ndarray__": torch.from_numpy(value.copy())}
    if isinstance(value, np.generic):
        return value.item()
    if id(value) in seen or _skip(value):
        return _SKIPPED
    seen.add(id(value))
    if isinstance(value, torch.Generator):
        return {"__generator__": value.get_state(), "device": str(value.device)}
    if isinstance(value, np.random.Generator):
        return {"__np_generator__": value.bit_generator.state}
    if isinstance(value, list | tuple):
        return {"__sequence__": [_export(v, seen) for v in value]}
    if isinstance(value, dict):
        return {"__dict__": {k: _export(v, seen) for k, v in value.items()}}
    if hasattr(value, "__dict__"):
        items = vars(value)
        if dataclasses.is_dataclass(value) and value.__dataclass_params__.frozen:
            # its fields: what else an immutable value holds is derived from them (a
            # cached_property such as PlatoonParams.numbers), and is left out
            items = {f.name: getattr(value, f.name) for f in dataclasses.fields(value)}
        return {"__object__": {k: _export(v, seen) for k, v in items.items() if not _skip(v)}}
    return _SKIPPED


def import_state(obj: Any, state: dict[str, Any]) -> None:
    """Write ``state`` (from :func:`export_state` of an object built alike) into ``obj``."""
    for key, saved in state.items():
        current = getattr(obj, key, None)
        restored = _import(current, saved)
        # an attribute behind a descriptor (the twin's torch views of its arrays) may hand out
        # a new object on each read: write it back even when it was restored in place
        descriptor = hasattr(type(getattr(type(obj), key, None)), "__set__")
        if restored is not current or descriptor or not hasattr(obj, key):
            setattr(obj, key, restored)


def _import(current: Any, saved: Any) -> Any:
    if isinstance(saved, torch.Tensor):
        device = current.device if isinstance(current, torch.Tensor) else saved.device
        return saved.to(device)
    if isinstance(saved, _LEAVES):
        return saved
    if not isinstance(saved, dict):
        raise TypeError(f"snapshot entry of type {type(saved).__name__} is not a state")
    if saved.get("__skipped__"):
        return current
    if "__device__" in saved:
        return torch.device(saved["__device__"])
    if "__ndarray__" in saved:
        return saved["__ndarray__"].numpy().copy()
    if "__generator__" in saved:
        generator = current
        if not isinstance(generator, torch.Generator):
            generator = torch.Generator(device=saved["device"])
        generator.set_state(saved["__generator__"])
        return generator
    if "__np_generator__" in saved:
        generator = current if isinstance(current, np.random.Generator) else None
        if generator is None:
            generator = np.random.default_rng()
        generator.bit_generator.state = saved["__np_generator__"]
        return generator
    if "__sequence__" in saved:
        items = saved["__sequence__"]
        old = list(current) if isinstance(current, list | tuple) else [None] * len(items)
        if len(old) != len(items):
            old = [None] * len(items)
        values = [_import(c, s) for c, s in zip(old, items, strict=True)]
        return tuple(values) if isinstance(current, tuple) else values
    if "__dict__" in saved:
        old = current if isinstance(current, dict) else {}
        return {k: _import(old.get(k), v) for k, v in saved["__dict__"].items()}
    if "__object__" in saved:
        if current is None:
            raise TypeError("snapshot holds an object where the target holds None")
        fields = saved["__object__"]
        if dataclasses.is_dataclass(current):
            values = {k: _import(getattr(current, k, None), v) for k, v in fields.items()}
            if current.__dataclass_params__.frozen:  # its init fields: the rest is derived
                names = {f.name for f in dataclasses.fields(current) if f.init}
                return dataclasses.replace(
                    current, **{k: v for k, v in values.items() if k in names}
                )
            for key, value in values.items():
                setattr(current, key, value)
            return current
        import_state(current, fields)
        return current
    raise TypeError(f"snapshot entry with keys {sorted(saved)} is not a state")
