"""The RRA observation's optional ``cam_innovation`` block (``rra_cam_innovation``): what a CAM
sent now would change in what the recipient holds, checked against the twin's own state."""

import numpy as np
import pytest
import torch

from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment.compose import compose_config, hydra_compose, job_config, to_run_config
from vdtn_marl.experiment.config import validate
from vdtn_marl.sim.layout import RRA_CONTROL_CLIP, RRA_OBS_FEATURES, RRAFeatureLayout
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin

OFF = 3  # sub-channel 0 at the "off" power level: nothing is sent


def _twin(backend: str, **overrides) -> DigitalTwin:
    params = TwinParams.from_overrides(episode_intervals=20, **overrides)
    twin = DigitalTwin(params, batch_size=3, seed=5, backend=backend)
    twin.reset(seed=5)
    return twin


def _interval(twin: DigitalTwin, action: int, command: float) -> None:
    """One interval with every link on ``action`` and every follower commanding ``command``."""
    ns = twin.ns
    for _ in range(twin.subframes_per_interval):
        twin.step_subframe(ns.from_torch(torch.full((twin.batch_size, twin.num_links), action)))
    commands = torch.full((twin.batch_size, twin.num_followers), command)
    twin.finish_interval(ns.from_torch(commands), perfect=False)
    twin.begin_interval()


def test_the_default_layout_is_the_features_table_and_the_option_appends_one_block():
    default = RRAFeatureLayout.for_subchannels(4)
    assert default.features == RRA_OBS_FEATURES
    assert "cam_innovation" not in default.slices
    with_it = RRAFeatureLayout.for_subchannels(4, cam_innovation=True)
    assert with_it.dim == default.dim + 2
    assert with_it["cam_innovation"] == slice(default.dim, default.dim + 2)
    low, high = with_it.bounds()
    assert low[-2:].tolist() == [-RRA_CONTROL_CLIP] * 2
    assert high[-2:].tolist() == [RRA_CONTROL_CLIP] * 2
    assert with_it.names()[-2:] == ["cam_innovation[0]", "cam_innovation[1]"]
    assert DigitalTwin(TwinParams.from_overrides(), batch_size=1).rra_obs_dim == default.dim


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_innovation_is_the_predecessors_content_now_minus_the_held_one(backend):
    twin = _twin(backend, rra_cam_innovation=True)
    lay, pp = twin.rra_layout, twin.params.platoon
    # nothing sent for three intervals while the followers accelerate: the held content ages
    for _ in range(3):
        _interval(twin, OFF, command=1.0)
    obs = torch.as_tensor(np.asarray(twin.rra_observation()))
    state = twin.platoon
    now = torch.stack(
        [
            pp.topology.predecessors_of(state.accel_mps2),
            pp.topology.predecessors_of(state.command_mps2),
        ],
        dim=-1,
    )
    expected = ((now - twin.cam_held) / pp.accel_max_mps2).clamp(-5.0, 5.0)
    got = obs[..., lay["cam_innovation"]]
    torch.testing.assert_close(got, expected.float())
    # followers 2 and 3 follow followers that commanded 1 m/s² while their CAMs were lost: the
    # held command is the start's, the innovation of the command is (1 − u₀)/u_max, not 0
    assert got[:, 1:, 1].abs().min() > 0.1
    # the block is constant over the interval's subframes, like the other control features
    twin.step_subframe(twin.ns.from_torch(torch.full((3, twin.num_links), OFF)))
    later = torch.as_tensor(np.asarray(twin.rra_observation()))[..., lay["cam_innovation"]]
    torch.testing.assert_close(later, got)


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_innovation_is_zero_after_a_delivery_of_unchanged_content(backend):
    twin = _twin(backend, rra_cam_innovation=True)
    lay = twin.rra_layout
    obs = np.asarray(twin.rra_observation())
    assert np.abs(obs[..., lay["cam_innovation"]]).max() == 0.0  # at reset: held = now
    # without the option the same twin's other features are the same numbers
    plain = _twin(backend)
    np.testing.assert_array_equal(
        np.asarray(plain.rra_observation())[..., : plain.rra_obs_dim], obs[..., : lay.dim - 2]
    )


def test_rra_cam_innovation_reaches_the_model_and_bad_values_name_the_key():
    with hydra_compose():
        cfg = to_run_config(job_config(compose_config("config", ["rra.cam_innovation=true"])))
        validate(cfg)
        assert cfg.twin_params().radio.rra_cam_innovation is True
        assert cfg.model_kwargs()["rra_cam_innovation"] is True
        plain = to_run_config(job_config(compose_config("config", [])))
        assert plain.twin_params().radio.rra_cam_innovation is False
        with pytest.raises(ConfigError, match="rra.cam_innovation"):
            to_run_config(
                job_config(
                    compose_config(
                        "config",
                        ["rra.cam_innovation=true", "+scenario.model.rra_cam_innovation=false"],
                    )
                )
            )
    with pytest.raises(ConfigError, match="rra_cam_innovation"):
        TwinParams.from_overrides(rra_cam_innovation=1)
