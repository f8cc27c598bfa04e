"""The NumPy twin (PettingZoo path) and the torch twin (batched path) give identical numbers."""

import numpy as np
import pytest
import torch

from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi import RolloutIVoIEstimator


def _as_numpy(x):
    return x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


@pytest.mark.parametrize("batch", [1, 3])
def test_numpy_and_torch_twins_agree(batch):
    """B = 1 (what the PettingZoo envs run): vehicle observations, rewards, CAM delays and
    IVoI bit-identical, RRA observations and V2I rates within a few ulp (NumPy's log1p may
    differ from torch's in the last bit); at B > 1 (with a partial reset) within float32
    round-off."""
    params = TwinParams.from_overrides(episode_intervals=20)
    twins = {
        backend: DigitalTwin(params, batch_size=batch, seed=4, backend=backend)
        for backend in ("numpy", "torch")
    }
    cacc = CACCController(params.platoon)
    estimator = RolloutIVoIEstimator(cacc, horizon_intervals=5, discount=0.99)
    actions_gen = torch.Generator().manual_seed(8)
    num_actions = params.radio.num_actions
    records = {}
    for twin in twins.values():
        twin.reset(seed=4)
    for k in range(4):
        actions = [
            torch.randint(0, num_actions, (batch, twins["torch"].num_links), generator=actions_gen)
            for _ in range(params.platoon.subframes_per_interval)
        ]
        for backend, twin in twins.items():
            if k > 0:
                if k == 2 and batch == 3:  # scenario 1 starts over: a partial reset
                    twin.reset(mask=torch.tensor([False, True, False]))
                    twin.begin_interval(torch.tensor([True, False, True]))
                else:
                    twin.begin_interval()
            observations = []
            for a in actions:
                observations.append(_as_numpy(twin.rra_observation()).copy())
                twin.step_subframe(a.numpy() if backend == "numpy" else a)
            obs = twin.vehicle_observation(perfect=False)
            record = twin.finish_interval(cacc(torch.as_tensor(obs)), perfect=False)
            records[backend] = (
                np.stack(observations),
                _as_numpy(obs),
                _as_numpy(record.reward),
                _as_numpy(record.cam_delay_subframes),
                _as_numpy(record.v2i_rate_bps),
                _as_numpy(estimator(twin, record)),
            )
        for i, (got, want) in enumerate(zip(records["numpy"], records["torch"], strict=True)):
            message = f"interval {k}, output {i}"
            if batch == 1 and i not in (0, 4):
                np.testing.assert_array_equal(got, want, err_msg=message)
            elif batch == 1:  # CAM bits left and V2I rates pass through log1p: last bits
                np.testing.assert_allclose(got, want, rtol=1e-6, atol=0, err_msg=message)
            else:
                np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6, err_msg=message)
