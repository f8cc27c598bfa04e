"""Moved to :mod:`vdtn_marl.cli.prepass`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl.cli import prepass as _moved

warnings.warn(
    "vdtn_marl.cli_prepass moved to vdtn_marl.cli.prepass; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
