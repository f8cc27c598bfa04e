"""Environment registry: ``make``, ``register``, ``spec``, ``list_envs`` (re-exported by
:mod:`vdtn_marl`).

Ids have the form ``namespace/name-vN``. Entry points are either callables or strings
``"module.path:ClassName"`` that are imported only when :func:`make` is called, so registering an
environment never imports torch or the simulator.

Third-party packages add environments through the ``vdtn_marl.envs`` entry-point group: every
entry point in that group is a zero-argument callable that calls :func:`register`. The group is
loaded once, on the first call of :func:`make`, :func:`list_envs` or :func:`spec`. A plugin that
fails emits a :class:`PluginLoadWarning` and is skipped.

Every spec names its ``api``: ``"pettingzoo"`` (a PettingZoo ``ParallelEnv``, most ids) or
``"gymnasium"`` (a single-agent ``gymnasium.Env``). A spec with a ``vector_entry_point`` also
has a batched face, made with ``make(id, batch_size=B)`` (the TorchRL ``VDTNTorchRLEnv`` of B
scenarios for the built-in ids), like Gymnasium's ``vector_entry_point``.

The ``"gymnasium"``-API ids are registered with Gymnasium's registry too, under the same ids
(namespace ``vdtn``), so ``gymnasium.make("vdtn/platoon-control-central-v0")`` works after
``import vdtn_marl``, in either order of the two imports. ``import vdtn_marl`` does not import
Gymnasium for that (it would triple the import's time): when Gymnasium is not imported yet, a
finder on ``sys.meta_path`` registers them as soon as ``import gymnasium`` has run, and goes.

Versions follow Gymnasium's rule: an environment whose default dynamics change gets a new
``-vN``, and :func:`make` (and :func:`spec`) of the id it supersedes raises a
:class:`DeprecatedEnvError` that names the new id, what changed and how to get the old
behaviour back. Superseded ids are not listed by :func:`list_envs`. Version history of the
built-in ids: docs/model.md ("Version history").
"""

from __future__ import annotations

import difflib
import importlib
import importlib.abc
import importlib.util
import re
import sys
import threading
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import metadata
from typing import Any

from vdtn_marl.errors import ConfigError, DeprecatedEnvError, UnknownEnvError

__all__ = [
    "APIS",
    "ENTRY_POINT_GROUP",
    "DeprecatedEnvError",
    "EnvSpec",
    "PluginLoadWarning",
    "UnknownEnvError",
    "list_envs",
    "make",
    "register",
    "register_with_gymnasium",
    "spec",
]

ENTRY_POINT_GROUP = "vdtn_marl.envs"

#: The APIs an environment may follow: ``"pettingzoo"`` (``pettingzoo.ParallelEnv``) or
#: ``"gymnasium"`` (a single-agent ``gymnasium.Env``).
APIS = ("pettingzoo", "gymnasium")

_ID_RE = re.compile(r"^[\w.-]+/[\w.-]+-v\d+$")
_ID_FORM = "'namespace/name-vN' (e.g. 'vdtn/platoon-control-v0')"


@dataclass(frozen=True)
class _Superseded:
    new_id: str
    changes: tuple[str, ...]  # what the new version changes, one entry per change
    hint: str  # how to get the old behaviour from the new id

    def message(self, old_id: str) -> str:
        version = self.new_id.rsplit("-", 1)[1]
        msg = f"{old_id} is superseded by {self.new_id} ({version}: {'; '.join(self.changes)})"
        return msg + (f"; {self.hint}" if self.hint else "")


class PluginLoadWarning(RuntimeWarning):
    """A ``vdtn_marl.envs`` entry point could not be loaded; the registry stays usable."""


