"""benchmarks/throughput.py (the side-by-side harness against a peer's checkout and the
targets it prints), profile_core.py and compile_kernel.py: not timings (the figures come from
running the scripts) but what they run and write."""

import importlib.util
import json
from pathlib import Path

import pytest
import torch

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


def test_compile_benchmark_runs_the_twins_own_kernel_arithmetic():
    """The benchmark's eager run is the twin's link-major kernel: the same outcomes, subframe
    by subframe, as ``subframe_step`` on a twin built alike (so what it compiles is what the
    twin runs)."""
    import dataclasses

    import torch

    from vdtn_marl.sim import link
    from vdtn_marl.sim.twin import DigitalTwin

    module = _script("compile_kernel.py")
    batch = link.LINK_MAJOR_MIN_BATCH
    interval = module.Interval(batch, seed=4)
    got = interval.run(link.link_major_arithmetic)
    twin = DigitalTwin(batch_size=batch, seed=4, draw_ahead=False)
    for t in range(twin.subframes_per_interval):
        outcome = twin.step_subframe(interval.actions[t])
        v2i_rate, v2v_bits, power, delivered, pending = (x.T for x in got[t][:5])
        want = dataclasses.astuple(outcome)
        for a, b in zip((v2i_rate, v2v_bits, power, delivered, pending), want, strict=True):
            assert torch.equal(a, b), t


@pytest.mark.slow
def test_compile_benchmark_writes_a_row_per_batch(tmp_path, capsys):
    out = tmp_path / "ck.json"
    module = _script("compile_kernel.py")
    argv = ["--batch-sizes", "8", "--repeats", "1", "--intervals", "1", "--out", str(out)]
    assert module.main(argv) == 0
    (row,) = json.loads(out.read_text())["rows"]
    assert row["batch_size"] == 8
    if row["compiled"]:  # a machine with a C++ compiler
        assert isinstance(row["bit_identical"], bool)
        assert row["eager_us"] > 0 and row["compiled_us"] > 0
    else:  # where compilation fails the row says why
        assert row["error"]
    with pytest.raises(SystemExit):
        module.main(["--repeats", "0"])
    assert "--repeats" in capsys.readouterr().err


def _estimate(later_s, pi_tilde_s, iterations, control):
    return {
        "seconds": {"pi_tilde_learned": pi_tilde_s},
        "budgets": {"control_iterations": iterations},
        "later_iteration_s": later_s,
        "chosen_batches": {"control": control, "rra": 512},
    }


def _stages_file(path, later_s, pi_tilde_s, iterations=500, control=1024, paper=None):
    """A stage_throughput.py result; ``paper`` (later_s, pi_tilde_s) adds its estimate at the
    experiment=paper sizes (control batch 256)."""
    data = {
        "written": "2026-01-01",
        "estimate": _estimate(later_s, pi_tilde_s, iterations, control),
    }
    if paper is not None:
        data["estimate_paper"] = _estimate(*paper, iterations, 256)
    path.write_text(json.dumps(data))
    return path


def test_pi_tilde_budget_leaves_pi_tilde_what_the_other_stages_leave_of_30_minutes(tmp_path):
    module = _script("pi_tilde_budget.py")
    stages = _stages_file(tmp_path / "st.json", later_s=3000.0, pi_tilde_s=2000.0)
    # other stages 1000 s: π̃ gets (1800 − 1000) / 500 = 1.6 s per iteration, 2.5× less than 4 s
    slow = module.budget(stages, [{"batch_size": 1024, "eager_over_floor": 2.0}])
    assert slow["allowed_pi_tilde_s_per_iteration"] == pytest.approx(1.6)
    assert slow["needed_speedup"] == pytest.approx(2.5)
    assert slow["reachable_at_the_floor"] is False
    fast = module.budget(stages, [{"batch_size": 1024, "eager_over_floor": 3.0}])
    assert fast["reachable_at_the_floor"] is True
    other_size = module.budget(stages, [{"batch_size": 256, "eager_over_floor": 9.0}])
    assert "reachable_at_the_floor" not in other_size
    assert module.budget(tmp_path / "absent.json", [])["missing"]
    assert "paper" not in slow  # the file has no estimate at the paper sizes


