"""Array helpers that let one function run on torch tensors or on NumPy arrays.

The batched core works on torch tensors; the single-scenario fast path of the PettingZoo
environments (``DigitalTwin(backend="numpy")``) runs the same functions on NumPy arrays, where
an operation on a handful of numbers costs a fraction of torch's dispatch. Code written with
these helpers performs the same float32 operations in the same order on either backend, so the
two give bit-identical results. Arithmetic, comparisons, ``abs`` and clamps are exactly rounded
in both libraries; the transcendental functions (:func:`log10`, :func:`exp`, :func:`sqrt`,
:func:`exp10`) are not (NumPy's and torch's vectorised implementations differ in the last bit
for some inputs), so on NumPy arrays they are evaluated by torch on a shared-memory view.
Random draws always come from the twin's torch generator.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from functools import lru_cache
from types import SimpleNamespace
from typing import TypeAlias

import numpy as np
import torch

Array: TypeAlias = torch.Tensor | np.ndarray


@contextmanager
def single_intra_op_thread() -> Iterator[None]:
    """Run torch's CPU kernels on one intra-op thread inside the block; restore the setting.

    The NumPy path hands torch a few arrays of one scenario (random draws, a log10 over the
    interval's tables). torch splits even ~1,000-element kernels across its intra-op threads,
    and waking a second thread costs tens to hundreds of µs when the other core is busy; one
    thread is always the faster choice at this size. ``torch.set_num_threads`` is
    process-wide, so other Python threads running torch meanwhile also see one thread.
    """
    threads = torch.get_num_threads()
    if threads == 1:
        yield
        return
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def xp(x: Array):
    """The array module of ``x``: ``numpy`` for NumPy arrays, else ``torch``."""
    return np if isinstance(x, np.ndarray) else torch


def clamp(x: Array, low: float | None = None, high: float | None = None) -> Array:
    """``torch.clamp`` on either backend (NaN propagates, like torch)."""
    if isinstance(x, np.ndarray):
        if low is not None:
            x = np.maximum(x, low)
        if high is not None:
            x = np.minimum(x, high)
        return x
    return x.clamp(low, high)


def float32_scalars(**values: float) -> SimpleNamespace | None:
    """``values`` as read-only float32 0-d arrays, for NumPy code on float32 arrays: the same
    operations as with the Python numbers (NumPy casts a Python scalar to the array's dtype
    first), at about a third of NumPy's cost per call on arrays of a few entries.

    None unless every value is a Python ``int`` or ``float`` (not a subclass): a NumPy scalar
    such as ``np.float64`` keeps its own dtype in an operation, so the caller keeps its own
    code for it."""
    if not all(type(value) in (int, float) for value in values.values()):
        return None
    arrays = {}
    for name, value in values.items():
        array = arrays[name] = np.array(value, np.float32)
        array.flags.writeable = False
    return SimpleNamespace(**arrays)


def _torch_on_numpy(x: np.ndarray, fn) -> np.ndarray:
    return fn(to_torch(x)).numpy()


def log10(x: Array) -> Array:
    return _torch_on_numpy(x, torch.log10) if isinstance(x, np.ndarray) else torch.log10(x)


def exp(x: Array) -> Array:
    return _torch_on_numpy(x, torch.exp) if isinstance(x, np.ndarray) else torch.exp(x)


def sqrt(x: Array) -> Array:
    return _torch_on_numpy(x, torch.sqrt) if isinstance(x, np.ndarray) else torch.sqrt(x)


def exp10(x: Array) -> Array:
    """10 ** x (``torch.pow(10.0, x)``)."""
    if isinstance(x, np.ndarray):
        return torch.pow(10.0, to_torch(x)).numpy()
    return torch.pow(10.0, x)


def stack(arrays: list[Array], axis: int = -1) -> Array:
    first = arrays[0]
    if not isinstance(first, np.ndarray):
        return torch.stack(arrays, dim=axis)
    if axis != -1 or any(a.shape != first.shape or a.dtype != first.dtype for a in arrays):
        return np.stack(arrays, axis=axis)
    out = np.empty((*first.shape, len(arrays)), first.dtype)  # np.stack without its overhead
    for i, a in enumerate(arrays):
        out[..., i] = a
    return out


def cat(arrays: list[Array], axis: int = -1) -> Array:
    if isinstance(arrays[0], np.ndarray):
        return np.concatenate(arrays, axis=axis)
    return torch.cat(arrays, dim=axis)


def as_float(x: Array) -> Array:
    """Cast to float32 (``Tensor.float()``; also for bool masks)."""
    if isinstance(x, np.ndarray):
        return x.astype(np.float32)
    return x.float()


def cast_like(x: Array, like: Array) -> Array:
    """Cast ``x`` to the dtype of ``like`` (``x.to(like.dtype)``)."""
    if isinstance(x, np.ndarray):
        return x.astype(like.dtype, copy=False)
    return x.to(like.dtype)


def repeat_rows(x: Array, times: int) -> Array:
    """Repeat a [B, ...] array ``times`` times along dim 0 (``Tensor.repeat(times, 1, ...)``)."""
    if isinstance(x, np.ndarray):
        return np.concatenate((x,) * times, axis=0)
    return x.repeat(times, *((1,) * (x.dim() - 1)))


def sum_axis(x: Array, axis: int) -> Array:
    """``x.sum(axis)`` (``np.add.reduce`` is what ``ndarray.sum`` runs, without its wrapper)."""
    if isinstance(x, np.ndarray):
        return np.add.reduce(x, axis=axis)
    return x.sum(dim=axis)


def mean_axis(x: Array, axis: int) -> Array:
    """``x.mean(axis)``; on NumPy what ``ndarray.mean`` computes (sum, then divide by the
    count), without its wrapper."""
    if isinstance(x, np.ndarray):
        return np.add.reduce(x, axis=axis) / x.shape[axis]
    return x.mean(dim=axis)


def to_numpy(x: torch.Tensor | np.ndarray) -> np.ndarray:
    """A NumPy view of a CPU tensor (no copy); arrays pass through."""
    if isinstance(x, np.ndarray):
        return x
    try:
        return x.numpy()  # the common case: a CPU tensor that needs no grad
    except (RuntimeError, TypeError):
        return x.detach().cpu().numpy()


def to_torch(x: np.ndarray | torch.Tensor) -> torch.Tensor:
    """A CPU tensor sharing the array's memory (no copy); tensors pass through."""
    if isinstance(x, torch.Tensor):
        return x
    if not isinstance(x, np.ndarray):
        return torch.as_tensor(x)
    if not x.flags.writeable:
        x = np.array(x)  # torch shares only writeable memory
    try:
        return torch.from_numpy(x)
    except ValueError:  # negative strides
        return torch.from_numpy(np.array(x))


_DTYPES = {
    "float32": (np.float32, torch.float32),
    "int64": (np.int64, torch.long),
    "bool": (np.bool_, torch.bool),
}


class ArrayNamespace:
    """The array type a twin holds its state in: NumPy arrays (``numpy=True``, CPU) or torch
    tensors on ``device``. Arrays are made, converted and masked here, so the twin's code runs
    without a branch per backend. :meth:`to_torch` and :meth:`from_torch` are the edges between
    the state and torch callers; on the NumPy backend they are views (no copy), on the torch
    backend they hand the arrays through."""

    def __init__(self, numpy: bool, device: torch.device):
        self.numpy = numpy
        self.device = device

    @property
    def lib(self):
        """The array module: ``numpy`` or ``torch`` (a property: deep copies of a twin do not
        copy modules)."""
        return np if self.numpy else torch

    @property
    def array_device(self) -> torch.device | None:
        """The ``device`` argument of the sim's array constructors: None for NumPy arrays."""
        return None if self.numpy else self.device

    def _dtype(self, name: str):
        return _DTYPES[name][0 if self.numpy else 1]

    def zeros(self, shape: tuple[int, ...], dtype: str = "float32") -> Array:
        if self.numpy:
            return np.zeros(shape, self._dtype(dtype))
        return torch.zeros(shape, dtype=self._dtype(dtype), device=self.device)

    def full(self, shape: tuple[int, ...], value, dtype: str = "float32") -> Array:
        if self.numpy:
            return np.full(shape, value, self._dtype(dtype))
        return torch.full(shape, value, dtype=self._dtype(dtype), device=self.device)

    def empty(self, shape: tuple[int, ...], dtype: str = "float32") -> Array:
        if self.numpy:
            return np.empty(shape, self._dtype(dtype))
        return torch.empty(shape, dtype=self._dtype(dtype), device=self.device)

    def from_torch(self, x):
        """A torch tensor, or a dataclass of them, in this namespace (NumPy views of CPU
        tensors on the NumPy backend; tensors pass through on the torch backend)."""
        if not self.numpy:
            return x
        return to_numpy(x) if isinstance(x, torch.Tensor) else _map_arrays(to_numpy, x)

    def to_torch(self, x):
        """An array of this namespace, or a dataclass of them, as torch tensors (sharing a
        NumPy array's memory: in-place writes reach the array)."""
        if not self.numpy:
            return x
        return to_torch(x) if isinstance(x, np.ndarray) else _map_arrays(to_torch, x)

    def asarray(self, x) -> Array:
        """An input (torch tensor or NumPy array) in this namespace, its dtype kept."""
        return to_numpy(x) if self.numpy else torch.as_tensor(x, device=self.device)

    def float32(self, x) -> Array:
        """An input (torch tensor or array) as float32 in this namespace."""
        if self.numpy:
            return to_numpy(x).astype(np.float32, copy=False)
        return torch.as_tensor(x).to(device=self.device, dtype=torch.float32)

    def mask(self, mask: torch.Tensor) -> Array:
        """A bool mask given as a torch tensor, in this namespace (on the twin's device)."""
        return mask.cpu().numpy() if self.numpy else mask.to(self.device)

    def copy(self, x: Array) -> Array:
        return x.copy() if self.numpy else x.clone()

    def where(self, condition: Array, x, y) -> Array:
        return np.where(condition, x, y) if self.numpy else torch.where(condition, x, y)

    def take_along_axis(self, x: Array, indices: Array, axis: int) -> Array:
        """Entries of ``x`` at ``indices`` along ``axis`` (``np.take_along_axis``); the other
        axes of ``indices`` broadcast to those of ``x`` (as fancy indexing on NumPy and a
        gather on torch, the faster form of each)."""
        if self.numpy:
            index = list(_index_grid(x.shape))
            index[axis] = indices
            return x[tuple(index)]
        shape = list(x.shape)
        shape[axis] = indices.shape[axis]
        return x.gather(axis, indices.expand(shape))

    def is_integer(self, x: Array) -> bool:
        """Whether ``x`` holds integers (a signed or unsigned int dtype; not bool)."""
        if self.numpy:
            return x.dtype.kind in "iu"
        dtype = x.dtype
        return not (dtype.is_floating_point or dtype.is_complex or dtype == torch.bool)

    def value_range(self, x: Array) -> tuple:
        """(min, max) of a non-empty ``x`` as scalars that compare with Python numbers (on
        torch one reduction and one device sync)."""
        if self.numpy:
            return x.min(), x.max()
        return tuple(torch.stack(torch.aminmax(x)).tolist())

    def own_threads(self):
        """Context of the twin's own torch calls: one intra-op thread on the NumPy backend
        (:func:`single_intra_op_thread`)."""
        return single_intra_op_thread() if self.numpy else nullcontext()


def like(x: Array, reference: Array) -> Array:
    """``x`` in the array type of ``reference`` (a NumPy array or a torch tensor, views where
    it can)."""
    return to_numpy(x) if isinstance(reference, np.ndarray) else to_torch(x)


@lru_cache(maxsize=64)
def _index_grid(shape: tuple[int, ...]) -> tuple[np.ndarray, ...]:
    """The open grid of a NumPy array of ``shape``: ``arange(shape[i])`` along axis i."""
    ndim = len(shape)
    return tuple(
        np.arange(n).reshape([-1 if j == i else 1 for j in range(ndim)])
        for i, n in enumerate(shape)
    )


def _map_arrays(convert, x):
    """``convert`` applied to an array, or to each array field of a dataclass (a new one)."""
    if not dataclasses.is_dataclass(x):
        return convert(x)
    values = {f.name: getattr(x, f.name) for f in dataclasses.fields(x)}
    return type(x)(
        **{
            name: convert(value) if isinstance(value, torch.Tensor | np.ndarray) else value
            for name, value in values.items()
        }
    )
