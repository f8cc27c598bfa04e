"""Moved to :mod:`vdtn_marl.cli.rollout`; importing it from here still works for one release
(it is the same module) and warns."""

import sys
import warnings

from vdtn_marl.cli import rollout as _moved

warnings.warn(
    "vdtn_marl.rollout moved to vdtn_marl.cli.rollout; import it from there",
    DeprecationWarning,
    stacklevel=2,
)
if __name__ == "__main__":  # python -m vdtn_marl.rollout
    raise SystemExit(_moved.main())
sys.modules[__name__] = _moved
