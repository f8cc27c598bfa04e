"""Value of Information estimators (docs/model.md §5).

IVoI ξ_k of follower i is the advantage, under the perfect-observation reference policy π*, of
what the acting system actually did in interval k (command u_k from the impaired observation,
taking force at its switch subframe) at the perfect state S_k:

    ξ_k = Q*(S_k, ũ_k) − V*(S_k)  ≤ 0 in expectation when π* is optimal.

An estimator is any callable ``estimator(twin, record) -> Tensor[B, F]`` called once per control
interval, right after the twin integrated it (``record`` is the
:class:`~vdtn_marl.sim.twin.IntervalRecord`). The environments add κ2·ξ_i to the reward of
``rra_i`` at the last subframe of the interval.

The named estimators are :data:`IVOI_ESTIMATORS` (``rra.ivoi_estimator=<name>``), each built
from the :class:`VoIReference` it measures against (π*'s policy, its value v*, the discount)
by its ``from_reference``. A new estimator is its class with ``from_reference``, one line in
the registry, and nothing else: the config's choices, the environments and the JOCC loop read
the registry.

Modules: :mod:`.registry` (:data:`IVOI_ESTIMATORS`, the estimators' names), :mod:`.rollout`
(discounted rollouts of a reference policy, :class:`RolloutValue`), :mod:`.estimators` (the
estimators, :func:`close_interval`) and :mod:`.evoi` (EVoI and Student-t intervals); every name
is importable from :mod:`vdtn_marl.voi`, each on first use, so that reading the registry imports
neither torch nor the twin.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vdtn_marl._lazy import lazy_exports

if TYPE_CHECKING:
    from vdtn_marl.voi.estimators import (
        IVoIEstimator,
        RolloutIVoIEstimator,
        TDIVoIEstimator,
        VoIReference,
        ZeroIVoIEstimator,
        close_interval,
        make_ivoi_estimator,
    )
    from vdtn_marl.voi.evoi import expected_voi, mean_ci
    from vdtn_marl.voi.registry import IVOI_BASELINES, IVOI_ESTIMATORS, ivoi_estimator_class
    from vdtn_marl.voi.rollout import (
        Policy,
        RolloutValue,
        bootstrapped_return,
        discounted_rollout,
    )

#: name → the module of this package that defines it
_HOMES = {
    "IVOI_BASELINES": "registry",
    "IVOI_ESTIMATORS": "registry",
    "ivoi_estimator_class": "registry",
    "IVoIEstimator": "estimators",
    "RolloutIVoIEstimator": "estimators",
    "TDIVoIEstimator": "estimators",
    "VoIReference": "estimators",
    "ZeroIVoIEstimator": "estimators",
    "close_interval": "estimators",
    "make_ivoi_estimator": "estimators",
    "expected_voi": "evoi",
    "mean_ci": "evoi",
    "Policy": "rollout",
    "RolloutValue": "rollout",
    "bootstrapped_return": "rollout",
    "discounted_rollout": "rollout",
}

__all__ = [
    "IVOI_BASELINES",
    "IVOI_ESTIMATORS",
    "IVoIEstimator",
    "Policy",
    "RolloutIVoIEstimator",
    "RolloutValue",
    "TDIVoIEstimator",
    "VoIReference",
    "ZeroIVoIEstimator",
    "bootstrapped_return",
    "close_interval",
    "discounted_rollout",
    "expected_voi",
    "ivoi_estimator_class",
    "make_ivoi_estimator",
    "mean_ci",
]


__getattr__, __dir__ = lazy_exports(__name__, _HOMES)
