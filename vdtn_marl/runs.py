"""Moved to :mod:`vdtn_marl.io`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl import io as _moved

warnings.warn(
    "vdtn_marl.runs moved to vdtn_marl.io; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
