"""Age of Information of the CAM content at each recipient (docs/model.md §4.8)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.sim.aoi import age_ms, interval_age_ms
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin

T = 50  # subframes per interval, δ = 1 ms, Δt = 50 ms


def test_interval_mean_and_peak_by_hand():
    """Held content 1 interval old at kΔt: CAM_k at d = 20 → the age runs 51..69 ms over
    subframes 1..19, then 20..50 ms: mean (Σ51..69 + Σ20..50)/50 = 44.5, peak 70. Held 2
    intervals old and CAM_k lost: 101..150 ms, mean 125.5. d = 1: 1..50 ms, mean 25.5, peak 51."""
    held = torch.tensor([[1, 2, 1]])
    delay = torch.tensor([[20, T + 1, 1]])
    mean, peak = interval_age_ms(held, delay, T, 1.0)
    assert mean.tolist() == [[44.5, 125.5, 25.5]]
    assert peak[0, 0] == 70.0 and peak[0, 2] == 51.0


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_the_closed_form_is_the_mean_of_the_per_subframe_ages(backend):
    """For every delivery subframe (and a loss) and held ages 1..4, the interval mean equals the
    mean of A(k, s) over s = 1..T, and the peak is the old content's age when CAM_k arrives."""
    held, delay = np.meshgrid(np.arange(1, 5), np.arange(1, T + 2), indexing="ij")
    if backend == "torch":
        held, delay = torch.from_numpy(held), torch.from_numpy(delay)
    per_subframe = np.stack(
        [np.asarray(age_ms(held, delay, s, 50.0, 1.0)) for s in range(1, T + 1)]
    )
    mean, peak = interval_age_ms(held, delay, T, 1.0)
    np.testing.assert_allclose(np.asarray(mean), per_subframe.mean(0), rtol=1e-6)
    delivered = np.asarray(delay) <= T
    # the old content's age at the delivery subframe: a_k·Δt + d_k·δ
    expected_peak = np.asarray(held) * 50.0 + np.asarray(delay)
    np.testing.assert_array_equal(np.asarray(peak)[delivered], expected_peak[delivered])


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_the_twin_reads_the_age_from_what_each_recipient_holds(backend):
    """Over 4 intervals of random RRA the twin's per-subframe AoI is, at every subframe, s ms
    where the link's CAM has arrived and (k − held interval)·50 + s ms elsewhere; at reset the
    recipients hold content one interval old; the interval mean of the samples is the closed
    form of the interval's delivery subframes."""
    params = TwinParams.from_overrides(cam_size_bits=3000)  # a mix of deliveries and losses
    twin = DigitalTwin(params, batch_size=8, seed=3, backend=backend)
    policy = RandomRRAPolicy(params.radio.num_actions, 3)
    delivered_any = lost_any = False
    for k in range(4):
        held_age = (twin.interval[:, None] - twin.cam_held_interval).clone()
        if k == 0:
            assert (held_age == 1).all()
            np.testing.assert_array_equal(np.asarray(twin.cam_age_ms()), 50.0)
        samples = []
        for _ in range(T):
            twin.step_subframe(policy(twin.rra_observation()))
            samples.append(torch.as_tensor(np.asarray(twin.cam_age_ms())).clone())
        delay = torch.as_tensor(np.asarray(twin.link_state.delay_subframes))
        s = torch.arange(1, T + 1)[:, None, None]
        expected = torch.where(delay <= s, s * 1.0, held_age * 50.0 + s)
        torch.testing.assert_close(torch.stack(samples), expected.float())
        mean, _ = interval_age_ms(held_age, delay, T, 1.0)
        torch.testing.assert_close(torch.stack(samples).mean(0), mean.float())
        delivered_any |= bool((delay <= T).any())
        lost_any |= bool((delay > T).any())
        twin.finish_interval(torch.zeros(8, 3), perfect=False)
        twin.begin_interval()
    assert delivered_any and lost_any
