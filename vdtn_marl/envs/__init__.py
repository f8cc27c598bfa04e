"""PettingZoo faces of the digital twin (and, in :mod:`vdtn_marl.envs.torchrl`, a batched
TorchRL face), and the registry of their ids (:mod:`vdtn_marl.envs.registration`). Use
:func:`vdtn_marl.make` with a registered id rather than the classes.

The classes are imported on first use, so that the registry (which ``import vdtn_marl`` reads)
imports neither torch nor the simulator."""

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from vdtn_marl.envs.control import PlatoonControlEnv
    from vdtn_marl.envs.radio import V2XRRAEnv
    from vdtn_marl.envs.two_timescale import TwoTimescaleEnv

__all__ = ["PlatoonControlEnv", "TwoTimescaleEnv", "V2XRRAEnv"]


def __getattr__(name: str):
    if name == "PlatoonControlEnv":
        from vdtn_marl.envs.control import PlatoonControlEnv

        return PlatoonControlEnv
    if name == "V2XRRAEnv":
        from vdtn_marl.envs.radio import V2XRRAEnv

        return V2XRRAEnv
    if name == "TwoTimescaleEnv":
        from vdtn_marl.envs.two_timescale import TwoTimescaleEnv

        return TwoTimescaleEnv
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
