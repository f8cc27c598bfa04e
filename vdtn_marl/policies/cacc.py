"""Linear CACC feedback/feedforward controller (docs/model.md §2.5).

u_i = k_p·e_p + k_d·e_v + k_ff·û_{i−1} − k_a·a_i, clipped to the actuator bounds, where û_{i−1}
is the predecessor's command as carried by the CAM the follower holds. It acts on the same
observation vector as a learned policy, so on impaired observations it sees the same stale CAM
content; it does not compensate the CAM delay. It is the default control module of the RRA
environment and the default reference policy of the rollout VoI estimator.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from types import SimpleNamespace

import torch

from vdtn_marl.sim.backend import clamp, float32_scalars
from vdtn_marl.sim.params import PlatoonParams
from vdtn_marl.sim.platoon import (
    GAP_ERROR_BOUND_M,
    SPEED_ERROR_BOUND_MPS,
    PlatoonState,
    numbers,
    spacing_errors,
)


@dataclass(frozen=True)
class CACCController:
    """Gains are per unit: k_p in 1/s², k_d in 1/s, k_ff and k_a dimensionless."""

    params: PlatoonParams = PlatoonParams()
    gap_gain: float = 0.45
    speed_gain: float = 1.2
    feedforward_gain: float = 1.0
    accel_gain: float = 0.0

    def __call__(self, observation: torch.Tensor) -> torch.Tensor:
        """Commands [..., F] (m/s²) from vehicle observations [..., F, 8] (torch or NumPy)."""
        u = (
            self.gap_gain * observation[..., 0]
            + self.speed_gain * observation[..., 1]
            + self.feedforward_gain * observation[..., 4]
            - self.accel_gain * observation[..., 2]
        )
        return clamp(u, self.params.accel_min_mps2, self.params.accel_max_mps2)

    def perfect_command(
        self,
        state: PlatoonState,
        params: PlatoonParams,
        gap_error: torch.Tensor | None = None,
        speed_error: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``self(perfect_observation(state, params))`` without building the features the law
        does not read: the same operations, so the same numbers. ``gap_error`` and
        ``speed_error`` are ``spacing_errors(state, params)`` when the caller has them."""
        if gap_error is None or speed_error is None:
            gap_error, speed_error = spacing_errors(state, params)
        # float32 NumPy arrays: the constants as float32 0-d arrays (the same numbers, faster)
        pc = numbers(params, gap_error, speed_error, state.command_mps2, state.accel_mps2)
        g = (self.numbers_float32 or self.numbers) if pc is not params.numbers else self.numbers
        lo, hi = pc.accel_min, pc.accel_max
        topology = params.topology
        u = (
            g.gap_gain * clamp(gap_error, g.gap_lo, g.gap_hi)
            + g.speed_gain * clamp(speed_error, g.speed_lo, g.speed_hi)
            + g.feedforward_gain * clamp(topology.predecessors_of(state.command_mps2), lo, hi)
            - g.accel_gain * clamp(topology.followers_of(state.accel_mps2), lo, hi)
        )
        return clamp(u, g.lo, g.hi)

    @cached_property
    def numbers(self) -> SimpleNamespace:
        """The law's numbers by short name (its gains, the error clips, its output bounds)."""
        return SimpleNamespace(
            gap_gain=self.gap_gain,
            speed_gain=self.speed_gain,
            feedforward_gain=self.feedforward_gain,
            accel_gain=self.accel_gain,
            gap_lo=-GAP_ERROR_BOUND_M,
            gap_hi=GAP_ERROR_BOUND_M,
            speed_lo=-SPEED_ERROR_BOUND_MPS,
            speed_hi=SPEED_ERROR_BOUND_MPS,
            lo=self.params.accel_min_mps2,
            hi=self.params.accel_max_mps2,
        )

    @cached_property
    def numbers_float32(self) -> SimpleNamespace | None:
        """:attr:`numbers` as float32 0-d arrays (see :func:`~vdtn_marl.sim.platoon.numbers`);
        None unless every one is a Python number."""
        return float32_scalars(**vars(self.numbers))
