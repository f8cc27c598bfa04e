"""Moved to :mod:`vdtn_marl.experiment.api`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl.experiment import api as _moved

warnings.warn(
    "vdtn_marl.algos.api moved to vdtn_marl.experiment.api; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
