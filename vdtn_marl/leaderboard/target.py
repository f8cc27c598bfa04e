"""The benchmark's headline claim (``benchmark.target``), checked paired by seed.

On each of its scenarios, ``method`` (e.g. JOCC, κ1 = 0.5) against ``reference`` (e.g. DRRA),
on the seeds both have (every method of a scenario is evaluated on the same held-out scenarios
per seed):

- **error criteria** (``error_metrics``, e.g. mean |gap error| and |speed error|): the ratio of
  means R = x̄ / ȳ (x: the method's per-seed values, y: the reference's) must be at most
  ``max_error_ratio``. Its interval is **Fieller's**: the ratios ρ for which the Student-t
  interval of the per-seed paired differences dᵢ(ρ) = xᵢ − ρ·yᵢ contains 0, i.e. the roots of

      (x̄ − ρȳ)² = q · (s_xx − 2ρ s_xy + ρ² s_yy),   q = t²_{n−1, (1+c)/2} / n

  (s: sample variances and covariance, ddof = 1). It is bounded when ȳ² > q s_yy (the
  reference's mean is distinguishable from 0; always so for errors that stay away from 0),
  else unbounded and the criterion is not decided. It is the t interval of the paired
  differences translated into a ratio: ``max_error_ratio`` lies above the interval exactly
  when the t interval of xᵢ − bound·yᵢ lies below 0. Fieller is preferred to the delta
  method, whose symmetric interval ignores the skew of a ratio of noisy means at few seeds.
- **gain criterion** (``gain_metric``, e.g. V2I throughput per link): the paired difference
  x − y with its t interval (mean ± t_{n−1} s/√n) must lie above 0.

Verdicts: ``met`` (the whole interval on the right side of the bound), ``missed by X`` (the
whole interval on the wrong side; X is the point estimate's distance to the bound),
``not decided: n = k < min_seeds = m`` (too few paired seeds, whatever the interval), or
``not decided: the interval straddles the bound (b)`` (``... is unbounded ...`` for a Fieller
interval without bounds). The target is met when every criterion is met on every scenario,
missed when one is missed. The intervals are Student-t based whatever ``benchmark.interval``
is, at ``benchmark.confidence``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from vdtn_marl.experiment.config import BenchmarkConfig, BenchmarkTargetConfig
from vdtn_marl.experiment.metrics import METRICS
from vdtn_marl.leaderboard.stats import t_ci
from vdtn_marl.reporting.tables import is_finite

MET, MISSED, UNDECIDED = "met", "missed", "not decided"
INTERVAL_TEXT = (
    "error criteria: ratio of means method/reference over the paired seeds with Fieller's "
    "interval (the ratios ρ whose Student-t interval of the per-seed differences "
    "method − ρ·reference contains 0); gain criterion: paired difference method − reference "
    "with its Student-t interval (mean ± t(n−1) · s/√n)"
)


def fieller_ratio_ci(
    x: Sequence[float], y: Sequence[float], confidence: float = 0.95
) -> tuple[float | None, float | None, float | None]:
    """(x̄/ȳ, low, high) of paired samples: Fieller's interval of the ratio of means (see the
    module doc). ``low``/``high`` are None when the interval is unbounded (ȳ² ≤ q s_yy);
    the ratio is None when ȳ = 0. One pair, or pairs with x = R·y exactly, give a zero-width
    interval at R (as :func:`~vdtn_marl.leaderboard.stats.t_ci` does for one value)."""
    import numpy as np
    from scipy.stats import t

    xs, ys = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if xs.shape != ys.shape or xs.ndim != 1 or xs.size == 0:
        raise ValueError("x and y must be non-empty paired samples of the same length")
    n = xs.size
    mx, my = float(xs.mean()), float(ys.mean())
    if my == 0.0:
        return None, None, None
    ratio = mx / my
    if n == 1:
        return ratio, ratio, ratio
    cov = np.cov(np.stack([xs, ys]), ddof=1)
    sxx, sxy, syy = float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])
    q = float(t.ppf((1.0 + confidence) / 2.0, n - 1)) ** 2 / n
    a = my * my - q * syy
    half_b = mx * my - q * sxy
    c = mx * mx - q * sxx
    if a <= 0.0:
        return ratio, None, None
    # ratio itself always satisfies the inequality, so the discriminant is >= 0 up to rounding
    root = float(np.sqrt(max(half_b * half_b - a * c, 0.0)))
    low, high = (half_b - root) / a, (half_b + root) / a
    return ratio, min(low, ratio), max(high, ratio)


def _paired(
    rows: Sequence[Mapping[str, Any]], scenario: str, a: str, b: str, key: str
) -> tuple[list[int], list[float], list[float]]:
    """(seeds, a's values, b's values) of the seeds both methods have with finite values."""
    runs = {
        m: {r["seed"]: r.get(key) for r in rows if r["scenario"] == scenario and r["method"] == m}
        for m in (a, b)
    }
    seeds = sorted(
        s for s in set(runs[a]) & set(runs[b]) if is_finite(runs[a][s]) and is_finite(runs[b][s])
    )
    return seeds, [float(runs[a][s]) for s in seeds], [float(runs[b][s]) for s in seeds]


def _fmt(value: float) -> str:
    return f"{value:.3g}"


def _verdict(
    n: int, min_seeds: int, low: float | None, high: float | None, estimate: float | None,
    bound: float, upper: bool, unbounded: str,
) -> tuple[str, str]:  # fmt: skip
    """(status, verdict): ``upper`` bounds need the interval at or below ``bound`` (error
    ratios), lower bounds above it (gains)."""
    if n < min_seeds:
        return UNDECIDED, f"not decided: n = {n} < min_seeds = {min_seeds}"
    if estimate is None or low is None or high is None:
        return UNDECIDED, f"not decided: {unbounded}"
    if upper:
        if high <= bound:
            return MET, MET
        if low > bound:
            return MISSED, f"missed by {_fmt(estimate - bound)}"
    else:
        if low > bound:
            return MET, MET
        if high <= bound:
            return MISSED, f"missed by {_fmt(bound - estimate)}"
    return UNDECIDED, f"not decided: the interval straddles the bound ({_fmt(bound)})"


def _scenario_criteria(
    rows: Sequence[Mapping[str, Any]], target: BenchmarkTargetConfig, scenario: str,
    confidence: float, labels: Mapping[str, str],
) -> list[dict[str, Any]]:  # fmt: skip
    """The target's criteria on one scenario (see :func:`check_target`)."""
    criteria = []
    for key in target.error_metrics:
        seeds, x, y = _paired(rows, scenario, target.method, target.reference, key)
        ratio = low = high = None
        if seeds:
            ratio, low, high = fieller_ratio_ci(x, y, confidence)
        unbounded = (
            f"the mean of {target.reference} is 0, the ratio is undefined"
            if seeds and ratio is None
            else f"the interval is unbounded (the mean of {target.reference} is not "
            f"distinguishable from 0 at n = {len(seeds)})"
        )
        status, verdict = _verdict(
            len(seeds), target.min_seeds, low, high, ratio, target.max_error_ratio, True,
            unbounded,
        )  # fmt: skip
        criteria.append(
            {
                "scenario": scenario,
                "metric": key,
                "label": labels.get(key, key),
                "kind": "error_ratio",
                "statistic": f"mean {target.method} / mean {target.reference}",
                "interval": "fieller",
                "n": len(seeds),
                "seeds": seeds,
                "mean_method": sum(x) / len(x) if x else None,
                "mean_reference": sum(y) / len(y) if y else None,
                "estimate": ratio,
                "ci_low": low,
                "ci_high": high,
                "bound": float(target.max_error_ratio),
                "requirement": f"ratio ≤ {_fmt(target.max_error_ratio)}",
                "status": status,
                "verdict": verdict,
            }
        )
    if target.gain_metric is not None:
        key = target.gain_metric
        seeds, x, y = _paired(rows, scenario, target.method, target.reference, key)
        mean = low = high = None
        if seeds:
            mean, low, high = t_ci([a - b for a, b in zip(x, y, strict=True)], confidence)
        status, verdict = _verdict(
            len(seeds), target.min_seeds, low, high, mean, 0.0, False, "no paired seed"
        )
        criteria.append(
            {
                "scenario": scenario,
                "metric": key,
                "label": labels.get(key, key),
                "kind": "gain_difference",
                "statistic": f"mean of {target.method} − {target.reference} per seed",
                "interval": "t",
                "n": len(seeds),
                "seeds": seeds,
                "mean_method": sum(x) / len(x) if x else None,
                "mean_reference": sum(y) / len(y) if y else None,
                "estimate": mean,
                "ci_low": low,
                "ci_high": high,
                "bound": 0.0,
                "requirement": "difference > 0 (whole interval)",
                "status": status,
                "verdict": verdict,
            }
        )
    return criteria


