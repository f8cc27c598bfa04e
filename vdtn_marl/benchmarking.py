"""Moved to :mod:`vdtn_marl.reporting.benchmarking`; importing it from here still works for one
release (it is the same module) and warns. ``loaded_checkpoints`` builds JOCC loops, so it moved
above, to :func:`vdtn_marl.experiment.api.loaded_checkpoints`."""

import sys
import warnings

from vdtn_marl.reporting import benchmarking as _moved

warnings.warn(
    "vdtn_marl.benchmarking moved to vdtn_marl.reporting.benchmarking; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
sys.modules[__name__] = _moved
