"""Simple policies the environments use when the user gives none."""

from __future__ import annotations

import numpy as np
import torch


class RandomRRAPolicy:
    """Uniformly random sub-channel × power level per link and subframe.

    Called with RRA observations [B, L, D] (NumPy or torch) and returns integer actions
    [B, L] of the same kind. :meth:`seed` makes it reproducible; the environments seed it
    from their own reset seed.
    """

    def __init__(self, num_actions: int, seed: int | None = None):
        if num_actions < 1:
            raise ValueError(f"num_actions={num_actions!r} must be >= 1")
        self.num_actions = num_actions
        self.seed(seed)

    def seed(self, seed: int | None) -> None:
        self._rng = np.random.default_rng(seed)
        self._torch_gen: torch.Generator | None = None
        self._seed = seed

    def __call__(self, observation):
        shape = observation.shape[:-1]
        if isinstance(observation, np.ndarray):
            return self._rng.integers(0, self.num_actions, size=shape)
        if self._torch_gen is None or self._torch_gen.device != observation.device:
            self._torch_gen = torch.Generator(device=observation.device)
            seed = self._seed if self._seed is not None else int(self._rng.integers(2**31))
            self._torch_gen.manual_seed(seed)
        return torch.randint(
            0, self.num_actions, shape, generator=self._torch_gen, device=observation.device
        )
