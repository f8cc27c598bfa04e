"""Non-learned baselines of the benchmark by name: :func:`make_rra_baseline` and
:func:`make_control_baseline` (RRA heuristics in :mod:`vdtn_marl.algos.rra_baselines`, the MPC
oracle in :mod:`vdtn_marl.algos.mpc_oracle`, the exact bound in
:mod:`vdtn_marl.algos.exact_oracle`).

Radio resource allocation (RRA) policies map RRA observations ``[..., L, D]`` (NumPy or torch,
docs/model.md §4.6) to integer actions ``[..., L]`` of the same kind, like
:class:`~vdtn_marl.envs.policies.RandomRRAPolicy`:

- ``"random"``: :class:`~vdtn_marl.envs.policies.RandomRRAPolicy` (uniform sub-channel × power).
- ``"round_robin"``: :class:`RoundRobinRRAPolicy`, link i on sub-channel (i + t) mod M at a
  fixed power level, t the subframe counter.
- ``"greedy"``: :class:`GreedyRRAPolicy`, maximum power on the sub-channel with the best
  estimated V2V SINR (own SNR against the V2I user's interference) read from the observation.

Control baselines map vehicle observations ``[B, F, 8]`` to commands ``[B, F]`` (m/s²):

- ``"cacc"``: the linear CACC on the (possibly delayed) observation,
  :class:`~vdtn_marl.sim.cacc.CACCController` (not duplicated here).
- ``"oracle"``: :class:`OracleController`, receding-horizon optimisation of the control reward
  on the twin's true state and the leader's known future trace (model-predictive control with
  preview). It reads the twin, not the observation: use :meth:`OracleController.bind` to get
  an observation → command callable. It also works with impaired observation (the command
  waits for the CAM). Its subgradient solver is approximate: with the default
  :data:`ORACLE_MPC_ITERATIONS` steps per interval its perfect-observation cost is 0.2–7.1 %
  above the exact optimum on the evaluation scenarios we measured; with 60 steps (leaderboard
  1.0) it was 19–42 % above it.
- ``"exact_oracle"``: :class:`~vdtn_marl.algos.exact_oracle.ExactOracleController`, the exact
  minimum of the episode's control cost over the known trace (a linear program solved once
  per episode): the perfect-observation lower bound on control cost.
- ``"causal_mpc"``: the same optimisation without the leader's future (it extrapolates the
  leader's present acceleration): the model-based reference for policies that observe only
  the present, such as π*.

Action encoding: see :mod:`vdtn_marl.algos.rra_baselines`.
"""

from __future__ import annotations

from vdtn_marl.algos.control_baselines import CONTROL_BASELINES
from vdtn_marl.algos.exact_oracle import (
    ExactOracleController,
)
from vdtn_marl.algos.mpc_oracle import (
    CAUSAL_MPC_ITERATIONS,
    ORACLE_MPC_ITERATIONS,
    OracleController,
)
from vdtn_marl.algos.rra_baselines import (
    RRA_BASELINES,
    GreedyRRAPolicy,
    RoundRobinRRAPolicy,
    RRAFeatureLayout,
    encode_rra_action,
    max_power_level,
)
from vdtn_marl.sim.params import PlatoonParams, TwinParams
from vdtn_marl.sim.twin import DigitalTwin

__all__ = [
    "CAUSAL_MPC_ITERATIONS",
    "CONTROL_BASELINES",
    "ExactOracleController",
    "RRA_BASELINES",
    "GreedyRRAPolicy",
    "ORACLE_MPC_ITERATIONS",
    "OracleController",
    "RRAFeatureLayout",
    "RoundRobinRRAPolicy",
    "encode_rra_action",
    "make_control_baseline",
    "make_rra_baseline",
    "max_power_level",
]


def _twin_params(twin_or_params) -> tuple[TwinParams, DigitalTwin | None]:
    if isinstance(twin_or_params, DigitalTwin):
        return twin_or_params.params, twin_or_params
    if isinstance(twin_or_params, TwinParams):
        return twin_or_params, None
    if twin_or_params is None:
        return TwinParams(), None
    raise TypeError(f"expected a DigitalTwin or TwinParams, got {type(twin_or_params).__name__}")


def make_rra_baseline(
    name: str, twin_or_params: DigitalTwin | TwinParams | None = None, seed: int | None = None
):
    """An RRA baseline by name, one of :data:`~vdtn_marl.algos.rra_baselines.RRA_BASELINES`
    (``"random"``, ``"round_robin"``, ``"greedy"``, ...).

    Sizes (L links, M sub-channels, P power levels) come from the twin or the parameters
    (default ``TwinParams()``). ``seed`` seeds ``"random"`` (the others are deterministic).
    Round robin and greedy transmit at the highest power level.
    """
    if name not in RRA_BASELINES:
        raise ValueError(
            f"RRA baseline {name!r} is not one of {', '.join(repr(k) for k in RRA_BASELINES)}"
        )
    params, _ = _twin_params(twin_or_params)
    return RRA_BASELINES[name](params, seed)


def make_control_baseline(
    name: str, params: DigitalTwin | TwinParams | PlatoonParams | None = None, **kwargs
):
    """A control baseline by name (``"cacc"``, ``"oracle"``, ``"causal_mpc"``, ``"exact_oracle"``).

    ``"cacc"`` returns a :class:`~vdtn_marl.sim.cacc.CACCController` for the platoon
    parameters (observations ``[B, F, 8]`` → commands ``[B, F]``). ``"oracle"`` needs the
    twin's true state: given a :class:`DigitalTwin` it returns the bound callable
    ``OracleController(**kwargs).bind(twin)``; given parameters it returns the unbound
    :class:`OracleController` — call ``.bind(twin)`` before using it as a control module.
    ``"causal_mpc"`` is the same controller with ``preview_intervals=0`` (no knowledge of the
    leader's future) and :data:`CAUSAL_MPC_ITERATIONS` solver steps. ``"exact_oracle"``: the
    :class:`~vdtn_marl.algos.exact_oracle.ExactOracleController`, the exact lower bound with
    perfect observation (bound likewise; a twin with radio raises). ``kwargs`` go to the
    controller's constructor.
    """
    if name not in CONTROL_BASELINES:
        raise ValueError(
            f"control baseline {name!r} is not one of "
            f"{', '.join(repr(k) for k in CONTROL_BASELINES)}"
        )
    if params is not None and not isinstance(params, DigitalTwin | TwinParams | PlatoonParams):
        raise TypeError(
            f"expected a DigitalTwin, TwinParams or PlatoonParams, got {type(params).__name__}"
        )
    twin = params if isinstance(params, DigitalTwin) else None
    platoon = params if isinstance(params, PlatoonParams) else _twin_params(params)[0].platoon
    entry = CONTROL_BASELINES[name]
    controller = entry.build(platoon, **kwargs)
    return controller.bind(twin) if entry.needs_twin and twin is not None else controller
