"""The registries of the non-learned policies, and their factories.

:data:`RRA_BASELINES` and :data:`CONTROL_BASELINES` are the only lists of names: the factories
:func:`make_rra_baseline` and :func:`make_control_baseline`, the config's ``rra`` and
``control`` choices and the tests read them. Each entry imports its policy's module when it
builds one, so reading the registries (the config schema does) imports neither torch nor a
solver.

A new RRA baseline is its class (a file of its own in this package, with ``from_params``),
one line in :data:`RRA_BASELINES` and ``conf/rra/<name>.yaml``; a new control baseline its
class, one entry in :data:`CONTROL_BASELINES` and ``conf/control/<name>.yaml``
(docs/registry.md).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from vdtn_marl.sim.params import PlatoonParams, TwinParams

if TYPE_CHECKING:
    from vdtn_marl.sim.twin import DigitalTwin


# ------------------------------------------------------------------------------------- RRA
#: The non-learned RRA policies, ``rra=<name>`` → ``"module:Class"`` of the policy, imported
#: when first built: a class with ``from_params(params: TwinParams, seed: int | None)``.
#: ``seed`` seeds the random one; the others are deterministic. Round robin, greedy and
#: opportunistic transmit at the highest power level.
RRA_BASELINES: dict[str, str] = {
    "random": "vdtn_marl.policies.rra:RandomRRAPolicy",
    "round_robin": "vdtn_marl.policies.rra:RoundRobinRRAPolicy",
    "greedy": "vdtn_marl.policies.rra:GreedyRRAPolicy",
    "opportunistic": "vdtn_marl.policies.opportunistic:OpportunisticRRAPolicy",
    "silent": "vdtn_marl.policies.rra:SilentRRAPolicy",
}


def rra_baseline_class(name: str) -> type:
    """The class of the RRA baseline ``name`` (imported on first use)."""
    if name not in RRA_BASELINES:
        raise ValueError(
            f"RRA baseline {name!r} is not one of {', '.join(repr(k) for k in RRA_BASELINES)}"
        )
    module, _, attribute = RRA_BASELINES[name].partition(":")
    return getattr(importlib.import_module(module), attribute)


# --------------------------------------------------------------------------------- control
@dataclass(frozen=True)
class ControlBaseline:
    """How to build one control baseline, and what it needs."""

    build: Callable[..., Any]  # (platoon: PlatoonParams, **options) -> controller
    needs_twin: bool  # reads the twin's true state: bound to a twin with ``.bind(twin)``
    solver_steps: bool = False  # takes ``control.mpc_iterations``
    in_runs: bool = True  # ``control=<name>`` may drive a run's followers


def _cacc(platoon: PlatoonParams, **options):
    from vdtn_marl.policies.cacc import CACCController

    return CACCController(platoon, **options)


def _oracle(platoon: PlatoonParams, **options):
    from vdtn_marl.policies.mpc_oracle import OracleController

    return OracleController(**options)


def _causal_mpc(platoon: PlatoonParams, **options):
    from vdtn_marl.policies.mpc_oracle import CAUSAL_MPC_ITERATIONS, OracleController

    options.setdefault("preview_intervals", 0)
    options.setdefault("iterations", CAUSAL_MPC_ITERATIONS)
    return OracleController(**options)


def _exact_oracle(platoon: PlatoonParams, **options):
    from vdtn_marl.policies.exact_oracle import ExactOracleController

    return ExactOracleController(**options)


#: The non-learned control policies, name → :class:`ControlBaseline`. ``exact_oracle`` (one
#: linear program per episode, perfect observation only) is the lower bound of the studies,
#: not a control a run can act with.
CONTROL_BASELINES: dict[str, ControlBaseline] = {
    "cacc": ControlBaseline(_cacc, needs_twin=False),
    "oracle": ControlBaseline(_oracle, needs_twin=True, solver_steps=True),
    "causal_mpc": ControlBaseline(_causal_mpc, needs_twin=True, solver_steps=True),
    "exact_oracle": ControlBaseline(_exact_oracle, needs_twin=True, in_runs=False),
}


# ------------------------------------------------------------------------------- factories
def _twin_and_params(given, allowed: tuple[type, ...]):
    """(the twin or None, its parameters) of a twin, of parameters of an ``allowed`` type, or
    of None (``TwinParams()``)."""
    from vdtn_marl.sim.twin import DigitalTwin  # imports torch: only when a policy is built

    if given is None:
        return None, TwinParams()
    if isinstance(given, DigitalTwin):
        return given, given.params
    if isinstance(given, allowed):
        return None, given
    names = ["DigitalTwin", *(t.__name__ for t in allowed)]
    expected = " or ".join(names) if len(names) == 2 else f"{', '.join(names[:-1])} or {names[-1]}"
    raise TypeError(f"expected a {expected}, got {type(given).__name__}")


def make_rra_baseline(
    name: str, twin_or_params: DigitalTwin | TwinParams | None = None, seed: int | None = None
):
    """An RRA baseline by name, one of :data:`RRA_BASELINES` (``"random"``, ``"round_robin"``,
    ``"greedy"``, ...).

    Sizes (L links, M sub-channels, P power levels) come from the twin or the parameters
    (default ``TwinParams()``). ``seed`` seeds ``"random"`` (the others are deterministic).
    """
    policy_class = rra_baseline_class(name)
    _, params = _twin_and_params(twin_or_params, (TwinParams,))
    return policy_class.from_params(params, seed)


def make_control_baseline(
    name: str, params: DigitalTwin | TwinParams | PlatoonParams | None = None, **kwargs
):
    """A control baseline by name, one of :data:`CONTROL_BASELINES` (``"cacc"``, ``"oracle"``,
    ``"causal_mpc"``, ``"exact_oracle"``).

    ``"cacc"`` returns a :class:`~vdtn_marl.policies.cacc.CACCController` for the platoon
    parameters (observations ``[B, F, 8]`` → commands ``[B, F]``). ``"oracle"`` needs the
    twin's true state: given a :class:`~vdtn_marl.sim.twin.DigitalTwin` it returns the bound
    callable ``OracleController(**kwargs).bind(twin)``; given parameters it returns the unbound
    :class:`~vdtn_marl.policies.mpc_oracle.OracleController` — call ``.bind(twin)`` before
    using it as a control module. ``"causal_mpc"`` is the same controller with
    ``preview_intervals=0`` (no knowledge of the leader's future) and
    :data:`~vdtn_marl.policies.mpc_oracle.CAUSAL_MPC_ITERATIONS` solver steps.
    ``"exact_oracle"``: the :class:`~vdtn_marl.policies.exact_oracle.ExactOracleController`,
    the exact lower bound with perfect observation (bound likewise; a twin with radio raises).
    ``kwargs`` go to the controller's constructor.
    """
    if name not in CONTROL_BASELINES:
        raise ValueError(
            f"control baseline {name!r} is not one of "
            f"{', '.join(repr(k) for k in CONTROL_BASELINES)}"
        )
    twin, given = _twin_and_params(params, (TwinParams, PlatoonParams))
    platoon = given if isinstance(given, PlatoonParams) else given.platoon
    entry = CONTROL_BASELINES[name]
    controller = entry.build(platoon, **kwargs)
    return controller.bind(twin) if entry.needs_twin and twin is not None else controller
