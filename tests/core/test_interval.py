"""The interval engine: the one place the interval protocol is written (vdtn_marl.core)."""

from __future__ import annotations

import ast
import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import torch

import vdtn_marl
from vdtn_marl.core.interval import IntervalEngine, check_burn_in, check_callable
from vdtn_marl.envs.base import ENGINE_PARTS
from vdtn_marl.envs.torchrl import MODES, VDTNTorchRLEnv
from vdtn_marl.errors import ConfigError
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.sim.completion import make_completion
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin

PACKAGE = Path(__file__).resolve().parents[2] / "vdtn_marl"
#: the twin's interval calls: only the core (and the twin itself) make them
PROTOCOL_CALLS = {"finish_interval", "begin_interval", "close_interval"}


def _faces():
    for env_id in vdtn_marl.list_envs(api="pettingzoo"):
        yield env_id, lambda env_id=env_id: vdtn_marl.make(env_id, seed=0, episode_intervals=4)
    for mode in MODES:
        yield (
            f"torchrl:{mode}",
            lambda mode=mode: VDTNTorchRLEnv(
                mode=mode, batch_size=2, seed=0, episode_intervals=4, ivoi_estimator="none"
            ),
        )


FACES = dict(_faces())


@pytest.mark.parametrize("face", sorted(FACES))
def test_every_face_runs_on_an_engine_that_owns_its_parts(face):
    env = FACES[face]()
    assert isinstance(env.engine, IntervalEngine)
    assert env.engine.twin is env.twin
    for name, target in ENGINE_PARTS.items():
        assert getattr(env, name) is getattr(env.engine, target)
    # replacing a part on the face replaces what the engine runs
    marker = make_completion("hold", None, env.twin.params.platoon)
    env.completion = marker
    assert env.engine.completion is marker
    assert "completion" not in env.__dict__


def test_no_module_outside_the_core_runs_the_interval_protocol():
    offenders = []
    for path in PACKAGE.rglob("*.py"):
        room = path.relative_to(PACKAGE).parts[0]
        if room in ("sim", "core"):
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Call):
                func = node.func
                name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
                if name in PROTOCOL_CALLS:
                    offenders.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {name}")
    assert not offenders, offenders


def _engine(batch=4, seed=3, **kwargs):
    params = TwinParams.from_overrides(episode_intervals=5)
    twin = DigitalTwin(params, batch_size=batch, seed=seed, backend="torch")
    twin.reset(seed=seed)
    kwargs.setdefault("rra_policy", RandomRRAPolicy(params.radio.num_actions, seed))
    kwargs.setdefault("control", CACCController(params.platoon))
    return IntervalEngine(twin, perfect=False, **kwargs)


def test_close_and_advance_run_an_episode_to_truncation():
    engine = _engine()
    engine.run_radio()
    for k in range(5):
        if k:
            engine.advance()
        assert engine.twin.subframe == engine.twin.subframes_per_interval
        closed = engine.close()
        assert closed.xi is None and closed.rra_reward is None  # no estimator, no reward
        assert closed.record.reward.shape == (4, engine.twin.num_followers)
        assert not bool(closed.terminated.any())
        assert bool(closed.truncated.all()) == (k == 4)
        assert bool((closed.going == ~closed.truncated).all())


def test_advance_starts_only_the_going_scenarios():
    engine = _engine()
    engine.run_radio()
    engine.close()
    before = torch.as_tensor(engine.twin.link_state.remaining_bits).clone()
    going = torch.tensor([True, False, True, False])
    engine.advance(going)
    after = torch.as_tensor(engine.twin.link_state.remaining_bits)
    # the going scenarios got a new CAM and ran its radio; the others kept theirs
    assert torch.equal(after[~going], before[~going])
    assert not torch.equal(after[going], before[going])


class _RowPolicy:
    """A deterministic policy whose actions depend on each scenario's own observation, which
    notes how many scenarios each call saw."""

    def __init__(self, num_actions: int, rowwise: bool):
        self.num_actions, self.rowwise, self.batches = num_actions, rowwise, []

    def __call__(self, observation):
        self.batches.append(observation.shape[0])
        return (observation.sum(-1) * 1e3).long().remainder(self.num_actions)


