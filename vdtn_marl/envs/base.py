"""What every VDTN PettingZoo environment shares: twin construction, spaces, action checks.

The environments are thin: they translate between PettingZoo's dicts and the twin's tensors
(``B = 1``); all physics lives in :mod:`vdtn_marl.sim`.
"""

from __future__ import annotations

import functools

import gymnasium
import numpy as np
import torch
from pettingzoo import ParallelEnv

from vdtn_marl.core.reward import RRAReward
from vdtn_marl.data.traces import TraceSource
from vdtn_marl.errors import ConfigError
from vdtn_marl.scenarios import DEFAULT_SCENARIO, Scenario, get_scenario, rra_name, vehicle_name
from vdtn_marl.sim.platoon import vehicle_observation_bounds
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord, resolve_device
from vdtn_marl.voi import make_ivoi_estimator

RENDER_MODES = ("rgb_array",)

__all__ = ["rra_name", "vehicle_name"]  # agent names, defined with the scenarios


def vehicle_observation_space(twin: DigitalTwin) -> gymnasium.spaces.Box:
    low, high = vehicle_observation_bounds(twin.params.platoon)
    return gymnasium.spaces.Box(
        np.array(low, np.float32), np.array(high, np.float32), dtype=np.float32
    )


def vehicle_action_space(twin: DigitalTwin) -> gymnasium.spaces.Box:
    pp = twin.params.platoon
    return gymnasium.spaces.Box(pp.accel_min_mps2, pp.accel_max_mps2, shape=(1,), dtype=np.float32)


def rra_observation_space(twin: DigitalTwin) -> gymnasium.spaces.Box:
    """Bounds of the RRA features (:data:`~vdtn_marl.sim.layout.RRA_OBS_FEATURES`)."""
    low, high = twin.rra_layout.bounds()
    return gymnasium.spaces.Box(low, high, dtype=np.float32)


def rra_action_space(twin: DigitalTwin) -> gymnasium.spaces.Discrete:
    return gymnasium.spaces.Discrete(twin.params.radio.num_actions)


def paid_ivoi_estimator(reward_fn: RRAReward, ivoi_estimator, horizon_intervals: int):
    """The IVoI estimator whose ξ ``reward_fn`` pays: ``ivoi_estimator`` (a name of
    :data:`~vdtn_marl.voi.IVOI_ESTIMATORS`, ``"none"`` or an object; ``"rollout"`` over
    ``horizon_intervals``) when the reward uses ξ, else ξ = 0 (nothing is estimated)."""
    options = {"horizon_intervals": horizon_intervals} if ivoi_estimator == "rollout" else {}
    return make_ivoi_estimator(ivoi_estimator if reward_fn.uses_ivoi else "none", **options)


def check_one_trace_choice(trace_source, model_kwargs: dict) -> None:
    """Raise :class:`ConfigError` when both ``traces=`` (a trace set by name, a model
    parameter) and ``trace_source=`` choose the leader traces of an environment."""
    if trace_source is not None and "traces" in model_kwargs:
        raise ConfigError(
            f"traces={model_kwargs['traces']!r} and trace_source={trace_source!r} both choose "
            "the leader traces; pass only one of them"
        )


def apply_max_cycles(max_cycles, model_kwargs: dict, *, interval_steps: bool) -> dict:
    """``model_kwargs`` with PettingZoo's ``max_cycles`` (steps per episode, BenchMARL's
    PettingZoo tasks pass it) as ``episode_intervals``, for a face whose one step is one control
    interval (``interval_steps``); a :class:`ConfigError` where a step is a subframe, or where
    both name the episode length differently."""
    if max_cycles is None:
        return model_kwargs
    if not interval_steps:
        raise ConfigError(
            f"max_cycles={max_cycles!r} counts steps of one control interval, and one step of "
            "this environment is one 1 ms subframe: pass episode_intervals=K (an episode is K "
            "control intervals of T subframes each)"
        )
    given = model_kwargs.get("episode_intervals", max_cycles)
    if given != max_cycles:
        raise ConfigError(
            f"max_cycles={max_cycles!r} and episode_intervals={given!r} both set the episode "
            "length (max_cycles is an alias of episode_intervals here); pass one of them"
        )
    return {**model_kwargs, "episode_intervals": max_cycles}