@dataclass(frozen=True)
class EnvSpec:
    """Everything the registry knows about one environment id."""

    id: str
    entry_point: str | Callable[..., Any]
    kwargs: dict[str, Any] = field(default_factory=dict, hash=False)
    agents: str = ""
    clocks: dict[str, int] = field(default_factory=dict, hash=False)
    description: str = ""
    data_source: str = ""
    uses_traces: bool = False
    api: str = "pettingzoo"
    vector_entry_point: str | Callable[..., Any] | None = None
    vector_kwargs: dict[str, Any] = field(default_factory=dict, hash=False)

    @property
    def data_sources(self) -> dict[str, dict[str, Any]]:
        """Trace sets selectable with the ``traces=`` kwarg, with their provenance.

        ``{name: {"name", "description", "synthetic", "source", "license"}}`` for an
        environment driven by leader traces (``uses_traces``), else ``{}``. Imports
        :mod:`vdtn_marl.data` (and torch) on first use only.
        """
        if not self.uses_traces:
            return {}
        from vdtn_marl.data import trace_set_provenance

        return trace_set_provenance()

    def load(self) -> Callable[..., Any]:
        """Return the entry point callable, importing it if it is a ``"module:attr"`` string."""
        return _load_entry_point(self.entry_point, self.id)

    def make(self, **kwargs: Any) -> Any:
        """Instantiate the environment with the registered defaults updated by ``kwargs``."""
        return self.load()(**{**self.kwargs, **kwargs})

    def make_batched(self, batch_size: int, **kwargs: Any) -> Any:
        """Instantiate the batched face (``vector_entry_point``) of ``batch_size`` scenarios
        with ``vector_kwargs`` updated by ``kwargs``; a :class:`ConfigError` for an id without
        one, naming the ids that have one."""
        if self.vector_entry_point is None:
            batched = [s.id for s in _REGISTRY.values() if s.vector_entry_point is not None]
            raise ConfigError(
                f"env {self.id!r} has no batched face (batch_size={batch_size!r}); ids with "
                f"one: {', '.join(sorted(batched)) or '(none)'}"
            )
        factory = _load_entry_point(self.vector_entry_point, self.id)
        return factory(**{**self.vector_kwargs, **kwargs, "batch_size": batch_size})


def _load_entry_point(entry_point: str | Callable[..., Any], env_id: str) -> Callable[..., Any]:
    if callable(entry_point):
        return entry_point
    module_name, _, attr_path = entry_point.partition(":")
    try:
        obj: Any = importlib.import_module(module_name)
        for part in attr_path.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise ImportError(
            f"cannot load entry point {entry_point!r} of env {env_id!r}: "
            f"{type(exc).__name__}: {exc}"
        ) from exc
    return obj


def _check_entry_point(entry_point: object, env_id: str, what: str = "entry point") -> None:
    if isinstance(entry_point, str):
        module_name, sep, attr_path = entry_point.partition(":")
        if not (module_name and sep and attr_path):
            raise ValueError(
                f"invalid {what} {entry_point!r} for env {env_id!r}: "
                "expected 'module.path:ClassName' or a callable"
            )
    elif not callable(entry_point):
        raise TypeError(f"{what} of env {env_id!r} must be a string or a callable")


_REGISTRY: dict[str, EnvSpec] = {}
_SUPERSEDED: dict[str, _Superseded] = {}
_PLUGINS_LOADED = False
_PLUGIN_LOCK = threading.RLock()
_GYMNASIUM_SYNCED = False  # whether register() also registers "gymnasium" ids with Gymnasium


def register(
    env_id: str,
    entry_point: str | Callable[..., Any],
    *,
    agents: str = "",
    clocks: dict[str, int] | None = None,
    description: str = "",
    data_source: str = "",
    uses_traces: bool = False,
    api: str = "pettingzoo",
    vector_entry_point: str | Callable[..., Any] | None = None,
    vector_kwargs: dict[str, Any] | None = None,
    override: bool = False,
    **defaults: Any,
) -> EnvSpec:
    """Register ``env_id``; extra keyword arguments become the default constructor kwargs.

    Raises ``ValueError`` for an id not of the form ``namespace/name-vN``, for a malformed
    entry-point string, for an ``api`` not in :data:`APIS`, and for an id that is already
    registered (unless ``override=True``). ``uses_traces=True`` marks an environment that takes
    the ``traces=`` kwarg: its spec lists the trace sets and their provenance
    (:attr:`EnvSpec.data_sources`). ``vector_entry_point`` (called with ``batch_size=B``, the
    ``vector_kwargs`` and the caller's kwargs) is the batched face that
    ``make(env_id, batch_size=B)`` builds.
    """
    if not isinstance(env_id, str) or not _ID_RE.match(env_id):
        raise ValueError(f"invalid env id {env_id!r}: expected the form {_ID_FORM}")
    _check_entry_point(entry_point, env_id)
    if vector_entry_point is not None:
        _check_entry_point(vector_entry_point, env_id, "vector entry point")
    if api not in APIS:
        raise ValueError(f"api={api!r} of env {env_id!r} must be one of {APIS}")
    if env_id in _REGISTRY and not override:
        raise ValueError(
            f"env id {env_id!r} is already registered "
            f"(entry point {_REGISTRY[env_id].entry_point!r}); pass override=True to replace it"
        )
    clocks = dict(clocks or {})
    for kind, period in clocks.items():
        if not isinstance(period, int) or isinstance(period, bool) or period < 1:
            raise ValueError(
                f"clock period of agent kind {kind!r} in env {env_id!r} must be a positive "
                f"integer number of 1 ms subframes, got {period!r}"
            )
    env_spec = EnvSpec(
        id=env_id,
        entry_point=entry_point,
        kwargs=dict(defaults),
        agents=agents,
        clocks=clocks,
        description=description,
        data_source=data_source,
        uses_traces=bool(uses_traces),
        api=api,
        vector_entry_point=vector_entry_point,
        vector_kwargs=dict(vector_kwargs or {}),
    )
    _REGISTRY[env_id] = env_spec
    if api == "gymnasium" and _GYMNASIUM_SYNCED:  # e.g. a plugin loaded after Gymnasium
        _to_gymnasium(env_spec, replace=override)
    return env_spec


