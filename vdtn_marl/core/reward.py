"""RRA rewards: ``jocc``, ``drra``, ``aoi`` and ``throughput`` (docs/model.md §5).

Per subframe every RRA agent gets κ1·s_g·g with g = Σ_m V2I rate (Mbps), shared (cooperative).
- ``jocc``: at the last subframe of each interval ``rra_i`` also gets κ2·s_ξ·ξ_i, the IVoI of
  follower i (the recipient of link i).
- ``drra`` (delay-aware baseline): every subframe κ2·progress_i, where progress_i is link i's
  spectral efficiency log2(1 + SINR)/10 while its CAM is pending and 1 once delivered (Liang et
  al.'s V2V reward), and at the last subframe −κ2·miss_penalty if the CAM missed its interval.
- ``aoi`` (AoI-aware baseline, the peers' objective: Parvini et al., IEEE TVT 2023): every
  subframe −κ2·s_A·A_i, where A_i is the Age of Information (ms) of the CAM content the
  recipient of link i holds at the end of the subframe (docs/model.md §4.8; the twin computes
  it from what the recipient holds, :meth:`~vdtn_marl.sim.twin.DigitalTwin.cam_age_ms`).
- ``throughput``: only the V2I term.
The scale factors s_g (``throughput_scale``, per Mbps), s_ξ (``ivoi_scale``) and s_A
(``aoi_scale``, per ms) are config values reported with results.

:class:`RRAReward`'s fields are the one home of the rewards' defaults (the config schema reads
them), and this module imports neither torch nor the twin: the rewards are arithmetic on the
arrays of either backend. Which IVoI estimator a reward pays is chosen above, where the
estimators are (:func:`vdtn_marl.envs.base.paid_ivoi_estimator`).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from vdtn_marl.errors import ConfigError

if TYPE_CHECKING:
    import torch

    from vdtn_marl.sim.link import SubframeOutcome

REWARD_KINDS = ("jocc", "drra", "aoi", "throughput")
KAPPA_SUM_ABS_TOL = 1e-6
"""How far κ1 + κ2 may be from 1 (rounding of typed decimals); the one tolerance used by the
config validation and the environments."""


def check_kappa(kappa1: float, kappa2: float | None) -> tuple[float, float]:
    """κ1, κ2 ∈ [0, 1] with κ1 + κ2 = 1; κ2 defaults to 1 − κ1."""
    for name, value in (("kappa1", kappa1), ("kappa2", kappa2)):
        if name == "kappa2" and value is None:
            kappa2 = value = 1.0 - kappa1
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            raise ConfigError(f"{name}={value!r} must be a number in [0, 1]")
        if not 0.0 <= value <= 1.0:
            raise ConfigError(f"{name}={value!r} is outside the allowed range [0, 1]")
    if abs(kappa1 + kappa2 - 1.0) > KAPPA_SUM_ABS_TOL:
        raise ConfigError(
            f"kappa1 + kappa2 = {kappa1 + kappa2!r} must equal 1 (kappa1={kappa1}, kappa2={kappa2})"
        )
    return float(kappa1), float(kappa2)


def _float32(value: float, array: np.ndarray):
    """``value`` for an operation with ``array``: a float32 0-d array when ``array`` is float32
    (the same result as the Python number, which NumPy casts to float32 first, for a third of
    the cost of the call), else the number itself. The reward's own copy of
    :func:`vdtn_marl.sim.backend.float32_scalars` (this module imports no torch)."""
    if array.dtype != np.float32 or type(value) not in (int, float):  # np.float64 stays strong
        return value
    key = (value, math.copysign(1.0, value))  # 0.0 and -0.0 apart
    cached = _FLOAT32.get(key)
    if cached is None:
        cached = _FLOAT32[key] = np.array(value, np.float32)
        cached.flags.writeable = False
    return cached


_FLOAT32: dict[tuple[float, float], np.ndarray] = {}


#: ``rra.term_scales``: ``fixed`` (s_g, s_ξ as configured: the paper's reading with constant
#: scales) or ``spread`` (each term divided by its spread between the throughput-only and the
#: delivery-first RRA policies, :func:`spread_scales`)
TERM_SCALES = ("fixed", "spread")


def spread_scales(
    interval_throughput_mbps: tuple[float, float], ivoi: tuple[float, float]
) -> tuple[float, float]:
    """(s_g, s_ξ) that give κ its stated meaning: each term of the ``jocc`` reward scaled by its
    spread between the throughput-only policy (no V2V transmission) and the delivery-first
    one (greedy), measured under the same acting system.

    ``interval_throughput_mbps`` = (silent, greedy): the mean over intervals of Σ_t g_t, the
    subframes' summed V2I rates (Mbps) of one interval; ``ivoi`` = (silent, greedy): the mean
    ξ per follower-interval. Then s_g = 1 / (G_silent − G_greedy) and s_ξ = 1 / (Ξ_greedy −
    Ξ_silent): a policy's per-interval reward is κ1 times the share of the throughput spread it
    keeps plus κ2 times the share of the IVoI spread it keeps (up to a constant), so that
    κ1 = κ2 = 0.5 ranks the two extremes equal. Raises :class:`ConfigError` where a spread is
    not positive (delivering CAMs carries more V2I, or is worth less than losing them: no
    trade-off to weigh)."""
    g_silent, g_greedy = (float(x) for x in interval_throughput_mbps)
    xi_silent, xi_greedy = (float(x) for x in ivoi)
    throughput_spread, ivoi_spread = g_silent - g_greedy, xi_greedy - xi_silent
    if not (math.isfinite(throughput_spread) and throughput_spread > 0):
        raise ConfigError(
            f"rra.term_scales=spread: the V2I spread G_silent − G_greedy = {throughput_spread!r} "
            "Mbps per interval must be > 0"
        )
    if not (math.isfinite(ivoi_spread) and ivoi_spread > 0):
        raise ConfigError(
            f"rra.term_scales=spread: the IVoI spread Ξ_greedy − Ξ_silent = {ivoi_spread!r} must "
            "be > 0 (the estimator values delivered CAMs no more than lost ones)"
        )
    return 1.0 / throughput_spread, 1.0 / ivoi_spread


@dataclass(frozen=True)
class RRAReward:
    kind: str = "jocc"
    kappa1: float = 0.5
    kappa2: float | None = None
    throughput_scale: float = 0.004
    ivoi_scale: float = 20.0
    miss_penalty: float = 1.0
    #: s_A per ms of AoI: 1/Δt, so an age of one control interval (50 ms) costs 1 per subframe,
    #: the scale of the ``drra`` progress term and miss penalty
    aoi_scale: float = 0.02

    def __post_init__(self):
        if self.kind not in REWARD_KINDS:
            raise ConfigError(f"reward={self.kind!r} must be one of {REWARD_KINDS}")
        k1, k2 = check_kappa(self.kappa1, self.kappa2)
        object.__setattr__(self, "kappa1", k1)
        object.__setattr__(self, "kappa2", k2)
        for name in ("throughput_scale", "ivoi_scale", "miss_penalty", "aoi_scale"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and 0.0 <= value < float("inf")):
                raise ConfigError(f"{name}={value!r} is outside the allowed range [0, inf)")

    @property
    def uses_ivoi(self) -> bool:
        return self.kind == "jocc" and self.kappa2 > 0

    @property
    def uses_aoi(self) -> bool:
        """Whether :meth:`per_subframe` needs the recipients' AoI (``cam_age_ms``)."""
        return self.kind == "aoi" and self.kappa2 > 0

    def v2i_throughput_mbps(self, outcome: SubframeOutcome):
        """g = Σ_m V2I rate in Mbps, [B]."""
        rate = outcome.v2i_rate_bps
        if isinstance(rate, np.ndarray):  # ndarray.sum without its wrapper, a float32 scalar
            return np.add.reduce(rate, axis=-1) * _float32(1e-6, rate)
        return rate.sum(axis=-1) * 1e-6

    def per_subframe(
        self, outcome: SubframeOutcome, bandwidth_hz: float, subframe_s: float, cam_age_ms=None
    ):
        """Reward of every RRA agent for this subframe [B, L], and g (Mbps) [B], on the
        outcome's backend (NumPy arrays or torch tensors). ``cam_age_ms`` [B, L]: the AoI of
        each link's recipient at the end of the subframe, needed when :attr:`uses_aoi`."""
        bits = outcome.v2v_bits
        numpy = isinstance(bits, np.ndarray)
        g = self.v2i_throughput_mbps(outcome)
        factor = self.kappa1 * self.throughput_scale
        if numpy:
            factor = _float32(factor, g)
            if isinstance(factor, np.ndarray):  # the numbers of `g · 1`, by fewer, cheaper calls
                reward = np.empty_like(bits)
                reward[...] = factor * g[:, None]
            else:
                reward = factor * g[:, None] * np.ones_like(bits)
        else:
            reward = factor * g[:, None] * bits.new_ones(bits.shape)
        if self.kind == "drra":
            efficiency = bits / (bandwidth_hz * subframe_s)
            done = outcome.delivered_now | ~outcome.was_pending
            if numpy:
                progress = np.where(done, 1.0, efficiency / 10.0)
            else:
                progress = (efficiency / 10.0).masked_fill(done, 1.0)
            reward = reward + self.kappa2 * progress
        elif self.uses_aoi:
            if cam_age_ms is None:
                raise ValueError("reward='aoi' needs cam_age_ms, the recipients' AoI [B, L]")
            reward = reward - (self.kappa2 * self.aoi_scale) * cam_age_ms
        return reward, g

    def at_interval_end(self, ivoi: torch.Tensor, cam_lost: torch.Tensor) -> torch.Tensor:
        """Extra reward at the last subframe, [B, L] (torch): κ2·s_ξ·ξ or the DRRA miss penalty."""
        if self.kind == "jocc":
            return self.kappa2 * self.ivoi_scale * ivoi
        if self.kind == "drra":
            return -self.kappa2 * self.miss_penalty * cam_lost.float()
        return ivoi.new_zeros(ivoi.shape)
