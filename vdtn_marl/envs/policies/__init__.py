"""Moved to :mod:`vdtn_marl.policies.rra`; importing it from here still works for one release (it
is the same module) and warns.

A package rather than a ``.py`` file, as the other old paths of moved modules are; it goes
with the shim."""

import sys
import warnings

from vdtn_marl.policies import rra as _moved

warnings.warn(
    "vdtn_marl.envs.policies moved to vdtn_marl.policies.rra; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
