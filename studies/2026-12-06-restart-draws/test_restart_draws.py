"""restart_draws.py: both orders restart the same scenarios at the same intervals,
the twin draws ahead where the batch allows it, and bad arguments are refused by name."""

import importlib.util
import json
from pathlib import Path

import pytest

from vdtn_marl.sim import link

SCRIPT = Path(__file__).resolve().parent / "restart_draws.py"


def _script():
    spec = importlib.util.spec_from_file_location("restart_draws", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_both_orders_are_timed_per_batch_and_repeat(tmp_path):
    out = tmp_path / "rd.json"
    batches = [4, link.DRAW_AHEAD_MIN_BATCH]
    argv = ["--batch-sizes", *map(str, batches), "--intervals", "2", "--repeats", "2"]
    assert _script().main([*argv, "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert [row["batch"] for row in data["rows"]] == batches
    assert [row["draw_ahead"] for row in data["rows"]] == [False, True]
    for row in data["rows"]:
        assert row["interval_first_ms"] > 0 and row["episodes_first_ms"] > 0
        assert row["ratio_min"] <= row["episodes_first_over_interval_first"] <= row["ratio_max"]
    assert len(data["runs"]) == len(batches) * 2 * 2
    assert all(len(run["seconds"]) == 2 for run in data["runs"])
    assert data["load_average_start"] and data["command"]


def test_the_orders_differ_in_their_numbers_not_in_who_restarts():
    script = _script()
    import torch

    from vdtn_marl.sim.twin import DigitalTwin

    seen = {}
    restart, reset = DigitalTwin.restart, DigitalTwin.reset

    def noted_restart(twin, mask):
        seen.setdefault("interval_first", []).append(mask.clone())
        return restart(twin, mask)

    def noted_reset(twin, seed=None, mask=None, begin=True):
        if mask is not None:
            seen.setdefault("episodes_first", []).append(mask.clone())
        return reset(twin, seed, mask, begin)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(DigitalTwin, "restart", noted_restart)
        mp.setattr(DigitalTwin, "reset", noted_reset)
        for order in script.ORDERS:
            script.time_restarts(order, 6, 3, 0.3)
    assert len(seen["interval_first"]) == len(seen["episodes_first"]) == 3
    for a, b in zip(seen["interval_first"], seen["episodes_first"], strict=True):
        assert torch.equal(a, b) and bool(a.any()) and not bool(a.all())


@pytest.mark.parametrize(
    "argv, name",
    [
        (["--batch-sizes", "1"], "--batch-sizes"),
        (["--intervals", "0"], "--intervals"),
        (["--fraction", "1.5"], "--fraction"),
    ],
)
def test_refuses_bad_arguments_by_name(argv, name, capsys):
    with pytest.raises(SystemExit):
        _script().parse_args(argv)
    assert name in capsys.readouterr().err
