"""A policy of your own on the leaderboard: an RRA policy named by its import path.

Score it under the benchmark's protocol (the same held-out scenarios and seeds as the built-in
methods) with

    vdtn-marl jocc rra=policy rra.policy=examples/my_rra.py:make_policy experiment=smoke
    vdtn-marl bench benchmark=smoke \
        '+submissions.orthogonal=["rra=policy","rra.policy=examples/my_rra.py:make_policy"]'

(docs/leaderboard.md, *Submissions*). The factory gets the run's model parameters and seed and
returns a callable: RRA observations ``[B, L, D]`` → actions ``[B, L]`` (a = sub-channel · P +
power level, level P − 1 is "off"; docs/model.md §4.6).

This one is a fixed orthogonal allocation: link i keeps sub-channel i mod M at the highest
power while its CAM is pending, and is off once the CAM is delivered (so it stops interfering
with the V2I uplink that shares the sub-channel).
"""

from __future__ import annotations

import torch

from vdtn_marl.policies import encode_rra_action, max_power_level
from vdtn_marl.sim.layout import RRAFeatureLayout


class FixedOrthogonalRRA:
    """Link i on sub-channel i mod M at the highest power while its CAM is pending."""

    def __init__(self, params):
        radio = params.radio
        self.layout = RRAFeatureLayout.from_radio(radio)
        self.num_subchannels = radio.num_subchannels
        self.power_levels = radio.num_power_levels
        self.max_power = max_power_level(radio)

    def __call__(self, observation):
        observation = torch.as_tensor(observation)
        links = torch.arange(observation.shape[-2], device=observation.device)
        subchannel = (links % self.num_subchannels).expand(observation.shape[:-1])
        pending = observation[..., self.layout.bits_left] > 0
        level = torch.where(pending, self.max_power, self.power_levels - 1)
        return encode_rra_action(subchannel, level, self.power_levels).long()


def make_policy(params, seed):
    """The factory ``rra.policy`` names: ``(TwinParams, seed) -> policy`` (no randomness here,
    so the seed is unused)."""
    return FixedOrthogonalRRA(params)