def test_pi_tilde_budget_also_fits_the_paper_sizes_and_recomputes_from_stored_rows(tmp_path):
    module = _script("pi_tilde_budget.py")
    # fastest sizes: others 1000 s, π̃ may take 1.6 s (needs 2.5×); paper sizes: others
    # 1200 s, π̃ may take 1.2 s of its 6 s (needs 5×)
    stages = _stages_file(tmp_path / "st.json", 3000.0, 2000.0, paper=(4200.0, 3000.0))
    rows = [
        {"batch_size": 1024, "eager_over_floor": 3.0},
        {"batch_size": 256, "eager_over_floor": 4.0},
    ]
    fit = module.budget(stages, rows)
    assert fit["reachable_at_the_floor"] is True
    paper = fit["paper"]
    assert paper["chosen_control_batch"] == 256
    assert paper["allowed_pi_tilde_s_per_iteration"] == pytest.approx(1.2)
    assert paper["needed_speedup"] == pytest.approx(5.0)
    assert paper["floor_speedup_here"] == 4.0 and paper["reachable_at_the_floor"] is False
    # rows timed at other samples per iteration are not set against the budget
    other_frames = module.budget(stages, rows, frames=16)
    assert "floor_speedup_here" not in other_frames
    assert "floor_speedup_here" not in other_frames["paper"]
    # --budget-only rewrites the budget of a stored result, its rows untouched
    out = tmp_path / "pt.json"
    stored = {"frames_per_iteration": module.CONTROL_FRAMES, "rows": rows, "budget": {}}
    out.write_text(json.dumps(stored))
    assert module.main(["--budget-only", "--stages", str(stages), "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["rows"] == rows
    assert result["budget"]["paper"]["reachable_at_the_floor"] is False
    with pytest.raises(SystemExit, match="--out"):
        module.main(["--budget-only", "--out", str(tmp_path / "absent.json")])


def test_pi_tilde_budget_refuses_batch_sizes_that_do_not_divide_the_frames(capsys):
    module = _script("pi_tilde_budget.py")
    with pytest.raises(SystemExit):
        module.parse_args(["--batch-sizes", "3", "--frames", "16"])
    assert "--batch-sizes" in capsys.readouterr().err


@pytest.mark.slow
def test_pi_tilde_budget_times_eager_and_compiled_iterations_and_their_floor(tmp_path):
    module = _script("pi_tilde_budget.py")
    out = tmp_path / "pt.json"
    stages = _stages_file(tmp_path / "st.json", later_s=3000.0, pi_tilde_s=2000.0, control=8)
    argv = ["--batch-sizes", "8", "--frames", "16", "--repeats", "1", "--calls", "2"]
    assert module.main([*argv, "--stages", str(stages), "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    (row,) = result["rows"]
    assert row["batch_size"] == 8 and len(row["eager"]) == 1
    assert row["eager"][0]["intervals"] == 2
    # one radio run per interval at least (more where scenarios ended and were reset)
    assert row["radio_runs_per_interval"] >= 1.0
    assert 0 < row["update_s"] < row["floor_s"]
    assert row["floor_s"] == pytest.approx(sum(row["floor_parts_s"].values()))
    if row["compiled"]:  # a machine with a C++ compiler
        assert isinstance(row["policy_actions_bit_identical"], bool)
        assert row["compiled_s"] > 0 and row["kernel_compiled_us"] > 0
    else:
        assert row["error"]
    # not the paper's samples per iteration: no floor against the 30-minute budget
    assert "floor_speedup_here" not in result["budget"]


def test_rra_mode_shortcut_refuses_batch_sizes_that_do_not_divide_the_frames(capsys):
    module = _script("rra_mode_shortcut.py")
    with pytest.raises(SystemExit):
        module.parse_args(["--batch-sizes", "3", "--frames", "16"])
    assert "--batch-sizes" in capsys.readouterr().err


def test_rra_mode_shortcut_reference_arm_computes_the_probabilities_every_call():
    """The reference arm turns the shortcut and the binding off, and restores both."""
    from vdtn_marl.algos import networks
    from vdtn_marl.algos.ppo import ActorPolicy

    module = _script("rra_mode_shortcut.py")
    separated = torch.tensor([[0.0, 3.0, -1.0]])
    assert networks.mode_shortcut(separated) is not None
    shipped_bound = ActorPolicy.bound
    with module.reference():
        assert networks.mode_shortcut(separated) is None
        assert ActorPolicy.bound(policy := object()) is policy
    assert networks.mode_shortcut(separated) is not None
    assert ActorPolicy.bound is shipped_bound


@pytest.mark.slow
def test_rra_mode_shortcut_times_both_arms_on_the_same_iterations(tmp_path):
    module = _script("rra_mode_shortcut.py")
    out = tmp_path / "m.json"
    argv = ["--batch-sizes", "8", "--frames", "16", "--repeats", "2", "--out", str(out)]
    assert module.main(argv) == 0
    (row,) = json.loads(out.read_text())["rows"]
    assert len(row["reference"]) == len(row["shipped"]) == 2
    assert row["actions_bit_identical"] is True
    # the shipped arm's calls: 50 subframes of 2 intervals per iteration at least
    assert row["mode_calls"] >= 2 * 2 * 50 and 0 <= row["long_way_calls"] <= row["mode_calls"]
    assert row["reference_over_shipped"] > 0
