"""benchmarks/throughput.py (the side-by-side harness against a peer's checkout and the
targets it prints) and profile_core.py: not timings (the figures come from
running the scripts) but what they run and write."""

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "throughput.py"

# A stand-in for a checkout of Liang et al.'s simulator: the names the harness calls, with
# the same settings layout; it checks the actions it is given.
FAKE_ENVIRONMENT = """
import numpy as np
class Environ:
    def __init__(self, down, up, left, right, width, height, n_veh, n_neighbor):
        self.n_Veh, self.n_neighbor, self.n_RB = n_veh, n_neighbor, n_veh
        self.time_fast, self.time_slow, self.demand_size = 0.001, 0.1, 100
        self.V2V_power_dB_List = [23, 15, 5, -100]
    def new_random_game(self):
        self.renew_channel()
    def renew_positions(self):
        pass
    def renew_neighbor(self):
        pass
    def renew_channel(self):
        pass
    def renew_channels_fastfading(self):
        pass
    def act_for_training(self, actions):
        assert actions.shape == (self.n_Veh, self.n_neighbor, 2)
        assert (actions[..., 0] < self.n_RB).all() and (actions[..., 1] < 4).all()
        return 0.0
    def Compute_Interference(self, actions):
        pass
"""
FAKE_TRAIN = """
import tensorflow  # never imported by the harness: only settings and get_state are read
up_lanes = [1.0]
down_lanes = [2.0]
left_lanes = [3.0]
right_lanes = [4.0]
width = 375
height = 649
n_veh = 4
n_neighbor = 1
def get_state(env, idx=(0, 0), ind_episode=1.0, epsi=0.02):
    return np.zeros(3)
"""


