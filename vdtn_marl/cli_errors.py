"""Moved to :mod:`vdtn_marl.cli.errors`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl.cli import errors as _moved

warnings.warn(
    "vdtn_marl.cli_errors moved to vdtn_marl.cli.errors; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