def make(env_id: str, *, batch_size: int | None = None, **kwargs: Any) -> Any:
    """Create the environment ``env_id``; ``kwargs`` override the registered defaults.

    With ``batch_size=B``, its batched face of B scenarios instead (the spec's
    ``vector_entry_point``: a TorchRL ``VDTNTorchRLEnv`` for the built-in ids).
    """
    env_spec = spec(env_id)
    if batch_size is None:
        return env_spec.make(**kwargs)
    return env_spec.make_batched(batch_size, **kwargs)


def spec(env_id: str) -> EnvSpec:
    """Return the :class:`EnvSpec` of ``env_id``.

    Raises :class:`DeprecatedEnvError` for an id that a newer version supersedes and
    :class:`UnknownEnvError` for any other id that is not registered.
    """
    _load_plugins()
    try:
        return _REGISTRY[env_id]
    except KeyError:
        if env_id in _SUPERSEDED:
            raise DeprecatedEnvError(_SUPERSEDED[env_id].message(env_id)) from None
        raise UnknownEnvError(_unknown_message(env_id)) from None


def list_envs(api: str | None = None) -> list[str]:
    """All registered ids, sorted; with ``api`` (one of :data:`APIS`), those of that API."""
    _load_plugins()
    if api is None:
        return sorted(_REGISTRY)
    if api not in APIS:
        raise ValueError(f"api={api!r} must be one of {APIS}")
    return sorted(env_id for env_id, s in _REGISTRY.items() if s.api == api)


def _supersede(old_id: str, new_id: str, changes: list[str] | tuple[str, ...], hint: str) -> None:
    """Mark ``old_id`` as superseded by the registered ``new_id``: :func:`make` of it raises
    :class:`DeprecatedEnvError` (unless someone registers ``old_id`` again)."""
    if new_id not in _REGISTRY:
        raise ValueError(f"{new_id!r}, which supersedes {old_id!r}, is not registered")
    _SUPERSEDED[old_id] = _Superseded(new_id, tuple(changes), hint)


def _unknown_message(env_id: object) -> str:
    known = sorted(_REGISTRY)
    msg = f"unknown env id {env_id!r}"
    close = difflib.get_close_matches(str(env_id), known, n=1)
    if close:
        msg += f"; did you mean {close[0]!r}?"
    return msg + f" known: {', '.join(known) if known else '(none)'}"


def _load_plugins() -> None:
    """Load the ``vdtn_marl.envs`` entry-point group once."""
    global _PLUGINS_LOADED
    if _PLUGINS_LOADED:
        return
    with _PLUGIN_LOCK:
        if _PLUGINS_LOADED:
            return
        # Set first: a plugin that calls list_envs()/make() must not recurse into loading.
        _PLUGINS_LOADED = True
        try:
            eps = list(metadata.entry_points(group=ENTRY_POINT_GROUP))
        except Exception as exc:  # a broken distribution on sys.path
            warnings.warn(
                f"could not list the {ENTRY_POINT_GROUP!r} entry points: "
                f"{type(exc).__name__}: {exc}",
                PluginLoadWarning,
                stacklevel=3,
            )
            return
        for ep in eps:
            dist = getattr(ep, "dist", None)
            origin = f" from distribution {dist.name!r}" if dist is not None else ""
            try:
                hook = ep.load()
                if not callable(hook):
                    raise TypeError(f"{ep.value!r} is not callable")
                hook()
            except Exception as exc:
                warnings.warn(
                    f"vdtn_marl env plugin {ep.name!r} ({ep.value}){origin} failed and was "
                    f"skipped: {type(exc).__name__}: {exc}",
                    PluginLoadWarning,
                    stacklevel=3,
                )


