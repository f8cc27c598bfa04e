"""Policies a user names in the config: ``rra.policy`` (with ``rra=policy``) and
``control.policy`` (with ``control=policy``), so that a method of one's own is scored under the
benchmark's protocol (``vdtn-marl jocc``, ``eval`` and ``bench``; docs/leaderboard.md,
*Submissions*).

A policy is named by one of:

- **an import path** ``package.module:factory`` or ``path/to/file.py:factory``: ``factory(params,
  seed)`` gets the run's :class:`~vdtn_marl.sim.params.TwinParams` and seed and returns the
  policy, a callable. An RRA policy maps RRA observations ``[B, L, D]`` (the features of
  ``twin.rra_layout``, docs/model.md §4.6) to integer actions ``[B, L]`` in ``[0, M·P)``
  (sub-channel × power level, :func:`~vdtn_marl.policies.encode_rra_action`); a control policy
  maps vehicle observations ``[B, F, 8]`` (``VEHICLE_OBS_FEATURES``) to commands ``[B, F]`` in
  m/s². A policy may have ``seed(seed)``, called when its environment is seeded, and a control
  policy ``bind(twin) -> policy`` like the MPC oracle (it then reads the twin's true state). A
  module path is imported as Python does, with the working directory searched last; a file
  path is loaded from that file.
- **a TorchRL module checkpoint**, a ``.pt`` file of ``torch.save(module)``: a TensorDict
  module (an actor such as TorchRL's ``ProbabilisticActor``) that reads ``(group,
  "observation")`` and writes ``(group, "action")``, group ``rra`` or ``vehicle``, acting
  deterministically (the mode of its distribution); or a plain ``torch.nn.Module`` mapping the
  observation tensor to the action tensor. It is unpickled (``weights_only=False``), which runs
  code from the file: name only files you trust.
- **a BenchMARL checkpoint** (``<experiment>/checkpoints/checkpoint_<frames>.pt`` of an
  experiment on a ``vdtn/rra`` or ``vdtn/control*`` task, needs ``vdtn-marl[benchmarl]``):
  BenchMARL rebuilds the experiment from the ``config.pkl`` in its folder
  (``Experiment.reload_from_file``) and its policy acts deterministically.

:func:`check_policy` runs at validation (before anything is written): it resolves an import
path (the factory exists and is callable) and reads a checkpoint far enough to know its kind.
:func:`load_policy` builds the policy for a run.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vdtn_marl.errors import ConfigError

#: config key → (the group whose observations the policy reads, what it is)
POLICY_KEYS: dict[str, tuple[str, str]] = {
    "rra.policy": ("rra", "RRA observations [B, L, D] → actions [B, L]"),
    "control.policy": ("vehicle", "vehicle observations [B, F, 8] → commands [B, F] (m/s²)"),
}
#: the kinds of checkpoint a ``.pt`` file may be (``vdtn`` is a vdtn-marl run's own)
CHECKPOINT_KINDS = ("module", "benchmarl", "vdtn")
_FORMS = (
    "an import path module:factory or file.py:factory, a TorchRL module checkpoint (.pt of "
    "torch.save(module)) or a BenchMARL checkpoint"
)


def is_import_path(spec: str) -> bool:
    """Whether ``spec`` names a factory (``module:attr`` or ``file.py:attr``), not a file."""
    head, sep, attr = spec.rpartition(":")
    if not sep or not attr or not head:
        return False
    if len(head) == 1 and head.isalpha():  # a Windows drive letter: C:path
        return False
    return attr.replace(".", "_").isidentifier()


def _import_module(key: str, spec: str, head: str):
    if head.endswith(".py"):
        path = Path(head)
        if not path.is_file():
            raise ConfigError(f"{key}={spec!r}: the file {head!r} does not exist")
        name = f"vdtn_marl_user_{abs(hash(str(path.resolve())))}"
        if name in sys.modules:
            return sys.modules[name]
        module_spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[name] = module
        try:
            module_spec.loader.exec_module(module)
        except Exception as exc:
            del sys.modules[name]
            raise ConfigError(
                f"{key}={spec!r}: importing {head} failed ({type(exc).__name__}: {exc})"
            ) from exc
        return module
    added = os.getcwd() not in sys.path
    if added:  # as `python -m` would: the user's own modules beside the command
        sys.path.append(os.getcwd())
    try:
        return importlib.import_module(head)
    except ImportError as exc:
        raise ConfigError(
            f"{key}={spec!r}: module {head!r} cannot be imported ({exc}); allowed: {_FORMS}"
        ) from exc
    except Exception as exc:
        raise ConfigError(
            f"{key}={spec!r}: importing {head!r} failed ({type(exc).__name__}: {exc})"
        ) from exc


def resolve_factory(key: str, spec: str) -> Callable:
    """The factory an import path names (a :class:`ConfigError` naming ``key`` if it does not
    resolve to a callable)."""
    head, _, attr = spec.rpartition(":")
    target: Any = _import_module(key, spec, head)
    for part in attr.split("."):
        if not hasattr(target, part):
            raise ConfigError(f"{key}={spec!r}: {head!r} has no attribute {attr!r}")
        target = getattr(target, part)
    if not callable(target):
        raise ConfigError(
            f"{key}={spec!r}: {attr} is a {type(target).__name__}, not a callable "
            "factory(params, seed) -> policy"
        )
    return target


def _load_file(key: str, path: Path, device: Any = "cpu") -> tuple[str, Any]:
    """(kind, content) of a ``.pt`` file: one of :data:`CHECKPOINT_KINDS`."""
    import torch

    from vdtn_marl.algos.checkpoint import FORMAT

    try:
        content = torch.load(path, map_location=device, weights_only=True)
    except Exception:  # a pickled module (or not a torch file): the full unpickler decides
        try:
            content = torch.load(path, map_location=device, weights_only=False)
        except Exception as exc:
            raise ConfigError(
                f"{key}={str(path)!r} cannot be read as a torch file ({type(exc).__name__}); "
                f"allowed: {_FORMS}"
            ) from exc
    if isinstance(content, torch.nn.Module):
        return "module", content
    if isinstance(content, dict) and content.get("format") == FORMAT:
        return "vdtn", content
    if isinstance(content, dict) and _is_benchmarl_checkpoint(content):
        return "benchmarl", content
    kind = type(content).__name__
    if isinstance(content, dict):
        keys = ", ".join(sorted(map(str, content))[:6])
        kind = f"dict with keys {keys}" + (", ..." if len(content) > 6 else "")
        if all(isinstance(v, torch.Tensor) for v in content.values()):
            kind = "state_dict (weights without the module: save the module itself)"
    raise ConfigError(
        f"{key}={str(path)!r} holds a {kind}, which is not a policy; allowed: {_FORMS}"
    )


def _is_benchmarl_checkpoint(content: dict) -> bool:
    """BenchMARL's ``Experiment.state_dict()``: the experiment's counters, the collector and
    one ``loss_<group>`` entry per group."""
    return "state" in content and any(str(k).startswith("loss_") for k in content)


def check_policy(key: str, spec: Any) -> None:
    """Check ``spec`` for ``key`` (one of :data:`POLICY_KEYS`) without building the policy."""
    _check_key_and_spec(key, spec)
    if is_import_path(spec):
        resolve_factory(key, spec)
    else:
        _policy_file(key, spec)


def _check_key_and_spec(key: str, spec: Any) -> None:
    if key not in POLICY_KEYS:
        raise ConfigError(f"{key!r} is not one of {', '.join(POLICY_KEYS)}")
    if not isinstance(spec, str) or not spec:
        raise ConfigError(f"{key}={spec!r} must name a policy: {_FORMS}")


def _policy_file(key: str, spec: str, device: Any = "cpu") -> tuple[str, Any]:
    """(kind, content) of the checkpoint ``spec`` names, refused unless it can act: a module,
    or a BenchMARL checkpoint in its experiment's folder."""
    path = Path(spec)
    if not path.is_file():
        raise ConfigError(
            f"{key}={spec!r} is neither an existing file nor an import path; allowed: {_FORMS}"
        )
    kind, content = _load_file(key, path, device)
    if kind == "vdtn":
        raise ConfigError(
            f"{key}={spec!r} is a vdtn-marl run checkpoint; evaluate it with `vdtn-marl eval "
            f"checkpoint={spec}`, or save its actor as a module (docs/leaderboard.md, "
            "Submissions); allowed here: " + _FORMS
        )
    if kind == "benchmarl":
        _benchmarl_config(key, path)
    return kind, content


