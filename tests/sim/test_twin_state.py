"""The twin holds its state once, in its backend's arrays, and hands torch tensors to callers."""

import copy

import numpy as np
import pytest
import torch

from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim import link
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.platoon import PlatoonState
from vdtn_marl.sim.snapshot import export_state, import_state
from vdtn_marl.sim.twin import DigitalTwin

PARAMS = TwinParams.from_overrides(episode_intervals=20)
STATE = (
    "leader_speed_mps",
    "platoon",
    "interval",
    "v2v_shadow_db",
    "v2i_shadow_db",
    "bs_offset_m",
    "shadow_position_m",
    "cam_snapshot",
    "cam_held",
    "cam_held_interval",
    "cam_delay_history",
    "command_history",
)


def _arrays(value):
    if isinstance(value, PlatoonState):
        return [value.position_m, value.speed_mps, value.accel_mps2, value.command_mps2]
    return [value]


def _copy(x) -> np.ndarray:
    return (x.numpy() if isinstance(x, torch.Tensor) else x).copy()


def _run(twin: DigitalTwin, intervals: int, seed: int = 3) -> list[np.ndarray]:
    """Random RRA actions and CACC commands for ``intervals`` intervals; what came out."""
    cacc = CACCController(twin.params.platoon)
    gen = torch.Generator().manual_seed(seed)
    out = []
    for _ in range(intervals):
        for _ in range(twin.subframes_per_interval):
            actions = torch.randint(
                0, twin.params.radio.num_actions, (twin.batch_size, twin.num_links), generator=gen
            )
            twin.step_subframe(twin.ns.from_torch(actions))
            out.append(_copy(twin.rra_observation()))
        obs = twin.vehicle_observation(perfect=False)
        record = twin.finish_interval(cacc(obs), perfect=False)
        out += [_copy(obs), _copy(record.reward), _copy(record.state_after.position_m)]
        twin.begin_interval()
    return out


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_state_is_held_in_the_backends_arrays_and_read_as_torch(backend):
    twin = DigitalTwin(PARAMS, batch_size=2, seed=0, backend=backend)
    held = np.ndarray if backend == "numpy" else torch.Tensor
    for name in STATE:
        for array, view in zip(
            _arrays(getattr(twin, "_" + name)), _arrays(getattr(twin, name)), strict=True
        ):
            assert isinstance(array, held), name
            assert isinstance(view, torch.Tensor), name
            assert view.data_ptr() == torch.as_tensor(array).data_ptr(), name  # no copy


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_writes_through_the_torch_attributes_reach_the_state(backend):
    twin = DigitalTwin(PARAMS, seed=0, backend=backend)
    twin.platoon.speed_mps[:] = 0.0  # in place, through the view
    assert float(abs(twin._platoon.speed_mps).max()) == 0.0
    state = twin.platoon
    moved = PlatoonState(
        state.position_m + 1.0, state.speed_mps, state.accel_mps2, state.command_mps2
    )
    twin.platoon = moved  # assigned: stored as the backend's arrays
    assert isinstance(twin._platoon.position_m, np.ndarray if backend == "numpy" else torch.Tensor)
    np.testing.assert_array_equal(np.asarray(twin._platoon.position_m), moved.position_m.numpy())


def _resumes(twin: DigitalTwin, saved: dict) -> None:
    """A twin built alike but seeded otherwise, given ``saved``, continues as ``twin`` does."""
    expected = _run(twin, 3)
    other = DigitalTwin(PARAMS, batch_size=2, seed=99, backend=twin.backend)
    import_state(other, saved)
    for got, want in zip(_run(other, 3), expected, strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_a_snapshot_resumes_bit_for_bit(backend):
    twin = DigitalTwin(PARAMS, batch_size=2, seed=1, backend=backend)
    _run(twin, 2)
    _resumes(twin, copy.deepcopy(export_state(twin)))


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_a_snapshot_under_the_public_names_resumes(backend):
    """A checkpoint written when the twin kept its state under the public names (before it
    held it once, in its backend's arrays) restores through those names."""
    twin = DigitalTwin(PARAMS, batch_size=2, seed=1, backend=backend)
    _run(twin, 2)
    saved = copy.deepcopy(export_state(twin))
    saved = {key.removeprefix("_") if key[1:] in STATE else key: v for key, v in saved.items()}
    assert set(STATE) <= set(saved)
    _resumes(twin, saved)


@pytest.mark.parametrize("fading_draws", ["normal", "exponential"])
def test_a_link_major_twin_resumes_mid_interval_bit_for_bit(fading_draws):
    """From LINK_MAJOR_MIN_BATCH on the torch twin's tables, link state and observation buffer
    are link-major views of reused buffers: a snapshot taken mid-interval, restored into a
    twin built alike, continues as the original does (the restored tables are plain tensors)."""
    batch = link.LINK_MAJOR_MIN_BATCH + 1

    def subframes(twin: DigitalTwin, count: int, gen: torch.Generator) -> list[np.ndarray]:
        out = []
        for _ in range(count):
            actions = torch.randint(
                0, twin.params.radio.num_actions, (batch, twin.num_links), generator=gen
            )
            outcome = twin.step_subframe(actions)
            out += [_copy(twin.rra_observation()), _copy(outcome.v2v_bits)]
        if twin.subframe == twin.subframes_per_interval:  # close the interval, run one more
            commands = CACCController(twin.params.platoon)(twin.vehicle_observation(False))
            out.append(_copy(twin.finish_interval(commands, perfect=False).reward))
            twin.begin_interval()
            out += _run(twin, 1)
        return out

    twin = DigitalTwin(PARAMS, batch_size=batch, seed=1, fading_draws=fading_draws)
    _run(twin, 1)
    subframes(twin, 20, torch.Generator().manual_seed(5))
    saved = copy.deepcopy(export_state(twin))
    rest = twin.subframes_per_interval - 20
    expected = subframes(twin, rest, torch.Generator().manual_seed(6))
    other = DigitalTwin(PARAMS, batch_size=batch, seed=99, fading_draws=fading_draws)
    import_state(other, saved)
    got = subframes(other, rest, torch.Generator().manual_seed(6))
    for a, b in zip(got, expected, strict=True):
        np.testing.assert_array_equal(a, b)