# --- Gymnasium's registry ------------------------------------------------------------------
def _to_gymnasium(env_spec: EnvSpec, replace: bool = False) -> None:
    import gymnasium

    if replace:
        gymnasium.registry.pop(env_spec.id, None)
    if env_spec.id not in gymnasium.registry:
        gymnasium.register(env_spec.id, entry_point=env_spec.entry_point, kwargs=env_spec.kwargs)


def register_with_gymnasium() -> list[str]:
    """Register every ``"gymnasium"``-API id of this registry (plugins' included) with
    Gymnasium's, each with its entry point and defaults (an id Gymnasium already has is left as
    it is); ids registered later follow. Imports Gymnasium; returns the ids."""
    global _GYMNASIUM_SYNCED
    ids = list_envs(api="gymnasium")
    for env_id in ids:
        _to_gymnasium(_REGISTRY[env_id])
    _GYMNASIUM_SYNCED = True
    return ids


class _ThenRegister(importlib.abc.Loader):
    """Gymnasium's own loader, then :func:`register_with_gymnasium` (see the module doc)."""

    def __init__(self, loader, finder: _WhenGymnasiumLoads):
        self.loader, self.finder = loader, finder

    def create_module(self, module_spec):
        return self.loader.create_module(module_spec)

    def exec_module(self, module) -> None:
        module.__loader__ = module.__spec__.loader = self.loader  # as if we were not there
        self.loader.exec_module(module)
        if self.finder in sys.meta_path:
            sys.meta_path.remove(self.finder)
        try:
            register_with_gymnasium()
        except Exception as exc:  # never make `import gymnasium` fail
            warnings.warn(
                f"vdtn-marl could not register its Gymnasium ids with Gymnasium: "
                f"{type(exc).__name__}: {exc}; use gymnasium.make('vdtn_marl.envs.central:<id>')",
                RuntimeWarning,
                stacklevel=2,
            )


class _WhenGymnasiumLoads(importlib.abc.MetaPathFinder):
    """Finds nothing itself: hands ``import gymnasium`` the spec the other finders find, with a
    loader that registers vdtn-marl's Gymnasium ids once Gymnasium has run."""

    def __init__(self):
        self._finding = False

    def find_spec(self, fullname, path=None, target=None):
        if fullname != "gymnasium" or self._finding:
            return None
        self._finding = True
        try:
            found = importlib.util.find_spec(fullname)
        finally:
            self._finding = False
        if found is None or not hasattr(found.loader, "exec_module"):
            return None
        found.loader = _ThenRegister(found.loader, self)
        return found


def _sync_with_gymnasium() -> None:
    """Register the Gymnasium ids with Gymnasium now if it is imported, else when it is."""
    if "gymnasium" in sys.modules:
        register_with_gymnasium()
    elif not any(isinstance(f, _WhenGymnasiumLoads) for f in sys.meta_path):
        sys.meta_path.insert(0, _WhenGymnasiumLoads())


def _reset_plugins_for_tests() -> None:
    """Forget that plugins were loaded so that the next registry call scans them again."""
    global _PLUGINS_LOADED
    with _PLUGIN_LOCK:
        _PLUGINS_LOADED = False


# --- built-in environments -----------------------------------------------------------------
# Lazy string entry points: nothing below imports the simulator or torch.
TRACES_NOTE = (
    "leader speed trace set, by name (kwarg `traces`, default udds; provenance of each "
    "in EnvSpec.data_sources) or a TraceSource (kwarg `trace_source`)"
)
BATCHED = "vdtn_marl.envs.torchrl:VDTNTorchRLEnv"  # make(id, batch_size=B): B scenarios, TorchRL

