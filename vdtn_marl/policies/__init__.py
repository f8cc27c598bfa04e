"""The non-learned policies of the benchmark, and their registries (:mod:`.registry`): build one
by name with :func:`make_rra_baseline` or :func:`make_control_baseline`.

Radio resource allocation (RRA) policies (:mod:`.rra`) map RRA observations ``[..., L, D]``
(NumPy or torch, docs/model.md §4.6) to integer actions ``[..., L]`` of the same kind:

- ``"random"``: :class:`RandomRRAPolicy` (uniform sub-channel × power), the environments'
  RRA policy when the user gives none.
- ``"round_robin"``: :class:`RoundRobinRRAPolicy`, link i on sub-channel (i + t) mod M at a
  fixed power level, t the subframe counter.
- ``"greedy"``: :class:`GreedyRRAPolicy`, maximum power on the sub-channel with the best
  estimated V2V SINR (own SNR against the V2I user's interference) read from the observation.

Control policies map vehicle observations ``[B, F, 8]`` to commands ``[B, F]`` (m/s²):

- ``"cacc"``: :class:`CACCController` (:mod:`.cacc`), the linear CACC on the (possibly
  delayed) observation: the environments' control module when the user gives none, and the
  default reference policy of the rollout IVoI estimator.
- ``"oracle"``: :class:`OracleController` (:mod:`.mpc_oracle`), receding-horizon optimisation
  of the control reward on the twin's true state and the leader's known future trace
  (model-predictive control with preview). It reads the twin, not the observation: use
  :meth:`OracleController.bind` to get an observation → command callable. It also works with
  impaired observation (the command waits for the CAM). Its subgradient solver is
  approximate: with the default :data:`ORACLE_MPC_ITERATIONS` steps per interval its
  perfect-observation cost is 0.2–7.1 % above the exact optimum on the evaluation scenarios we
  measured; with 60 steps (leaderboard 1.0) it was 19–42 % above it.
- ``"exact_oracle"``: :class:`ExactOracleController` (:mod:`.exact_oracle`), the exact minimum
  of the episode's control cost over the known trace (a linear program solved once per
  episode): the perfect-observation lower bound on control cost.
- ``"causal_mpc"``: the same optimisation as ``"oracle"`` without the leader's future (it
  extrapolates the leader's present acceleration): the model-based reference for policies
  that observe only the present, such as π*.

Every name is importable from here; each is imported on first use, so that reading the
registries imports no torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vdtn_marl._lazy import lazy_exports

if TYPE_CHECKING:
    from vdtn_marl.policies.cacc import CACCController
    from vdtn_marl.policies.exact_oracle import ExactOracleController
    from vdtn_marl.policies.mpc_oracle import (
        CAUSAL_MPC_ITERATIONS,
        ORACLE_MPC_ITERATIONS,
        OracleController,
    )
    from vdtn_marl.policies.registry import (
        CONTROL_BASELINES,
        RRA_BASELINES,
        ControlBaseline,
        make_control_baseline,
        make_rra_baseline,
        rra_baseline_class,
    )
    from vdtn_marl.policies.rra import (
        GreedyRRAPolicy,
        RandomRRAPolicy,
        RoundRobinRRAPolicy,
        RRAFeatureLayout,
        encode_rra_action,
        max_power_level,
    )

#: name → the module of this package that defines it
_HOMES = {
    "CACCController": "cacc",
    "ExactOracleController": "exact_oracle",
    "CAUSAL_MPC_ITERATIONS": "mpc_oracle",
    "ORACLE_MPC_ITERATIONS": "mpc_oracle",
    "OracleController": "mpc_oracle",
    "CONTROL_BASELINES": "registry",
    "RRA_BASELINES": "registry",
    "ControlBaseline": "registry",
    "rra_baseline_class": "registry",
    "make_control_baseline": "registry",
    "make_rra_baseline": "registry",
    "GreedyRRAPolicy": "rra",
    "RandomRRAPolicy": "rra",
    "RoundRobinRRAPolicy": "rra",
    "RRAFeatureLayout": "rra",
    "encode_rra_action": "rra",
    "max_power_level": "rra",
}

__all__ = [
    "CACCController",
    "CAUSAL_MPC_ITERATIONS",
    "CONTROL_BASELINES",
    "ControlBaseline",
    "ExactOracleController",
    "GreedyRRAPolicy",
    "ORACLE_MPC_ITERATIONS",
    "OracleController",
    "RRAFeatureLayout",
    "RRA_BASELINES",
    "RandomRRAPolicy",
    "RoundRobinRRAPolicy",
    "encode_rra_action",
    "make_control_baseline",
    "make_rra_baseline",
    "max_power_level",
    "rra_baseline_class",
]


__getattr__, __dir__ = lazy_exports(__name__, _HOMES)
