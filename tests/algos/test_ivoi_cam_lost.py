"""The ``cam_lost`` IVoI baseline: ξ of the actual command minus ξ had the CAM been lost."""

import copy
import dataclasses

import pytest
import torch

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.policies import make_rra_baseline
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi import RolloutIVoIEstimator

GAMMA = 0.98
PARAMS = TwinParams.from_overrides(episode_intervals=12)
T = PARAMS.platoon.subframes_per_interval


def _run_radio(twin: DigitalTwin, rra) -> None:
    for _ in range(T):
        actions = torch.as_tensor(rra(twin.rra_observation())).long()
        twin.step_subframe(actions.numpy() if twin.backend == "numpy" else actions)


def _twin_at_interval_end(backend: str, intervals: int = 3) -> tuple[DigitalTwin, CACCController]:
    """A twin under round-robin RRA whose interval ``intervals`` has run all its subframes
    (with the physical V2V channel random RRA delivers too few CAMs for both cases to occur)."""
    twin = DigitalTwin(PARAMS, batch_size=16, seed=7, radio=True, backend=backend)
    twin.reset(seed=7)
    rra = make_rra_baseline("round_robin", PARAMS, 7)
    cacc = CACCController(PARAMS.platoon)
    for k in range(intervals):
        if k > 0:
            twin.begin_interval()
        _run_radio(twin, rra)
        if k < intervals - 1:
            twin.finish_interval(cacc(twin.vehicle_observation(False)), perfect=False)
    return twin, cacc


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_cams_lost_observation_is_the_observation_of_a_lost_cam(backend):
    """``cams_lost=True`` must give what the follower sees when its CAM did not arrive: the
    same as forcing every link's delivery subframe to T + 1 ('not delivered')."""
    twin, _ = _twin_at_interval_end(backend)
    actual = twin.vehicle_observation(False)
    counterfactual = twin.vehicle_observation(False, cams_lost=True)
    in_time = twin.switch_subframe(perfect=False) < T
    assert in_time.any() and (~in_time).any()  # both cases occur in this setting
    dropped = copy.deepcopy(twin)
    dropped.drop_cams(torch.ones(16, twin.num_links, dtype=torch.bool))
    torch.testing.assert_close(counterfactual, dropped.vehicle_observation(False))
    torch.testing.assert_close(twin.vehicle_observation(False), actual)  # the original is intact
    # followers whose CAM was not in time see the same thing either way; the others do not
    torch.testing.assert_close(counterfactual[~in_time], actual[~in_time])
    assert not torch.equal(counterfactual[in_time], actual[in_time])
    # perfect observation has no CAM to lose
    torch.testing.assert_close(
        twin.vehicle_observation(True, cams_lost=True), twin.vehicle_observation(True)
    )


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_cam_lost_ivoi_is_the_ivoi_of_the_actual_command_minus_that_of_a_lost_cam(backend):
    twin, cacc = _twin_at_interval_end(backend)
    command_if_lost = cacc(twin.vehicle_observation(False, cams_lost=True))
    record = twin.finish_interval(
        cacc(twin.vehicle_observation(False)), perfect=False, command_if_lost_mps2=command_if_lost
    )
    common = dict(reference_policy=cacc, horizon_intervals=4, discount=GAMMA)
    difference = RolloutIVoIEstimator(**common, baseline="cam_lost")(twin, record)
    paper = RolloutIVoIEstimator(**common)  # baseline="optimal"
    as_if_lost = dataclasses.replace(
        record,
        command_mps2=record.command_if_lost_mps2,
        switch_subframe=torch.full_like(record.switch_subframe, T),
    )
    in_time = record.switch_subframe < T
    expected = torch.where(
        in_time, paper(twin, record) - paper(twin, as_if_lost), torch.zeros_like(difference)
    )
    torch.testing.assert_close(difference, expected, rtol=1e-4, atol=1e-5)
    assert (difference[in_time] != 0).any()  # the test can tell a wrong branch from a right one
    assert (difference[~in_time] == 0).all()


def test_drop_cams_loses_only_the_chosen_cams_and_checks_its_input():
    twin, cacc = _twin_at_interval_end("torch")
    in_time = twin.switch_subframe(perfect=False) < T
    mask = torch.zeros_like(in_time)
    mask[0] = True  # every CAM of scenario 0
    twin.drop_cams(mask)
    after = twin.switch_subframe(perfect=False) < T
    assert not after[0].any()
    torch.testing.assert_close(after[1:], in_time[1:])
    with pytest.raises(ValueError, match="expected bool"):
        twin.drop_cams(torch.zeros(16, 1, dtype=torch.bool))
    record = twin.finish_interval(cacc(twin.vehicle_observation(False)), perfect=False)
    assert (record.cam_delay_subframes[0] == T + 1).all()
    twin.begin_interval()
    with pytest.raises(RuntimeError, match="after 0 of 50 subframes"):
        twin.drop_cams(mask)


def test_cam_lost_ivoi_needs_the_counterfactual_command_and_a_known_baseline():
    twin, cacc = _twin_at_interval_end("torch")
    record = twin.finish_interval(cacc(twin.vehicle_observation(False)), perfect=False)
    assert record.command_if_lost_mps2 is None
    estimator = RolloutIVoIEstimator(cacc, horizon_intervals=2, baseline="cam_lost")
    assert estimator.needs_command_if_lost
    with pytest.raises(ValueError, match="command_if_lost_mps2"):
        estimator(twin, record)
    with pytest.raises(ValueError, match="baseline='lost'.*optimal, cam_lost"):
        RolloutIVoIEstimator(cacc, baseline="lost")
    with pytest.raises(ValueError, match=r"command_if_lost_mps2 has shape \(16, 2\)"):
        twin.finish_interval(
            torch.zeros(16, twin.num_followers), False, command_if_lost_mps2=torch.zeros(16, 2)
        )


def test_evaluation_feeds_the_counterfactual_command_to_the_estimator():
    """evaluate_system computes the lost-CAM command when the estimator asks for it: ξ is then
    exactly 0 on every follower-interval whose CAM was not in time, and not 0 on the rest."""
    cacc = CACCController(PARAMS.platoon)
    result = evaluate_system(
        PARAMS, cacc, None, perfect=False, episodes=8, intervals=12, seed=3, gamma=GAMMA,
        ivoi_estimator=RolloutIVoIEstimator(cacc, 3, GAMMA, baseline="cam_lost"),
    )  # fmt: skip
    assert result.metrics["ivoi_mean_lost"] == 0.0
    assert result.metrics["ivoi_mean_delivered"] != 0.0
    assert result.metrics["ivoi_std"] > 0.0
