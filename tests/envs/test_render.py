"""rgb_array rendering of the PettingZoo environments."""

from __future__ import annotations

import numpy as np
import pytest

from vdtn_marl.envs import PlatoonControlEnv, TwoTimescaleEnv
from vdtn_marl.envs.render import render_twin


def _random_actions(env, infos, rng):
    actions = {}
    for agent in env.agents:
        if infos.get(agent, {}).get("acts", True):
            space = env.action_space(agent)
            space.seed(int(rng.integers(1 << 31)))
            actions[agent] = space.sample()
    return actions


def _check_image(image):
    assert isinstance(image, np.ndarray)
    assert image.dtype == np.uint8
    assert image.ndim == 3 and image.shape[2] == 3
    assert image.shape[0] > 100 and image.shape[1] > 100
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 1


@pytest.mark.parametrize(
    ("factory", "steps"),
    [
        (lambda mode: PlatoonControlEnv(render_mode=mode, seed=0), 3),
        (lambda mode: PlatoonControlEnv(impaired=True, render_mode=mode, seed=0), 3),
        (lambda mode: TwoTimescaleEnv(kappa1=1.0, render_mode=mode, seed=0), 53),
    ],
    ids=["control-perfect", "control-impaired", "two-timescale"],
)
def test_render_rgb_array(factory, steps):
    env = factory("rgb_array")
    rng = np.random.default_rng(0)
    _, infos = env.reset(seed=0)
    _check_image(env.render())
    for _ in range(steps):
        _, _, _, _, infos = env.step(_random_actions(env, infos, rng))
    image = env.render()
    _check_image(image)
    assert env.render().shape == image.shape
    env.close()


@pytest.mark.parametrize("cls", [PlatoonControlEnv, TwoTimescaleEnv])
def test_render_none_mode_returns_none(cls):
    env = cls(render_mode=None, seed=0)
    env.reset(seed=0)
    assert env.render() is None


def test_render_twin_partial_interval():
    env = TwoTimescaleEnv(kappa1=1.0, seed=1)
    _, infos = env.reset(seed=1)
    rng = np.random.default_rng(1)
    for _ in range(10):
        _, _, _, _, infos = env.step(_random_actions(env, infos, rng))
    _check_image(render_twin(env.twin))