def _benchmarl_config(key: str, path: Path) -> Path:
    """The ``config.pkl`` BenchMARL wrote in the experiment's folder, two levels above its
    checkpoints (``<experiment>/checkpoints/checkpoint_<frames>.pt``)."""
    config = path.resolve().parent.parent / "config.pkl"
    if not config.is_file():
        raise ConfigError(
            f"{key}={str(path)!r} is a BenchMARL checkpoint outside its experiment's folder: "
            f"BenchMARL rebuilds the policy from {config}, which does not exist; name the "
            "checkpoint in <experiment>/checkpoints/"
        )
    return config


class ModulePolicy:
    """A plain ``torch.nn.Module`` as a policy: observations → actions, without gradients, on
    the module's device; discrete actions (RRA) as integers."""

    def __init__(self, module, discrete: bool):
        self.module = module.eval()
        self.discrete = discrete

    def __call__(self, observation):
        import torch

        with torch.no_grad():
            action = self.module(torch.as_tensor(observation, dtype=torch.float32))
        if self.discrete:
            action = action.long()
        return action


def load_policy(key: str, spec: str, params, seed: int, device: Any = "cpu") -> Callable:
    """The policy ``spec`` names for ``key`` (see the module doc), on ``device``."""
    _check_key_and_spec(key, spec)
    group, expects = POLICY_KEYS[key]
    if is_import_path(spec):
        try:
            policy = resolve_factory(key, spec)(params, seed)
        except ConfigError:
            raise
        except Exception as exc:
            raise ConfigError(
                f"{key}={spec!r}: the factory raised {type(exc).__name__}: {exc}"
            ) from exc
        if not callable(policy):
            raise ConfigError(
                f"{key}={spec!r}: the factory returned a {type(policy).__name__}, not a "
                f"callable policy ({expects})"
            )
        return policy
    kind, content = _policy_file(key, spec, device)
    if kind == "benchmarl":
        content = benchmarl_policy(key, Path(spec), device)  # a TensorDict module
    return module_policy(content, group)


