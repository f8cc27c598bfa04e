"""Actor and critic networks of one agent group, built from TorchRL parts.

- Actor: observation scaling → :class:`~torchrl.modules.MultiAgentMLP` (decentralised) →
  a :class:`~torchrl.modules.ProbabilisticActor`. Continuous groups (``vehicle``: acceleration,
  m/s²) use a TanhNormal bounded to the action range with a state-independent scale; discrete
  groups (``rra``: sub-channel × power level) use a Categorical over logits.
- Critic: observation scaling → MultiAgentMLP with ``centralized=True`` for MAPPO (every agent's
  value sees the whole group's observations: CTDE) or ``False`` for IPPO. Agents have their own
  rewards (each follower its own cost, each RRA agent its own follower's IVoI), so a shared
  centralised critic has one output per agent (:class:`OwnValue`) rather than one value that
  TorchRL would copy to every agent.
``share_params`` makes one network serve every agent of the group. The hidden layers' activation
is tanh: :class:`Tanh` (``nn.Tanh``, ``activation="tanh"``) or :class:`SigmoidTanh`
(``"tanh_sigmoid"``, the same function from torch's sigmoid kernel, faster on CPUs;
:data:`ACTIVATION_CLASSES`).

Observations are standardised inside the networks (:class:`ObservationScaler`): first with the
bounds of the environment's observation spec, then, once :meth:`ObservationScaler.fit_` has
seen a batch of real observations, with their per-feature mean and standard deviation (as
TorchRL's ``ObservationNorm.init_stats`` does), so features in m, m/s, m/s², ms and dB enter
the networks on a common scale and the statistics travel with the weights in checkpoints.
A feature mask zeroes features a policy must not use (the "no state augmentation" baseline
drops the CAM delay/age and the previous command).

Policy prior (``prior=...`` on continuous groups): the TanhNormal's location is the prior's
command (mapped through atanh) plus the MLP's output, whose last layer starts at zero. With the
linear CACC controller as prior, the untrained policy's mean is CACC and PPO learns a residual
on top of it; the action distribution, log-probabilities and loss are those of an ordinary
TanhNormal policy. Without a prior the policy starts from zero commands.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch
import torch.nn.functional as F
from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
from torch import nn
from torchrl.data import Bounded, Composite
from torchrl.data import Categorical as CategoricalSpec
from torchrl.modules import MultiAgentMLP, ProbabilisticActor, TanhNormal


class Tanh(nn.Tanh):
    """``nn.Tanh`` that names its function (:attr:`function`) and its in-place form
    (:attr:`function_`), which the fast path of :class:`CategoricalMode` calls directly."""

    function = staticmethod(torch.tanh)
    function_ = staticmethod(torch.tanh_)


class SigmoidTanh(nn.Module):
    """tanh(x) computed as 2·sigmoid(2x) − 1 (the identity is exact; the float32 results
    differ from ``torch.tanh``'s by at most a few 1e-7), from torch's sigmoid kernel
    (``algo.activation=tanh_sigmoid``)."""

    @staticmethod
    def function(x: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(x * 2.0) * 2.0 - 1.0

    @staticmethod
    def function_(x: torch.Tensor) -> torch.Tensor:
        """:meth:`function` in place on ``x`` (the same operations, so the same numbers bit for
        bit, without allocating three temporaries; not for tensors autograd needs)."""
        return torch.sigmoid_(x.mul_(2.0)).mul_(2.0).sub_(1.0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.function(x)


#: ``algo.activation`` → the hidden layers' module class (the names are
#: :data:`vdtn_marl.algos.params.ACTIVATIONS`); each class's ``function`` is what its
#: forward applies, ``function_`` the same in place
ACTIVATION_CLASSES: dict[str, type[nn.Module]] = {"tanh": Tanh, "tanh_sigmoid": SigmoidTanh}


def activation_class(name: str) -> type[nn.Module]:
    """The module class of ``algo.activation`` ``name``."""
    try:
        return ACTIVATION_CLASSES[name]
    except KeyError:
        raise ValueError(
            f"activation={name!r} must be one of {', '.join(ACTIVATION_CLASSES)}"
        ) from None


#: Vehicle observation features a policy without state augmentation does not see:
#: CAM delay (ms), CAM age (ms) and its previous command (m/s²) (docs/model.md §2.4).
AUGMENTATION_FEATURES = (5, 6, 7)


class ObservationScaler(nn.Module):
    """Per-feature affine standardisation; masked features become 0.

    Starts as the map of [low, high] to [−1, 1]; :meth:`fit_` replaces it by
    (x − mean) / max(std, floor) from observed data, with ``floor`` = 10⁻³ of the feature's
    range so constant features stay finite.
    """

    def __init__(self, low: torch.Tensor, high: torch.Tensor, mask: torch.Tensor | None = None):
        super().__init__()
        low = low.detach().float()
        high = high.detach().float()
        span = (high - low).clamp_min(1e-6)
        keep = torch.ones_like(low) if mask is None else mask.float()
        self.register_buffer("center", (high + low) / 2)
        self.register_buffer("scale", keep * 2.0 / span)
        self.register_buffer("keep", keep)
        self.register_buffer("floor", span * 1e-3)

    @torch.no_grad()
    def fit_(self, observations: torch.Tensor) -> None:
        """Set the statistics from ``observations`` [..., features] (any batch shape)."""
        flat = observations.reshape(-1, self.center.numel()).float().to(self.center.device)
        self.center.copy_(flat.mean(0))
        std = flat.std(0, unbiased=False) if flat.shape[0] > 1 else torch.zeros_like(self.center)
        self.scale.copy_(self.keep / torch.maximum(std, self.floor))

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return (observation - self.center) * self.scale


class OwnValue(nn.Module):
    """[..., n_agents, n_agents] → [..., n_agents, 1]: agent i keeps output i.

    A centralised MultiAgentMLP with shared parameters gives every agent the same output
    vector (one network on the same joined input); with ``n_agents`` outputs, output i is
    agent i's value, so a shared critic still has one value per agent.
    """

    def forward(self, values: torch.Tensor) -> torch.Tensor:
        return values.diagonal(dim1=-2, dim2=-1).unsqueeze(-1)


def scalers(module: nn.Module) -> list[ObservationScaler]:
    """Every :class:`ObservationScaler` inside ``module``."""
    return [m for m in module.modules() if isinstance(m, ObservationScaler)]


def _zero_last_layer(body: MultiAgentMLP) -> None:
    """Start a MultiAgentMLP at output 0 (so a residual policy starts at its prior)."""
    keys = sorted(body.params.keys(), key=int)
    last = body.params[keys[-1]]
    with torch.no_grad():
        last["weight"].zero_()
        last["bias"].zero_()


class ResidualLocation(nn.Module):
    """loc = atanh(prior(observation) / u_max) + MLP(scaled observation), pre-tanh units."""

    def __init__(
        self,
        scaler: ObservationScaler,
        body: nn.Module,
        prior: Callable[[torch.Tensor], torch.Tensor] | None,
        low: float,
        high: float,
    ):
        super().__init__()
        self.scaler = scaler
        self.body = body
        self.prior = prior
        self.register_buffer("center", torch.tensor((high + low) / 2))
        self.register_buffer("half_range", torch.tensor((high - low) / 2))

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        loc = self.body(self.scaler(observation))
        if self.prior is not None:
            ratio = (self.prior(observation).unsqueeze(-1) - self.center) / self.half_range
            loc = loc + torch.atanh(ratio.clamp(-0.995, 0.995))
        return loc


def _scaler(spec: Composite, group: str, drop_features: Sequence[int]) -> ObservationScaler:
    obs_spec = spec[group, "observation"]
    low = obs_spec.space.low.reshape(-1, obs_spec.shape[-1])[0]
    high = obs_spec.space.high.reshape(-1, obs_spec.shape[-1])[0]
    mask = torch.ones_like(low, dtype=torch.bool)
    for index in drop_features:
        if not 0 <= index < mask.numel():
            raise ValueError(f"drop feature index {index} is outside [0, {mask.numel() - 1}]")
        mask[index] = False
    return ObservationScaler(low, high, mask)


def _group_mlp(
    n_inputs: int,
    n_outputs: int,
    n_agents: int,
    centralised: bool,
    share_params: bool,
    depth: int,
    num_cells: int,
    device: torch.device | str,
    activation: str = "tanh",
) -> MultiAgentMLP:
    """The MultiAgentMLP every actor and critic of a group is built on (tanh activations,
    from the module class of ``activation``)."""
    return MultiAgentMLP(
        n_inputs,
        n_outputs,
        n_agents,
        centralized=centralised,
        share_params=share_params,
        device=device,
        depth=depth,
        num_cells=num_cells,
        activation_class=activation_class(activation),
    )


def group_shape(spec: Composite, group: str) -> tuple[int, int]:
    """(number of agents, observation size) of ``group`` in a batched observation spec."""
    shape = spec[group, "observation"].shape
    return int(shape[-2]), int(shape[-1])


def make_actor(
    observation_spec: Composite,
    action_spec: Composite,
    group: str,
    *,
    share_params: bool = True,
    depth: int = 2,
    num_cells: int = 64,
    drop_features: Sequence[int] = (),
    initial_log_scale: float = -1.5,
    prior: Callable[[torch.Tensor], torch.Tensor] | None = None,
    device: torch.device | str = "cpu",
    activation: str = "tanh",
) -> ProbabilisticActor:
    """Stochastic policy of ``group``; writes ``(group, "action")`` and its log-probability.

    ``prior`` (continuous groups only): a controller observations [..., n, D] → commands
    [..., n] that the policy's mean starts from (see the module doc). ``initial_log_scale`` is
    the initial log standard deviation of the pre-tanh Gaussian.
    """
    n_agents, n_obs = group_shape(observation_spec, group)
    action = action_spec[group, "action"]
    scaler = _scaler(observation_spec, group, drop_features).to(device)
    if isinstance(action, CategoricalSpec):
        n_out = int(action.space.n)
        body = _group_mlp(
            n_obs, n_out, n_agents, False, share_params, depth, num_cells, device, activation
        )
        module = TensorDictModule(
            nn.Sequential(scaler, body),
            in_keys=[(group, "observation")],
            out_keys=[(group, "logits")],
        )
        return ProbabilisticActor(
            module,
            in_keys={"logits": (group, "logits")},
            out_keys=[(group, "action")],
            distribution_class=torch.distributions.Categorical,
            return_log_prob=True,
            log_prob_key=(group, "action_log_prob"),
        )
    if not isinstance(action, Bounded):
        raise TypeError(f"group {group!r} has an action spec {type(action).__name__}")
    n_act = int(action.shape[-1])
    low = action.space.low.reshape(-1)[0].item()
    high = action.space.high.reshape(-1)[0].item()
    if prior is not None and n_act != 1:
        raise ValueError(f"a policy prior needs one action per agent, group {group!r} has {n_act}")
    body = _group_mlp(
        n_obs, n_act, n_agents, False, share_params, depth, num_cells, device, activation
    )
    if prior is not None:
        _zero_last_layer(body)
    net = nn.Sequential(
        ResidualLocation(scaler, body, prior, low, high),
        AddStateIndependentNormalScale(
            n_act, scale_mapping="exp", init_value=initial_log_scale, device=device
        ),
    )
    module = TensorDictModule(
        net, in_keys=[(group, "observation")], out_keys=[(group, "loc"), (group, "scale")]
    )
    return ProbabilisticActor(
        module,
        in_keys={"loc": (group, "loc"), "scale": (group, "scale")},
        out_keys=[(group, "action")],
        distribution_class=TanhNormal,
        distribution_kwargs={"low": low, "high": high},
        return_log_prob=True,
        log_prob_key=(group, "action_log_prob"),
    )


class CategoricalMode:
    """The deterministic action of a discrete actor of :func:`make_actor` with shared
    parameters: observations [..., n_agents, D] → long [..., n_agents], bit for bit what the
    ProbabilisticActor returns under ``InteractionType.DETERMINISTIC`` (the mode of
    ``torch.distributions.Categorical``: the argmax of the softmax of the logits normalised by
    their logsumexp), computed straight from the layers.

    An RRA policy acts every 1 ms subframe: the actor's TensorDict wrapping, its distribution
    object and the re-binding of the shared parameters cost about twice the network itself at
    B ≈ 100 scenarios, 50 times per control interval. The weights are read at every call, so
    training, ``load_state_dict`` and in-place updates show at once. Build it with
    :meth:`of`, which returns None for any other actor.
    """

    def __init__(self, scaler: ObservationScaler, body: MultiAgentMLP):
        self.scaler = scaler
        self.body = body
        self.n_agents = int(body.n_agents)
        self.layers = list(body._empty_net)
        kinds = (nn.Linear, *ACTIVATION_CLASSES.values())
        if not all(type(layer) in kinds for layer in self.layers):
            raise TypeError(
                f"CategoricalMode expects Linear and activation layers, got {self.layers}"
            )
        # per layer: None for a Linear layer, else the activation's function
        self._functions = [getattr(layer, "function", None) for layer in self.layers]
        # what the call applies: an activation right after a Linear layer works in place on
        # that layer's fresh output (bit for bit the same numbers, no temporaries)
        after_linear = [False, *(function is None for function in self._functions[:-1])]
        self._calls = [
            getattr(layer, "function_", function) if function is not None and linear else function
            for layer, function, linear in zip(
                self.layers, self._functions, after_linear, strict=True
            )
        ]

    @classmethod
    def of(cls, actor) -> CategoricalMode | None:
        """The fast mode of ``actor`` when it is a Categorical actor of :func:`make_actor`
        with shared parameters (one network for every agent), else None."""
        try:
            net = actor.module[0].module
            distribution = actor.module[1].distribution_class
        except (AttributeError, IndexError, TypeError):
            return None
        if distribution is not torch.distributions.Categorical:
            return None
        if not isinstance(net, nn.Sequential) or len(net) != 2:
            return None
        scaler, body = net
        if not isinstance(scaler, ObservationScaler) or not isinstance(body, MultiAgentMLP):
            return None
        if not body.share_params or body.centralized or body.agent_dim != -2:
            return None
        return cls(scaler, body)

    def accepts(self, observation: torch.Tensor) -> bool:
        """Whether ``observation`` has the shape the actor itself would accept (else the caller
        goes through the actor, which names the problem)."""
        shape = observation.shape
        return (
            observation.dim() >= 2
            and shape[-2] == self.n_agents
            and shape[-1] == self.scaler.center.numel()
        )

    def weights(self) -> list[tuple[torch.Tensor, torch.Tensor] | None]:
        """Per layer, the Linear layer's (weight, bias) as they are now, None for an
        activation."""
        params = self.body.params
        return [
            (params[str(i)]["weight"], params[str(i)]["bias"]) if function is None else None
            for i, function in enumerate(self._calls)
        ]

    def bound(self) -> Callable[[torch.Tensor], torch.Tensor]:
        """:meth:`__call__` with the weights read once, now: for a run of calls in which the
        weights cannot change (the 50 subframes of one interval's radio), without reading
        the TensorDict of parameters at every call."""
        weights = self.weights()
        return lambda observation: self._act(observation, weights)

    def __call__(self, observation: torch.Tensor) -> torch.Tensor:
        return self._act(observation, self.weights())

    def _act(self, observation: torch.Tensor, weights) -> torch.Tensor:
        x = self.scaler(observation)
        for function, layer in zip(self._calls, weights, strict=True):
            x = F.linear(x, *layer) if function is None else function(x)
        return categorical_mode(x)


#: How far (relative to the largest |logit| of a call, plus 1) a row's best logit must lead
#: its others for :func:`categorical_mode` to take it without computing the probabilities.
#: The probabilities' rounding moves a difference of logits by a few float32 ulps of the
#: logits (≈ 1e-7 relative), so 1e-5 leaves a wide margin.
MODE_MARGIN = 1e-5


def categorical_mode(logits: torch.Tensor) -> torch.Tensor:
    """The mode of ``torch.distributions.Categorical(logits=logits)`` [..., A] → long [...],
    bit for bit: the first largest entry of the softmax of the logits normalised by their
    logsumexp (what TorchRL's deterministic Categorical actor returns).

    Mathematically that is the first largest logit; in float32 two logits closer than the
    probabilities' rounding may give equal probabilities, and then the first of them is the
    mode even if it is the smaller logit. On the CPU (float32 or float64 logits) a row whose
    best logit leads the row's others by more than :data:`MODE_MARGIN` × (1 + the call's
    largest |logit|) takes the argmax of its logits (:func:`mode_shortcut`); the other rows,
    and every row on other devices (where the check would wait for the device) or in coarser
    dtypes, compute the probabilities as Categorical does. Each row's mode depends on that row
    alone, so both ways give the same numbers."""
    shortcut = mode_shortcut(logits)
    if shortcut is None:
        return _mode_from_probabilities(logits)
    modes, near_rows = shortcut
    if near_rows is None:
        return modes
    flat = logits.reshape(-1, logits.shape[-1])
    modes = modes.reshape(-1).index_copy(
        0, near_rows, _mode_from_probabilities(flat.index_select(0, near_rows))
    )
    return modes.view(logits.shape[:-1])


def _mode_from_probabilities(logits: torch.Tensor) -> torch.Tensor:
    normalised = logits - logits.logsumexp(dim=-1, keepdim=True)  # as Categorical holds them
    # Categorical.mode is probs.argmax; max's indices are argmax's (the first maximal entry
    # of a row) and torch reduces a last axis of a few entries faster this way
    return F.softmax(normalised, dim=-1).max(dim=-1).indices


def mode_shortcut(logits: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None] | None:
    """On the CPU, the argmax of ``logits`` [..., A] and the flat indices of the rows where it
    need not be the mode of :func:`categorical_mode` (None when there are none): rows in which
    another logit comes within :data:`MODE_MARGIN` × (1 + the largest |logit|) of the best.
    None on other devices, for dtypes coarser than float32 (whose rounding the margin does not
    cover) and where a logit is inf or NaN."""
    if logits.device.type != "cpu" or logits.dtype not in (torch.float32, torch.float64):
        return None
    if not 0 < logits.numel() < 2**24:
        return None
    top = logits.max(dim=-1)
    low, high = logits.aminmax()
    margin = MODE_MARGIN * (1.0 + max(-float(low), float(high)))
    if not math.isfinite(margin):  # an inf or NaN among the logits
        return None
    # 1 for each entry above its row's best − margin (the best itself is), else 0; a float
    # sum of fewer than 2**24 ones is exact (and cheaper than a bool compare and count)
    near = (logits - (top.values - margin).unsqueeze(-1)).clamp_min_(0).sign_()
    if int(near.sum()) == top.values.numel():  # each row's best alone within the margin
        return top.indices, None
    rows = near.reshape(-1, logits.shape[-1]).sum(dim=-1).gt(1.0).nonzero().flatten()
    return top.indices, rows


def make_critic(
    observation_spec: Composite,
    group: str,
    *,
    centralised: bool = True,
    share_params: bool = True,
    depth: int = 2,
    num_cells: int = 64,
    device: torch.device | str = "cpu",
    activation: str = "tanh",
) -> TensorDictModule:
    """State-value network of ``group``; writes ``(group, "state_value")`` [..., n_agents, 1]."""
    n_agents, n_obs = group_shape(observation_spec, group)
    scaler = _scaler(observation_spec, group, ()).to(device)
    if centralised and share_params:
        # one network on the joined observations, one output per agent: agents have their
        # own rewards, so their values differ (TorchRL would copy one output to every agent)
        body = nn.Sequential(
            _group_mlp(n_obs, n_agents, n_agents, True, True, depth, num_cells, device, activation),
            OwnValue(),
        )
    else:
        body = _group_mlp(
            n_obs, 1, n_agents, centralised, share_params, depth, num_cells, device, activation
        )
    return TensorDictModule(
        nn.Sequential(scaler, body),
        in_keys=[(group, "observation")],
        out_keys=[(group, "state_value")],
    )
