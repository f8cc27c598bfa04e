"""vdtn-marl: multi-agent RL benchmark for joint vehicle platoon control and C-V2X radio
resource allocation in a Vehicular Digital Twin Network.

>>> import vdtn_marl
>>> vdtn_marl.list_envs()  # doctest: +SKIP
['vdtn/platoon-control-impaired-v1', 'vdtn/platoon-control-v0', 'vdtn/v2x-rra-v1', ...]
>>> env = vdtn_marl.make("vdtn/vdtn-joint-v1")  # doctest: +SKIP
"""

from importlib import metadata as _metadata

from vdtn_marl.envs.registration import (
    DeprecatedEnvError,
    EnvSpec,
    PluginLoadWarning,
    UnknownEnvError,
    list_envs,
    make,
    register,
    spec,
)

try:
    __version__ = _metadata.version("vdtn-marl")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.1.0"

__all__ = [
    "DeprecatedEnvError",
    "EnvSpec",
    "PluginLoadWarning",
    "UnknownEnvError",
    "__version__",
    "list_envs",
    "make",
    "register",
    "spec",
]
