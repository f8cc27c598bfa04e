"""Platoon control environments: ``vdtn/platoon-control-v0`` and ``-impaired-v1``.

One step is one control interval (Δt = 50 ms). Agents ``vehicle_1..vehicle_{N−1}`` (one per
follower, named by vehicle id: ``vehicle_1..3, vehicle_5..7`` with ``scenario="two_platoons"``
and N = 8).

=================  ==========================================================================
observation        Box(8) float32: gap error (m), speed error (m/s), own acceleration (m/s²),
                   predecessor's acceleration and command from the CAM (m/s²), CAM delay
                   (ms: when the command takes force, 0..T), CAM age (ms, at the interval
                   start), previous own command (m/s²). docs/model.md §2.4
action             Box(1) float32 in [u_min, u_max] m/s²: the acceleration command u_k.
                   NaN or out-of-range values raise.
reward             per follower: −(|e_p|/ê_p + α|e_v|/ê_v + β|u|/u_max + γ_j|jerk|/j_max);
                   collision penalty on the colliding follower. docs/model.md §2.3
start state        followers at the desired gap and the leader's initial speed, a = 0
termination        any gap ≤ 0 (collision) ends the episode for every agent
truncation         after ``episode_intervals`` intervals (default 400 = 20 s); ``max_cycles``,
                   PettingZoo's name for it, is accepted as an alias
=================  ==========================================================================

With ``impaired=True`` every interval's CAMs cross the C-V2X link layer, driven by
``rra_policy`` (a callable: RRA observations [1, L, D] → integer actions [1, L]; random by
default), before the followers decide: late CAMs delay the command switch, lost ones leave the
follower with older CAM content (docs/model.md §4.5). Without it, observation is perfect.

``completion`` (``"none"``, ``"hold"``, ``"kalman"``, ``"learned"`` with
``completion_predictor=``, or a completer object) replaces stale CAM content in the impaired
observations by a prediction (docs/model.md §4.7); with perfect observation it is a no-op.

Version history (docs/model.md, "Version history"; ``vdtn/platoon-control-v0`` has no radio and
stays v0):

- ``vdtn/platoon-control-impaired-v1`` (2026-12):

  - V2V path loss WINNER+ B1 with effective antenna heights and a free-space floor by default
    (v0: Liang et al.'s form; ``v2v_pathloss_form="liang"`` restores it).
  - The RRA observation its ``rra_policy`` reads has 4M + 12 features (v0: 4M + 6): the
    recipient's CAM content age, its last 3 CAM delays and its 2 earlier commands are appended
    (:data:`vdtn_marl.sim.layout.RRA_OBS_FEATURES`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from vdtn_marl.core.interval import IntervalEngine
from vdtn_marl.envs.base import (
    VDTNParallelEnv,
    apply_max_cycles,
    vehicle_action_space,
    vehicle_observation_space,
)
from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.sim.completion import make_completion

#: Per-follower info before the first interval closes (same keys and types as interval_infos).
INITIAL_INTERVAL_INFO = {
    "gap_error_m": 0.0,
    "speed_error_mps": 0.0,
    "command_mps2": 0.0,
    "switch_ms": 0.0,
    "cam_delivered": True,
    "cam_delay_ms": 0.0,
    "collided": False,
}


def interval_infos(record, names: list[str], interval_ms: float, subframe_ms: float) -> dict:
    """Per-follower diagnostics of one interval (keys of :data:`INITIAL_INTERVAL_INFO`).

    ``cam_delay_ms`` is the CAM's delivery time, −1 when it was lost.
    """
    t_sub = record.cam_delay_subframes[0].tolist()
    switch = record.switch_subframe[0].tolist()
    gap = record.gap_error_m[0].tolist()
    speed = record.speed_error_mps[0].tolist()
    command = record.command_mps2[0].tolist()
    collided = record.collided[0].tolist()
    limit = round(interval_ms / subframe_ms)
    return {
        name: {
            "gap_error_m": gap[i],
            "speed_error_mps": speed[i],
            "command_mps2": command[i],
            "switch_ms": switch[i] * subframe_ms,
            "cam_delivered": t_sub[i] <= limit,
            "cam_delay_ms": t_sub[i] * subframe_ms if t_sub[i] <= limit else -1.0,
            "collided": collided[i],
        }
        for i, name in enumerate(names)
    }


class PlatoonControlEnv(VDTNParallelEnv):
    """Followers' longitudinal control; perfect or link-impaired observation (see module doc)."""

    def __init__(
        self,
        impaired: bool = False,
        rra_policy: Callable | None = None,
        seed: int | None = None,
        render_mode: str | None = None,
        device: str = "cpu",
        completion="none",
        completion_predictor=None,
        max_cycles: int | None = None,
        **model_kwargs,
    ):
        model_kwargs = apply_max_cycles(max_cycles, model_kwargs, interval_steps=True)
        super().__init__(
            radio=impaired, seed=seed, render_mode=render_mode, device=device, **model_kwargs
        )
        self.impaired = impaired
        self.metadata = {
            **self.metadata,
            "name": "platoon_control_impaired_v1" if impaired else "platoon_control_v0",
        }
        self.possible_agents = self.scenario.vehicle_agents(self.twin.topology)
        self.agents: list[str] = []
        rra_policy = rra_policy or RandomRRAPolicy(self.twin.params.radio.num_actions, seed)
        self.engine = IntervalEngine(  # with radio (impaired) it runs each interval's T subframes
            self.twin,
            perfect=not impaired,
            rra_policy=rra_policy,
            completion=make_completion(completion, completion_predictor, self.twin.params.platoon),
        )

    def _observation_space(self, agent):
        return vehicle_observation_space(self.twin)

    def _action_space(self, agent):
        return vehicle_action_space(self.twin)

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None and hasattr(self.rra_policy, "seed"):
            self.rra_policy.seed(seed)
        self.engine.reset(seed=seed)  # and the first interval's radio when impaired
        self.agents = self.possible_agents[:]
        self.last_record = None
        return self._observations(), {a: dict(INITIAL_INTERVAL_INFO) for a in self.agents}

    def _observations(self, cams_lost: bool = False) -> dict[str, np.ndarray]:
        """Each follower's observation; ``cams_lost`` (impaired, at an episode's end): what it
        knows at the next decision time before that interval's CAM arrives."""
        obs = self.engine.observe(cams_lost=cams_lost)[0].cpu().numpy()
        return {name: obs[i] for i, name in enumerate(self.possible_agents)}

    def step(self, actions: dict):
        self._check_action_keys(actions)
        if not self.agents:
            raise RuntimeError("step() called on a finished episode; call reset() first")
        commands = self._vehicle_commands(actions, self.agents)
        closed = self.engine.close(torch.as_tensor(commands, device=self.twin.device)[None])
        record = self.last_record = closed.record
        terminated = bool(closed.terminated[0])
        truncated = bool(closed.truncated[0])
        if not (terminated or truncated):
            self.engine.advance()  # the next interval, with its radio when impaired
        rewards = record.reward[0].tolist()
        names = self.agents
        infos = interval_infos(record, names, self.twin.interval_ms, self.twin.subframe_ms)
        finished = terminated or truncated
        obs = self._observations(cams_lost=finished and self.impaired)
        self.agents = [] if finished else names
        return (
            obs,
            {n: rewards[i] for i, n in enumerate(names)},
            dict.fromkeys(names, terminated),
            dict.fromkeys(names, truncated),
            infos,
        )
