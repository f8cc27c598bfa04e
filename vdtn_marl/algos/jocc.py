"""Moved to :mod:`vdtn_marl.experiment.jocc`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl.experiment import jocc as _moved

warnings.warn(
    "vdtn_marl.algos.jocc moved to vdtn_marl.experiment.jocc; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
if __name__ == "__main__":  # python -m vdtn_marl.algos.jocc
    raise SystemExit(_moved.main())
sys.modules[__name__] = _moved
