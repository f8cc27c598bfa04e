"""The observation returned with an episode's last step (what PPO bootstraps from on truncation).

At the end of interval k the twin does not run interval k + 1's radio, so the followers'
final observation is what they know at (k + 1)Δt before CAM_{k+1} arrives: their own state at
(k + 1)Δt, the newest CAM content they hold at its age, and a command that would take force only
at the next interval (delay = T subframes), i.e. ``vehicle_observation(cams_lost=True)``.
"""

import numpy as np
import torch

from vdtn_marl.envs import PlatoonControlEnv, TwoTimescaleEnv
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.sim.layout import VEHICLE_OBS_FEATURES

T = 50
INTERVALS = 3
DELAY = VEHICLE_OBS_FEATURES.index("cam_delay_ms")
AGE = VEHICLE_OBS_FEATURES.index("cam_age_ms")
GAP = VEHICLE_OBS_FEATURES.index("gap_error_m")
DELIVERING = [12, 0, 4]  # links 1-3 on sub-channels 3, 0, 1 at 23 dBm: most CAMs arrive in time


def _check_final(obs: np.ndarray, twin) -> None:
    """``obs`` [F, 8]: the follower's observation after the last interval closed."""
    expected = twin.vehicle_observation(perfect=False, cams_lost=True)[0].cpu().numpy()
    np.testing.assert_array_equal(obs, expected)
    assert (obs[:, DELAY] == T).all()  # no CAM of interval k + 1 yet
    assert (obs[:, AGE] >= T).all()  # the content held is at least one interval old
    perfect = twin.vehicle_observation(perfect=True)[0].cpu().numpy()
    np.testing.assert_array_equal(obs[:, GAP], perfect[:, GAP])  # own sensing at (k + 1)Δt


def test_pettingzoo_control_env_final_observation():
    env = PlatoonControlEnv(
        impaired=True,
        rra_policy=lambda o: np.array([DELIVERING]),
        episode_intervals=INTERVALS,
        seed=0,
    )
    obs, _ = env.reset(seed=0)
    delivered = []
    for _ in range(INTERVALS):
        obs, _, _, truncated, infos = env.step({a: np.zeros(1, np.float32) for a in env.agents})
        delivered.append(infos["vehicle_1"]["cam_delivered"])
    assert all(truncated.values()) and any(delivered)
    _check_final(np.stack([obs[a] for a in env.possible_agents]), env.twin)


def test_two_timescale_env_final_vehicle_observation():
    env = TwoTimescaleEnv(episode_intervals=INTERVALS, seed=0)
    obs, infos = env.reset(seed=0)
    truncated = {}
    for step in range(INTERVALS * T):
        actions = dict(zip(env.rra_agents, DELIVERING, strict=True))
        if step % T == T - 1:
            actions |= {a: np.zeros(1, np.float32) for a in env.vehicle_agents}
        obs, _, _, truncated, infos = env.step(actions)
    assert all(truncated.values())
    _check_final(np.stack([obs[a] for a in env.vehicle_agents]), env.twin)


def test_torchrl_impaired_control_face_final_observation():
    env = VDTNTorchRLEnv(mode="control_impaired", batch_size=4, seed=0, episode_intervals=2)
    td = env.reset()
    for _ in range(2):
        td["vehicle", "action"] = torch.zeros(4, 3, 1)
        td = env.step(td)["next"]
    assert td["vehicle", "truncated"].all()
    final = td["vehicle", "observation"]
    expected = env.twin.vehicle_observation(perfect=False, cams_lost=True)
    torch.testing.assert_close(final, expected, rtol=0, atol=0)
    assert (final[..., DELAY] == T).all()


def test_torchrl_joint_face_final_vehicle_observation():
    env = VDTNTorchRLEnv(mode="joint", batch_size=4, seed=0, episode_intervals=2)
    td = env.reset()
    for _ in range(2 * T):
        td["rra", "action"] = torch.tensor([DELIVERING] * 4)
        td["vehicle", "action"] = torch.zeros(4, 3, 1)
        td = env.step(td)["next"]
    assert td["vehicle", "truncated"].all()
    expected = env.twin.vehicle_observation(perfect=False, cams_lost=True)
    torch.testing.assert_close(td["vehicle", "observation"], expected, rtol=0, atol=0)
