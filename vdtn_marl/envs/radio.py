"""Radio resource allocation environment: ``vdtn/v2x-rra-v1``.

Agents ``rra_1..rra_{N−1}``: the base station's allocator of each V2V link, acting every 1 ms
subframe. The control side runs inside with a given control module (impaired observations →
commands; linear CACC by default) and the reward is one of
:data:`~vdtn_marl.core.reward.REWARD_KINDS` (``jocc``, ``drra``, ``aoi``, ``throughput``;
docs/model.md §5). It is :class:`~vdtn_marl.envs.two_timescale.TwoTimescaleEnv` with the
vehicles driven internally, so the two share every line of stepping logic.

Observation of ``rra_i``: Box(4M + 6) float32 — own-link SNR at maximum power per sub-channel,
interference-to-noise its transmitter would cause at the BS per sub-channel, interference-to-
noise from each V2I user at its receiver (all in units of 10 dB), V2V occupancy of each
sub-channel in the last subframe, fraction of CAM bits left, fraction of the interval left, and
four control features of its recipient (gap and speed error, predecessor acceleration, last
command; normalised). Action: Discrete(M·P), sub-channel a // P, power level a % P (the last
level is off).

Version history (docs/model.md, "Version history"):

- ``vdtn/v2x-rra-v1`` (2026-12):

  - V2V path loss WINNER+ B1 with effective antenna heights and a free-space floor by default
    (v0: Liang et al.'s form; ``v2v_pathloss_form="liang"`` restores it).
  - RRA observation of 4M + 12 features (v0: 4M + 6): the recipient's CAM content age, its
    last 3 CAM delays and its 2 earlier commands are appended
    (:data:`vdtn_marl.sim.layout.RRA_OBS_FEATURES`).
"""

from __future__ import annotations

from collections.abc import Callable

from vdtn_marl.envs.two_timescale import TwoTimescaleEnv


class V2XRRAEnv(TwoTimescaleEnv):
    """RRA agents only; the followers are driven by ``control_module`` inside."""

    def __init__(self, control_module: Callable | None = None, **kwargs):
        if "vehicles_are_agents" in kwargs:
            raise TypeError(
                "V2XRRAEnv drives the vehicles internally; use TwoTimescaleEnv for both groups"
            )
        super().__init__(vehicles_are_agents=False, control_module=control_module, **kwargs)
