"""Moved to :mod:`vdtn_marl.reporting`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl import reporting as _moved

warnings.warn(
    "vdtn_marl.results moved to vdtn_marl.reporting; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
