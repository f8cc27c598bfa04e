"""The core: the interval protocol written once (:mod:`.interval`), on top of :mod:`vdtn_marl.sim`,
and the RRA rewards it pays (:mod:`.reward`).

Every environment face, the evaluation, the completion predictor's training data and the
benchmarks run their intervals through :class:`~vdtn_marl.core.interval.IntervalEngine`.

Every name is imported on first use, so that reading the rewards' defaults (the config schema
does) imports neither the twin nor torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vdtn_marl._lazy import lazy_exports

if TYPE_CHECKING:
    from vdtn_marl.core.interval import IntervalEngine, IntervalOutcome, close_interval
    from vdtn_marl.core.reward import REWARD_KINDS, RRAReward, check_kappa

#: name → the module of this package that defines it
_HOMES = {
    "IntervalEngine": "interval",
    "IntervalOutcome": "interval",
    "close_interval": "interval",
    "REWARD_KINDS": "reward",
    "RRAReward": "reward",
    "check_kappa": "reward",
}

__all__ = [
    "REWARD_KINDS",
    "IntervalEngine",
    "IntervalOutcome",
    "RRAReward",
    "check_kappa",
    "close_interval",
]


__getattr__, __dir__ = lazy_exports(__name__, _HOMES)
