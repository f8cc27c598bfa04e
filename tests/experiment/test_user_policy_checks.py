"""A user's policy is checked (issue 57, item 1): called once on an observation of the run at
validation, its output must have the shape, dtype and values the run can use, and a module
must be of the task (RRA or control) and for the number of agents of the run; each failure is
one line naming the policy, the problem and the allowed values, exit code 2, nothing written.
A policy that fails later in the run is one line naming it and the call, exit code 1, with the
last checkpoint kept and the resume hint.
"""

from __future__ import annotations

import textwrap

import pytest
import torch

from tests.experiment.test_user_policy import SMOKE, _one_line_error, _Silent
from vdtn_marl import cli
from vdtn_marl.errors import PolicyError
from vdtn_marl.experiment import user_policy
from vdtn_marl.sim.params import TwinParams

pytestmark = pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema")

POLICIES = '''
import torch


class Returns:
    """An RRA policy (observations [B, L, D]) or a control policy ([B, F, 8]) that returns
    ``make(observation)`` from call ``bad_from`` on, and the valid ``good`` before it."""

    def __init__(self, make, bad_from=1, good=lambda obs: torch.zeros(obs.shape[:-1]).long()):
        self.make, self.bad_from, self.good, self.calls = make, bad_from, good, 0

    def __call__(self, observation):
        self.calls += 1
        if self.calls < self.bad_from:
            return self.good(observation)
        return self.make(observation)


def _rows(obs, value, dtype=torch.long):
    return torch.full(obs.shape[:-1], value, dtype=dtype)


def half(params, seed):
    return Returns(lambda obs: _rows(obs, 0.5, torch.float32))


def too_high(params, seed):
    return Returns(lambda obs: _rows(obs, params.radio.num_actions))


def negative(params, seed):
    return Returns(lambda obs: _rows(obs, -1))


def nan_rra(params, seed):
    return Returns(lambda obs: _rows(obs, float("nan"), torch.float32))


def one_link_too_many(params, seed):
    return Returns(lambda obs: torch.zeros(obs.shape[0], obs.shape[1] + 1, dtype=torch.long))


def nothing(params, seed):
    return Returns(lambda obs: None)


def raises_at_once(params, seed):
    def policy(observation):
        raise RuntimeError("not trained yet")

    return policy


def _commands(obs, value):
    return torch.full(obs.shape[:-1], value)


def hard(params, seed):
    return Returns(lambda obs: _commands(obs, 100.0))


def nan_control(params, seed):
    return Returns(lambda obs: _commands(obs, float("nan")))


def one_command(params, seed):
    return Returns(lambda obs: torch.zeros(obs.shape[0]))


def fails_on_call_3(params, seed):
    def boom(observation):
        raise RuntimeError("boom")

    return Returns(boom, bad_from=3)


def bad_on_call_3(params, seed):
    return Returns(lambda obs: _rows(obs, params.radio.num_actions), bad_from=3)
'''


@pytest.fixture
def policies(tmp_path, monkeypatch):
    """A module of policies, ``checked.py``, in the working directory (tmp_path)."""
    (tmp_path / "checked.py").write_text(textwrap.dedent(POLICIES))
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def _refused(root, capsys, overrides, *fragments) -> str:
    assert cli.main(["jocc", "hydra.run.dir=out", *SMOKE, *overrides]) == 2
    line = _one_line_error(capsys, *fragments)
    assert not (root / "out").exists()  # nothing written, not even .hydra/
    return line


RRA_ALLOWED = "allowed: integer actions in [0, 15]"
CONTROL_ALLOWED = "allowed: finite commands in [-2.6, 2.6] m/s²"


@pytest.mark.parametrize(
    ("factory", "fragments"),
    [
        ("half", ["dtype torch.float32", RRA_ALLOWED]),
        ("too_high", ["such as 16", RRA_ALLOWED]),
        ("negative", ["such as -1", RRA_ALLOWED]),
        ("nan_rra", ["dtype torch.float32", RRA_ALLOWED]),
        ("one_link_too_many", ["shape (2, 4)", "allowed: shape (2, 3)"]),
        ("nothing", ["returned a NoneType", RRA_ALLOWED]),
        ("raises_at_once", ["raised RuntimeError: not trained yet"]),
    ],
)
def test_an_rra_policys_output_is_checked_before_anything_is_written(
    policies, capsys, factory, fragments
):
    overrides = ["control=cacc", "rra=policy", f"rra.policy=checked:{factory}"]
    line = _refused(policies, capsys, overrides, f"rra.policy='checked:{factory}'", *fragments)
    assert "called once on an observation [2, 3, " in line and "3 links" in line


@pytest.mark.parametrize(
    ("factory", "fragments"),
    [
        ("hard", ["such as 100", CONTROL_ALLOWED]),
        ("nan_control", ["such as nan", CONTROL_ALLOWED]),
        ("one_command", ["shape (2,)", "allowed: shape (2, 3)"]),
    ],
)
def test_a_control_policys_output_is_checked_before_anything_is_written(
    policies, capsys, factory, fragments
):
    overrides = [
        "control=policy", f"control.policy=checked:{factory}", "control.warm_start=none",
        "rra=greedy",
    ]  # fmt: skip
    line = _refused(policies, capsys, overrides, f"control.policy='checked:{factory}'", *fragments)
    assert "[2, 3, 8]" in line and "3 followers" in line


