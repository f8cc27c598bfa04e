"""VoI estimators against the identity E[Σ_k γ^k ξ_k] = EVoI and the sign of ξ."""

import pytest
import torch

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.policies import make_rra_baseline
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi import (
    IVOI_ESTIMATORS,
    RolloutIVoIEstimator,
    RolloutValue,
    TDIVoIEstimator,
    VoIReference,
    discounted_rollout,
    expected_voi,
    make_ivoi_estimator,
    mean_ci,
)

INTERVALS = 20
GAMMA = 0.98


@pytest.fixture(scope="module")
def tracking_setting():
    """A pure tracking reward (no accel/jerk terms), where perfect-information CACC is a
    strong reference: late CAMs can only hurt it."""
    params = TwinParams.from_overrides(
        episode_intervals=INTERVALS, weight_accel=0.0, weight_jerk=0.0, weight_speed=1.0
    )
    cacc = CACCController(params.platoon)
    value = RolloutValue(cacc, horizon_intervals=INTERVALS, discount=GAMMA)
    common = dict(episodes=32, intervals=INTERVALS, seed=11, gamma=GAMMA)
    impaired = evaluate_system(
        params, cacc, None, perfect=False, ivoi_estimator=TDIVoIEstimator(value, GAMMA), **common
    )
    perfect = evaluate_system(params, cacc, None, perfect=True, **common)
    return params, cacc, impaired, perfect, common


def test_td_ivoi_sums_to_evoi_within_its_confidence_interval(tracking_setting):
    _, _, impaired, perfect, _ = tracking_setting
    evoi, low, high = expected_voi(impaired.returns, perfect.returns)
    ivoi_mean, ivoi_low, ivoi_high = mean_ci(impaired.ivoi_sums)
    assert low < evoi < high
    assert low <= ivoi_mean <= high
    assert ivoi_low <= evoi <= ivoi_high
    # with the exact finite-horizon value the telescoping sum holds scenario by scenario
    torch.testing.assert_close(
        impaired.ivoi_sums, impaired.returns - perfect.returns, atol=1e-3, rtol=1e-3
    )


def test_ivoi_is_negative_in_expectation_when_the_reference_is_good(tracking_setting):
    params, cacc, impaired, perfect, common = tracking_setting
    evoi, _, evoi_high = expected_voi(impaired.returns, perfect.returns)
    assert evoi_high < 0.0
    _, _, ivoi_high = mean_ci(impaired.ivoi_sums)
    assert ivoi_high < 0.0
    rollout = evaluate_system(
        params,
        cacc,
        None,
        perfect=False,
        ivoi_estimator=RolloutIVoIEstimator(cacc, horizon_intervals=5, discount=GAMMA),
        **common,
    )
    _, _, rollout_high = mean_ci(rollout.ivoi_sums)
    assert rollout_high < 0.0


def test_perfect_observation_has_zero_ivoi():
    params = TwinParams.from_overrides(episode_intervals=10)
    cacc = CACCController(params.platoon)
    value = RolloutValue(cacc, horizon_intervals=10, discount=GAMMA)
    result = evaluate_system(
        params, cacc, None, perfect=True, episodes=4, intervals=10, seed=3, gamma=GAMMA,
        ivoi_estimator=TDIVoIEstimator(value, GAMMA),
    )  # fmt: skip
    torch.testing.assert_close(result.ivoi_sums, torch.zeros(4), atol=1e-4, rtol=0)


def test_td_estimator_with_a_critic_callable():
    params = TwinParams.from_overrides(episode_intervals=10)
    cacc = CACCController(params.platoon)

    def zero_critic(obs):
        return torch.zeros(obs.shape[:-1])

    result = evaluate_system(
        params, cacc, None, perfect=False, episodes=4, intervals=10, seed=3, gamma=GAMMA,
        ivoi_estimator=make_ivoi_estimator("td", value=zero_critic, discount=GAMMA),
    )  # fmt: skip
    # v ≡ 0 makes ξ the reward itself, so Σγ^k ξ_k is the discounted return
    torch.testing.assert_close(result.ivoi_sums, result.returns, atol=1e-5, rtol=1e-5)


