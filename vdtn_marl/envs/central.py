"""Gymnasium single-agent face: centralised control of all followers.

``vdtn/platoon-control-central-v0`` and ``vdtn/platoon-control-impaired-central-v1`` are
:class:`~vdtn_marl.envs.control.PlatoonControlEnv` (perfect or link-impaired observation) seen
by one agent that commands every follower, for single-agent libraries (Stable-Baselines3,
CleanRL) and Gymnasium's tools. One step is one 50 ms control interval.

=================  ==========================================================================
observation        Box(8·F) float32: the F followers' observations (``vehicle_1`` first),
                   8 features each (docs/model.md §2.4; the PettingZoo face's Box(8))
action             Box(F) float32 in [u_min, u_max] m/s²: the acceleration command of each
                   follower, in the same order. NaN or out-of-range values raise.
reward             the sum of the followers' rewards (the team's reward; docs/model.md §2.3);
                   ``info["rewards"]`` has each follower's
termination        any collision; truncation after ``episode_intervals`` (``max_cycles``)
info               ``"followers"``: the PettingZoo face's per-follower infos
=================  ==========================================================================

Every id of the ``"gymnasium"`` API in vdtn-marl's registry is in Gymnasium's registry too
(:func:`~vdtn_marl.envs.registration.register_with_gymnasium`), so after ``import vdtn_marl``
``gymnasium.make("vdtn/platoon-control-central-v0")`` works, as does the ``module:id`` form
``gymnasium.make("vdtn_marl.envs.central:vdtn/platoon-control-central-v0")`` without it;
``vdtn_marl.make(id)`` builds the same class.
Keyword arguments are those of ``PlatoonControlEnv`` (model parameters, ``traces``, ``seed``,
``rra_policy``, ``completion``, ``render_mode="rgb_array"``).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from vdtn_marl.envs.registration import register_with_gymnasium


class CentralControlEnv(gymnasium.Env):
    """One agent commands all followers of a :class:`PlatoonControlEnv` (see module doc)."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(self, impaired: bool = False, render_mode: str | None = None, **kwargs: Any):
        from vdtn_marl.envs.control import PlatoonControlEnv

        self.multi_agent = PlatoonControlEnv(impaired=impaired, render_mode=render_mode, **kwargs)
        self.render_mode = render_mode
        self.followers = list(self.multi_agent.possible_agents)
        one_obs = self.multi_agent.observation_space(self.followers[0])
        one_action = self.multi_agent.action_space(self.followers[0])
        f = len(self.followers)
        self.observation_space = gymnasium.spaces.Box(
            np.tile(one_obs.low, f), np.tile(one_obs.high, f), dtype=np.float32
        )
        self.action_space = gymnasium.spaces.Box(
            float(one_action.low[0]), float(one_action.high[0]), shape=(f,), dtype=np.float32
        )

    def _flat(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.concatenate([obs[name] for name in self.followers]).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        obs, infos = self.multi_agent.reset(seed=seed, options=options)
        return self._flat(obs), {"followers": infos}

    def step(self, action):
        f = len(self.followers)
        try:
            commands = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            commands = None
        if commands is None or commands.shape != (f,):
            raise ValueError(
                f"action {action!r} must be {f} commands (m/s²), one per follower "
                f"{self.followers[0]}..{self.followers[-1]}, in "
                f"[{self.action_space.low[0]}, {self.action_space.high[0]}]"
            )
        actions = {name: commands[i : i + 1] for i, name in enumerate(self.followers)}
        obs, rewards, terminated, truncated, infos = self.multi_agent.step(actions)
        reward = float(sum(rewards[name] for name in self.followers))
        info = {"followers": infos, "rewards": rewards}
        return (
            self._flat(obs),
            reward,
            any(terminated.values()),
            any(truncated.values()),
            info,
        )

    def render(self):
        return self.multi_agent.render()

    def close(self):
        self.multi_agent.close()


__all__ = ["CentralControlEnv", "register_with_gymnasium"]
