"""Moved to :mod:`vdtn_marl.policies`; importing it from here still works for one release (it is
the same module) and warns.

A package rather than a ``.py`` file only so that git sees the file's move as a rename (edits
made elsewhere to the old file merge into the new one); it goes with the shim."""

import sys
import warnings

import vdtn_marl.policies as _moved

warnings.warn(
    "vdtn_marl.algos.baselines moved to vdtn_marl.policies; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
