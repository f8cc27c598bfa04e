"""Policies of the user's own (``rra=policy rra.policy=...``, ``control=policy
control.policy=...``): by import path, as a TorchRL module checkpoint, in `jocc` and `eval`, and
every kind of bad input as one line before anything is written.

The end-to-end runs use smoke budgets; a policy by import path that builds a baseline must give
the run of that baseline by name bit for bit (the slot changes nothing but who acts).
BenchMARL checkpoints are tested on the BenchMARL stack (tests/integrations/test_benchmarl.py).
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import pytest
import torch

from vdtn_marl import cli
from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment import user_policy
from vdtn_marl.sim.params import TwinParams

pytestmark = pytest.mark.filterwarnings("ignore:(?s).*validated against ConfigStore schema")

#: what a smoke run is compared on: every evaluation metric of the summary
COMPARED = (
    "control_cost", "gap_error_abs_m", "speed_error_abs_mps", "cam_delivery_rate",
    "v2i_throughput_mbps_per_link", "aoi_ms_mean", "collision_rate", "evoi",
    "optimal_control_cost", "ivoi_sum",
)  # fmt: skip
SMOKE = ("experiment=smoke", "progress=false")

POLICIES = '''
import torch

from vdtn_marl.policies import CACCController, make_rra_baseline

CALLS = []


def greedy(params, seed):
    """The greedy baseline, built as the registry builds it."""
    return make_rra_baseline("greedy", params, seed)


def cacc(params, seed):
    return CACCController(params.platoon)


class AlwaysOff:
    """Every link silent: the last power level of every sub-channel."""

    def __init__(self, params):
        self.off = params.radio.num_power_levels - 1

    def __call__(self, observation):
        CALLS.append(tuple(observation.shape))
        return torch.full(observation.shape[:-1], self.off, dtype=torch.long)


def always_off(params, seed):
    return AlwaysOff(params)


def broken(params, seed):
    raise RuntimeError("no weights here")


NOT_CALLABLE = 3
'''


@pytest.fixture
def policies(tmp_path, monkeypatch):
    """A module of policies, ``mypolicies.py``, in the working directory (tmp_path)."""
    (tmp_path / "mypolicies.py").write_text(textwrap.dedent(POLICIES))
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    return tmp_path


def _jocc(run_dir: str, *overrides: str) -> dict:
    assert cli.main(["jocc", f"hydra.run.dir={run_dir}", *SMOKE, *overrides]) == 0
    return json.loads((Path(run_dir) / "summary.json").read_text())


def _same_results(a: dict, b: dict) -> None:
    for key in COMPARED:
        assert a[key] == b[key] or (a[key] != a[key] and b[key] != b[key]), key


@pytest.mark.slow
def test_an_rra_policy_by_import_path_runs_as_the_baseline_it_builds(policies):
    by_name = _jocc("greedy", "control=cacc", "rra=greedy")
    by_path = _jocc("mine", "control=cacc", "rra=policy", "rra.policy=mypolicies:greedy")
    assert by_path["rra"] == "policy" and by_path["config"]["rra"]["policy"] == "mypolicies:greedy"
    assert "rra" not in by_path["trainer_iterations"]  # nothing trained on the RRA side
    _same_results(by_path, by_name)
    by_file = _jocc("file", "control=cacc", "rra=policy", "rra.policy=mypolicies.py:greedy")
    _same_results(by_file, by_name)


@pytest.mark.slow
def test_a_control_policy_by_import_path_runs_as_the_baseline_it_builds(policies):
    by_name = _jocc("cacc", "control=cacc", "rra=greedy")
    by_path = _jocc(
        "mine", "control=policy", "control.policy=mypolicies:cacc", "control.warm_start=none",
        "rra=greedy",
    )  # fmt: skip
    assert by_path["control"] == "policy" and by_path["trainer_iterations"]["pi_tilde"] == 0
    _same_results(by_path, by_name)


@pytest.mark.slow
def test_the_users_rra_policy_is_what_acts(policies):
    summary = _jocc("off", "control=cacc", "rra=policy", "rra.policy=mypolicies:always_off")
    assert summary["cam_delivery_rate"] == 0.0  # every link silent: no CAM is delivered
    import mypolicies  # the module the run imported (cwd on the path)

    assert mypolicies.CALLS and all(shape[-2] == 3 for shape in mypolicies.CALLS)  # [B, L, D]


def _rra_actor(params: TwinParams):
    from vdtn_marl.algos.networks import make_actor
    from vdtn_marl.envs.torchrl import VDTNTorchRLEnv

    env = VDTNTorchRLEnv("rra", batch_size=2, seed=0)
    return env, make_actor(env.full_observation_spec, env.full_action_spec, "rra")


def test_a_torchrl_module_checkpoint_acts_as_the_module(tmp_path):
    from vdtn_marl.algos.ppo import ActorPolicy

    params = TwinParams()
    env, actor = _rra_actor(params)
    torch.save(actor, tmp_path / "actor.pt")
    loaded = user_policy.load_policy("rra.policy", str(tmp_path / "actor.pt"), params, seed=0)
    observation = env.reset()["rra", "observation"]
    expected = ActorPolicy(actor, "rra")(observation)
    assert torch.equal(loaded(observation), expected)
    assert expected.dtype == torch.long and expected.shape == observation.shape[:-1]


class _Silent(torch.nn.Module):
    """A plain module: observations [..., L, D] → the 'off' action of every link."""

    def __init__(self, off: int):
        super().__init__()
        self.off = off

    def forward(self, observation):
        return torch.full(observation.shape[:-1], float(self.off))


def test_a_plain_module_checkpoint_gives_integer_actions(tmp_path):
    params = TwinParams()
    torch.save(_Silent(params.radio.num_power_levels - 1), tmp_path / "silent.pt")
    policy = user_policy.load_policy("rra.policy", str(tmp_path / "silent.pt"), params, 0)
    actions = policy(torch.zeros(4, 3, 10))
    assert actions.dtype == torch.long and actions.shape == (4, 3)
    assert torch.all(actions == params.radio.num_power_levels - 1)


@pytest.mark.slow
def test_a_module_checkpoint_runs_in_jocc(tmp_path, monkeypatch):
    params = TwinParams()
    torch.save(_Silent(params.radio.num_power_levels - 1), tmp_path / "silent.pt")
    monkeypatch.chdir(tmp_path)
    summary = _jocc("run", "control=cacc", "rra=policy", f"rra.policy={tmp_path / 'silent.pt'}")
    assert summary["cam_delivery_rate"] == 0.0


def test_eval_scores_a_checkpoints_control_with_the_users_rra_policy(policies):
    from tests.test_cli_eval import _make_run

    _make_run(policies / "run", list(SMOKE), "jocc", ("pi_star", "pi_tilde"))
    argv = ["eval", "checkpoint=run", "hydra.run.dir=ev", "progress=false"]
    assert cli.main([*argv, "rra=policy", "rra.policy=mypolicies:always_off"]) == 0
    summary = json.loads((policies / "ev" / "summary.json").read_text())
    assert summary["rra"] == "policy" and summary["cam_delivery_rate"] == 0.0
    assert summary["warnings"] == []


def _one_line_error(capsys, *fragments: str) -> str:
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    for fragment in fragments:
        assert fragment in lines[0], err
    return lines[0]


@pytest.mark.parametrize(
    ("overrides", "fragments"),
    [
        (["rra=policy"], ["rra.policy=None"]),
        (["rra=policy", "rra.policy=nosuchmodule:make"], ["rra.policy=", "nosuchmodule"]),
        (["rra=policy", "rra.policy=mypolicies:nothing"], ["rra.policy=", "no attribute"]),
        (["rra=policy", "rra.policy=mypolicies:NOT_CALLABLE"], ["rra.policy=", "not a callable"]),
        (["rra=policy", "rra.policy=missing.py:make"], ["rra.policy=", "does not exist"]),
        (["rra=policy", "rra.policy=missing.pt"], ["rra.policy=", "neither an existing file"]),
        (["rra=greedy", "rra.policy=mypolicies:greedy"], ["rra.policy=", "needs rra=policy"]),
        (["control=policy"], ["control.policy=None"]),
        (["control=learned", "control.policy=mypolicies:cacc"], ["needs control=policy"]),
        (["rra=policy", "rra.policy=mypolicies:broken"], ["rra.policy=", "no weights here"]),
    ],
)
def test_bad_policies_are_one_line_before_anything_is_written(
    policies, capsys, overrides, fragments
):
    assert cli.main(["jocc", "hydra.run.dir=out", *SMOKE, *overrides]) == 2
    _one_line_error(capsys, *fragments)
    assert not (policies / "out" / "summary.json").exists()
    assert not (policies / "out" / "checkpoints").exists()


def test_checkpoints_that_are_not_policies_are_one_line(tmp_path, monkeypatch, capsys):
    from tests.test_cli_eval import _make_run

    monkeypatch.chdir(tmp_path)
    torch.save(_Silent(3).state_dict() | {"w": torch.zeros(2)}, tmp_path / "weights.pt")
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    _make_run(tmp_path / "run", list(SMOKE), "jocc", ("pi_star",))
    cases = {
        "weights.pt": "state_dict",
        "junk.pt": "cannot be read",
        "run/checkpoints/last.pt": "vdtn-marl run checkpoint",
    }
    for path, fragment in cases.items():
        argv = ["jocc", "hydra.run.dir=out", *SMOKE, "rra=policy", f"rra.policy={path}"]
        assert cli.main(argv) == 2, path
        _one_line_error(capsys, f"rra.policy='{path}'", fragment)
    assert not (tmp_path / "out").exists()


def test_import_paths_and_files_are_told_apart():
    assert user_policy.is_import_path("pkg.mod:make")
    assert user_policy.is_import_path("dir/my.py:make_policy")
    assert user_policy.is_import_path("pkg.mod:Factory.build")
    assert not user_policy.is_import_path("runs/actor.pt")
    assert not user_policy.is_import_path("C:actor.pt")
    assert not user_policy.is_import_path("pkg.mod:")
    with pytest.raises(ConfigError, match="rra.policy"):
        user_policy.check_policy("rra.policy", "")
    with pytest.raises(ConfigError, match="not one of"):
        user_policy.check_policy("vehicle.policy", "pkg:make")


@pytest.mark.slow
def test_bench_scores_a_submission_beside_the_benchmarks_methods(policies):
    submission = "+submissions.mine=['rra=policy','rra.policy=mypolicies:always_off']"
    cells = "cells=[platoon4/mine/seed0,platoon4/greedy/seed0]"
    argv = ["bench", "benchmark=smoke", "out_dir=lb", "progress=false", submission, cells]
    assert cli.main(argv) == 0
    report = json.loads((policies / "lb" / "leaderboard.json").read_text())
    stats = report["statistics"]["platoon4"]
    assert set(stats) == {"greedy", "mine"}
    assert (
        stats["mine"]["cam_delivery_rate"]["mean"]
        == 0.0
        < stats["greedy"]["cam_delivery_rate"]["mean"]
    )
    runs = {(r["method"], r["seed"]) for r in report["runs"]}
    assert runs == {("greedy", 0), ("mine", 0)}
    # the same held-out scenarios: both were evaluated with the run seed's evaluation seed
    configs = [
        json.loads((policies / "lb" / "platoon4" / m / "seed0" / "summary.json").read_text())
        for m in ("greedy", "mine")
    ]
    assert configs[0]["config"]["experiment"] == configs[1]["config"]["experiment"]
    assert configs[0]["config"]["scenario"] == configs[1]["config"]["scenario"]
    assert "(submission)" in (policies / "lb" / "LEADERBOARD.md").read_text()
    manifest = json.loads((policies / "lb" / "benchmark.json").read_text())
    assert "mine" not in manifest["benchmark"]["methods"] and "mine" in manifest["submissions"]


@pytest.mark.slow
def test_a_control_actor_checkpoint_drives_the_followers(tmp_path, monkeypatch):
    from vdtn_marl.algos.networks import make_actor
    from vdtn_marl.algos.ppo import ActorPolicy
    from vdtn_marl.envs.torchrl import VDTNTorchRLEnv

    env = VDTNTorchRLEnv("control_impaired", batch_size=2, seed=0)
    actor = make_actor(env.full_observation_spec, env.full_action_spec, "vehicle")
    torch.save(actor, tmp_path / "control.pt")
    policy = user_policy.load_policy(
        "control.policy", str(tmp_path / "control.pt"), TwinParams(), 0
    )
    observation = env.reset()["vehicle", "observation"]
    commands = policy(observation)
    assert torch.equal(commands, ActorPolicy(actor, "vehicle")(observation))
    assert commands.dtype == torch.float32 and commands.shape == observation.shape[:-1]
    monkeypatch.chdir(tmp_path)
    summary = _jocc(
        "run", "control=policy", f"control.policy={tmp_path / 'control.pt'}", "rra=greedy"
    )
    assert summary["control"] == "policy" and summary["trainer_iterations"]["pi_tilde"] == 0
