"""The deadline-aware opportunistic RRA policy (when it sends, what it gives on the twin) and the
silent one."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.policies import RRAFeatureLayout, make_control_baseline, make_rra_baseline
from vdtn_marl.policies.opportunistic import OpportunisticRRAPolicy
from vdtn_marl.sim import link
from vdtn_marl.sim.params import RadioParams, TwinParams

RADIO = RadioParams()
LAYOUT = RRAFeatureLayout.from_radio(RADIO)
T = 50
DECODE = link.ActionTables.build(RADIO, torch.device("cpu"))


def _observation(snr_db: float, bits_left: float = 1.0, time_left: float = 1.0, links: int = 1):
    """One scenario's RRA observation: ``snr_db`` on sub-channel 1, 0 dB elsewhere, no V2I
    interference, a CAM with ``bits_left`` (fraction) and ``time_left`` (fraction) left."""
    obs = torch.zeros(1, links, LAYOUT.dim)
    obs[..., LAYOUT.v2i_interference] = -5.0  # −50 dB INR: the score is the SNR
    obs[..., LAYOUT.own_snr.start + 1] = snr_db / 10.0
    obs[..., LAYOUT.bits_left] = bits_left
    obs[..., LAYOUT.time_left] = time_left
    return obs


def _sends(actions: torch.Tensor) -> bool:
    return bool((DECODE.power_mw[actions] > 0).all())


def test_sends_in_better_than_usual_subframes_and_waits_in_worse_ones():
    policy = OpportunisticRRAPolicy(1, RADIO, subframes_per_interval=T)
    first = policy(_observation(20.0))  # the first score starts the mean: s = s̄, send
    assert _sends(first) and int(first) // RADIO.num_power_levels == 1
    assert not _sends(policy(_observation(10.0, time_left=0.9)))  # below s̄ = 20 dB: wait
    # s̄ is now 20 − 0.05·10 = 19.5 dB: 19.6 dB is above it
    assert _sends(policy(_observation(19.6, time_left=0.88)))


def test_the_deadline_forces_the_cam_out_at_a_hand_computed_subframe():
    """At s̄ = 20 dB a subframe carries W·Δt·log2(1 + 100) bits; a whole CAM needs
    14,400 / that ≈ 12.0 subframes, so with margin 2 a below-mean subframe is used once
    n_left ≤ 2·12.0 + 1 ≈ 25.0."""
    per_subframe = RADIO.subchannel_bandwidth_hz * 1e-3 * math.log2(1 + 100.0)
    needed = RADIO.cam_size_bits / per_subframe
    threshold = 2.0 * needed + 1.0
    edge = math.floor(threshold)
    for subframes_left, expect in ((edge + 1, False), (edge, True)):
        policy = OpportunisticRRAPolicy(1, RADIO, subframes_per_interval=T, mean_weight=1e-6)
        policy(_observation(20.0))
        got = policy(_observation(5.0, time_left=subframes_left / T))
        assert _sends(got) is expect, (subframes_left, threshold)


def test_a_delivered_link_is_silent_and_numpy_matches_torch():
    policy = OpportunisticRRAPolicy(2, RADIO, subframes_per_interval=T)
    obs = _observation(20.0, links=2)
    obs[0, 1, LAYOUT.bits_left] = 0.0
    actions = policy(obs)
    assert _sends(actions[0, 0]) and not _sends(actions[0, 1])
    policy.reset()
    np_actions = policy(obs.numpy())
    assert isinstance(np_actions, np.ndarray) and np_actions.dtype == np.int64
    assert np_actions.tolist() == actions.tolist()


@pytest.mark.parametrize(
    ("key", "value"), [("mean_weight", 0.0), ("mean_weight", 1.5), ("deadline_margin", 0.5)]
)
def test_bad_settings_name_the_key(key, value):
    with pytest.raises(ValueError, match=key):
        OpportunisticRRAPolicy(1, RADIO, **{key: value})


def test_it_delivers_like_greedy_and_carries_more_v2i_under_cacc():
    """The witness of what the channel allows at greedy's control: the same CAM delivery and
    |gap error|, more V2I per link (paired scenarios)."""
    params = TwinParams()
    common = dict(perfect=False, episodes=8, intervals=100, seed=11)
    cacc = make_control_baseline("cacc", params)
    greedy = evaluate_system(params, cacc, make_rra_baseline("greedy", params), **common).metrics
    waits = evaluate_system(params, cacc, make_rra_baseline("opportunistic", params), **common)
    waits = waits.metrics
    assert waits["cam_delivery_rate"] >= greedy["cam_delivery_rate"] - 0.01
    assert waits["gap_error_abs_m"] <= 1.02 * greedy["gap_error_abs_m"]
    assert waits["v2i_throughput_mbps_per_link"] >= 1.03 * greedy["v2i_throughput_mbps_per_link"]
    assert waits["cam_latency_ms_mean"] > greedy["cam_latency_ms_mean"]  # it waits


def test_silent_never_transmits_and_leaves_the_v2i_uplinks_their_clean_rate():
    params = TwinParams()
    common = dict(perfect=False, episodes=4, intervals=20, seed=3)
    cacc = make_control_baseline("cacc", params)
    silent = evaluate_system(params, cacc, make_rra_baseline("silent", params), **common).metrics
    greedy = evaluate_system(params, cacc, make_rra_baseline("greedy", params), **common).metrics
    assert silent["cam_delivery_rate"] == 0.0
    assert silent["v2i_throughput_mbps_per_link"] > 1.2 * greedy["v2i_throughput_mbps_per_link"]
    actions = make_rra_baseline("silent", params)(np.zeros((2, 3, LAYOUT.dim), np.float32))
    assert actions.dtype == np.int64 and bool(
        (DECODE.power_mw[torch.as_tensor(actions)] == 0).all()
    )
