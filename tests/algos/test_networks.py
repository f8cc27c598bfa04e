"""Critic and observation scaling of the agent-group networks."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Bounded, Composite

from vdtn_marl.algos.networks import ObservationScaler, make_critic

N_AGENTS, N_OBS = 3, 4


def _spec() -> Composite:
    box = Bounded(low=-1.0, high=1.0, shape=(N_AGENTS, N_OBS))
    return Composite({"agents": Composite({"observation": box}, shape=(N_AGENTS,))})


def _values(critic, observation: torch.Tensor) -> torch.Tensor:
    td = TensorDict({("agents", "observation"): observation}, batch_size=observation.shape[:-2])
    return critic(td).get(("agents", "state_value"))


@pytest.mark.parametrize("share_params", [True, False])
def test_centralised_critic_fits_values_that_differ_between_agents(share_params):
    """Agents have their own rewards, so their values differ on the same state: a critic that
    gave every agent one value (TorchRL's centralised shared MLP) cannot fit them."""
    torch.manual_seed(0)
    critic = make_critic(_spec(), "agents", centralised=True, share_params=share_params)
    observation = torch.rand(256, N_AGENTS, N_OBS) * 2 - 1
    # agent i's value: its own first feature plus an agent-specific offset
    target = (observation[..., 0] + torch.arange(N_AGENTS)).unsqueeze(-1)
    assert _values(critic, observation).shape == (256, N_AGENTS, 1)
    optimiser = torch.optim.Adam(critic.parameters(), lr=1e-2)
    for _ in range(400):
        loss = (_values(critic, observation) - target).pow(2).mean()
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    # one value for all agents leaves at least the offsets' variance (2/3) unexplained
    assert loss.item() < 0.02


def test_centralised_critic_values_see_every_agents_observation():
    torch.manual_seed(0)
    critic = make_critic(_spec(), "agents", centralised=True, share_params=True)
    observation = torch.zeros(1, N_AGENTS, N_OBS)
    moved = observation.clone()
    moved[0, 2] = 0.9  # only the last agent's observation changes
    change = (_values(critic, moved) - _values(critic, observation)).abs().squeeze()
    assert (change > 0).all()  # every agent's value depends on it


@pytest.mark.parametrize("share_params", [True, False])
def test_decentralised_critic_values_see_only_their_own_observation(share_params):
    torch.manual_seed(0)
    critic = make_critic(_spec(), "agents", centralised=False, share_params=share_params)
    observation = torch.zeros(1, N_AGENTS, N_OBS)
    moved = observation.clone()
    moved[0, 2] = 0.9
    change = (_values(critic, moved) - _values(critic, observation)).abs().squeeze()
    assert (change[:2] == 0).all() and change[2] > 0


def test_observation_scaler_standardises_and_masks():
    low, high = torch.tensor([-10.0, 0.0, -1.0]), torch.tensor([10.0, 50.0, 1.0])
    scaler = ObservationScaler(low, high, mask=torch.tensor([True, True, False]))
    data = torch.stack([torch.randn(1000) * 2 + 3, torch.rand(1000) * 50, torch.randn(1000)], -1)
    scaler.fit_(data)
    z = scaler(data)
    assert z[:, 0].mean().abs() < 1e-4 and (z[:, 0].std() - 1).abs() < 1e-2
    assert (z[:, 2] == 0).all()
