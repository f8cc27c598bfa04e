"""The registry of non-learned control baselines, read by
:func:`vdtn_marl.algos.baselines.make_control_baseline`, the config's ``control`` choices and
the tests. Each entry builds its controller from the platoon parameters and keyword options,
importing its module on first use (so reading the registry imports no solver).

A new control baseline is its class, one entry here and ``conf/control/<name>.yaml``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from vdtn_marl.sim.params import PlatoonParams


@dataclass(frozen=True)
class ControlBaseline:
    """How to build one baseline, and what it needs."""

    build: Callable[..., Any]  # (platoon: PlatoonParams, **options) -> controller
    needs_twin: bool  # reads the twin's true state: bound to a twin with ``.bind(twin)``
    solver_steps: bool = False  # takes ``control.mpc_iterations``
    in_runs: bool = True  # ``control=<name>`` may drive a run's followers


def _cacc(platoon: PlatoonParams, **options):
    from vdtn_marl.sim.cacc import CACCController

    return CACCController(platoon, **options)


def _oracle(platoon: PlatoonParams, **options):
    from vdtn_marl.algos.mpc_oracle import OracleController

    return OracleController(**options)


def _causal_mpc(platoon: PlatoonParams, **options):
    from vdtn_marl.algos.mpc_oracle import CAUSAL_MPC_ITERATIONS, OracleController

    options.setdefault("preview_intervals", 0)
    options.setdefault("iterations", CAUSAL_MPC_ITERATIONS)
    return OracleController(**options)


def _exact_oracle(platoon: PlatoonParams, **options):
    from vdtn_marl.algos.exact_oracle import ExactOracleController

    return ExactOracleController(**options)


#: name → :class:`ControlBaseline`. ``exact_oracle`` (one linear program per episode, perfect
#: observation only) is the lower bound of the studies, not a control a run can act with.
CONTROL_BASELINES: dict[str, ControlBaseline] = {
    "cacc": ControlBaseline(_cacc, needs_twin=False),
    "oracle": ControlBaseline(_oracle, needs_twin=True, solver_steps=True),
    "causal_mpc": ControlBaseline(_causal_mpc, needs_twin=True, solver_steps=True),
    "exact_oracle": ControlBaseline(_exact_oracle, needs_twin=True, in_runs=False),
}