register(
    "vdtn/platoon-control-v0",
    "vdtn_marl.envs.control:PlatoonControlEnv",
    agents="vehicle_1..vehicle_{N-1} (followers)",
    clocks={"vehicle": 50},
    description="platoon control, one step = one 50 ms control interval, perfect observation",
    data_source=TRACES_NOTE,
    uses_traces=True,
    vector_entry_point=BATCHED,
    vector_kwargs={"mode": "control"},
    impaired=False,
)
register(
    "vdtn/platoon-control-impaired-v1",
    "vdtn_marl.envs.control:PlatoonControlEnv",
    agents="vehicle_1..vehicle_{N-1} (followers)",
    clocks={"vehicle": 50},
    description=(
        "platoon control, one step = one 50 ms control interval; observations arrive through "
        "CAMs with the delay/loss of the C-V2X link layer, driven by an RRA policy "
        "(random by default)"
    ),
    data_source=TRACES_NOTE,
    uses_traces=True,
    vector_entry_point=BATCHED,
    vector_kwargs={"mode": "control_impaired"},
    impaired=True,
)
register(
    "vdtn/v2x-rra-v1",
    "vdtn_marl.envs.radio:V2XRRAEnv",
    agents="rra_1..rra_{N-1} (base-station RRA agent of each V2V link)",
    clocks={"rra": 1},
    description=(
        "C-V2X radio resource allocation, one step = one 1 ms subframe; the platoon is driven "
        "by a control module inside the environment"
    ),
    data_source=TRACES_NOTE,
    uses_traces=True,
    vector_entry_point=BATCHED,
    vector_kwargs={"mode": "rra"},
)
register(
    "vdtn/vdtn-joint-v1",
    "vdtn_marl.envs.two_timescale:TwoTimescaleEnv",
    agents=(
        "vehicle_1..vehicle_{N-1} (followers, every 50 ms) and "
        "rra_1..rra_{N-1} (RRA agent of each V2V link, every 1 ms)"
    ),
    clocks={"vehicle": 50, "rra": 1},
    description=(
        "joint two-timescale platoon control and C-V2X radio resource allocation; "
        "vehicles act every 50 ms, RRA agents every 1 ms subframe"
    ),
    data_source=TRACES_NOTE,
    uses_traces=True,
    vector_entry_point=BATCHED,
    vector_kwargs={"mode": "joint"},
)

CENTRAL_AGENTS = "one agent: the commands of all followers vehicle_1..vehicle_{N-1} together"
register(
    "vdtn/platoon-control-central-v0",
    "vdtn_marl.envs.central:CentralControlEnv",
    agents=CENTRAL_AGENTS,
    clocks={"vehicle": 50},
    description=(
        "Gymnasium single-agent face of vdtn/platoon-control-v0: centralised control of all "
        "followers, one Box action of all commands, one observation vector, team reward"
    ),
    data_source=TRACES_NOTE,
    uses_traces=True,
    api="gymnasium",
    impaired=False,
)
register(
    "vdtn/platoon-control-impaired-central-v1",
    "vdtn_marl.envs.central:CentralControlEnv",
    agents=CENTRAL_AGENTS,
    clocks={"vehicle": 50},
    description=(
        "Gymnasium single-agent face of vdtn/platoon-control-impaired-v1: centralised control "
        "of all followers on CAMs that cross the C-V2X link layer"
    ),
    data_source=TRACES_NOTE,
    uses_traces=True,
    api="gymnasium",
    impaired=True,
)

# --- superseded versions -------------------------------------------------------------------
# What each version changed, one entry per change (docs/model.md, "Version history"); an id is
# bumped when its default dynamics change. vdtn/platoon-control-v0 has no radio: still v0.
V1_CHANNEL_CHANGE = (
    "V2V path loss WINNER+ B1 with effective antenna heights and a free-space floor by "
    "default, was Liang et al.'s form"
)
V1_RRA_OBSERVATION_CHANGE = (
    "RRA observation (what RRA agents and policies read) of 4M + 12 features, was 4M + 6: the "
    "recipient's CAM content age, its last 3 CAM delays and 2 earlier commands appended "
    "(vdtn_marl.sim.layout)"
)
V0_CHANNEL_HINT = "for v0's channel pass v2v_pathloss_form='liang'"
VERSION_CHANGES: dict[str, tuple[str, ...]] = {
    "vdtn/platoon-control-impaired-v1": (V1_CHANNEL_CHANGE, V1_RRA_OBSERVATION_CHANGE),
    "vdtn/v2x-rra-v1": (V1_CHANNEL_CHANGE, V1_RRA_OBSERVATION_CHANGE),
    "vdtn/vdtn-joint-v1": (V1_CHANNEL_CHANGE, V1_RRA_OBSERVATION_CHANGE),
    # a face of the impaired dynamics, versioned with them
    "vdtn/platoon-control-impaired-central-v1": (V1_CHANNEL_CHANGE, V1_RRA_OBSERVATION_CHANGE),
}
"""Changes of each built-in id against its previous version (what DeprecatedEnvError says)."""
for _new_id, _changes in VERSION_CHANGES.items():
    _supersede(_new_id.removesuffix("-v1") + "-v0", _new_id, _changes, V0_CHANNEL_HINT)

_sync_with_gymnasium()  # last: every built-in id is registered