def test_bad_estimator_arguments_raise():
    with pytest.raises(ValueError, match="value="):
        make_ivoi_estimator("td")
    with pytest.raises(ValueError, match="ivoi_estimator='bogus'"):
        make_ivoi_estimator("bogus")
    with pytest.raises(TypeError, match="horizon_interval"):  # a misspelt option
        make_ivoi_estimator("td", value=lambda o: o[..., 0], horizon_interval=5)
    with pytest.raises(TypeError, match="must be callable"):
        TDIVoIEstimator(value=3)
    with pytest.raises(ValueError, match="discount"):
        TDIVoIEstimator(value=lambda o: o[..., 0], discount=1.5)
    with pytest.raises(ValueError, match="EVoI pairs"):
        expected_voi(torch.zeros(3), torch.zeros(4))


def test_ivoi_is_split_by_cam_delivery_of_the_followers_own_link():
    """ξ_i := 1 when follower i's CAM (link i) missed its interval, else 0: the split must put
    every 0 under 'delivered' and every 1 under 'lost', scenario by scenario."""
    # synthetic traces (10-30 m/s) and round-robin RRA: every scenario both delivers and
    # loses CAMs (random RRA delivers too few on the physical V2V channel, docs/model.md §4.2)
    params = TwinParams.from_overrides(episode_intervals=10, traces="synthetic")
    round_robin = make_rra_baseline("round_robin", params, 5)
    t = params.platoon.subframes_per_interval

    def lost_indicator(twin, record):
        return (record.cam_delay_subframes > t).float()

    result = evaluate_system(
        params, CACCController(params.platoon), round_robin, perfect=False, episodes=6,
        intervals=10, seed=5, gamma=1.0, ivoi_estimator=lost_indicator,
    )  # fmt: skip
    delivered, lost = result.ivoi_delivered, result.ivoi_lost
    assert delivered.shape == lost.shape == (6,)
    # the round-robin RRA policy loses some CAMs and delivers some in every scenario
    assert torch.isfinite(delivered).all() and torch.isfinite(lost).all()
    torch.testing.assert_close(delivered, torch.zeros(6, dtype=torch.float64))
    torch.testing.assert_close(lost, torch.ones(6, dtype=torch.float64))
    assert result.metrics["ivoi_mean_delivered"] == 0.0
    assert result.metrics["ivoi_mean_lost"] == 1.0
    # with γ = 1, Σ_k ξ_k counts the lost CAMs: their share is the measured loss rate
    assert result.metrics["collision_rate"] == 0.0
    loss_rate = float(result.ivoi_sums.double().mean()) / 10
    assert loss_rate == pytest.approx(1.0 - result.metrics["cam_delivery_rate"], rel=1e-5)
    # ξ is a 0/1 indicator: its standard deviation is that of a Bernoulli(loss rate)
    expected_std = (loss_rate * (1.0 - loss_rate)) ** 0.5
    assert result.metrics["ivoi_std"] == pytest.approx(expected_std, rel=1e-5)


