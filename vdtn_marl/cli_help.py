"""Moved to :mod:`vdtn_marl.cli.help`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl.cli import help as _moved

warnings.warn(
    "vdtn_marl.cli_help moved to vdtn_marl.cli.help; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