def _two_intervals_closed(batch: int, seed: int, rowwise: bool):
    """An engine whose RRA policy is a :class:`_RowPolicy`, after two closed intervals, and
    that policy with no call noted yet."""
    engine = _engine(batch=batch, seed=seed)
    engine.rra_policy = policy = _RowPolicy(engine.twin.params.radio.num_actions, rowwise)
    engine.run_radio()
    engine.close()
    engine.advance()
    engine.close()
    policy.batches.clear()
    return engine, policy


@pytest.mark.parametrize("kind", ["reset", "advance"])
@pytest.mark.parametrize(
    "batch, masked",
    [(6, [1, 4]), (6, [0, 1, 3, 4]), (300, [7, 150, 299])],
    ids=["few", "most", "link-major"],
)
def test_a_rowwise_policy_is_asked_for_the_masked_scenarios_alone(kind, batch, masked):
    """After a partial reset (and a partial start) a ``rowwise`` policy sees the masked
    scenarios only (at most half the batch: the interval runs for them alone), and the twin
    ends bit for bit where it ends when the policy sees them all."""
    mask = torch.zeros(batch, dtype=torch.bool)
    mask[masked] = True
    twins = {}
    for rowwise in (False, True):
        engine, policy = _two_intervals_closed(batch, 5, rowwise)
        if kind == "reset":
            engine.reset(mask)
        else:
            engine.advance(mask)
        assert set(policy.batches) == ({len(masked)} if rowwise else {batch})
        assert len(policy.batches) == engine.twin.subframes_per_interval
        twins[rowwise] = engine.twin
    for field in dataclasses.fields(twins[True].link_state):
        assert torch.equal(
            getattr(twins[True].link_state, field.name),
            getattr(twins[False].link_state, field.name),
        ), field.name
    assert torch.equal(twins[True]._v2i_rate_sum, twins[False]._v2i_rate_sum)
    # the masked scenarios' observations, subframe by subframe
    assert torch.equal(twins[True]._rra_obs[:, mask], twins[False]._rra_obs[:, mask])
    assert twins[True].subframe == twins[False].subframe == twins[True].subframes_per_interval


def test_the_jocc_policy_slot_passes_on_its_policys_rowwise():
    """JOCC hands π̃'s environment a slot whose policy changes; the engine reads ``rowwise``
    through it."""
    from vdtn_marl.experiment.jocc import SwitchablePolicy

    slot = SwitchablePolicy(_RowPolicy(16, rowwise=True))
    assert slot.rowwise
    slot.policy = RandomRRAPolicy(16, 0)
    assert not slot.rowwise


def test_the_engine_drives_the_radio_only_with_a_policy_and_a_radio():
    assert _engine().drives_radio
    assert not _engine(rra_policy=None).drives_radio
    params = TwinParams.from_overrides(episode_intervals=5)
    silent = IntervalEngine(
        DigitalTwin(params, batch_size=1, seed=0, radio=False),
        perfect=True,
        rra_policy=RandomRRAPolicy(params.radio.num_actions, 0),
    )
    assert not silent.drives_radio
    silent.twin.reset(seed=0)
    silent.advance()  # starts the interval without touching a radio it has not got


def test_the_cam_lost_command_is_asked_first_so_the_completer_ends_on_the_actual_cams():
    calls = []

    class Recording:
        needs_command_if_lost = True

        def __call__(self, twin, record):
            calls.append("xi")
            return torch.zeros(record.reward.shape)

    class Control(CACCController):
        def __call__(self, observation):
            calls.append("decide")
            return super().__call__(observation)

    params = TwinParams.from_overrides(episode_intervals=5)
    engine = _engine(control=Control(params.platoon), ivoi_estimator=Recording())
    engine.run_radio()
    closed = engine.close()
    assert calls == ["decide", "decide", "xi"]
    assert closed.record.command_if_lost_mps2 is not None


def test_constructor_checks_name_the_key():
    with pytest.raises(TypeError, match="rra_policy"):
        check_callable("rra_policy", 3, "observations -> actions")
    with pytest.raises(TypeError, match="control_module"):
        _engine(control="cacc")
    with pytest.raises(ConfigError, match="burn_in_intervals"):
        check_burn_in(True, 10)
    with pytest.raises(ConfigError, match="burn_in_intervals"):
        check_burn_in(10, 10)
    assert check_burn_in(9, 10) == 9