def check_target(
    rows: Sequence[Mapping[str, Any]], benchmark: BenchmarkConfig
) -> dict[str, Any] | None:
    """The target report (None without ``benchmark.target``): the definition, one entry per
    scenario and criterion (scenario, metric, kind, n, seeds, both means, estimate with
    ``ci_low``/``ci_high``, bound, status, verdict) and the overall status."""
    target = benchmark.target
    if target is None:
        return None
    if isinstance(target, Mapping):
        target = BenchmarkTargetConfig(**dict(target))
    labels = {m.key: m.label.replace("\\", "") for m in METRICS}
    confidence = benchmark.confidence
    criteria = [
        c
        for scenario in target.scenarios
        for c in _scenario_criteria(rows, target, scenario, confidence, labels)
    ]
    statuses = {c["status"] for c in criteria}
    overall = MISSED if MISSED in statuses else MET if statuses == {MET} else UNDECIDED
    return {
        "scenarios": list(target.scenarios),
        "method": target.method,
        "reference": target.reference,
        "max_error_ratio": float(target.max_error_ratio),
        "min_seeds": int(target.min_seeds),
        "confidence": confidence,
        "interval": INTERVAL_TEXT,
        "criteria": criteria,
        "status": overall,
    }


def _num(value: Any, signed: bool = False) -> str:
    if not is_finite(value):
        return "–"
    return f"{float(value):+.4g}" if signed else f"{float(value):.4g}"


