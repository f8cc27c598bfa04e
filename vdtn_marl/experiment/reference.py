"""The reference check: is π* the optimum the IVoI and the EVoI are measured against?

IVoI is an advantage under π* and EVoI = J̃ − J* compares the acting system with π* on perfect
observations, so both mean what they claim only where π* is at least as good as every policy
that could stand in for it. Every ``evaluate`` stage scores π* against these comparators on
the same held-out scenarios (paired by scenario, discounted control return per follower):

=============  =================================================================================
comparator     what it is
=============  =================================================================================
``start``      π*'s own policy before its first PPO update (the causal-MPC imitation of
               ``control.warm_start=causal_mpc``, or the CACC prior), perfect observations
``causal_mpc`` the causal MPC (no preview of the leader's future), perfect observations; it
               plans every follower's command jointly from the twin's true state (the leader's
               acceleration and every vehicle's state), so it knows more than one follower's
               observation, which is all π* reads
``cacc``       the linear CACC, perfect observations
``acting``     the acting system (π̃ or a control baseline under the run's RRA policy) on
               impaired observations: J* − J̃ = −EVoI
=============  =================================================================================

For each comparator c the row holds ``pi_star_minus_<c>`` = mean over scenarios of J* − J_c and
its Student-t 95 % interval (``_ci_low``, ``_ci_high``). The check fails (``reference_ok`` false,
``reference_problems`` says why, and the run log, the terminal and the leaderboard report say so)
where

- π* ends worse than its start (the mean difference is below 0: fine-tuning made it worse), or
- the interval of J* − J_c lies below 0 for another comparator (for ``acting``: EVoI's interval
  lies above 0).

The ``acting`` comparator is left out where the acting control is the MPC oracle, which knows
the leader's future and may beat any causal π* on perfect observations by right.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import torch

from vdtn_marl.voi import mean_ci

#: The comparators, in the order the row lists them (see the module doc).
REFERENCE_COMPARATORS = ("start", "causal_mpc", "cacc", "acting")
#: How the terminal and the leaderboard report introduce a failed check.
REFERENCE_WARNING = "the reference check failed (π* is not the optimum IVoI and EVoI assume): "
#: What each comparator is, for the problems' text.
COMPARATOR_TEXT = {
    "start": "its start (the policy before its first PPO update)",
    "causal_mpc": "the causal MPC",
    "cacc": "the CACC",
    "acting": "the acting system on impaired observations (EVoI's interval lies above 0)",
}


def reference_check(
    optimal_returns: torch.Tensor, comparators: Mapping[str, torch.Tensor | None]
) -> dict[str, Any]:
    """The check's row entries (see the module doc) from π*'s per-scenario returns [E] and
    each comparator's [E] (None: not scored in this run, left out)."""
    unknown = set(comparators) - set(REFERENCE_COMPARATORS)
    if unknown:
        raise ValueError(
            f"comparators {sorted(unknown)} are not among {', '.join(REFERENCE_COMPARATORS)}"
        )
    optimal = torch.as_tensor(optimal_returns, dtype=torch.float64).reshape(-1)
    row: dict[str, Any] = {}
    problems = []
    for name in REFERENCE_COMPARATORS:
        returns = comparators.get(name)
        if returns is None:
            continue
        other = torch.as_tensor(returns, dtype=torch.float64).reshape(-1)
        if other.shape != optimal.shape:
            raise ValueError(
                f"comparator {name!r} has {other.numel()} scenarios, π* {optimal.numel()}: "
                "the check pairs them"
            )
        mean, low, high = mean_ci(optimal - other)
        key = f"pi_star_minus_{name}"
        row.update({key: mean, f"{key}_ci_low": low, f"{key}_ci_high": high})
        worse = mean < 0.0 if name == "start" else high < 0.0
        if worse:
            problems.append(
                f"π* is worse than {COMPARATOR_TEXT[name]}: J* − J = {mean:.4g} "
                f"[{low:.4g}, {high:.4g}]"
            )
    row["reference_ok"] = not problems
    row["reference_problems"] = "; ".join(problems)
    return row


def row_problems(row: Mapping[str, Any]) -> str:
    """Why a run's summary (or a leaderboard row) fails the check, '' where it passes.

    A summary written before the check existed has no ``reference_ok``: there the EVoI's
    interval (above 0: the acting system beats π*) is all it can say."""
    ok = row.get("reference_ok")
    if ok is not None and ok == ok:  # NaN: a row without the column in a mixed table
        if isinstance(ok, str):
            ok = ok.strip().lower() == "true"
        return "" if ok else str(row.get("reference_problems") or "failed")
    low = row.get("evoi_ci_low")
    try:
        low = float(low)
    except (TypeError, ValueError):
        return ""
    if low > 0.0 and row.get("control") != "oracle":
        return f"EVoI's interval lies above 0 (its low end {low:.4g}): π* is beaten"
    return ""


def scenarios_memo(position: dict[str, Any], scenarios: Mapping[str, Any]) -> dict[str, Any]:
    """The comparators' scores kept in a run's ``position`` (so in its checkpoints) for the
    evaluation ``scenarios`` (a plain description of them): emptied where they were scored
    on other scenarios (an ``eval`` with other evaluation settings)."""
    memo = position.get("reference")
    if not isinstance(memo, dict) or memo.get("scenarios") != dict(scenarios):
        memo = position["reference"] = {"scenarios": dict(scenarios)}
    return memo


def scored_once(memo: dict[str, Any], name: str, score: Callable[[], torch.Tensor]) -> torch.Tensor:
    """``memo[name]`` as a tensor, computed with ``score()`` and stored as a list the first
    time (comparators that do not change during a run are scored once)."""
    if name not in memo:
        memo[name] = [float(x) for x in score()]
    return torch.tensor(memo[name], dtype=torch.float64)
