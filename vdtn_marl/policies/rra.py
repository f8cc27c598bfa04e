"""Radio resource allocation (RRA) heuristics: random (the environments' default), round robin,
greedy (best estimated SINR) and silent (no V2V transmission: the throughput-only extreme).

They map RRA observations ``[..., L, D]`` (NumPy or torch, docs/model.md §4.6) to integer
actions ``[..., L]`` of the same kind. Action encoding (``vdtn_marl.sim.link.ActionTables``):
a = c·P + l for sub-channel c ∈ [0, M) and power level l ∈ [0, P);
``RadioParams.v2v_power_levels_dbm`` lists levels 0..P−2 (23, 15, 5 dBm by default, level 0 the
highest) and the last level P−1 is "off".

Each class builds itself for a twin's parameters with ``from_params(params, seed)``;
:func:`~vdtn_marl.policies.registry.make_rra_baseline` builds them by name from the registry
:data:`~vdtn_marl.policies.registry.RRA_BASELINES`.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from vdtn_marl.sim.layout import RRA_OBS_GAIN_SCALE_DB, RRAFeatureLayout
from vdtn_marl.sim.params import RadioParams, TwinParams

_LN10_OVER_10 = math.log(10.0) / 10.0


def encode_rra_action(subchannel, power_level, num_power_levels: int):
    """RRA action index a = sub-channel·P + power level (inverse of ``link.ActionTables``).

    Works elementwise on ints, NumPy arrays and torch tensors.
    """
    return subchannel * num_power_levels + power_level


def max_power_level(radio: RadioParams) -> int:
    """Index of the highest transmit power in ``radio.v2v_power_levels_dbm`` (0 by default)."""
    return int(np.argmax(radio.v2v_power_levels_dbm))


def _check_power_level(power_level: int, num_power_levels: int) -> None:
    if (
        isinstance(power_level, bool)
        or not isinstance(power_level, int | np.integer)
        or not 0 <= power_level < num_power_levels
    ):
        raise ValueError(
            f"power_level={power_level!r} must be an integer in [0, {num_power_levels - 1}] "
            f"(level {num_power_levels - 1} is 'off')"
        )


def _check_links(observation, num_links: int, dim: int | None = None) -> None:
    shape = tuple(observation.shape)
    if len(shape) < 2 or shape[-2] != num_links or (dim is not None and shape[-1] != dim):
        want = f"[..., {num_links}, {dim if dim is not None else 'D'}]"
        raise ValueError(f"RRA observation has shape {shape}, expected {want}")


class RandomRRAPolicy:
    """Uniformly random sub-channel × power level per link and subframe: the RRA policy of the
    environments when the user gives none.

    Called with RRA observations [B, L, D] (NumPy or torch) and returns integer actions
    [B, L] of the same kind. :meth:`seed` makes it reproducible; the environments seed it
    from their own reset seed.
    """

    def __init__(self, num_actions: int, seed: int | None = None):
        if num_actions < 1:
            raise ValueError(f"num_actions={num_actions!r} must be >= 1")
        self.num_actions = num_actions
        self.seed(seed)

    @classmethod
    def from_params(cls, params: TwinParams, seed: int | None = None) -> RandomRRAPolicy:
        """Uniform over the ``params.radio.num_actions`` actions, seeded with ``seed``."""
        return cls(params.radio.num_actions, seed)

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


class RoundRobinRRAPolicy:
    """Fixed rotating allocation: link i on sub-channel (i + t) mod M at ``power_level``.

    t counts the calls (one per 1 ms subframe) since construction or :meth:`reset`; with
    L ≤ M the links use distinct sub-channels in every subframe. Called with RRA observations
    ``[..., L, D]`` (NumPy or torch); returns integer actions ``[..., L]`` of the same kind
    (int64). ``power_level`` indexes ``RadioParams.v2v_power_levels_dbm`` (0 = 23 dBm by
    default); the last level ``num_power_levels − 1`` is "off".
    """

    def __init__(
        self, num_links: int, num_subchannels: int, num_power_levels: int, power_level: int = 0
    ):
        for name, value in (
            ("num_links", num_links),
            ("num_subchannels", num_subchannels),
            ("num_power_levels", num_power_levels),
        ):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}={value!r} must be an integer >= 1")
        _check_power_level(power_level, num_power_levels)
        self.num_links = int(num_links)
        self.num_subchannels = int(num_subchannels)
        self.num_power_levels = int(num_power_levels)
        self.power_level = int(power_level)
        self._links = np.arange(self.num_links)
        self._links_torch: dict[torch.device, torch.Tensor] = {}
        self.reset()

    @classmethod
    def from_params(cls, params: TwinParams, seed: int | None = None) -> RoundRobinRRAPolicy:
        """One link per follower, every sub-channel, the highest power level (``seed``
        unused: deterministic)."""
        radio = params.radio
        return cls(
            params.platoon.num_followers,
            radio.num_subchannels,
            radio.num_power_levels,
            max_power_level(radio),
        )

    def seed(self, seed: int | None) -> None:
        """No randomness; resets the subframe counter (API symmetry with the random policy)."""
        self.reset()

    def reset(self) -> None:
        """Restart the rotation at t = 0."""
        self.t = 0

    def __call__(self, observation):
        _check_links(observation, self.num_links)
        t, self.t = self.t, self.t + 1
        if isinstance(observation, np.ndarray):
            channel = (self._links + t) % self.num_subchannels
            actions = encode_rra_action(channel, self.power_level, self.num_power_levels)
            return np.broadcast_to(actions, observation.shape[:-1]).astype(np.int64)
        dev = observation.device
        links = self._links_torch.get(dev)
        if links is None:
            links = self._links_torch[dev] = torch.arange(self.num_links, device=dev)
        channel = (links + t) % self.num_subchannels
        actions = encode_rra_action(channel, self.power_level, self.num_power_levels)
        return actions.expand(observation.shape[:-1]).clone()


class GreedyRRAPolicy:
    """Each link transmits at maximum power on its best sub-channel, read from the observation.

    Score of sub-channel m for link i (dB): the estimated SINR against the V2I user on m,

        s_m = SNR_m − 10·log10(1 + INR_m),

    with SNR_m the own-link SNR at maximum power (``own_snr`` block) and INR_m the V2I user's
    interference-to-noise ratio at the link's receiver (``v2i_interference`` block), both in dB
    (:class:`RRAFeatureLayout`). For INR ≫ 1 this is SNR − INR. Interference from the other
    V2V links and the harm done to the V2I uplink are ignored (greedy, uncoordinated). Ties go
    to the lowest sub-channel. Batched: observations ``[..., L, D]`` (NumPy or torch) →
    int64 actions ``[..., L]`` of the same kind.

    Args:
        num_links: L V2V links (followers).
        radio: radio parameters (M, power levels); defaults to ``RadioParams()``.
        power_level: power level used (default: the highest, :func:`max_power_level`).
    """

    def __init__(
        self, num_links: int, radio: RadioParams | None = None, power_level: int | None = None
    ):
        if isinstance(num_links, bool) or not isinstance(num_links, int | np.integer):
            raise ValueError(f"num_links={num_links!r} must be an integer >= 1")
        if num_links < 1:
            raise ValueError(f"num_links={num_links!r} must be an integer >= 1")
        radio = radio or RadioParams()
        self.num_links = int(num_links)
        self.layout = RRAFeatureLayout.from_radio(radio)
        self.num_power_levels = radio.num_power_levels
        self.power_level = max_power_level(radio) if power_level is None else power_level
        _check_power_level(self.power_level, self.num_power_levels)

    @classmethod
    def from_params(cls, params: TwinParams, seed: int | None = None) -> GreedyRRAPolicy:
        """One link per follower, the highest power level (``seed`` unused: deterministic)."""
        return cls(params.platoon.num_followers, params.radio)

    def seed(self, seed: int | None) -> None:
        """Deterministic policy: nothing to seed (API symmetry)."""

    def reset(self) -> None:
        """Stateless policy: nothing to reset (API symmetry)."""

    def scores_db(self, observation):
        """Estimated SINR s_m (dB) of each sub-channel, ``[..., L, M]``."""
        _check_links(observation, self.num_links, self.layout.dim)
        lay = self.layout
        snr_db = observation[..., lay.own_snr] * RRA_OBS_GAIN_SCALE_DB
        inr_db = observation[..., lay.v2i_interference] * RRA_OBS_GAIN_SCALE_DB
        if isinstance(observation, np.ndarray):
            soft = np.logaddexp(0.0, inr_db * _LN10_OVER_10)
        else:
            soft = torch.logaddexp(torch.zeros_like(inr_db), inr_db * _LN10_OVER_10)
        return snr_db - soft / _LN10_OVER_10  # 10·log10(1 + 10^(INR/10))

    def __call__(self, observation):
        best = self.scores_db(observation).argmax(-1)
        actions = encode_rra_action(best, self.power_level, self.num_power_levels)
        return actions.astype(np.int64) if isinstance(actions, np.ndarray) else actions.long()


class SilentRRAPolicy:
    """Every V2V link stays silent (the "off" power level on sub-channel 0): no CAM is ever
    delivered and the V2I uplinks carry their interference-free rate. The throughput-only
    extreme of the RRA objective, against which a policy's V2I gain and its CAMs' value are
    measured. Observations ``[..., L, D]`` (NumPy or torch) → int64 actions ``[..., L]``."""

    def __init__(self, num_links: int, num_power_levels: int):
        for name, value in (("num_links", num_links), ("num_power_levels", num_power_levels)):
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"{name}={value!r} must be an integer >= 1")
        self.num_links = int(num_links)
        self.off_action = encode_rra_action(0, int(num_power_levels) - 1, int(num_power_levels))

    @classmethod
    def from_params(cls, params: TwinParams, seed: int | None = None) -> SilentRRAPolicy:
        """One link per follower (``seed`` unused: deterministic)."""
        return cls(params.platoon.num_followers, params.radio.num_power_levels)

    def seed(self, seed: int | None) -> None:
        """Deterministic policy: nothing to seed (API symmetry)."""

    def reset(self) -> None:
        """Stateless policy: nothing to reset (API symmetry)."""

    def __call__(self, observation):
        _check_links(observation, self.num_links)
        shape = observation.shape[:-1]
        if isinstance(observation, np.ndarray):
            return np.full(shape, self.off_action, dtype=np.int64)
        return torch.full(shape, self.off_action, dtype=torch.long, device=observation.device)
