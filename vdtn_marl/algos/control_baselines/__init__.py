"""Moved to :mod:`vdtn_marl.policies.registry`; importing it from here still works for one release
(it is the same module) and warns.

A package rather than a ``.py`` file only so that git sees the file's move as a rename (edits
made elsewhere to the old file merge into the new one); it goes with the shim."""

import sys
import warnings

from vdtn_marl.policies import registry as _moved

warnings.warn(
    "vdtn_marl.algos.control_baselines moved to vdtn_marl.policies.registry; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