def _actor(mode: str, group: str, **env_kw):
    from vdtn_marl.algos.networks import make_actor
    from vdtn_marl.envs.torchrl import VDTNTorchRLEnv

    env = VDTNTorchRLEnv(mode, batch_size=2, seed=0, **env_kw)
    return make_actor(env.full_observation_spec, env.full_action_spec, group)


def test_a_control_checkpoint_is_refused_as_an_rra_policy_and_back(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    torch.save(_actor("control_impaired", "vehicle"), tmp_path / "control.pt")
    torch.save(_actor("rra", "rra"), tmp_path / "rra.pt")
    line = _refused(
        tmp_path, capsys, ["control=cacc", "rra=policy", "rra.policy=control.pt"],
        "rra.policy='control.pt'", "it is a control policy", "allowed for rra.policy",
    )  # fmt: skip
    assert "('rra', 'observation')" in line
    overrides = ["control=policy", "control.policy=rra.pt", "control.warm_start=none"]
    _refused(tmp_path, capsys, overrides, "control.policy='rra.pt'", "it is an RRA policy")


def test_a_checkpoint_for_4_vehicles_is_refused_on_platoon8(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    torch.save(_actor("rra", "rra"), tmp_path / "rra4.pt")  # the default: 4 vehicles, 3 links
    overrides = ["scenario=platoon8", "control=cacc", "rra=policy", "rra.policy=rra4.pt"]
    _refused(
        tmp_path, capsys, overrides, "rra.policy='rra4.pt'", "built for 3 agents",
        "scenario.num_vehicles=8", "allowed: a policy for 7 agents",
    )  # fmt: skip


def test_a_plain_module_with_nan_actions_is_named_not_cast(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    torch.save(_Silent(float("nan")), tmp_path / "nan.pt")
    overrides = ["control=cacc", "rra=policy", "rra.policy=nan.pt"]
    line = _refused(tmp_path, capsys, overrides, "rra.policy='nan.pt'", "such as nan")
    assert "-9223372036854775808" not in line


@pytest.mark.parametrize(
    ("factory", "fragment"),
    [("fails_on_call_3", "raised RuntimeError: boom"), ("bad_on_call_3", "such as 16")],
)
def test_a_policy_that_fails_later_names_the_call_and_keeps_the_checkpoint(
    policies, capsys, factory, fragment
):
    argv = ["jocc", "hydra.run.dir=out", *SMOKE, "control=cacc", "rra=policy"]
    with pytest.raises(SystemExit) as info:
        cli.main([*argv, f"rra.policy=checked:{factory}"])
    assert info.value.code == 1
    line = _one_line_error(capsys, f"rra.policy='checked:{factory}'", "on call 3", fragment)
    checkpoint = policies / "out" / "checkpoints" / "last.pt"
    assert checkpoint.is_file() and f"the last checkpoint is {checkpoint}" in line
    assert "continue with: vdtn-marl jocc" in line and "resume=true" in line
    assert not (policies / "out" / "summary.json").exists()


def test_the_checked_policy_passes_through_and_counts_bound_calls():
    params = TwinParams()
    calls = []

    class Bindable:
        rowwise = True

        def __call__(self, observation):
            calls.append("call")
            return torch.zeros(observation.shape[:-1], dtype=torch.long)

        def bound(self):
            return lambda observation: torch.full(observation.shape[:-1], 99)

        def seed(self, seed):
            calls.append(seed)

    check = user_policy.OutputCheck.of("rra.policy", "mine:make", params)
    policy = user_policy.CheckedPolicy(Bindable(), check)
    assert policy.rowwise and not hasattr(policy, "bind")
    policy.seed(7)
    observation = torch.zeros(2, 3, 10)
    assert policy(observation).tolist() == [[0, 0, 0], [0, 0, 0]]
    with pytest.raises(PolicyError, match=r"'mine:make' failed on call 2 .*such as 99"):
        policy.bound()(observation)
    assert calls == [7, "call"]


def test_an_rra_action_out_of_range_late_in_a_run_names_the_policy():
    """Every call's values are checked, not only the first ones: call 1500 of an RRA policy
    (30 intervals of 50 subframes) returning 16 of 16 actions is named, with its call."""
    params = TwinParams()
    count = [0]

    def late(observation):
        count[0] += 1
        value = 16 if count[0] == 1500 else 0
        return torch.full(observation.shape[:-1], value, dtype=torch.long)

    check = user_policy.OutputCheck.of("rra.policy", "mine:late", params)
    policy = user_policy.CheckedPolicy(late, check)
    observation = torch.zeros(2, 3, 10)
    for _ in range(1499):
        policy(observation)
    with pytest.raises(PolicyError, match=r"'mine:late' failed on call 1500 .*such as 16"):
        policy(observation)
