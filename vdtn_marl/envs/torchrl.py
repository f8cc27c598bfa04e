"""Batched TorchRL face of the digital twin: :class:`VDTNTorchRLEnv`.

One :class:`~torchrl.envs.EnvBase` over one :class:`~vdtn_marl.sim.twin.DigitalTwin` with
``backend="torch"`` and B scenarios (``batch_size=[B]``), on any torch device. It follows the
TorchRL multi-agent convention: one nested group per agent kind.

- ``"control"``: group ``vehicle``; one step = one control interval, perfect observation
  (the PettingZoo ``PlatoonControlEnv``).
- ``"control_impaired"``: group ``vehicle``; one step = one control interval; before the
  followers decide, the interval's T radio subframes run with ``rra_policy``
  (``PlatoonControlEnv(impaired=True)``).
- ``"rra"``: group ``rra``; one step = one subframe; the followers are driven inside by
  ``control_module`` (``V2XRRAEnv``).
- ``"joint"``: groups ``vehicle`` and ``rra``; one step = one subframe; vehicle actions are read
  only at the step that closes the interval (twin subframe T−1), announced by the
  ``("vehicle", "acts")`` observation (``TwoTimescaleEnv``).

Keys: ``(group, "observation")``, ``(group, "action")``, ``(group, "reward")`` and
``done``/``terminated``/``truncated`` at the root ([B, 1]) and per group ([B, F, 1] or
[B, L, 1]). A collision of any follower terminates the scenario for every agent; truncation
after ``episode_intervals`` intervals. Partial resets use the ``"_reset"`` entries.

Two opt-in outputs, as TorchRL's ``PettingZooWrapper(return_state=True)`` and VMAS's infos
(BenchMARL's tasks turn both on: its centralised critics read the state, its logger the infos):

- ``return_state=True``: ``"state"`` [B, 3N] float32 at the root, the PettingZoo faces'
  ``state()`` of each scenario: positions (m), speeds (m/s), accelerations (m/s²) of all N
  vehicles.
- ``return_info=True``: ``(group, "info")`` in every group, one float32 [B, agents] entry per
  key of :attr:`~VDTNTorchRLEnv.info_keys`, agent i of either group being follower i and the
  V2V link that carries its CAM (0 at a reset, ``cam_delivered`` 1):

  =======================  ===============================================================
  ``gap_error_abs_m``      |gap error| (m) of the follower in its last finished interval
  ``speed_error_abs_mps``  |speed error| (m/s) of the follower then
  ``collided``             1 where the follower collided then (what terminates a scenario)
  ``cam_delivered``        1 where its CAM of that interval was delivered within it (radio
                           modes; the mean is the CAM delivery rate)
  ``aoi_ms``               Age of Information (ms) of the CAM content the follower holds:
                           the interval's mean in the vehicle group, at the end of this
                           subframe in the ``rra`` group (docs/model.md §4.8; radio modes)
  ``v2i_throughput_mbps``  V2I throughput of the cell (Mbps, all V2I links together): the
                           interval's mean in the vehicle group, this subframe's in the
                           ``rra`` group (radio modes)
  =======================  ===============================================================

  In the ``rra`` and ``joint`` modes (one step = one subframe) ``closes_interval`` is 1 at the
  step that closes an interval, and the interval entries keep the last finished interval's
  values for the next T steps (0 before the first): their mean over the steps where
  ``closes_interval`` is 1 is their mean over intervals (the BenchMARL task logs that one).
  The infos are what ``PettingZooWrapper`` makes of the PettingZoo faces' ``infos`` (same
  meaning; absolute errors here, so that means over agents stay errors).

``render(mode="rgb_array")`` draws scenario 0, as the PettingZoo faces draw their one scenario
(:func:`~vdtn_marl.envs.render.render_twin`).

All scenarios share the twin's subframe clock. Scenarios finish at the closing subframe of an
interval, where every scenario is at subframe 0 of the next one, so automatic resets keep the
batch in step. A scenario reset explicitly in the middle of an interval (``"rra"``/``"joint"``)
joins the batch at the current subframe: its first interval is shorter.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator, Sequence

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from vdtn_marl.core.interval import (
    IntervalEngine,
    check_burn_in,
    check_estimator_has_control,
)
from vdtn_marl.core.reward import RRAReward
from vdtn_marl.data.traces import TraceSource
from vdtn_marl.envs.base import (
    EngineBacked,
    apply_max_cycles,
    check_one_trace_choice,
    paid_ivoi_estimator,
    rra_observation_space,
    vehicle_observation_space,
)
from vdtn_marl.errors import ConfigError
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.scenarios import DEFAULT_SCENARIO, Scenario, get_scenario
from vdtn_marl.sim.aoi import interval_age_ms
from vdtn_marl.sim.completion import make_completion
from vdtn_marl.sim.link import cam_delivered
from vdtn_marl.sim.snapshot import export_state, import_state
from vdtn_marl.sim.twin import DigitalTwin, resolve_device
from vdtn_marl.voi import IVoIEstimator

MODES = ("control", "control_impaired", "rra", "joint")

#: ``(group, "info")`` keys of ``return_info=True`` in every mode (see the module doc).
INTERVAL_INFO_KEYS = ("gap_error_abs_m", "speed_error_abs_mps", "collided")
#: ... and in the modes whose CAMs cross the radio (all but ``"control"``).
RADIO_INFO_KEYS = ("cam_delivered", "aoi_ms", "v2i_throughput_mbps")
#: ... and in the modes whose one step is one subframe (``"rra"``, ``"joint"``).
SUBFRAME_INFO_KEYS = ("closes_interval",)
#: The ``rra`` group's entries that are of the step's subframe, not of the last interval.
RRA_SUBFRAME_INFO_KEYS = ("aoi_ms", "v2i_throughput_mbps", "closes_interval")


def _batch_size(batch_size: int | Sequence[int] | torch.Size) -> int:
    if isinstance(batch_size, torch.Size | list | tuple):
        if len(batch_size) != 1:
            raise ConfigError(f"batch_size={batch_size!r} must be one integer B >= 1 (or [B])")
        batch_size = batch_size[0]
    if isinstance(batch_size, bool) or not isinstance(batch_size, int) or batch_size < 1:
        raise ConfigError(f"batch_size={batch_size!r} must be an integer >= 1")
    return int(batch_size)


class VDTNTorchRLEnv(EngineBacked, EnvBase):
    """B scenarios of the VDTN benchmark as one batched TorchRL environment (see module doc).

    Args:
        mode: ``"control"``, ``"control_impaired"``, ``"rra"`` or ``"joint"``.
        batch_size: B ≥ 1 scenarios (an int or ``[B]``).
        device: torch device of the twin and of every tensor.
        seed: seed of the twin (and of the default random RRA policy).
        rra_policy: ``"control_impaired"`` only: RRA observations [B, L, D] → long [B, L]
            (default: uniformly random).
        control_module: ``"rra"`` only: impaired vehicle observations [B, F, 8] → commands
            [B, F] (default: linear CACC).
        reward, kappa1, kappa2, throughput_scale, ivoi_scale, miss_penalty, aoi_scale: the RRA
            reward (:class:`~vdtn_marl.core.reward.RRAReward`), ``"rra"``/``"joint"`` only.
        ivoi_estimator, ivoi_horizon_intervals: the VoI estimator (:mod:`vdtn_marl.voi`).
        trace_source: leader trace set (default: the model's ``traces``).
        completion, completion_predictor: completion of stale CAM content in the impaired
            vehicle observations (those of the ``vehicle`` group and those ``control_module``
            reads): ``"none"``, ``"hold"``, ``"kalman"``, ``"learned"`` or a completer object
            (:mod:`vdtn_marl.sim.completion`, docs/model.md §4.7); a no-op in ``"control"``.
        burn_in_intervals: ``"rra"`` only: a full reset then drives every scenario for K
            control intervals, K drawn uniformly from 0..``burn_in_intervals`` (one K per
            reset, from the twin's generator), with ``control_module`` on impaired observations
            and uniformly random RRA actions, and no reward; so RRA agents that collect short
            rollouts from reset also see the platoon mid-episode, where a CAM's content matters
            (at reset the platoon is in equilibrium). A scenario that collides during the
            burn-in starts anew. Must leave at least one interval of the episode.
        max_cycles: ``"control"``/``"control_impaired"`` only (one step is one control
            interval there): PettingZoo's name of ``episode_intervals``, accepted as an alias.
        scenario: the world, a name of :data:`vdtn_marl.scenarios.SCENARIOS` (default
            ``"platoon"``: one platoon with predecessor following; ``"two_platoons"``: two
            platoons sharing the cell) or a :class:`~vdtn_marl.scenarios.Scenario`.
        return_state: emit the global ``"state"`` [B, 3N] (see the module doc).
        return_info: emit ``(group, "info")`` with the domain metrics (see the module doc).
        **model_kwargs: model parameters for
            :meth:`~vdtn_marl.sim.params.TwinParams.from_overrides` (e.g. ``num_vehicles=6``,
            ``episode_intervals=100``).
    """

    batch_locked = True

    def __init__(
        self,
        mode: str = "control",
        batch_size: int | Sequence[int] | torch.Size = 1,
        device: str | torch.device = "cpu",
        seed: int | None = None,
        rra_policy: Callable | None = None,
        control_module: Callable | None = None,
        reward: str = "jocc",
        kappa1: float = RRAReward.kappa1,
        kappa2: float | None = None,
        ivoi_estimator: str | IVoIEstimator = "rollout",
        ivoi_horizon_intervals: int = 10,
        throughput_scale: float = RRAReward.throughput_scale,
        ivoi_scale: float = RRAReward.ivoi_scale,
        miss_penalty: float = RRAReward.miss_penalty,
        aoi_scale: float = RRAReward.aoi_scale,
        trace_source: str | TraceSource | None = None,
        completion="none",
        completion_predictor=None,
        burn_in_intervals: int = 0,
        scenario: str | Scenario = DEFAULT_SCENARIO,
        max_cycles: int | None = None,
        return_state: bool = False,
        return_info: bool = False,
        **model_kwargs,
    ):
        if mode not in MODES:
            raise ConfigError(f"mode={mode!r} must be one of {MODES}")
        model_kwargs = apply_max_cycles(
            max_cycles, model_kwargs, interval_steps=mode in ("control", "control_impaired")
        )
        b = _batch_size(batch_size)
        dev = resolve_device(device)
        super().__init__(device=dev, batch_size=torch.Size([b]))
        self.mode = mode
        self.has_vehicles = mode != "rra"
        self.has_rra = mode in ("rra", "joint")
        self.impaired = mode != "control"  # CAMs cross the radio in every mode but "control"
        check_one_trace_choice(trace_source, model_kwargs)
        self.scenario = get_scenario(scenario)
        params = self.scenario.twin_params(**model_kwargs)
        self.twin = DigitalTwin(
            params,
            batch_size=b,
            device=dev,
            seed=seed,
            trace_source=trace_source,
            radio=self.impaired,
            backend="torch",
        )
        twin = self.twin
        self.num_scenarios = b
        self.num_followers = twin.num_followers
        self.num_links = twin.num_links
        self.num_actions = params.radio.num_actions
        pp = params.platoon
        self.accel_min_mps2, self.accel_max_mps2 = (
            float(pp.accel_min_mps2),
            float(pp.accel_max_mps2),
        )

        rra_policy_used = None
        if mode == "control_impaired":
            rra_policy_used = rra_policy or RandomRRAPolicy(self.num_actions, seed)
        elif rra_policy is not None:
            raise ConfigError(
                f"rra_policy is only used with mode='control_impaired', not mode={mode!r}"
            )
        control = None
        if mode == "rra":
            control = control_module or CACCController(pp)
        elif control_module is not None:
            raise ConfigError(f"control_module is only used with mode='rra', not mode={mode!r}")
        reward_fn = estimator = None
        if self.has_rra:
            reward_fn = RRAReward(
                reward, kappa1, kappa2, throughput_scale, ivoi_scale, miss_penalty, aoi_scale
            )
            estimator = paid_ivoi_estimator(reward_fn, ivoi_estimator, ivoi_horizon_intervals)
        check_estimator_has_control(
            estimator,
            mode == "joint",
            "use mode='rra', not mode='joint' (where the vehicles are agents)",
        )
        self.engine = IntervalEngine(
            twin,
            perfect=not self.impaired,
            rra_policy=rra_policy_used,
            control=control,
            completion=make_completion(completion, completion_predictor, pp),
            ivoi_estimator=estimator,
            reward_fn=reward_fn,
        )
        check_burn_in(burn_in_intervals, params.episode_intervals)
        if burn_in_intervals and mode != "rra":
            raise ConfigError(f"burn_in_intervals is only used with mode='rra', not mode={mode!r}")
        self.burn_in_intervals = burn_in_intervals
        self._burn_in_exact: int | None = None  # set by burned_in()
        self._vehicle_obs: torch.Tensor | None = None
        # the scenarios whose new episodes the last step already started (_step_interval)
        self._restarted: torch.Tensor | None = None
        self.return_state = bool(return_state)
        self.return_info = bool(return_info)
        self.info_keys = (
            INTERVAL_INFO_KEYS
            + (RADIO_INFO_KEYS if self.impaired else ())
            + (SUBFRAME_INFO_KEYS if self.has_rra else ())
        )
        self._last_info: dict[str, torch.Tensor] | None = None  # of the last closed interval
        self._last_record = None  # the last closed interval, for render()
        self._make_specs()

    # ------------------------------------------------------------------ groups
    @property
    def group_map(self) -> dict[str, list[str]]:
        """Agent group → its agents' names, in the order of the group's dimension (TorchRL's
        ``PettingZooWrapper.group_map`` convention): ``{"vehicle": ["vehicle_1", ...]}``,
        ``{"rra": ["rra_1", ...]}`` or both."""
        groups = {}
        if self.has_vehicles:
            groups["vehicle"] = self.scenario.vehicle_agents(self.twin.topology)
        if self.has_rra:
            groups["rra"] = self.scenario.rra_agents(self.twin.topology)
        return groups

    # ------------------------------------------------------------------ specs
    def _make_specs(self) -> None:
        b, f, n_l, dev = self.num_scenarios, self.num_followers, self.num_links, self.device
        veh_box = vehicle_observation_space(self.twin)
        rra_box = rra_observation_space(self.twin)

        def bounded(box, shape):
            low = torch.as_tensor(box.low, dtype=torch.float32, device=dev).expand(shape)
            high = torch.as_tensor(box.high, dtype=torch.float32, device=dev).expand(shape)
            return Bounded(
                low=low.clone(), high=high.clone(), shape=shape, dtype=torch.float32, device=dev
            )

        def flags(shape):
            return Categorical(n=2, shape=shape, dtype=torch.bool, device=dev)

        def done_group(shape):
            return {k: flags(shape) for k in ("done", "terminated", "truncated")}

        def info(shape):
            entry = {k: Unbounded(shape=shape, dtype=torch.float32, device=dev) for k in keys}
            return {"info": Composite(entry, shape=shape, device=dev)} if self.return_info else {}

        keys = self.info_keys
        obs, act, rew = {}, {}, {}
        done = done_group((b, 1))
        if self.return_state:
            n = self.twin.params.platoon.num_vehicles
            obs["state"] = Unbounded(shape=(b, 3 * n), dtype=torch.float32, device=dev)
        if self.has_vehicles:
            group = (b, f)
            vehicle_obs = {"observation": bounded(veh_box, (b, f, veh_box.shape[0]))}
            if self.mode == "joint":
                vehicle_obs["acts"] = flags((b, f, 1))
            obs["vehicle"] = Composite({**vehicle_obs, **info(group)}, shape=group, device=dev)
            act["vehicle"] = Composite(
                action=Bounded(
                    low=self.accel_min_mps2,
                    high=self.accel_max_mps2,
                    shape=(b, f, 1),
                    dtype=torch.float32,
                    device=dev,
                ),
                shape=group,
                device=dev,
            )
            rew["vehicle"] = Composite(
                reward=Unbounded(shape=(b, f, 1), dtype=torch.float32, device=dev),
                shape=group,
                device=dev,
            )
            done["vehicle"] = Composite(done_group((b, f, 1)), shape=group, device=dev)
        if self.has_rra:
            group = (b, n_l)
            obs["rra"] = Composite(
                {"observation": bounded(rra_box, (b, n_l, rra_box.shape[0])), **info(group)},
                shape=group,
                device=dev,
            )
            act["rra"] = Composite(
                action=Categorical(n=self.num_actions, shape=group, dtype=torch.long, device=dev),
                shape=group,
                device=dev,
            )
            rew["rra"] = Composite(
                reward=Unbounded(shape=(b, n_l, 1), dtype=torch.float32, device=dev),
                shape=group,
                device=dev,
            )
            done["rra"] = Composite(done_group((b, n_l, 1)), shape=group, device=dev)
        self.full_observation_spec = Composite(obs, shape=(b,), device=dev)
        self.full_action_spec = Composite(act, shape=(b,), device=dev)
        self.full_reward_spec = Composite(rew, shape=(b,), device=dev)
        self.full_done_spec = Composite(done, shape=(b,), device=dev)

    # ------------------------------------------------------------------ state
    #: What a snapshot of the environment holds (see :meth:`state_dict`).
    _STATE_ATTRS = ("twin", "completion", "rra_policy", "control_module", "_vehicle_obs")

    def state_dict(self) -> dict:
        """The scenarios' state (the twin with its generator, the completion filter, the RRA
        policy's generator, the vehicles' last observation) as plain containers of tensors
        (:func:`~vdtn_marl.sim.snapshot.export_state`): saved in checkpoints, so scenarios that
        persist across PPO iterations resume bit for bit. Policy weights are not included."""
        holder = type("EnvState", (), {})()
        for name in self._STATE_ATTRS:
            setattr(holder, name, getattr(self, name))
        return export_state(holder)

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` into an environment built with the same arguments."""
        import_state(self, state)

    # ------------------------------------------------------------------ seeding
    def _set_seed(self, seed: int | None) -> None:
        self.twin.seed(seed)
        if self.rra_policy is not None and hasattr(self.rra_policy, "seed"):
            self.rra_policy.seed(seed)

    # ------------------------------------------------------------------ actions
    def _vehicle_commands(self, tensordict: TensorDictBase) -> torch.Tensor:
        """Validated commands [B, F] (m/s²) from ``("vehicle", "action")`` [B, F, 1]."""
        action = tensordict.get(("vehicle", "action"), None)
        expected = (self.num_scenarios, self.num_followers, 1)
        lo, hi = self.accel_min_mps2, self.accel_max_mps2
        if action is None:
            raise KeyError("missing ('vehicle', 'action') in the step tensordict")
        action = torch.as_tensor(action, device=self.device)
        if tuple(action.shape) != expected:
            raise ValueError(
                f"('vehicle', 'action') has shape {tuple(action.shape)}, expected {expected}"
            )
        if action.dtype == torch.bool or action.is_complex():
            raise ValueError(
                f"('vehicle', 'action') has dtype {action.dtype}; "
                f"expected real m/s² in [{lo}, {hi}]"
            )
        wide = action.double()
        bad = ~((wide >= lo) & (wide <= hi))  # NaN compares False: rejected too
        if bool(bad.any()):
            first = bad.nonzero()[0].tolist()
            raise ValueError(
                f"vehicle action {wide[tuple(first)].item()!r} m/s² (scenario {first[0]}, "
                f"follower {first[1] + 1}) is outside [{lo}, {hi}]"
            )
        return action.reshape(expected[:2]).to(torch.float32)

    def _rra_actions(self, tensordict: TensorDictBase) -> torch.Tensor:
        """Validated RRA actions [B, L] (long) from ``("rra", "action")``."""
        action = tensordict.get(("rra", "action"), None)
        expected = (self.num_scenarios, self.num_links)
        top = self.num_actions - 1
        if action is None:
            raise KeyError("missing ('rra', 'action') in the step tensordict")
        action = torch.as_tensor(action, device=self.device)
        if tuple(action.shape) != expected:
            raise ValueError(
                f"('rra', 'action') has shape {tuple(action.shape)}, expected {expected}"
            )
        if action.dtype.is_floating_point or action.is_complex() or action.dtype == torch.bool:
            raise ValueError(
                f"('rra', 'action') has dtype {action.dtype}; expected integers in [0, {top}] "
                "(sub-channel × power level)"
            )
        bad = (action < 0) | (action > top)
        if bool(bad.any()):
            first = bad.nonzero()[0].tolist()
            raise ValueError(
                f"RRA action {action[tuple(first)].item()} "
                f"(scenario {first[0]}, link {first[1] + 1}) "
                f"is outside [0, {top}] (sub-channel × power level)"
            )
        return action.long()

    # ------------------------------------------------------------------ radio
    @contextlib.contextmanager
    def burned_in(self, intervals: int) -> Iterator[None]:
        """Inside the block, a full reset drives every scenario for exactly ``intervals``
        control intervals (random RRA, the control module driving), as the burn-in does:
        mid-episode states, e.g. to fit observation statistics (``"rra"`` mode only)."""
        if self.mode != "rra":
            raise ConfigError(f"burned_in is only used with mode='rra', not mode={self.mode!r}")
        if not 0 <= intervals < self.twin.params.episode_intervals:
            raise ConfigError(
                f"intervals={intervals!r} must be in [0, {self.twin.params.episode_intervals - 1}]"
            )
        self._burn_in_exact = intervals
        try:
            yield
        finally:
            self._burn_in_exact = None

    def _burn_in(self) -> None:
        """Drive every scenario for K ~ U{0..``burn_in_intervals``} intervals (see __init__)."""
        twin = self.twin
        draw = torch.randint(
            0, 2**31 - 1, (2,), generator=twin.generator, device=twin.generator.device
        ).tolist()
        intervals = draw[0] % (self.burn_in_intervals + 1)
        if self._burn_in_exact is not None:
            intervals = self._burn_in_exact
        rra = RandomRRAPolicy(self.num_actions, draw[1])
        engine = self.engine
        for _ in range(intervals):
            engine.run_radio(policy=rra)
            collided = engine.finish().collided.any(-1)
            engine.advance(~collided)
            if bool(collided.any()):
                engine.reset(collided)

    # ------------------------------------------------------------------ state, infos, frames
    def _state(self) -> torch.Tensor:
        """``"state"`` [B, 3N] float32: positions (m), speeds (m/s), accelerations (m/s²)."""
        st = self.twin.platoon
        return torch.cat([st.position_m, st.speed_mps, st.accel_mps2], -1).to(torch.float32)

    def _held_age(self) -> torch.Tensor | None:
        """Age (intervals) of the CAM content each recipient holds at the interval's start,
        [B, F]: read before the interval closes, for its AoI (radio modes with infos only)."""
        if not (self.return_info and self.impaired):
            return None
        return self.twin.interval[:, None] - self.twin.cam_held_interval

    def _reset_info(self, mask: torch.Tensor | None) -> None:
        """The infos of a reset (all zero, ``cam_delivered`` 1) in the ``mask`` scenarios."""
        if not self.return_info:
            return
        b, f = self.num_scenarios, self.num_followers
        keys = [k for k in self.info_keys if k not in SUBFRAME_INFO_KEYS]
        initial = {k: torch.zeros(b, f, device=self.device) for k in keys}
        if "cam_delivered" in initial:
            initial["cam_delivered"].fill_(1.0)
        if mask is None or self._last_info is None:
            self._last_info = initial
        else:
            rows = mask[:, None]
            self._last_info = {
                k: torch.where(rows, initial[k], v) for k, v in self._last_info.items()
            }

    def _close_info(self, record, held_age: torch.Tensor | None) -> None:
        """Keep the infos of the interval ``record`` closed (and the record, for render())."""
        self._last_record = record
        if not self.return_info:
            return
        info = {
            "gap_error_abs_m": record.gap_error_m.abs(),
            "speed_error_abs_mps": record.speed_error_mps.abs(),
            "collided": record.collided,
        }
        if self.impaired:
            twin, f = self.twin, self.num_followers
            t = twin.subframes_per_interval
            delay = record.cam_delay_subframes  # link i carries follower i's CAM
            info["cam_delivered"] = cam_delivered(delay, t)
            info["aoi_ms"] = interval_age_ms(held_age, delay, t, twin.subframe_ms)[0]
            g = record.v2i_rate_bps.sum(-1) * 1e-6
            info["v2i_throughput_mbps"] = g[:, None].expand(self.num_scenarios, f)
        self._last_info = {k: v.to(torch.float32) for k, v in info.items()}

    def _group_infos(
        self, closing: bool = False, aoi_ms=None, v2i_mbps=None
    ) -> dict[str, dict[str, torch.Tensor]]:
        """``(group, "info")`` of every group; ``closing``: the step closed an interval; the
        ``rra`` group's AoI and V2I throughput are this subframe's (``aoi_ms`` [B, L],
        ``v2i_mbps`` [B]; 0 when not given)."""
        if not self.return_info:
            return {}
        b = self.num_scenarios
        info = dict(self._last_info)
        if self.has_rra:
            info["closes_interval"] = torch.full((b, 1), float(closing), device=self.device)

        def entries(n: int) -> dict[str, torch.Tensor]:
            return {k: v.to(torch.float32).expand(b, n).clone() for k, v in info.items()}

        infos = {}
        if self.has_vehicles:
            infos["vehicle"] = entries(self.num_followers)
        if self.has_rra:
            zeros = torch.zeros(b, self.num_links, device=self.device)
            info["aoi_ms"] = zeros if aoi_ms is None else aoi_ms
            info["v2i_throughput_mbps"] = zeros if v2i_mbps is None else v2i_mbps[:, None]
            infos["rra"] = entries(self.num_links)
        return infos

    def render(self, mode: str = "rgb_array"):
        """An RGB frame [H, W, 3] uint8 of scenario 0 after the last step (the road, the gaps,
        each V2V link's CAM; :func:`~vdtn_marl.envs.render.render_twin`): what BenchMARL's
        evaluation video records, one frame per step."""
        if mode != "rgb_array":
            raise ConfigError(f"render(mode={mode!r}): only mode='rgb_array' is drawn")
        from vdtn_marl.envs.render import render_twin

        return render_twin(self.twin, self._last_record)

    # ------------------------------------------------------------------ outputs
    def _vehicle_acts(self) -> torch.Tensor:
        acts = self.twin.subframe == self.twin.subframes_per_interval - 1
        return torch.full(
            (self.num_scenarios, self.num_followers, 1), acts, dtype=torch.bool, device=self.device
        )

    def _output(
        self,
        vehicle_obs,
        rra_obs,
        vehicle_reward,
        rra_reward,
        terminated,
        truncated,
        infos: dict[str, dict[str, torch.Tensor]] | None = None,
    ) -> TensorDict:
        b, f, n_l = self.num_scenarios, self.num_followers, self.num_links
        term = terminated[:, None]
        trunc = truncated[:, None]
        done = term | trunc
        out = {"done": done, "terminated": term, "truncated": trunc}
        infos = infos or {}
        if self.return_state:
            out["state"] = self._state()

        def group(n, extra, name):
            flags = {
                "done": done[:, None].expand(b, n, 1).clone(),
                "terminated": term[:, None].expand(b, n, 1).clone(),
                "truncated": trunc[:, None].expand(b, n, 1).clone(),
            }
            if name in infos:
                flags["info"] = TensorDict(infos[name], batch_size=(b, n), device=self.device)
            return TensorDict({**extra, **flags}, batch_size=(b, n), device=self.device)

        if self.has_vehicles:
            extra = {"observation": vehicle_obs}
            if self.mode == "joint":
                extra["acts"] = self._vehicle_acts()
            if vehicle_reward is not None:
                extra["reward"] = vehicle_reward.to(torch.float32)[..., None]
            out["vehicle"] = group(f, extra, "vehicle")
        if self.has_rra:
            extra = {"observation": rra_obs}
            if rra_reward is not None:
                extra["reward"] = rra_reward.to(torch.float32)[..., None]
            out["rra"] = group(n_l, extra, "rra")
        return TensorDict(out, batch_size=(b,), device=self.device)

    # ------------------------------------------------------------------ reset
    def _reset_mask(self, tensordict: TensorDictBase | None) -> torch.Tensor | None:
        if tensordict is None:
            return None
        parts = []
        for key in self.reset_keys:
            value = tensordict.get(key, None)
            if value is not None:
                parts.append(
                    torch.as_tensor(value, device=self.device)
                    .reshape(self.num_scenarios, -1)
                    .any(-1)
                )
        if not parts:
            return None
        return torch.stack(parts).any(0)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs) -> TensorDictBase:
        twin, engine = self.twin, self.engine
        mask = self._reset_mask(tensordict)
        restarted, self._restarted = self._restarted, None
        full = mask is None or bool(mask.all())
        if full:
            engine.reset()  # with the first interval's radio in "control_impaired"
            if self.burn_in_intervals or self._burn_in_exact is not None:
                self._burn_in()
            self._last_record = None
            self._reset_info(None)
        else:
            self._reset_info(mask)  # also those the step that ended them started anew
            if restarted is not None:  # started by the step that ended them
                mask = mask & ~restarted
            if bool(mask.any()):
                engine.reset(mask, keep_clock=self.has_rra)

        vehicle_obs = rra_obs = None
        if self.has_vehicles:
            fresh = engine.observe(None if full or self.mode != "joint" else mask)
            if self.mode == "joint":
                if full or self._vehicle_obs is None:
                    self._vehicle_obs = fresh
                else:
                    self._vehicle_obs = torch.where(mask[:, None, None], fresh, self._vehicle_obs)
                vehicle_obs = self._vehicle_obs.clone()
            else:
                vehicle_obs = fresh
        if self.has_rra:
            rra_obs = twin.rra_observation().clone()
        false = torch.zeros(self.num_scenarios, dtype=torch.bool, device=self.device)
        return self._output(vehicle_obs, rra_obs, None, None, false, false, self._group_infos())

    # ------------------------------------------------------------------ step
    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        self._restarted = None
        if self.has_rra:
            return self._step_subframe(tensordict)
        return self._step_interval(tensordict)

    def _step_interval(self, tensordict: TensorDictBase) -> TensorDictBase:
        engine = self.engine
        held_age = self._held_age()
        closed = engine.close(self._vehicle_commands(tensordict))
        self._close_info(closed.record, held_age)
        going = closed.going
        all_going = bool(going.all())
        final_obs = None
        if self.impaired and not all_going:
            # what finished scenarios know at the next decision time, before its CAM arrives
            final_obs = engine.observe(~going, cams_lost=True)
        if bool(going.any()):
            # the next interval, with its radio in "control_impaired"; the ended scenarios'
            # new episodes start with it, one radio run for all, and the reset that follows
            # (TorchRL's) finds them started. With none going, that reset starts them all.
            engine.restart_ended(going)
            if not all_going:
                self._restarted = ~going
        obs = engine.observe()
        if final_obs is not None:
            obs = torch.where(going[:, None, None], obs, final_obs)
        return self._output(
            obs,
            None,
            closed.record.reward,
            None,
            closed.terminated,
            closed.truncated,
            self._group_infos(),
        )

    def _step_subframe(self, tensordict: TensorDictBase) -> TensorDictBase:
        twin = self.twin
        last = twin.subframes_per_interval - 1
        closing = twin.subframe == last
        rra_actions = self._rra_actions(tensordict)
        commands = self._vehicle_commands(tensordict) if closing and self.has_vehicles else None

        engine = self.engine
        rra_reward, v2i_mbps = engine.subframe_reward(engine.step_subframe(rra_actions))
        rra_reward = rra_reward.to(torch.float32)
        aoi_ms = twin.cam_age_ms() if self.return_info else None  # at this subframe's end
        b = self.num_scenarios
        terminated = torch.zeros(b, dtype=torch.bool, device=self.device)
        truncated = terminated.clone()
        vehicle_reward = (
            torch.zeros(b, self.num_followers, device=self.device) if self.has_vehicles else None
        )
        going = None
        final_rra_obs = None
        if closing:
            held_age = self._held_age()
            closed = engine.close(commands)
            self._close_info(closed.record, held_age)
            rra_reward = rra_reward + closed.rra_reward.to(torch.float32)
            if vehicle_reward is not None:
                vehicle_reward = closed.record.reward
            terminated, truncated, going = closed.terminated, closed.truncated, closed.going
            if not bool(going.all()):  # what finished scenarios show, before the next interval
                final_rra_obs = twin.rra_observation().clone()
                if self.has_vehicles:
                    final_vehicle_obs = engine.observe(~going, cams_lost=True)
                    self._vehicle_obs = torch.where(
                        going[:, None, None], self._vehicle_obs, final_vehicle_obs
                    )
            engine.advance(going)
        vehicle_obs = None
        if self.has_vehicles:
            if twin.subframe == last:
                fresh = engine.observe()
                self._vehicle_obs = (
                    fresh
                    if going is None
                    else torch.where(going[:, None, None], fresh, self._vehicle_obs)
                )
            vehicle_obs = self._vehicle_obs.clone()
        rra_obs = twin.rra_observation().clone()
        if final_rra_obs is not None:
            rra_obs = torch.where(going[:, None, None], rra_obs, final_rra_obs)
        infos = self._group_infos(bool(closing), aoi_ms, v2i_mbps)
        return self._output(
            vehicle_obs, rra_obs, vehicle_reward, rra_reward, terminated, truncated, infos
        )