def test_the_numpy_twin_takes_the_policy_actions_as_they_are():
    env = vdtn_marl.make("vdtn/platoon-control-impaired-v1", seed=1, episode_intervals=3)
    assert env.twin.backend == "numpy"
    obs, _ = env.reset(seed=1)
    assert env.twin.subframe == env.twin.subframes_per_interval  # the radio ran
    action = {a: np.zeros(1, np.float32) for a in env.agents}
    env.step(action)
    assert env.twin.subframe == env.twin.subframes_per_interval


@pytest.mark.parametrize(
    "make, key",
    [
        (lambda: vdtn_marl.make("vdtn/platoon-control-impaired-v1", rra_policy=3), "rra_policy"),
        (lambda: vdtn_marl.make("vdtn/v2x-rra-v1", control_module=3), "control_module"),
        (lambda: VDTNTorchRLEnv(mode="control_impaired", rra_policy=3), "rra_policy"),
        (lambda: VDTNTorchRLEnv(mode="rra", control_module=3), "control_module"),
    ],
)
def test_every_face_refuses_a_part_that_is_not_callable_naming_it(make, key):
    with pytest.raises(TypeError, match=key):
        make()


def _rows_equal(twin_a, twin_b, rows):
    """The scenarios ``rows`` [B] (bool) of two twins: the same interval, platoon, link state,
    V2I totals and RRA observations, bit for bit."""
    assert torch.equal(twin_a.interval[rows], twin_b.interval[rows])
    for field in dataclasses.fields(twin_a._platoon):
        a, b = getattr(twin_a._platoon, field.name), getattr(twin_b._platoon, field.name)
        assert torch.equal(a[rows], b[rows]), field.name
    for field in dataclasses.fields(twin_a.link_state):
        a, b = getattr(twin_a.link_state, field.name), getattr(twin_b.link_state, field.name)
        assert torch.equal(a[rows], b[rows]), field.name
    assert torch.equal(twin_a._v2i_rate_sum[rows], twin_b._v2i_rate_sum[rows])
    assert torch.equal(twin_a._rra_obs[:, rows], twin_b._rra_obs[:, rows])


@pytest.mark.parametrize("rowwise", [False, True], ids=["whole-batch policy", "rowwise"])
@pytest.mark.parametrize("ended", [[1, 4], [0, 1, 3, 4]], ids=["few", "most"])
def test_restart_ended_is_an_advance_and_a_reset_in_one_radio_run(ended, rowwise):
    """``restart_ended(going)``: the going scenarios are where ``advance(going)`` puts them,
    bit for bit, and every scenario where a reset of the ended ones made after the interval's
    draws and an interval start from those draws put it, with the policy asked once per
    subframe for the whole batch."""
    batch = 6
    going = torch.ones(batch, dtype=torch.bool)
    going[ended] = False
    engine, policy = _two_intervals_closed(batch, 7, rowwise)
    in_steps, as_advance = copy.deepcopy(engine), copy.deepcopy(engine)
    engine.restart_ended(going)
    assert policy.batches == [batch] * engine.twin.subframes_per_interval
    assert engine.twin.subframe == engine.twin.subframes_per_interval
    assert engine.twin.interval[~going].eq(0).all() and engine.twin.interval[going].eq(2).all()
    as_advance.advance(going)  # the interval's draws come first: the going ones' are advance's
    _rows_equal(engine.twin, as_advance.twin, going)
    twin = in_steps.twin
    start = twin.generator.get_state()
    twin._interval_draws()  # the generator past the interval's draws
    twin.reset(mask=~going, begin=False)  # the new episodes' draws after them
    twin.generator.set_state(start)  # the interval from its own draws
    in_steps.advance()
    _rows_equal(engine.twin, twin, torch.ones(batch, dtype=torch.bool))


def test_restart_ended_with_all_or_none_going_is_advance_or_reset():
    for going in (torch.ones(4, dtype=torch.bool), torch.zeros(4, dtype=torch.bool)):
        engine = _engine(seed=8)
        engine.run_radio()
        engine.close()
        other = copy.deepcopy(engine)
        engine.restart_ended(going)
        if bool(going.all()):
            other.advance()
        else:
            other.reset()
        _rows_equal(engine.twin, other.twin, torch.ones(4, dtype=torch.bool))