def _script(name: str = SCRIPT.name):
    """A fresh copy of the benchmark script ``benchmarks/<name>`` as a module."""
    spec = importlib.util.spec_from_file_location(f"_bench_{name[:-3]}", SCRIPT.parent / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_peer_path_without_the_simulator_is_refused_before_anything_runs(tmp_path, capsys):
    out = tmp_path / "t.json"
    with pytest.raises(SystemExit):
        _script().main(["--peer", "liang", str(tmp_path), "--out", str(out)])
    assert "--peer liang" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(SystemExit):
        _script().main(["--peer", "nobody", str(tmp_path)])
    assert "--peer 'nobody'" in capsys.readouterr().err


def test_peer_rows_are_timed_in_the_same_run_and_ratios_printed(tmp_path, capsys):
    checkout = tmp_path / "liang checkout"
    checkout.mkdir()
    (checkout / "Environment_marl.py").write_text(FAKE_ENVIRONMENT)
    (checkout / "main_marl_train.py").write_text(FAKE_TRAIN)
    module = _script()
    out = tmp_path / "t.json"
    args = ["--seconds", "0.05", "--repeats", "2", "--rows", "core", "--batch-sizes", "8"]
    assert (
        module.main([*args, "--no-cuda", "--peer", "liang", str(checkout), "--out", str(out)]) == 0
    )
    printed = capsys.readouterr().out
    assert "compared with Liang et al. Environ (4 vehicles" in printed
    data = json.loads(out.read_text())
    rows = {r["kind"] + str(r["batch_size"]) + r["backend"]: r for r in data["results"]}
    peer, core = rows["peer1numpy"], rows["core8torch"]
    # one subframe = one act_for_training, fast fading, interference, 4 observations
    assert peer["agent_steps_per_s"] == pytest.approx(4 * peer["subframes_per_s"])
    assert core["peer_ratio_of"] == "agent-subframe steps/s"
    ours, theirs = core["runs_agent_steps_per_s"], peer["runs_agent_steps_per_s"]
    ratios = sorted(a / b for a, b in zip(ours, theirs, strict=True))
    assert core["peer_ratio"] == pytest.approx((ratios[0] + ratios[1]) / 2)
    assert rows["core1numpy"]["peer_ratio_of"] == "subframes/s"
    # the user's path is not written into the results
    assert str(checkout) not in out.read_text()
    assert "PEER_CHECKOUT" in data["argv"]


@pytest.mark.slow
def test_profile_attributes_the_fading_draws_to_the_interval_start(tmp_path, capsys):
    out = tmp_path / "profile.json"
    module = _script("profile_core.py")
    module.LIMIT_VALUES = 1 << 16  # the machine's limits on small arrays: a quick test
    assert module.main(["--batch-sizes", "3", "--intervals", "2", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    (row,) = data["results"]
    assert row["interval_ms"] == pytest.approx(sum(row["per_interval_ms"].values()))
    # platoon4: W = 3LM + L² + M = 49 gains per scenario and subframe, two normals each
    assert row["draws_per_interval"] == 2 * 50 * 3 * 49
    start_ops = {o["op"]: o for o in row["ops"]["start"]}
    assert "aten::normal_" in start_ops
    assert "aten::normal_" not in {o["op"] for o in row["ops"]["subframes"]}
    assert data["limits"]["normal_per_s"] > 0
    assert "| 3 |" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        module.main(["--batch-sizes", "0"])
    assert "--batch-sizes" in capsys.readouterr().err


@pytest.mark.slow
def test_profile_with_draws_ahead_times_the_wait_and_leaves_the_draws_out_of_the_start(
    tmp_path, capsys
):
    from vdtn_marl.sim.link import DRAW_AHEAD_MIN_BATCH

    out = tmp_path / "profile.json"
    module = _script("profile_core.py")
    module.LIMIT_VALUES = 1 << 16
    argv = ["--batch-sizes", str(DRAW_AHEAD_MIN_BATCH), "--intervals", "2", "--draw-ahead"]
    assert module.main([*argv, "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    (row,) = data["results"]
    assert data["draw_ahead"] and row["draw_ahead"]
    assert set(row["per_interval_ms"]) == set(module.PHASES_AHEAD)
    assert row["interval_ms"] == pytest.approx(sum(row["per_interval_ms"].values()))
    # the normals are drawn on the second thread, so in no phase of the main thread
    assert "aten::normal_" not in {o["op"] for o in row["ops"]["start"]}
    assert "| wait ms |" in capsys.readouterr().out


def test_profile_writes_each_fading_law_to_its_own_file_by_default():
    module = _script("profile_core.py")
    assert module.parse_args([]).out.name == "profile_core.json"
    exponential = module.parse_args(["--fading-draws", "exponential"])
    assert exponential.out.name == "profile_core_exponential.json"
    ahead = module.parse_args(["--draw-ahead"])
    assert ahead.out.name == "profile_core_draw_ahead.json"
    assert module.parse_args(["--out", "x.json"]).out.name == "x.json"


def test_draw_ahead_rows_are_their_own_series(tmp_path):
    """``--draw-ahead on off``: one row each, recorded in the JSON; the targets judge each
    series on its own rows."""
    out = tmp_path / "t.json"
    module = _script()
    args = ["--seconds", "0.02", "--repeats", "1", "--rows", "core", "--no-cuda"]
    sizes = ["--batch-sizes", "128", "4096", "8192"]
    monkey_rows = []

    def fake_core(batch, device, backend, seconds, seed, traces, fading="normal", ahead=True):
        monkey_rows.append((batch, backend, ahead))
        rate = 1000.0 * (2.0 if ahead else 1.0)
        return {
            "name": f"B={batch}" + ("" if ahead else ", draw-ahead off"),
            "kind": "core", "batch_size": batch, "device": device, "backend": backend,
            "fading_draws": fading, "draw_ahead": ahead and batch >= 128,
            "draw_ahead_requested": ahead, "subframes_per_s": rate,
            "agent_steps_per_s": rate * batch * 3,
        }  # fmt: skip

    module.bench_core = fake_core
    assert module.main([*args, *sizes, "--draw-ahead", "on", "off", "--out", str(out)]) == 0
    assert (128, "torch", True) in monkey_rows and (128, "torch", False) in monkey_rows
    targets = json.loads(out.read_text())["targets"]
    named = [t["target"] for t in targets]
    assert sum("no lower at a larger B" in name for name in named) == 2
    assert any("draw-ahead off: agent-subframe" in name for name in named)
    steps = [t for t in targets if ">= 4,000,000" in t["target"]]
    assert sorted(t["value"] for t in steps) == [1000.0 * 4096 * 3, 2000.0 * 4096 * 3]
