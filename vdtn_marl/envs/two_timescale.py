"""The two-timescale wrapper: ``vdtn/vdtn-joint-v1`` (and the base of ``vdtn/v2x-rra-v1``).

One ``step()`` is one 1 ms subframe; ``t = step mod T`` (T = 50). Every agent has a clock:

=============  =======  =====================================================================
agent          period   acts at
=============  =======  =====================================================================
``rra_i``      1        every step: sub-channel × power of the V2V link to vehicle i (from
                        its predecessor, i−1 in one platoon), Discrete(M·P). docs/model.md §4.4
``vehicle_i``  T        the step with t = T−1, which closes interval k: its command u_k,
                        Box(1) m/s². Its observation is emitted at the step before (after
                        the CAM's delivery deadline, docs/model.md §4.5) and only changes then.
=============  =======  =====================================================================

``infos[agent]["acts"]`` is True when the agent's action is read at the next step; off-tick
vehicle actions may be omitted and are ignored. All agents stay in ``env.agents`` for the whole
episode. At the step that closes interval k the twin integrates the platoon (u_k takes force at
the CAM's delivery subframe), the vehicles get their interval reward, the VoI estimator
computes ξ_i for every follower, and ``rra_i`` gets κ2·s_ξ·ξ_i on top of its κ1·s_g·g term;
``infos["rra_i"]["ivoi"]`` reports ξ_i at that step (docs/model.md §5).

With ``vehicles_are_agents=False`` the followers are driven by ``control_module`` (a callable:
impaired observations [1, F, 8] torch → commands [1, F]; linear CACC by default), which is
:class:`~vdtn_marl.envs.radio.V2XRRAEnv`.

``completion`` (``"none"``, ``"hold"``, ``"kalman"``, ``"learned"`` with
``completion_predictor=``, or a completer object) replaces stale CAM content in the vehicle
observations, those of the agents and those the control module reads, by a prediction
(docs/model.md §4.7).

Version history (docs/model.md, "Version history"):

- ``vdtn/vdtn-joint-v1`` and ``vdtn/v2x-rra-v1`` (2026-12):

  - V2V path loss WINNER+ B1 with effective antenna heights and a free-space floor by default
    (v0: Liang et al.'s form; ``v2v_pathloss_form="liang"`` restores it).
  - RRA observation of 4M + 12 features (v0: 4M + 6): the recipient's CAM content age, its
    last 3 CAM delays and its 2 earlier commands are appended
    (:data:`vdtn_marl.sim.layout.RRA_OBS_FEATURES`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from vdtn_marl.core.interval import IntervalEngine, check_estimator_has_control
from vdtn_marl.core.reward import RRAReward
from vdtn_marl.envs.base import (
    VDTNParallelEnv,
    apply_max_cycles,
    paid_ivoi_estimator,
    rra_action_space,
    rra_observation_space,
    vehicle_action_space,
    vehicle_observation_space,
)
from vdtn_marl.envs.control import INITIAL_INTERVAL_INFO, interval_infos
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.completion import make_completion
from vdtn_marl.voi import IVoIEstimator


class TwoTimescaleEnv(VDTNParallelEnv):
    """Vehicles (every control interval) and RRA agents (every subframe) on one clock."""

    def __init__(
        self,
        kappa1: float = RRAReward.kappa1,
        kappa2: float | None = None,
        reward: str = "jocc",
        ivoi_estimator: str | IVoIEstimator = "rollout",
        ivoi_horizon_intervals: int = 10,
        throughput_scale: float = RRAReward.throughput_scale,
        ivoi_scale: float = RRAReward.ivoi_scale,
        miss_penalty: float = RRAReward.miss_penalty,
        aoi_scale: float = RRAReward.aoi_scale,
        vehicles_are_agents: bool = True,
        control_module: Callable | None = None,
        seed: int | None = None,
        render_mode: str | None = None,
        device: str = "cpu",
        completion="none",
        completion_predictor=None,
        max_cycles: int | None = None,
        **model_kwargs,
    ):
        apply_max_cycles(max_cycles, model_kwargs, interval_steps=False)  # refused: subframes
        reward_fn = RRAReward(
            reward, kappa1, kappa2, throughput_scale, ivoi_scale, miss_penalty, aoi_scale
        )
        super().__init__(
            radio=True, seed=seed, render_mode=render_mode, device=device, **model_kwargs
        )
        twin = self.twin
        estimator = paid_ivoi_estimator(reward_fn, ivoi_estimator, ivoi_horizon_intervals)
        self.vehicles_are_agents = vehicles_are_agents
        check_estimator_has_control(
            estimator,
            vehicles_are_agents,
            "with the vehicles as agents (vehicles_are_agents=True) there is none: use the V2X "
            "RRA env",
        )
        self.engine = IntervalEngine(  # the RRA agents step the subframes
            twin,
            perfect=False,
            control=control_module or CACCController(twin.params.platoon),
            completion=make_completion(completion, completion_predictor, twin.params.platoon),
            ivoi_estimator=estimator,
            reward_fn=reward_fn,
        )
        self.vehicle_agents = self.scenario.vehicle_agents(twin.topology)
        self.rra_agents = self.scenario.rra_agents(twin.topology)
        self.possible_agents = (
            self.vehicle_agents if vehicles_are_agents else []
        ) + self.rra_agents
        self.agents: list[str] = []
        self.metadata = {
            **self.metadata,
            "name": "vdtn_joint_v1" if vehicles_are_agents else "v2x_rra_v1",
        }
        self._period = {
            a: twin.subframes_per_interval for a in self.vehicle_agents
        } | dict.fromkeys(self.rra_agents, 1)

    # -- clocks
    def clock_period(self, agent: str) -> int:
        """Subframes between two actions of ``agent``: 1 for ``rra_*``, T for ``vehicle_*``."""
        return self._period[self._check_agent(agent)]

    def _vehicle_tick_next(self) -> bool:
        return self.twin.subframe == self.twin.subframes_per_interval - 1

    def _observation_space(self, agent):
        return (
            vehicle_observation_space(self.twin)
            if agent.startswith("vehicle_")
            else rra_observation_space(self.twin)
        )

    def _action_space(self, agent):
        return (
            vehicle_action_space(self.twin)
            if agent.startswith("vehicle_")
            else rra_action_space(self.twin)
        )

    # -- API
    def reset(self, seed: int | None = None, options: dict | None = None):
        self.engine.reset(seed=seed)
        self.agents = self.possible_agents[:]
        self.last_record = None
        self._refresh_vehicle_obs()
        self._last_closing = dict.fromkeys(self.vehicle_agents, INITIAL_INTERVAL_INFO)
        return self._observations(), self._infos(closing=None, ivoi=None, throughput_mbps=0.0)

    def _refresh_vehicle_obs(self, cams_lost: bool = False) -> None:
        if self.vehicles_are_agents:
            obs = self.engine.observe(cams_lost=cams_lost)[0].cpu().numpy()
            self._vehicle_obs = {name: obs[i] for i, name in enumerate(self.vehicle_agents)}

    def _observations(self) -> dict[str, np.ndarray]:
        rra = self._as_numpy(self.twin.rra_observation())[0].copy()
        out = {name: rra[i] for i, name in enumerate(self.rra_agents)}
        if self.vehicles_are_agents:
            out.update(self._vehicle_obs)
        return out

    def _infos(self, closing, ivoi, throughput_mbps: float) -> dict[str, dict]:
        """Same keys at every step (TorchRL's PettingZooWrapper builds its spec at reset).

        ``rra_i``: ``acts``, ``v2i_throughput_mbps`` (this subframe), ``closes_interval``,
        ``ivoi`` (ξ_i at the closing step, 0 otherwise), the CAM outcome of link i's last
        finished interval and ``collided`` (whether link i's recipient collided then: the
        reason an episode is terminated). ``vehicle_i``: ``acts`` and the diagnostics of its
        last interval.
        """
        if closing is not None:
            self._last_closing = closing
        last = self._last_closing
        vehicle_acts = self._vehicle_tick_next()
        infos = {}
        for i, name in enumerate(self.rra_agents):
            recipient = last[self.vehicle_agents[i]]
            infos[name] = {
                "acts": True,
                "v2i_throughput_mbps": throughput_mbps,
                "closes_interval": closing is not None,
                "ivoi": ivoi[i] if ivoi is not None else 0.0,
                "cam_delivered": recipient["cam_delivered"],
                "cam_delay_ms": recipient["cam_delay_ms"],
                "collided": recipient["collided"],  # why an episode ends (terminated)
            }
        if self.vehicles_are_agents:
            for name in self.vehicle_agents:
                infos[name] = {"acts": vehicle_acts, **last[name]}
        return infos

    def step(self, actions: dict):
        self._check_action_keys(actions)
        if not self.agents:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        twin = self.twin
        closes_interval = twin.subframe == twin.subframes_per_interval - 1
        rra_actions = self._rra_actions(actions, self.rra_agents)
        commands = None
        if closes_interval and self.vehicles_are_agents:
            commands = torch.as_tensor(self._vehicle_commands(actions, self.vehicle_agents))[None]

        engine = self.engine
        reward, throughput = engine.subframe_reward(
            engine.step_subframe(self._to_twin(rra_actions))
        )
        rra_reward = self._as_numpy(reward)[0]
        throughput_mbps = float(throughput[0])
        vehicle_reward = [0.0] * twin.num_followers
        terminated = truncated = False
        closing = ivoi = None
        if closes_interval:
            closed = self.engine.close(commands)
            record = self.last_record = closed.record
            extra = closed.rra_reward[0].cpu().numpy()
            rra_reward = rra_reward.astype(np.float64) + extra
            ivoi = closed.xi[0].tolist()
            vehicle_reward = record.reward[0].tolist()
            closing = interval_infos(
                record, self.vehicle_agents, twin.interval_ms, twin.subframe_ms
            )
            terminated = bool(closed.terminated[0])
            truncated = bool(closed.truncated[0])
            if not (terminated or truncated):
                self.engine.advance()
            else:  # what the followers know at the next decision time, before its CAM arrives
                self._refresh_vehicle_obs(cams_lost=True)
        if self._vehicle_tick_next():
            self._refresh_vehicle_obs()

        names = self.agents
        rewards = dict(zip(self.rra_agents, rra_reward.tolist(), strict=True))
        if self.vehicles_are_agents:
            rewards.update({name: vehicle_reward[i] for i, name in enumerate(self.vehicle_agents)})
        infos = self._infos(closing, ivoi, throughput_mbps)
        obs = self._observations()
        if terminated or truncated:
            self.agents = []
        return (
            obs,
            rewards,
            dict.fromkeys(names, terminated),
            dict.fromkeys(names, truncated),
            infos,
        )