#: The acting parts a face keeps on its :class:`~vdtn_marl.core.interval.IntervalEngine`:
#: the face's attribute name → the engine's.
ENGINE_PARTS = {
    "rra_policy": "rra_policy",
    "control_module": "control",
    "completion": "completion",
    "ivoi_estimator": "ivoi_estimator",
    "reward_fn": "reward_fn",
}


class EngineBacked:
    """A face whose acting parts (:data:`ENGINE_PARTS`) live on its ``engine``: reading
    ``env.completion`` reads the engine's, and assigning one (``env.ivoi_estimator = …``)
    changes what the engine runs. Build ``self.engine`` before touching them."""

    def __setattr__(self, name, value):
        target = ENGINE_PARTS.get(name)
        if target is None:
            super().__setattr__(name, value)
        else:  # also for torch modules, which nn.Module would otherwise register
            setattr(self.__dict__["engine"], target, value)


for _name, _target in ENGINE_PARTS.items():
    setattr(
        EngineBacked,
        _name,
        property(lambda self, _t=_target: getattr(self.engine, _t), doc=f"the engine's {_target}"),
    )
del _name, _target


class VDTNParallelEnv(EngineBacked, ParallelEnv):
    """Common plumbing of the four environments (one scenario, B = 1).

    Model parameters are keyword arguments (any field of
    :class:`~vdtn_marl.sim.params.PlatoonParams` / ``RadioParams``, plus ``episode_intervals``
    and ``traces``), e.g. ``make("vdtn/platoon-control-v0", num_vehicles=6)``. ``scenario``
    names the world (:data:`vdtn_marl.scenarios.SCENARIOS`; default ``"platoon"``, one
    platoon with predecessor following), e.g. ``scenario="two_platoons", num_vehicles=8``.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 20, "is_parallelizable": True}

    def __init__(
        self,
        *,
        radio: bool,
        seed: int | None = None,
        render_mode: str | None = None,
        device: str = "cpu",
        trace_source: TraceSource | None = None,
        scenario: str | Scenario = DEFAULT_SCENARIO,
        **model_kwargs,
    ):
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ConfigError(f"render_mode={render_mode!r} must be None or one of {RENDER_MODES}")
        self.render_mode = render_mode
        check_one_trace_choice(trace_source, model_kwargs)
        self.scenario = get_scenario(scenario)
        params = self.scenario.twin_params(**model_kwargs)
        backend = "numpy" if resolve_device(device).type == "cpu" else "torch"
        self.twin = DigitalTwin(
            params,
            batch_size=1,
            device=device,
            seed=seed,
            trace_source=trace_source,
            radio=radio,
            backend=backend,
        )
        self._numpy = backend == "numpy"
        self.last_record: IntervalRecord | None = None

    # -- spaces (cached: PettingZoo requires the same object on every call)
    @functools.cache  # noqa: B019 - one cache entry per (env, agent), by design
    def observation_space(self, agent: str) -> gymnasium.spaces.Space:
        return self._observation_space(self._check_agent(agent))

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> gymnasium.spaces.Space:
        return self._action_space(self._check_agent(agent))

    def _check_agent(self, agent: str) -> str:
        if agent not in self.possible_agents:
            raise KeyError(f"unknown agent {agent!r}; agents are {self.possible_agents}")
        return agent

    def _check_action_keys(self, actions: dict) -> None:
        known = self.__dict__.get("_known_agents")
        if known is None or known[0] is not self.possible_agents:
            known = self._known_agents = (self.possible_agents, frozenset(self.possible_agents))
        if not known[1].issuperset(actions):
            unknown = set(actions) - known[1]
            raise KeyError(
                f"unknown agent(s) {sorted(unknown)} in actions; agents are {self.possible_agents}"
            )

    def _vehicle_commands(self, actions: dict, names: list[str]) -> np.ndarray:
        """Acceleration commands [F] (m/s²) from a dict of Box(1) actions, validated."""
        pp = self.twin.params.platoon
        missing = [n for n in names if n not in actions]
        if missing:
            raise KeyError(f"missing actions for {missing}")
        out = np.empty(len(names), np.float32)
        for i, name in enumerate(names):
            try:
                value = np.asarray(actions[name])
            except (TypeError, ValueError):  # e.g. a ragged list
                value = None
            if value is None or value.dtype.kind not in "biuf":  # a string ("left"), None
                raise ValueError(
                    f"action of {name} = {actions[name]!r} must be one number (m/s²) in "
                    f"[{pp.accel_min_mps2}, {pp.accel_max_mps2}]"
                )
            value = value.astype(np.float64, copy=False)
            if value.shape != (1,):  # as Box(1,).contains: a bare number is refused too
                raise ValueError(
                    f"action of {name} = {actions[name]!r} has shape {value.shape}, expected "
                    f"(1,): one number (m/s²) in [{pp.accel_min_mps2}, {pp.accel_max_mps2}] in "
                    "an array, e.g. np.array([0.5], np.float32)"
                )
            u = float(value.reshape(()))
            if not (pp.accel_min_mps2 <= u <= pp.accel_max_mps2):  # also rejects NaN
                raise ValueError(
                    f"action of {name} = {u!r} m/s² is outside "
                    f"[{pp.accel_min_mps2}, {pp.accel_max_mps2}]"
                )
            out[i] = u
        return out

    def _rra_actions(self, actions: dict, names: list[str]) -> np.ndarray:
        """RRA actions [1, L] (ints) from a dict of Discrete actions, validated."""
        n_act = self.twin.params.radio.num_actions
        out = []
        for name in names:
            try:
                value = actions[name]
            except KeyError:
                missing = [n for n in names if n not in actions]
                raise KeyError(f"missing actions for {missing}") from None
            if type(value) is int or isinstance(value, np.integer):  # the common case, fast
                a = int(value)
            else:
                array = np.asarray(value)
                if array.shape not in ((), (1,)) or array.dtype.kind not in "iu":
                    raise ValueError(
                        f"action of {name} = {value!r} must be one integer in [0, {n_act - 1}]"
                    )
                a = int(array.reshape(()))
            if not 0 <= a < n_act:
                raise ValueError(f"action of {name} = {a} is outside [0, {n_act - 1}]")
            out.append(a)
        return np.array([out], np.int64)

    def _to_twin(self, array: np.ndarray) -> np.ndarray | torch.Tensor:
        return array if self._numpy else torch.as_tensor(array, device=self.twin.device)

    @staticmethod
    def _as_numpy(x) -> np.ndarray:
        return x if isinstance(x, np.ndarray) else x.detach().cpu().numpy()

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        from vdtn_marl.envs.render import render_twin

        return render_twin(self.twin, self.last_record)

    def close(self):
        pass

    @functools.cached_property
    def state_space(self) -> gymnasium.spaces.Box:
        """Space of :meth:`state`: N positions (m), N speeds (m/s, ≥ 0), N accelerations
        (m/s²; the leader's follows its trace, so no actuator bound applies)."""
        n = self.twin.params.platoon.num_vehicles
        low = np.full(3 * n, -np.inf, np.float32)
        low[n : 2 * n] = 0.0
        return gymnasium.spaces.Box(low, np.full(3 * n, np.inf, np.float32), dtype=np.float32)

    def state(self) -> np.ndarray:
        """Global state: positions (m), speeds (m/s), accelerations (m/s²) of all vehicles
        (float32, in :attr:`state_space`)."""
        st = self.twin.platoon
        state = torch.cat([st.position_m[0], st.speed_mps[0], st.accel_mps2[0]]).cpu().numpy()
        return state.astype(np.float32, copy=False)
