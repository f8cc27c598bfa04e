"""Lazy re-exports for a package's ``__init__`` (PEP 562): each name is imported from the module
of the package that defines it on first use, so that importing the package stays cheap (no
torch, no Hydra). Imports nothing of ours, like :mod:`vdtn_marl.errors`.

    __getattr__, __dir__ = lazy_exports(__name__, {"DigitalTwin": "twin", ...})
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(
    package: str, homes: Mapping[str, str]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of ``package`` for ``homes`` (name →
    the submodule of ``package`` that defines it)."""

    def __getattr__(name: str) -> Any:
        home = homes.get(name)
        if home is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        return getattr(importlib.import_module(f"{package}.{home}"), name)

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(homes))

    return __getattr__, __dir__
