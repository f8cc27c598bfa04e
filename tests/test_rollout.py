"""The Quick-start rollout runs and reports finite, physically plausible numbers."""

import math

from vdtn_marl.rollout import main, run


def test_rollout_reports_every_metric():
    results = run(intervals=3, seed=0, kappa1=0.5, device="cpu")
    assert results["control intervals"] == 3
    assert 0.5 < results["V2I throughput per link (Mbps)"] < 5.0
    assert 0.0 <= results["CAM delivery rate"] <= 1.0
    assert results["mean IVoI per interval"] <= 1e-6 or math.isnan(
        results["mean IVoI per interval"]
    )


def test_rollout_cli_prints_table(capsys):
    assert main(["--intervals", "2", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "V2I throughput per link (Mbps)" in out and "CAM delivery rate" in out
