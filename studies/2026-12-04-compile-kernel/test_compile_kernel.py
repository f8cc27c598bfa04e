"""Tests of this study's script (not collected by the default test run):
``python -m pytest studies/2026-12-04-compile-kernel/test_compile_kernel.py``."""

import importlib.util
import json
from pathlib import Path

import pytest
import torch

HERE = Path(__file__).resolve().parent


def _script(name: str):
    spec = importlib.util.spec_from_file_location(f"_study_{Path(name).stem}", HERE / name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_compile_benchmark_runs_the_twins_own_kernel_arithmetic():
    """The benchmark's eager run is the twin's link-major kernel: the same outcomes, subframe
    by subframe, as ``subframe_step`` on a twin built alike (so what it compiles is what the
    twin runs)."""
    import dataclasses

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
