"""RRA rewards: ``jocc``, ``drra`` and ``throughput`` (docs/model.md §5).

Per subframe every RRA agent gets κ1·s_g·g with g = Σ_m V2I rate (Mbps), shared (cooperative).
- ``jocc``: at the last subframe of each interval ``rra_i`` also gets κ2·s_ξ·ξ_i, the IVoI of
  follower i (the recipient of link i).
- ``drra`` (delay-aware baseline): every subframe κ2·progress_i, where progress_i is link i's
  spectral efficiency log2(1 + SINR)/10 while its CAM is pending and 1 once delivered (Liang et
  al.'s V2V reward), and at the last subframe −κ2·miss_penalty if the CAM missed its interval.
- ``throughput``: only the V2I term.
The scale factors s_g (``throughput_scale``, per Mbps) and s_ξ (``ivoi_scale``) are config
values reported with results.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from vdtn_marl.envs.base import check_kappa
from vdtn_marl.errors import ConfigError
from vdtn_marl.sim.link import SubframeOutcome
from vdtn_marl.voi import make_ivoi_estimator

REWARD_KINDS = ("jocc", "drra", "throughput")


@dataclass(frozen=True)
class RRAReward:
    kind: str = "jocc"
    kappa1: float = 0.5
    kappa2: float | None = None
    throughput_scale: float = 0.004
    ivoi_scale: float = 20.0
    miss_penalty: float = 1.0

    def __post_init__(self):
        if self.kind not in REWARD_KINDS:
            raise ConfigError(f"reward={self.kind!r} must be one of {REWARD_KINDS}")
        k1, k2 = check_kappa(self.kappa1, self.kappa2)
        object.__setattr__(self, "kappa1", k1)
        object.__setattr__(self, "kappa2", k2)
        for name in ("throughput_scale", "ivoi_scale", "miss_penalty"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and 0.0 <= value < float("inf")):
                raise ConfigError(f"{name}={value!r} is outside the allowed range [0, inf)")

    @property
    def uses_ivoi(self) -> bool:
        return self.kind == "jocc" and self.kappa2 > 0

    def v2i_throughput_mbps(self, outcome: SubframeOutcome):
        """g = Σ_m V2I rate in Mbps, [B]."""
        return outcome.v2i_rate_bps.sum(axis=-1) * 1e-6

    def per_subframe(self, outcome: SubframeOutcome, bandwidth_hz: float, subframe_s: float):
        """Reward of every RRA agent for this subframe [B, L], and g (Mbps) [B]."""
        xp = np if isinstance(outcome.v2v_bits, np.ndarray) else torch
        g = self.v2i_throughput_mbps(outcome)
        reward = (self.kappa1 * self.throughput_scale) * g[:, None] * xp.ones_like(outcome.v2v_bits)
        if self.kind == "drra":
            efficiency = outcome.v2v_bits / (bandwidth_hz * subframe_s)
            done = outcome.delivered_now | ~outcome.was_pending
            progress = xp.where(done, 1.0, efficiency / 10.0)
            reward = reward + self.kappa2 * progress
        return reward, g

    def at_interval_end(self, ivoi: torch.Tensor, cam_lost: torch.Tensor) -> torch.Tensor:
        """Extra reward at the last subframe, [B, L] (torch): κ2·s_ξ·ξ or the DRRA miss penalty."""
        if self.kind == "jocc":
            return self.kappa2 * self.ivoi_scale * ivoi
        if self.kind == "drra":
            return -self.kappa2 * self.miss_penalty * cam_lost.float()
        return torch.zeros_like(ivoi)


def paid_ivoi_estimator(reward_fn: RRAReward, ivoi_estimator, horizon_intervals: int):
    """The IVoI estimator whose ξ ``reward_fn`` pays: ``ivoi_estimator`` (a name of
    :data:`~vdtn_marl.voi.IVOI_ESTIMATORS`, ``"none"`` or an object; ``"rollout"`` over
    ``horizon_intervals``) when the reward uses ξ, else ξ = 0 (nothing is estimated)."""
    options = {"horizon_intervals": horizon_intervals} if ivoi_estimator == "rollout" else {}
    return make_ivoi_estimator(ivoi_estimator if reward_fn.uses_ivoi else "none", **options)