def module_policy(module, group: str) -> Callable:
    """A TensorDict module (reads ``(group, "observation")``) as a deterministic policy, or a
    plain module as :class:`ModulePolicy`."""
    from tensordict.nn import TensorDictModuleBase

    from vdtn_marl.algos.ppo import ActorPolicy

    if isinstance(module, TensorDictModuleBase):
        module.eval()
        return ActorPolicy(module, group)
    return ModulePolicy(module, discrete=group == "rra")


def benchmarl_policy(key: str, path: Path, device: Any = "cpu"):
    """The policy of a BenchMARL experiment's checkpoint: BenchMARL rebuilds the experiment
    from the ``config.pkl`` it wrote in the experiment's folder
    (``Experiment.reload_from_file``), with loggers off and its folder in a scratch directory
    (nothing is written beside the checkpoint)."""
    import tempfile

    _benchmarl_config(key, path)
    # registers the vdtn tasks the pickled config names (or names the extra to install)
    importlib.import_module("vdtn_marl.integrations.benchmarl")
    from benchmarl.experiment import Experiment

    with tempfile.TemporaryDirectory(prefix="vdtn-benchmarl-") as scratch:
        patch = {
            "save_folder": scratch, "loggers": [], "render": False, "checkpoint_at_end": False,
            "checkpoint_interval": 0, "sampling_device": str(device),
            "train_device": str(device), "buffer_device": str(device),
            "restore_map_location": str(device),
        }  # fmt: skip
        try:
            experiment = Experiment.reload_from_file(str(path.resolve()), experiment_patch=patch)
        except Exception as exc:
            raise ConfigError(
                f"{key}={str(path)!r}: BenchMARL could not rebuild its experiment "
                f"({type(exc).__name__}: {exc})"
            ) from exc
    return experiment.policy