def target_markdown(result: Mapping[str, Any]) -> list[str]:
    """The report's target section (lines of LEADERBOARD.md)."""
    m, r = result["method"], result["reference"]
    level = f"{result['confidence']:.0%}"
    lines = [
        f"## Target: {m} against {r} on {', '.join(result['scenarios'])}",
        "",
        f"Paired by seed (the seeds both have), each criterion decided from "
        f"{result['min_seeds']} paired seeds on: every error metric's ratio of means "
        f"{m}/{r} at most {_fmt(result['max_error_ratio'])} (the whole {level} Fieller "
        f"interval: the ratios ρ whose Student-t interval of the per-seed differences "
        f"{m} − ρ·{r} contains 0), and the gain metric above {r}'s (the whole {level} "
        "Student-t interval of the paired differences above 0).",
        "",
        f"| scenario | criterion | n | {m} | {r} | estimate [{level} CI] | requirement | verdict |",
        "|---|---|--:|--:|--:|--:|---|---|",
    ]
    for c in result["criteria"]:
        signed = c["kind"] == "gain_difference"
        what = "ratio" if c["kind"] == "error_ratio" else "difference"
        label = c["label"].replace("|", "\\|")  # a markdown table cell
        if c["estimate"] is None:
            estimate = "–"
        elif c["ci_low"] is None:
            estimate = f"{_num(c['estimate'], signed)} [unbounded]"
        else:
            estimate = (
                f"{_num(c['estimate'], signed)} "
                f"[{_num(c['ci_low'], signed)}, {_num(c['ci_high'], signed)}]"
            )
        lines.append(
            f"| {c['scenario']} | {label}: {what} | {c['n']} | {_num(c['mean_method'])} | "
            f"{_num(c['mean_reference'])} | {estimate} | {c['requirement']} | {c['verdict']} |"
        )
    lines += ["", f"**Target {result['status']}.**"]
    return lines
