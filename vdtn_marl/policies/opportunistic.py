"""A deadline-aware opportunistic RRA policy: send in the link's better subframes, by the
interval's deadline.

A CAM is generated at the start of every control interval and is only needed at the
recipient's next decision; a minimum-latency policy (greedy, DRRA) spends the link's first
subframes on it whatever their fading, and its interference on the V2I uplink of the
sub-channel it takes with it. This policy reads only the RRA observation (docs/model.md §4.6,
:class:`~vdtn_marl.sim.layout.RRAFeatureLayout`) and, per link and subframe:

1. scores each sub-channel by its estimated SINR s_m (dB) as the greedy policy does
   (:meth:`~vdtn_marl.policies.rra.GreedyRRAPolicy.scores_db`) and takes the best, s;
2. compares s with the link's running mean s̄ of that score (an exponential moving average
   over subframes with weight ``mean_weight``, updated after the decision);
3. sends the CAM at the highest power on that sub-channel when the link has bits left and
   either s ≥ s̄ (a better than usual subframe) or the deadline forces it:

       n_left ≤ deadline_margin · n_need,   n_need = bits_left / (W·log2(1 + 10^(s̄/10))·Δt_sf),

   with n_left the subframes left in the interval (this one included), bits_left the CAM's
   bits still to send, W the sub-channel bandwidth and Δt_sf the subframe; otherwise it stays
   silent (the "off" power level).

The deadline margin is > 1 because the policy sends in about half of the subframes; with the
default margin it delivers CAMs as often as greedy does (tests/policies/test_baselines.py).

State: the running mean ``[..., L]`` (NumPy or torch, like the observations), started from the
first score it sees and reset by :meth:`reset` and :meth:`seed`, and whenever the
observations' shape changes. It travels in environment checkpoints with the policy.
"""

from __future__ import annotations

import numpy as np
import torch

from vdtn_marl.policies.rra import GreedyRRAPolicy, encode_rra_action, max_power_level
from vdtn_marl.sim.params import RadioParams, TwinParams

#: Weight of the newest score in the running mean (a time constant of about 20 subframes).
MEAN_WEIGHT = 0.05
#: n_left ≤ margin · n_need forces the CAM out (see the module doc).
DEADLINE_MARGIN = 2.0


class OpportunisticRRAPolicy:
    """Deadline-aware opportunistic RRA (see the module doc). Observations ``[..., L, D]``
    (NumPy or torch) → int64 actions ``[..., L]`` of the same kind.

    Args:
        num_links: L V2V links (followers).
        radio: radio parameters (M, power levels, bandwidth, CAM size); default ``RadioParams()``.
        subframes_per_interval: T, the subframes of one control interval.
        subframe_s: one subframe's duration (s).
        mean_weight: weight of the newest score in the running mean, in (0, 1].
        deadline_margin: the deadline rule's margin, ≥ 1.
    """

    def __init__(
        self,
        num_links: int,
        radio: RadioParams | None = None,
        subframes_per_interval: int = 50,
        subframe_s: float = 1e-3,
        mean_weight: float = MEAN_WEIGHT,
        deadline_margin: float = DEADLINE_MARGIN,
    ):
        radio = radio or RadioParams()
        if not 0.0 < mean_weight <= 1.0:
            raise ValueError(f"mean_weight={mean_weight!r} must be in (0, 1]")
        if not deadline_margin >= 1.0:
            raise ValueError(f"deadline_margin={deadline_margin!r} must be >= 1")
        if (
            isinstance(subframes_per_interval, bool)
            or not isinstance(subframes_per_interval, int | np.integer)
            or subframes_per_interval < 1
        ):
            raise ValueError(
                f"subframes_per_interval={subframes_per_interval!r} must be an integer >= 1"
            )
        if not subframe_s > 0:
            raise ValueError(f"subframe_s={subframe_s!r} must be > 0 s")
        self.greedy = GreedyRRAPolicy(num_links, radio)
        self.layout = self.greedy.layout
        self.num_links = self.greedy.num_links
        self.num_power_levels = radio.num_power_levels
        self.send_level = max_power_level(radio)
        self.off_level = radio.num_power_levels - 1
        self.subframes_per_interval = int(subframes_per_interval)
        self.cam_size_bits = float(radio.cam_size_bits)
        self.bits_per_subframe_per_bps_hz = radio.subchannel_bandwidth_hz * subframe_s
        self.mean_weight = float(mean_weight)
        self.deadline_margin = float(deadline_margin)
        self.mean_score_db = None  # [..., L], the running mean s̄

    @classmethod
    def from_params(cls, params: TwinParams, seed: int | None = None) -> OpportunisticRRAPolicy:
        """One link per follower, the model's radio and clock (``seed`` unused:
        deterministic)."""
        platoon = params.platoon
        return cls(
            platoon.num_followers,
            params.radio,
            subframes_per_interval=platoon.subframes_per_interval,
            subframe_s=platoon.subframe_s,
        )

    def seed(self, seed: int | None) -> None:
        """No randomness; forgets the running mean (API symmetry with the random policy)."""
        self.reset()

    def reset(self) -> None:
        """Forget the running mean: the next call starts it from its scores."""
        self.mean_score_db = None

    def __call__(self, observation):
        scores = self.greedy.scores_db(observation)  # [..., L, M], checks the shape
        numpy = isinstance(observation, np.ndarray)
        lay = self.layout
        if numpy:
            best, score = scores.argmax(-1), scores.max(-1)
        else:
            score, best = scores.max(-1)
        mean = self.mean_score_db
        if mean is None or tuple(mean.shape) != tuple(score.shape):
            mean = score.copy() if numpy else score.clone()
        bits_left = observation[..., lay.bits_left] * self.cam_size_bits
        subframes_left = observation[..., lay.time_left] * self.subframes_per_interval
        # bits per subframe at the mean SINR: W·Δt·log2(1 + 10^(s̄/10))
        if numpy:
            mean_rate = self.bits_per_subframe_per_bps_hz * np.log2(1.0 + 10.0 ** (mean / 10.0))
        else:
            mean_rate = self.bits_per_subframe_per_bps_hz * torch.log2(
                1.0 + torch.pow(10.0, mean / 10.0)
            )
        needed = bits_left / (mean_rate + _TINY_BITS)
        forced = subframes_left <= self.deadline_margin * needed + _ONE_SUBFRAME_SLACK
        send = (bits_left > 0) & ((score >= mean) | forced)
        level = (
            np.where(send, self.send_level, self.off_level)
            if numpy
            else torch.where(send, self.send_level, self.off_level)
        )
        self.mean_score_db = mean + self.mean_weight * (score - mean)
        actions = encode_rra_action(best, level, self.num_power_levels)
        return actions.astype(np.int64) if numpy else actions.long()


#: Guards the division where the mean SINR's rate underflows to 0 bits.
_TINY_BITS = 1e-9
#: The subframe being decided counts in ``subframes_left``: keep one of slack.
_ONE_SUBFRAME_SLACK = 1.0
