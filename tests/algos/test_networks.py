"""Critic and observation scaling of the agent-group networks."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.data import Bounded, Categorical, Composite

from vdtn_marl.algos.networks import (
    ACTIVATION_CLASSES,
    CategoricalMode,
    ObservationScaler,
    SigmoidTanh,
    categorical_mode,
    make_actor,
    make_critic,
    mode_shortcut,
)
from vdtn_marl.algos.params import ACTIVATIONS
from vdtn_marl.algos.ppo import ActorPolicy

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


N_ACTIONS = 6


def _discrete_actor(share_params: bool = True, activation: str = "tanh"):
    actions = Composite(
        {
            "agents": Composite(
                {"action": Categorical(N_ACTIONS, shape=(N_AGENTS,))}, shape=(N_AGENTS,)
            )
        }
    )
    return make_actor(_spec(), actions, "agents", share_params=share_params, activation=activation)


@pytest.mark.parametrize("activation", ACTIVATIONS)
@pytest.mark.parametrize("scale", [0.1, 1.0, 30.0])
def test_fast_categorical_mode_gives_the_actors_own_deterministic_actions(scale, activation):
    """The RRA policy's fast path returns, bit for bit, what the ProbabilisticActor does under
    InteractionType.DETERMINISTIC (the slow path, ``ActorPolicy.action``), also where the
    logits are far apart (large scale) and where several are tied (zero last layer), with
    every activation of ``algo.activation``."""
    torch.manual_seed(1)
    actor = _discrete_actor(activation=activation)
    hidden = [m for m in actor.modules() if isinstance(m, ACTIVATION_CLASSES[activation])]
    assert hidden  # the network is built with the activation asked for
    policy = ActorPolicy(actor, "agents")
    assert policy.mode is not None
    observation = (torch.rand(4096, N_AGENTS, N_OBS) * 2 - 1) * scale
    fast = policy(observation)
    assert fast.dtype == torch.long and fast.shape == (4096, N_AGENTS)
    assert torch.equal(fast, policy.action(observation))
    assert len(fast.unique()) > 1  # the comparison covers several actions
    with torch.no_grad():  # ties: every logit equal, the mode is the first action
        for name, value in actor.named_parameters():
            if name.endswith("4.weight") or name.endswith("4.bias"):
                value.zero_()
    assert torch.equal(policy(observation), policy.action(observation))
    assert (policy(observation) == 0).all()


@pytest.mark.parametrize("activation", ACTIVATIONS)
def test_fast_categorical_mode_acts_the_same_on_any_subset_of_the_batch(activation):
    """What ``ActorPolicy.rowwise`` promises the interval engine: the fast path's actions for
    some scenarios alone are, bit for bit, theirs in the whole batch (here at the batch sizes
    of π̃ and a partial reset's few scenarios); a stochastic policy promises nothing."""
    torch.manual_seed(3)
    policy = ActorPolicy(_discrete_actor(activation=activation), "agents")
    assert policy.rowwise
    assert not ActorPolicy(_discrete_actor(), "agents", deterministic=False).rowwise
    for batch in (256, 1024):
        observation = torch.rand(batch, N_AGENTS, N_OBS) * 2 - 1
        whole = policy(observation)
        for size in (1, 2, 3, 7, 40, batch // 2):
            rows = torch.randperm(batch)[:size].sort().values
            assert torch.equal(policy(observation.index_select(0, rows)), whole[rows])


def test_fast_categorical_mode_reads_the_current_weights():
    """Weights loaded or trained after the policy was made are the ones it acts with."""
    torch.manual_seed(2)
    actor, other = _discrete_actor(), _discrete_actor()
    policy = ActorPolicy(actor, "agents")
    observation = torch.rand(512, N_AGENTS, N_OBS) * 2 - 1
    before = policy(observation)
    actor.load_state_dict(other.state_dict())
    after = policy(observation)
    assert not torch.equal(before, after)
    assert torch.equal(after, ActorPolicy(other, "agents").action(observation))


def _distribution_mode(logits: torch.Tensor) -> torch.Tensor:
    return torch.distributions.Categorical(logits=logits).mode


def test_categorical_mode_is_the_distributions_mode_bit_for_bit(monkeypatch):
    """Well separated logits take the argmax without the probabilities; logits closer than
    the probabilities' rounding (whose Categorical mode is the first of them, not the
    largest logit) and exact ties go the long way, for the whole call."""
    torch.manual_seed(4)
    logits = torch.randn(4096, 3, 16) * 3
    expected = _distribution_mode(logits)
    with monkeypatch.context() as patched:  # the fast path computes no softmax
        patched.setattr(torch.nn.functional, "softmax", None)
        assert torch.equal(categorical_mode(logits), expected)
    near = torch.tensor([[0.0, 1e-8, -3.0], [2.0, 2.0, 1.0], [1e-8, 0.0, 2e-8]])
    # the probabilities round equal: the mode is the first entry, the argmax another
    assert torch.equal(_distribution_mode(near), torch.tensor([0, 0, 0]))
    assert torch.equal(near.argmax(-1), torch.tensor([1, 0, 2]))
    assert torch.equal(categorical_mode(near), torch.tensor([0, 0, 0]))
    mixed = logits.clone()
    mixed[17, 1, :3] = near[0]  # one near tie in a large call
    mixed[17, 1, 3:] = -10.0
    _, near_rows = mode_shortcut(mixed)  # that row alone goes the long way
    assert near_rows.tolist() == [17 * 3 + 1]
    assert torch.equal(categorical_mode(mixed), _distribution_mode(mixed))
    assert categorical_mode(mixed)[17, 1] == 0
    coarse = near.to(torch.bfloat16)  # its rounding is wider than the margin: the long way
    assert mode_shortcut(coarse) is None
    assert torch.equal(categorical_mode(coarse), _distribution_mode(coarse))
    for bad in (float("nan"), float("inf"), -float("inf")):
        odd = logits[:8].clone()
        odd[3, 0, 5] = bad
        assert torch.equal(categorical_mode(odd), _distribution_mode(odd))


def test_bound_policy_acts_as_the_policy_with_the_weights_of_its_binding():
    """``ActorPolicy.bound()`` (one interval's radio) acts as the policy does; a binding made
    after new weights were loaded acts with them."""
    torch.manual_seed(5)
    actor, other = _discrete_actor(), _discrete_actor()
    policy = ActorPolicy(actor, "agents")
    observation = torch.rand(512, N_AGENTS, N_OBS) * 2 - 1
    bound = policy.bound()
    assert torch.equal(bound(observation), policy(observation))
    actor.load_state_dict(other.state_dict())
    assert torch.equal(policy.bound()(observation), ActorPolicy(other, "agents")(observation))
    stochastic = ActorPolicy(actor, "agents", deterministic=False)
    assert stochastic.bound() is stochastic


def test_fast_categorical_mode_only_for_shared_discrete_actors():
    """Actors with a parameter set per agent, continuous actors and stochastic policies keep
    the actor's own path; so does an observation of the wrong shape (the actor names it)."""
    assert CategoricalMode.of(_discrete_actor(share_params=False)) is None
    box = Bounded(low=-1.0, high=1.0, shape=(N_AGENTS, 1))
    continuous = make_actor(
        _spec(), Composite({"agents": Composite({"action": box}, shape=(N_AGENTS,))}), "agents"
    )
    assert CategoricalMode.of(continuous) is None
    assert ActorPolicy(_discrete_actor(), "agents", deterministic=False).mode is None
    with pytest.raises((RuntimeError, ValueError)):
        ActorPolicy(_discrete_actor(), "agents")(torch.zeros(2, N_AGENTS + 1, N_OBS))


def test_every_activation_name_has_a_module_class():
    """``algo.activation``'s allowed names (validated by the config) and the classes the
    networks build are one list."""
    assert tuple(ACTIVATION_CLASSES) == ACTIVATIONS
    with pytest.raises(ValueError, match="activation"):
        _discrete_actor(activation="relu")


@pytest.mark.parametrize("activation", ACTIVATIONS)
def test_in_place_activation_gives_the_same_numbers(activation):
    """Each activation's ``function_`` (what the RRA policy's fast path applies to a Linear
    layer's output) writes ``function``'s numbers bit for bit into its argument."""
    cls = ACTIVATION_CLASSES[activation]
    x = torch.randn(3000, 64) * torch.logspace(-3, 1.5, 64)  # saturation and the linear part
    x[:3, 0] = torch.tensor([0.0, 30.0, -30.0])
    buffer = x.clone()
    out = cls.function_(buffer)
    assert out.data_ptr() == buffer.data_ptr()
    assert torch.equal(out, cls.function(x))
    assert torch.equal(out, cls()(x))


def test_sigmoid_tanh_is_tanh_to_float32_rounding():
    """2·sigmoid(2x) − 1 is tanh(x): within a few 1e-7 of the float64 tanh everywhere, exact
    at 0 and in saturation; its gradient is tanh's (1 − tanh²) to the same precision."""
    x = torch.linspace(-20.0, 20.0, 200_001, dtype=torch.float32, requires_grad=True)
    y = SigmoidTanh()(x)
    exact = torch.tanh(x.detach().double())
    assert (y.detach().double() - exact).abs().max() < 3e-7
    assert SigmoidTanh()(torch.tensor([0.0, 30.0, -30.0])).tolist() == [0.0, 1.0, -1.0]
    y.sum().backward()
    assert (x.grad.double() - (1 - exact**2)).abs().max() < 1e-6
