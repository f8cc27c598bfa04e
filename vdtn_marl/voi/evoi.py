"""EVoI and confidence intervals of per-scenario means (docs/model.md §5)."""

from __future__ import annotations

import torch


def mean_ci(samples: torch.Tensor, confidence: float = 0.95) -> tuple[float, float, float]:
    """Mean and Student-t confidence interval (low, high) of i.i.d. per-scenario samples."""
    from scipy import stats

    x = torch.as_tensor(samples, dtype=torch.float64).reshape(-1)
    n = x.numel()
    if n == 0:
        raise ValueError("mean_ci needs at least one sample")
    mean = float(x.mean())
    if n == 1:
        return mean, float("nan"), float("nan")
    half = float(stats.t.ppf(0.5 + confidence / 2, n - 1)) * float(x.std(unbiased=True)) / n**0.5
    return mean, mean - half, mean + half


def expected_voi(
    impaired_returns: torch.Tensor, perfect_returns: torch.Tensor, confidence: float = 0.95
) -> tuple[float, float, float]:
    """EVoI = J̃ − J* with its CI, from per-scenario returns of the acting policy on impaired
    observations and of the optimal policy on perfect ones, paired by scenario (same seeds and
    leader traces)."""
    impaired = torch.as_tensor(impaired_returns, dtype=torch.float64).reshape(-1)
    perfect = torch.as_tensor(perfect_returns, dtype=torch.float64).reshape(-1)
    if impaired.shape != perfect.shape:
        raise ValueError(
            f"EVoI pairs scenarios: got {impaired.numel()} impaired and {perfect.numel()} perfect"
        )
    return mean_ci(impaired - perfect, confidence)
