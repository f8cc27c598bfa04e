"""IVoI attribution: follower i's ξ is paid to rra_i, the disseminator of link i, and to no
other link (docs/model.md §5). Evaluation averages over followers, so a permutation of the
links would pass every aggregate test: here each follower's ξ is distinct and known."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import vdtn_marl
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv

S_XI = 20.0


class LabelledIVoI:
    """ξ[b, i] = 0.01·(i + 1) + 0.001·k: a different value for every follower i (and interval k)."""

    def __call__(self, twin, record):
        followers = torch.arange(1, twin.num_followers + 1, dtype=torch.float32)
        return 0.01 * followers[None, :] + 0.001 * record.interval[:, None].float()


def expected_xi(follower: int, interval: int) -> float:
    return 0.01 * follower + 0.001 * interval


def _rra_env_ids() -> list[str]:
    ids = []
    for env_id in vdtn_marl.list_envs(api="pettingzoo"):
        try:
            env = vdtn_marl.make(env_id)
        except Exception:  # a superseded id that refuses to build
            continue
        if any(a.startswith("rra_") for a in env.possible_agents):
            ids.append(env_id)
        env.close()
    return ids


@pytest.mark.parametrize("env_id", _rra_env_ids())
def test_pettingzoo_faces_pay_each_followers_ivoi_to_its_own_link(env_id):
    env = vdtn_marl.make(env_id, kappa1=0.0, ivoi_estimator=LabelledIVoI(), ivoi_scale=S_XI)
    env.reset(seed=0)
    t_per_interval = env.twin.subframes_per_interval
    checked = 0
    for step in range(2 * t_per_interval):
        actions = {a: env.action_space(a).sample() for a in env.agents if a.startswith("rra_")}
        actions |= {a: np.zeros(1, np.float32) for a in env.agents if a.startswith("vehicle_")}
        _, rewards, *_, infos = env.step(actions)
        if step % t_per_interval != t_per_interval - 1:
            continue
        interval = step // t_per_interval
        for agent in (a for a in env.agents if a.startswith("rra_")):
            follower = int(agent.split("_")[1])
            assert infos[agent]["ivoi"] == pytest.approx(expected_xi(follower, interval)), agent
            assert rewards[agent] == pytest.approx(S_XI * expected_xi(follower, interval)), agent
            checked += 1
    assert checked == 2 * env.twin.num_links
    env.close()


@pytest.mark.parametrize("mode", ["rra", "joint"])
def test_torchrl_face_pays_each_followers_ivoi_to_its_own_link(mode):
    env = VDTNTorchRLEnv(
        mode, batch_size=2, seed=0, kappa1=0.0, ivoi_estimator=LabelledIVoI(), ivoi_scale=S_XI
    )
    td = env.reset()
    t_per_interval = env.twin.subframes_per_interval
    for step in range(t_per_interval):
        td.set(("rra", "action"), torch.zeros(2, env.num_links, dtype=torch.long))
        if mode == "joint":
            td.set(("vehicle", "action"), torch.zeros(2, env.num_followers, 1))
        td = env.step(td)
        reward = td.get(("next", "rra", "reward")).squeeze(-1)  # [B, L]
        if step < t_per_interval - 1:
            assert float(reward.abs().max()) == 0.0
        td = td.get("next")
    expected = torch.tensor([S_XI * expected_xi(i, 0) for i in range(1, env.num_links + 1)])
    torch.testing.assert_close(reward, expected.expand(2, -1))
