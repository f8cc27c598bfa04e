"""The core: the interval protocol written once (:mod:`.interval`), on top of :mod:`vdtn_marl.sim`.

Every environment face, the evaluation, the completion predictor's training data and the
benchmarks run their intervals through :class:`~vdtn_marl.core.interval.IntervalEngine`.
"""

from vdtn_marl.core.interval import IntervalEngine, IntervalOutcome, close_interval

__all__ = ["IntervalEngine", "IntervalOutcome", "close_interval"]
