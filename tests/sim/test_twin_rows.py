"""``DigitalTwin.run_subframes``: an interval's subframes for some scenarios alone give those
scenarios the numbers of the masked full-batch subframes (``step_subframe(mask=)``)."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin


def _act(radio):
    """The highest power (level 0) on a sub-channel that depends on each scenario's own
    observation only."""
    powers, channels = radio.num_power_levels, radio.num_subchannels

    def act(observation):
        channel = (observation.sum(-1) * 1e3).long().remainder(channels)
        return channel * powers

    return act


def _twin(batch: int, backend: str = "torch") -> DigitalTwin:
    params = TwinParams.from_overrides(episode_intervals=6)
    return DigitalTwin(params, batch_size=batch, seed=11, backend=backend)


def _after_a_partial_reset(batch: int, mask: torch.Tensor) -> DigitalTwin:
    """A twin two intervals in (CAMs delivered, some not), then ``mask``'s scenarios reset."""
    twin = _twin(batch)
    act = _act(twin.params.radio)
    for _ in range(2):
        for _ in range(twin.subframes_per_interval):
            twin.step_subframe(act(twin.rra_observation()))
        twin.finish_interval(torch.zeros(batch, twin.num_followers), False)
        twin.begin_interval()
    twin.reset(mask=mask)
    return twin


@pytest.mark.parametrize(
    "batch, rows",
    [(5, [0, 3]), (300, [2, 77, 299]), (300, list(range(0, 300, 2)) + list(range(1, 221, 2)))],
    ids=["dense", "link-major-batch", "link-major-rows"],
)
def test_rows_alone_give_the_masked_subframes_numbers(batch, rows):
    mask = torch.zeros(batch, dtype=torch.bool)
    mask[rows] = True
    masked, alone = (_after_a_partial_reset(batch, mask) for _ in range(2))
    act = _act(masked.params.radio)
    for _ in range(masked.subframes_per_interval):
        masked.step_subframe(act(masked.rra_observation()), mask=mask)
    seen = []

    def recording(observation):
        seen.append(observation.shape[0])
        return act(observation)

    alone.run_subframes(torch.tensor(rows), recording)
    assert seen == [len(rows)] * alone.subframes_per_interval
    delivered = masked.link_state.remaining_bits[mask] <= 0
    assert 0 < int(delivered.sum()) < delivered.numel()  # the check sees both outcomes
    for field in dataclasses.fields(masked.link_state):
        assert torch.equal(
            getattr(alone.link_state, field.name), getattr(masked.link_state, field.name)
        ), field.name
    assert torch.equal(alone._v2i_rate_sum, masked._v2i_rate_sum)
    assert torch.equal(alone._rra_obs[:, mask], masked._rra_obs[:, mask])
    assert alone.subframe == masked.subframe == alone.subframes_per_interval


def test_rows_actions_are_checked_against_the_rows_shape():
    twin = _twin(4)
    n_act = twin.params.radio.num_actions
    with pytest.raises(ValueError, match=r"\[0, " + str(n_act - 1) + r"\]"):
        twin.run_subframes(torch.tensor([1, 2]), lambda obs: torch.full(obs.shape[:-1], n_act))
    with pytest.raises(ValueError, match="expected"):
        twin.run_subframes(torch.tensor([1, 2]), lambda obs: torch.zeros(4, twin.num_links).long())


def test_rows_need_a_torch_twin():
    twin = _twin(1, backend="numpy")
    with pytest.raises(RuntimeError, match="run_subframes"):
        twin.run_subframes(torch.tensor([0]), _act(twin.params.radio))


@pytest.mark.parametrize(
    "batch, rows",
    [(5, [1, 4]), (300, [0, 150, 151]), (520, list(range(0, 520, 2)))],
    ids=["dense", "link-major-batch", "link-major-rows"],
)
def test_a_partial_reset_builds_the_rows_interval_as_the_merge_does(batch, rows, monkeypatch):
    """A partial reset of at most half the batch builds the reset scenarios' tables, CAM
    progress and observations alone; the twin is bit for bit the one that builds them all and
    keeps the rows (the path of larger masks)."""
    mask = torch.zeros(batch, dtype=torch.bool)
    mask[rows] = True
    alone = _after_a_partial_reset(batch, mask)
    built = []
    monkeypatch.setattr(DigitalTwin, "_begin_rows_interval", lambda twin, r: built.append(r))
    assert alone.few_rows(mask) is not None
    monkeypatch.setattr(DigitalTwin, "few_rows", lambda twin, mask: None)
    merged = _after_a_partial_reset(batch, mask)
    assert built == []  # the patched merge path ran, not the rows path
    for field in dataclasses.fields(merged.tables):
        assert torch.equal(getattr(alone.tables, field.name), getattr(merged.tables, field.name)), (
            field.name
        )
    for field in dataclasses.fields(merged.link_state):
        assert torch.equal(
            getattr(alone.link_state, field.name), getattr(merged.link_state, field.name)
        ), field.name
    assert torch.equal(alone._rra_obs, merged._rra_obs)
    assert torch.equal(alone._v2i_rate_sum, merged._v2i_rate_sum)
    assert torch.equal(alone.platoon.position_m, merged.platoon.position_m)
    assert torch.equal(alone.generator.get_state(), merged.generator.get_state())
