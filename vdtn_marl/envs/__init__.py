"""PettingZoo faces of the digital twin (and, in :mod:`vdtn_marl.envs.torchrl`, a batched
TorchRL face). Use :func:`vdtn_marl.make` with a registered id rather than the classes."""

from vdtn_marl.envs.control import PlatoonControlEnv
from vdtn_marl.envs.radio import V2XRRAEnv
from vdtn_marl.envs.two_timescale import TwoTimescaleEnv

__all__ = ["PlatoonControlEnv", "TwoTimescaleEnv", "V2XRRAEnv"]
