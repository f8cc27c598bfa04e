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
path (the factory exists and is callable) and reads a checkpoint far enough to know its kind;
:func:`probe_policy` then builds the policy and calls it once on an observation of the run's
model: a TensorDict module must read its group's observation (an RRA policy is not a control
policy) and have the run's number of agents, and the output must be a tensor of shape ``[B, L]``
(``[B, F]``), integers in ``[0, M·P)`` for RRA actions, finite commands within the platoon's
acceleration limits for control. :func:`load_policy` builds the policy for a run, as a
:class:`CheckedPolicy`: a call that raises or returns what the run cannot use is a
:class:`~vdtn_marl.errors.PolicyError` naming the policy and the call (shape and dtype are
checked on every call, and so are its values: one ``aminmax`` per call, a few µs against a
subframe's hundreds).
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from vdtn_marl.errors import ConfigError, PolicyError

#: config key → (the group whose observations the policy reads, what it is)
POLICY_KEYS: dict[str, tuple[str, str]] = {
    "rra.policy": ("rra", "RRA observations [B, L, D] → actions [B, L]"),
    "control.policy": ("vehicle", "vehicle observations [B, F, 8] → commands [B, F] (m/s²)"),
}
#: the kinds of checkpoint a ``.pt`` file may be (``vdtn`` is a vdtn-marl run's own)
CHECKPOINT_KINDS = ("module", "benchmarl", "vdtn")
#: how far a command may pass the acceleration limits (float32 rounding of the limits), m/s²
ACCEL_TOLERANCE_MPS2 = 1e-5
#: the scenarios of the observation a policy is called on at validation
PROBE_SCENARIOS = 2
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
    the module's device. Discrete actions (RRA) may come as floats holding whole numbers: its
    :class:`CheckedPolicy` checks them and makes them integers (``whole_floats``)."""

    def __init__(self, module, discrete: bool):
        self.module = module.eval()
        self.discrete = discrete
        self.whole_floats = discrete

    def __call__(self, observation):
        import torch

        with torch.no_grad():
            return self.module(torch.as_tensor(observation, dtype=torch.float32))


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
        return CheckedPolicy(policy, OutputCheck.of(key, spec, params))
    kind, content = _policy_file(key, spec, device)
    if kind == "benchmarl":
        content = benchmarl_policy(key, Path(spec), device)  # a TensorDict module
    _check_group(key, spec, content)
    policy = module_policy(content, group)
    whole_floats = getattr(policy, "whole_floats", False)
    return CheckedPolicy(policy, OutputCheck.of(key, spec, params, whole_floats))


def _check_group(key: str, spec: str, module) -> None:
    """A TensorDict module reads its group's observation: a control policy (``vehicle``) is
    not an RRA policy, nor the other way round."""
    in_keys = list(getattr(module, "in_keys", None) or [])
    if not in_keys or not hasattr(module, "out_keys"):  # a plain module: its output tells
        return
    group, expects = POLICY_KEYS[key]
    if (group, "observation") in in_keys:
        return
    kinds = {"rra": "an RRA policy", "vehicle": "a control policy"}
    other = next((g for g in kinds if (g, "observation") in in_keys), None)
    what = kinds[other] if other else "a policy of neither group"
    raise ConfigError(
        f"{key}={spec!r} reads {in_keys}: it is {what}; allowed for {key}: a policy reading "
        f"{(group, 'observation')}, {expects}"
    )


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


@dataclass(frozen=True)
class OutputCheck:
    """What a policy for ``key`` must return on observations ``[B, n, D]`` of the run's model:
    a tensor (or array) ``[B, n]``; RRA actions integers in ``[0, M·P)`` (``whole_floats``:
    floats holding whole numbers too, a plain module's), control commands finite and within
    the platoon's acceleration limits."""

    key: str
    spec: str
    num_actions: int
    num_subchannels: int
    num_power_levels: int
    accel_min_mps2: float
    accel_max_mps2: float
    whole_floats: bool = False

    @classmethod
    def of(cls, key: str, spec: str, params, whole_floats: bool = False) -> OutputCheck:
        radio, platoon = params.radio, params.platoon
        return cls(
            key, spec, int(radio.num_actions), int(radio.num_subchannels),
            int(radio.num_power_levels), float(platoon.accel_min_mps2),
            float(platoon.accel_max_mps2), whole_floats,
        )  # fmt: skip

    @property
    def rra(self) -> bool:
        return self.key == "rra.policy"

    @property
    def allowed(self) -> str:
        """The allowed values, as a message ends with them."""
        if self.rra:
            return (
                f"allowed: integer actions in [0, {self.num_actions - 1}] (sub-channel × power "
                f"level, {self.num_subchannels} × {self.num_power_levels})"
            )
        return (
            f"allowed: finite commands in [{self.accel_min_mps2:g}, {self.accel_max_mps2:g}] "
            "m/s² (the platoon's acceleration limits)"
        )

    def problem(self, observation, output) -> str | None:
        """What is wrong with ``output`` for ``observation`` (None: nothing): its type, shape,
        dtype and values (range, finite: a few tensor operations, which wait for an
        accelerator)."""
        import torch

        what = "actions" if self.rra else "commands"
        if not isinstance(output, torch.Tensor):
            try:
                output = torch.as_tensor(output)
            except Exception:
                return f"returned a {type(output).__name__}; {self.allowed}, a tensor [B, n]"
        expected = observation.shape[:-1]
        if output.shape != expected:
            per = "link" if self.rra else "follower"
            return (
                f"returned {what} of shape {tuple(output.shape)}; allowed: shape "
                f"{tuple(expected)}, one per {per} of the observation {list(observation.shape)}"
            )
        if output.dtype not in _dtypes(self.rra, self.whole_floats):
            return f"returned {what} of dtype {output.dtype}; {self.allowed}"
        floating = output.is_floating_point()
        if self.rra:
            low_ok, high_ok = 0, self.num_actions - 1
        else:
            low_ok = self.accel_min_mps2 - ACCEL_TOLERANCE_MPS2
            high_ok = self.accel_max_mps2 + ACCEL_TOLERANCE_MPS2
        low, high = (float(v) for v in torch.aminmax(output))  # a NaN gives NaN: refused
        whole = not (self.rra and floating) or bool((output == output.round()).all())
        if low_ok <= low and high <= high_ok and whole:
            return None
        bad = ~((output >= low_ok) & (output <= high_ok))
        if self.rra and floating:
            bad = bad | (output != output.round())
        shown = ", ".join(f"{v:g}" for v in output[bad].flatten()[:4].tolist())
        count = f"{int(bad.sum())} of {bad.numel()}"
        return f"returned {what} such as {shown} ({count}); {self.allowed}"


@functools.cache
def _dtypes(rra: bool, whole_floats: bool) -> frozenset:
    """The dtypes a policy's output may have: integers for RRA actions (floats too with
    ``whole_floats``), integers or floats for control commands."""
    import torch

    integers = {torch.uint8, torch.int8, torch.int16, torch.int32, torch.int64}
    floats = {torch.float16, torch.bfloat16, torch.float32, torch.float64}
    return frozenset(integers | floats if not rra or whole_floats else integers)


class CheckedPolicy:
    """A user's policy that says which it is when a call fails: a call that raises, or returns
    what :class:`OutputCheck` refuses, is a :class:`~vdtn_marl.errors.PolicyError` naming the
    policy and the call. Shape, dtype and values are checked on every call. The policy's
    own attributes (``seed``, ``rowwise``, ...) are the wrapper's; what ``bind(twin)`` and
    ``bound()`` return is checked too, counting the same calls."""

    def __init__(self, policy, check: OutputCheck, calls: list[int] | None = None):
        self.policy = policy
        self.check = check
        self.calls = calls if calls is not None else [0]  # shared with bind()'s and bound()'s

    def __call__(self, observation):
        self.calls[0] += 1
        call = self.calls[0]
        try:
            output = self.policy(observation)
        except Exception as exc:
            self._fail(call, observation, f"raised {type(exc).__name__}: {exc}", exc)
        problem = self.check.problem(observation, output)
        if problem is not None:
            self._fail(call, observation, problem)
        if self.check.whole_floats:
            import torch

            output = torch.as_tensor(output).long()
        return output

    def _fail(self, call: int, observation, problem: str, cause=None):
        shape = list(getattr(observation, "shape", ()))
        message = f"{self.check.key}={self.check.spec!r} failed on call {call} (observation "
        raise PolicyError(f"{message}{shape}): it {problem}", problem) from cause

    def __getattr__(self, name: str):
        policy = self.__dict__.get("policy")
        if name.startswith("__") or policy is None:
            raise AttributeError(name)
        attr = getattr(policy, name)
        if name in ("bind", "bound") and callable(attr):

            def checked(*args, **kwargs):
                return CheckedPolicy(attr(*args, **kwargs), self.check, self.calls)

            return checked
        return attr


def probe_policy(key: str, spec: str, params, seed: int) -> None:
    """Build the policy ``spec`` names for ``key`` and call it once on an observation of the
    run's model (:data:`PROBE_SCENARIOS` scenarios of a twin of ``params``, on the CPU): a
    :class:`ConfigError` naming the policy, the problem and the allowed values if it cannot
    act in the run (see the module doc)."""
    from vdtn_marl.sim.twin import DigitalTwin

    policy = load_policy(key, spec, params, seed)
    twin = DigitalTwin(params, batch_size=PROBE_SCENARIOS, seed=seed, draw_ahead=False)
    twin.reset(seed=seed)
    if key == "rra.policy":
        observation = twin.rra_observation().clone()
        agents = f"{twin.num_links} links"
    else:
        observation = twin.vehicle_observation(perfect=False)
        agents = f"{twin.num_followers} followers"
    where = (
        f"{key}={spec!r}, called once on an observation {list(observation.shape)} of the run "
        f"(scenario.num_vehicles={params.platoon.num_vehicles}: {agents})"
    )
    built_for = _agents_of(policy.policy)
    if built_for is not None and built_for != observation.shape[-2]:
        raise ConfigError(
            f"{where}: it was built for {built_for} agents; allowed: a policy for "
            f"{observation.shape[-2]} agents, {agents}"
        )
    if hasattr(policy, "bind"):
        policy = policy.bind(twin)
    if hasattr(policy, "seed"):
        policy.seed(seed)
    try:
        policy(observation)
    except PolicyError as exc:
        raise ConfigError(f"{where}: it {exc.problem}") from exc


def _agents_of(policy) -> int | None:
    """The number of agents the networks of a module policy were built for (TorchRL's and
    BenchMARL's multi-agent networks say it: ``n_agents``), None if none says."""
    import torch

    module = getattr(policy, "actor", None) or getattr(policy, "module", None)
    if not isinstance(module, torch.nn.Module):
        return None
    for part in module.modules():
        n_agents = getattr(part, "n_agents", None)
        if isinstance(n_agents, int) and not isinstance(n_agents, bool):
            return n_agents
    return None