def test_perfect_observation_without_radio_has_no_delivery_split():
    params = TwinParams.from_overrides(episode_intervals=5)
    result = evaluate_system(
        params, CACCController(params.platoon), None, perfect=True, episodes=2, intervals=5,
        seed=5, ivoi_estimator=lambda twin, record: torch.zeros_like(record.reward),
    )  # fmt: skip
    assert result.ivoi_delivered is None and result.ivoi_lost is None
    assert "ivoi_mean_lost" not in result.metrics


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_a_collision_ends_a_rollout_as_it_ends_the_episode(backend):
    """Scenario 0 starts with follower 1 closing on the leader at 15 m/s from 0.5 m: it
    collides in the first interval. Its return over 5 intervals must be that interval's
    reward with the penalty counted once (the environment terminates there), while the
    other scenario keeps earning rewards after the first interval (synthetic traces: a
    moving leader, so the rewards are not all 0 as at a standstill)."""
    params = TwinParams.from_overrides(episode_intervals=20, traces="synthetic")
    twin = DigitalTwin(params, batch_size=2, seed=3, radio=False, backend=backend)
    twin.reset(seed=3)
    state = twin.platoon if backend == "torch" else twin.platoon.torch()
    state = state.clone()
    pp = params.platoon
    state.position_m[0, 1] = state.position_m[0, 0] - pp.vehicle_length_m - 0.5
    state.speed_mps[0, 1] = state.speed_mps[0, 0] + 15.0
    if backend == "numpy":
        state = state.numpy()
    interval = torch.zeros(2, dtype=torch.long)
    cacc = CACCController(pp)
    one, _ = discounted_rollout(twin, state, interval, cacc, 1, GAMMA)
    five, _ = discounted_rollout(twin, state, interval, cacc, 5, GAMMA)
    assert float(one[0].sum()) < pp.collision_penalty / 2  # the penalty is in interval 1
    torch.testing.assert_close(five[0], one[0])  # ... and nothing after it
    assert not torch.equal(five[1], one[1])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_evaluation_with_radio_and_ivoi_runs_on_cuda():
    params = TwinParams.from_overrides(episode_intervals=4)
    cacc = CACCController(params.platoon)
    estimator = TDIVoIEstimator(RolloutValue(cacc, horizon_intervals=4, discount=GAMMA), GAMMA)
    result = evaluate_system(
        params, cacc, None, perfect=False, episodes=8, intervals=4, seed=0, gamma=GAMMA,
        device="cuda", ivoi_estimator=estimator,
    )  # fmt: skip
    for key in ("control_cost", "cam_delivery_rate", "cam_latency_ms_p50", "ivoi_std"):
        assert key in result.metrics and result.metrics[key] == result.metrics[key], key


@pytest.mark.parametrize("name", sorted(IVOI_ESTIMATORS))
def test_every_registered_estimator_gives_the_reference_policy_zero_advantage(name):
    """Built by name from a reference (CACC, its exact finite-horizon value), each estimator of
    the registry returns ξ [B, F] that is 0 where the acting system plays the reference's own
    commands on perfect observations, and the config accepts the name."""
    from dataclasses import replace

    from vdtn_marl.experiment.config import RunConfig, validate

    params = TwinParams.from_overrides(episode_intervals=INTERVALS)
    cacc = CACCController(params.platoon)
    reference = VoIReference(
        policy=cacc, value=RolloutValue(cacc, horizon_intervals=INTERVALS, discount=GAMMA),
        discount=GAMMA,
    )  # fmt: skip
    # rollouts to the episode end need no bootstrap (td ignores the rollout options)
    estimator = make_ivoi_estimator(name, reference, horizon_intervals=INTERVALS, bootstrap=False)
    twin = DigitalTwin(params, batch_size=6, seed=3, radio=False)
    for _ in range(4):
        record = twin.finish_interval(cacc(twin.vehicle_observation(perfect=True)), perfect=True)
        xi = estimator(twin, record)
        assert xi.shape == (6, params.platoon.num_followers)
        torch.testing.assert_close(xi, torch.zeros_like(xi), atol=1e-4, rtol=0)
        twin.begin_interval()
    cfg = RunConfig()
    validate(replace(cfg, rra=replace(cfg.rra, ivoi_estimator=name)))


def test_follower_returns_are_each_followers_share_of_the_return(tracking_setting):
    params, _, impaired, perfect, common = tracking_setting
    for result in (impaired, perfect):
        per = result.follower_returns
        assert per.shape == (common["episodes"], params.platoon.num_followers)
        torch.testing.assert_close(per.mean(-1), result.returns)
        assert not torch.allclose(per[:, 0], per[:, -1])  # one return per follower, not a copy
