"""The RRA rewards of :mod:`vdtn_marl.core.reward`: the AoI-aware reward (docs/model.md §5)."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import vdtn_marl
from vdtn_marl.core.reward import REWARD_KINDS, RRAReward
from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment.config import LEARNED_RRA, RunConfig, validate

T = 50
OFF = 3  # sub-channel 0, the last power level (off)
MAX_POWER = 0  # sub-channel 0 at 23 dBm


def _outcome(lib):
    """A subframe with V2I rates summing to 4 Mbps and three silent V2V links."""
    rates = lib.asarray([[1e6, 2e6, 0.0, 1e6]]) if lib is np else torch.tensor([[1e6, 2e6, 0, 1e6]])
    zeros = lib.zeros((1, 3))
    false = lib.zeros((1, 3), dtype=bool) if lib is np else torch.zeros(1, 3, dtype=torch.bool)
    return SimpleNamespace(
        v2i_rate_bps=rates, v2v_bits=zeros, v2v_power_mw=zeros, delivered_now=false,
        was_pending=false,
    )  # fmt: skip


@pytest.mark.parametrize("lib", [np, torch], ids=["numpy", "torch"])
def test_aoi_reward_is_minus_the_scaled_age_plus_the_throughput_term(lib):
    """κ1 = 0.25: 0.25·0.004·4 Mbps − 0.75·0.02·A for ages 10, 60 and 110 ms."""
    reward_fn = RRAReward("aoi", kappa1=0.25)
    age = lib.asarray([[10.0, 60.0, 110.0]]) if lib is np else torch.tensor([[10.0, 60.0, 110.0]])
    reward, g = reward_fn.per_subframe(_outcome(lib), 180e3, 1e-3, cam_age_ms=age)
    assert float(g[0]) == pytest.approx(4.0)
    np.testing.assert_allclose(np.asarray(reward), [[-0.146, -0.896, -1.646]], rtol=1e-6)


def test_aoi_reward_pays_nothing_more_at_the_interval_end_and_needs_the_age():
    reward_fn = RRAReward("aoi")
    assert reward_fn.uses_aoi and not reward_fn.uses_ivoi
    lost = torch.tensor([[True, False, True]])
    assert reward_fn.at_interval_end(torch.ones(1, 3), lost).tolist() == [[0.0, 0.0, 0.0]]
    with pytest.raises(ValueError, match="cam_age_ms"):
        reward_fn.per_subframe(_outcome(np), 180e3, 1e-3)
    # κ2 = 0 leaves the throughput term alone: the age is neither needed nor paid
    assert not RRAReward("aoi", kappa1=1.0).uses_aoi


def test_aoi_scale_out_of_range_names_the_key():
    with pytest.raises(ConfigError, match="aoi_scale=-1"):
        RRAReward("aoi", aoi_scale=-1.0)
    cfg = RunConfig()
    with pytest.raises(ConfigError, match="rra.aoi_scale=-1"):
        validate(replace(cfg, rra=replace(cfg.rra, name="aoi", aoi_scale=-1.0)))


def test_every_reward_is_a_learned_rra_method():
    """The config's choices are read from the registry: every reward validates as ``rra.name``
    and trains the RRA agents."""
    cfg = RunConfig()
    for kind in REWARD_KINDS:
        validated = validate(replace(cfg, rra=replace(cfg.rra, name=kind)))
        assert kind in LEARNED_RRA and validated.rra.learned


def test_the_aoi_reward_is_paid_to_the_link_whose_recipient_it_measures():
    """Link 1 sends a short CAM at full power, links 2 and 3 stay off (κ1 = 0, κ2 = 1). At
    subframe s of the first interval the recipients hold content one interval old (reset):
    rra_2 and rra_3 get −0.02·(50 + s) every subframe, rra_1 the same until its CAM arrives at
    d and −0.02·s from then on. In the second interval the silent links' recipients hold
    content two intervals old: −0.02·(100 + s)."""
    env = vdtn_marl.make(
        "vdtn/v2x-rra-v1", seed=0, reward="aoi", kappa1=0.0, cam_size_bits=400, traces="constant"
    )
    env.reset(seed=0)
    actions = {"rra_1": MAX_POWER, "rra_2": OFF, "rra_3": OFF}
    for interval in range(2):
        for s in range(1, T + 1):
            _, rewards, *_ = env.step(actions)
            if s < T:  # the interval's delivery subframes, before the interval closes
                delay = np.asarray(env.twin.link_state.delay_subframes)[0]
            held_ms = 50.0 * (interval + 1)
            assert rewards["rra_2"] == pytest.approx(-0.02 * (held_ms + s), rel=1e-5)
            assert rewards["rra_3"] == pytest.approx(-0.02 * (held_ms + s), rel=1e-5)
            first = s if delay[0] <= s else 50.0 + s
            assert rewards["rra_1"] == pytest.approx(-0.02 * first, rel=1e-5), (interval, s)
        assert delay[0] < T and (delay[1:] == T + 1).all()


@pytest.mark.parametrize("scale", [0.004, np.float64(0.004)], ids=["float", "np.float64"])
def test_numpy_throughput_term_is_the_general_formulas_bit_for_bit(scale):
    """On float32 NumPy outcomes the throughput term takes float32 0-d constants (cheaper
    calls) only for Python numbers: the numbers and dtype of κ1·s_g·g·1 either way."""
    rng = np.random.default_rng(3)
    rates = (rng.uniform(0.0, 5e6, (64, 4))).astype(np.float32)
    bits = np.zeros((64, 3), np.float32)
    outcome = SimpleNamespace(v2i_rate_bps=rates, v2v_bits=bits)
    reward_fn = RRAReward("jocc", kappa1=0.3, throughput_scale=scale)
    reward, g = reward_fn.per_subframe(outcome, 180e3, 1e-3)
    want_g = rates.sum(axis=-1) * 1e-6
    want = (reward_fn.kappa1 * reward_fn.throughput_scale) * want_g[:, None] * np.ones_like(bits)
    for got, expected in ((g, want_g), (reward, want)):
        assert got.dtype == expected.dtype and got.tobytes() == expected.tobytes()


def test_spread_scales_make_each_terms_spread_one_by_hand():
    from vdtn_marl.core.reward import spread_scales

    # silent carries 500 Mbps·subframes per interval, greedy 400; ξ −0.02 against −0.015
    s_g, s_xi = spread_scales((500.0, 400.0), (-0.02, -0.015))
    assert s_g == pytest.approx(1 / 100) and s_xi == pytest.approx(1 / 0.005)
    # κ1 = κ2 = 0.5 ranks the two extremes equal: 0.5·s_g·ΔG = 0.5·s_ξ·ΔΞ
    assert 0.5 * s_g * 100.0 == pytest.approx(0.5 * s_xi * 0.005)


@pytest.mark.parametrize(
    ("throughput", "ivoi", "key"),
    [((400.0, 400.0), (-0.02, -0.01), "V2I spread"), ((500.0, 400.0), (-0.01, -0.02), "IVoI")],
)
def test_spread_scales_refuse_a_spread_that_is_not_positive(throughput, ivoi, key):
    from vdtn_marl.core.reward import spread_scales

    with pytest.raises(ConfigError, match=key):
        spread_scales(throughput, ivoi)
