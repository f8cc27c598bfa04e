"""Linear CACC feedback/feedforward controller (docs/model.md §2.5).

u_i = k_p·e_p + k_d·e_v + k_ff·û_{i−1} − k_a·a_i, clipped to the actuator bounds, where û_{i−1}
is the predecessor's command as carried by the CAM the follower holds. It acts on the same
observation vector as a learned policy, so on impaired observations it sees the same stale CAM
content; it does not compensate the CAM delay. It is the default control module of the RRA
environment and the default reference policy of the rollout VoI estimator.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from vdtn_marl.sim.params import PlatoonParams


@dataclass(frozen=True)
class CACCController:
    """Gains are per unit: k_p in 1/s², k_d in 1/s, k_ff and k_a dimensionless."""

    params: PlatoonParams = PlatoonParams()
    gap_gain: float = 0.45
    speed_gain: float = 1.2
    feedforward_gain: float = 1.0
    accel_gain: float = 0.0

    def __call__(self, observation: torch.Tensor) -> torch.Tensor:
        """Commands [..., F] (m/s²) from vehicle observations [..., F, 8]."""
        u = (
            self.gap_gain * observation[..., 0]
            + self.speed_gain * observation[..., 1]
            + self.feedforward_gain * observation[..., 4]
            - self.accel_gain * observation[..., 2]
        )
        return u.clamp(self.params.accel_min_mps2, self.params.accel_max_mps2)
