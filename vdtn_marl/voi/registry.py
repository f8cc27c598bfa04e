"""The registry of IVoI estimators: :data:`IVOI_ESTIMATORS`, the only list of their names.

The config's ``rra.ivoi_estimator`` choices, :func:`~vdtn_marl.voi.make_ivoi_estimator`, the
JOCC loop and the tests read it. Entries are ``"module:Class"`` strings, imported when first
used, so reading the registry (the config schema does) imports neither torch nor the twin.

A new estimator is its class with ``from_reference(reference, **options)`` (in a file of its
own or in :mod:`.estimators`) and one line here (docs/registry.md).
"""

from __future__ import annotations

import importlib

#: The named IVoI estimators, ``rra.ivoi_estimator=<name>`` → ``"module:Class"`` of a class with
#: ``from_reference(reference, **options)``.
IVOI_ESTIMATORS: dict[str, str] = {
    "td": "vdtn_marl.voi.estimators:TDIVoIEstimator",
    "rollout": "vdtn_marl.voi.estimators:RolloutIVoIEstimator",
}

#: what ξ compares the acting system's command with (``rra.ivoi_baseline``,
#: :class:`~vdtn_marl.voi.estimators.RolloutIVoIEstimator`)
IVOI_BASELINES = ("optimal", "cam_lost")


def ivoi_estimator_class(name: str) -> type:
    """The class of the IVoI estimator ``name`` (imported on first use)."""
    if name not in IVOI_ESTIMATORS:
        raise ValueError(
            f"ivoi_estimator={name!r} is not one of "
            f"{', '.join(repr(k) for k in (*IVOI_ESTIMATORS, 'none'))} (or an object)"
        )
    module, _, attribute = IVOI_ESTIMATORS[name].partition(":")
    return getattr(importlib.import_module(module), attribute)
