"""The reference check: π* against its start, the causal MPC, the CACC and the acting system."""

from __future__ import annotations

import json

import pytest
import torch

from vdtn_marl.experiment.reference import (
    REFERENCE_COMPARATORS,
    reference_check,
    row_problems,
    scored_once,
)
from vdtn_marl.leaderboard.report import _reference_lines, reference_failures

OPTIMAL = torch.tensor([-1.0, -1.2, -0.8, -1.1, -0.9])


def test_every_comparator_no_worse_than_pi_star_passes_and_reports_paired_differences():
    worse = {name: OPTIMAL - 0.1 for name in REFERENCE_COMPARATORS}
    row = reference_check(OPTIMAL, worse)
    assert row["reference_ok"] is True and row["reference_problems"] == ""
    for name in REFERENCE_COMPARATORS:
        assert row[f"pi_star_minus_{name}"] == pytest.approx(0.1)
        # constant differences: a zero-width interval around the mean
        assert row[f"pi_star_minus_{name}_ci_low"] == pytest.approx(0.1)


def test_a_pi_star_worse_than_its_start_fails_even_within_the_noise():
    start = OPTIMAL + torch.tensor([0.3, -0.3, 0.2, -0.2, 0.01])  # mean J* − J = −0.002
    row = reference_check(OPTIMAL, {"start": start})
    assert row["pi_star_minus_start_ci_low"] < 0 < row["pi_star_minus_start_ci_high"]
    assert row["reference_ok"] is False and "its start" in row["reference_problems"]


@pytest.mark.parametrize("name", [n for n in REFERENCE_COMPARATORS if n != "start"])
def test_other_comparators_fail_only_when_the_interval_lies_below_zero(name):
    noisy = OPTIMAL + torch.tensor([0.3, -0.3, 0.2, -0.2, 0.01])
    assert reference_check(OPTIMAL, {name: noisy})["reference_ok"] is True
    better = OPTIMAL + torch.tensor([0.2, 0.25, 0.3, 0.2, 0.22])
    row = reference_check(OPTIMAL, {name: better})
    assert row[f"pi_star_minus_{name}_ci_high"] < 0
    assert row["reference_ok"] is False and "π* is worse than" in row["reference_problems"]


def test_the_acting_comparator_is_minus_evoi():
    from vdtn_marl.voi import expected_voi

    acting = OPTIMAL + torch.tensor([0.2, -0.1, 0.05, 0.3, -0.2])
    row = reference_check(OPTIMAL, {"acting": acting})
    evoi, low, high = expected_voi(acting, OPTIMAL)
    assert row["pi_star_minus_acting"] == pytest.approx(-evoi)
    assert (row["pi_star_minus_acting_ci_low"], row["pi_star_minus_acting_ci_high"]) == (
        pytest.approx(-high),
        pytest.approx(-low),
    )


def test_unpaired_or_unknown_comparators_are_refused():
    with pytest.raises(ValueError, match="cacc"):
        reference_check(OPTIMAL, {"cacc": OPTIMAL[:3]})
    with pytest.raises(ValueError, match="greedy"):
        reference_check(OPTIMAL, {"greedy": OPTIMAL})


def test_scored_once_scores_a_comparator_once_and_keeps_it_as_plain_floats():
    memo, calls = {}, []

    def score():
        calls.append(1)
        return OPTIMAL

    for _ in range(3):
        assert torch.equal(scored_once(memo, "cacc", score), OPTIMAL.double())
    assert len(calls) == 1 and all(isinstance(x, float) for x in memo["cacc"])


def _row(**values):
    return {"scenario": "platoon4", "method": "drra", "seed": 0, "control": "learned", **values}


@pytest.mark.parametrize(
    ("row", "fails"),
    [
        (_row(reference_ok=True, evoi_ci_low=0.5), False),  # the check's own verdict wins
        (_row(reference_ok=False, reference_problems="π* is worse than the CACC"), True),
        (_row(reference_ok="False", reference_problems="x"), True),  # read back from a CSV
        (_row(evoi_ci_low=0.3), True),  # a summary written before the check: EVoI's interval
        (_row(evoi_ci_low=-0.3), False),
        (_row(evoi_ci_low=0.3, control="oracle"), False),  # the oracle may beat π* by right
        (_row(reference_ok=float("nan"), evoi_ci_low=0.3), True),  # a mixed table's gap
    ],
)
def test_row_problems_reads_the_check_or_the_evoi_interval(row, fails):
    assert bool(row_problems(row)) is fails


def test_the_leaderboard_report_lists_the_runs_that_fail():
    rows = [
        _row(seed=0, reference_ok=True),
        _row(seed=1, reference_ok=False, reference_problems="π* is worse than its start"),
        _row(seed=2, evoi_ci_low=0.2),
    ]
    failures = reference_failures(rows)
    assert [f["seed"] for f in failures] == [1, 2]
    text = "\n".join(_reference_lines(failures, len(rows)))
    assert "FAILED in 2 of 3 runs" in text and "| platoon4 | drra | 1 |" in text
    assert "passed in all 1 runs" in "\n".join(_reference_lines([], 1))


@pytest.mark.slow
def test_a_run_checks_its_reference_and_the_check_fires_on_a_broken_pi_star(tmp_path, capsys):
    """A smoke JOCC run scores π* against every comparator; with π*'s actor then broken (full
    braking whatever it sees) the same loop's next evaluation fails the check, and the CLI's
    warning names it."""
    from vdtn_marl import cli
    from vdtn_marl.experiment.jocc import JointOptimisation

    run_dir = tmp_path / "run"
    assert cli.main(["jocc", f"hydra.run.dir={run_dir}", "experiment=smoke", "progress=false"]) == 0
    summary = json.loads((run_dir / "summary.json").read_text())
    for name in REFERENCE_COMPARATORS:
        assert f"pi_star_minus_{name}_ci_high" in summary, name
    start_ok = summary["pi_star_minus_start"] >= 0
    others_ok = all(summary[f"pi_star_minus_{n}_ci_high"] >= 0 for n in REFERENCE_COMPARATORS[1:])
    assert summary["reference_ok"] is (start_ok and others_ok)
    printed = capsys.readouterr().err
    assert ("reference check failed" in printed) is not summary["reference_ok"]

    loop = JointOptimisation.from_checkpoint(run_dir / "checkpoints" / "last.pt", tmp_path / "e")
    assert {"start", "causal_mpc", "cacc"} <= set(loop.reference_memo())  # from the checkpoint
    with torch.no_grad():
        weights = dict(loop.pi_star.actor.named_parameters())
        *_, last_weight, last_bias = (w for n, w in weights.items() if ".body.params." in n)
        last_weight.zero_()
        last_bias.fill_(-10.0)  # the residual's output: full braking beside the prior
    row = loop.evaluate()
    assert row["reference_ok"] is False
    for text in ("its start", "the CACC", "the causal MPC"):
        assert text in row["reference_problems"], text
