"""Age of Information (AoI) of the CAM content at each recipient (docs/model.md §4.8).

Recipient i (the follower at the end of V2V link i) holds the content of the newest CAM it has
received; CAM_k is generated at kΔt. Its AoI at time τ is τ minus the generation time of the
content it holds, in ms, sampled at the end of every subframe s = 1..T of interval k:

    A(k, s) = s·δ               if CAM_k has arrived by then (d_k ≤ s),
    A(k, s) = a_k·Δt + s·δ      otherwise,

with δ the subframe (1 ms), Δt = T·δ the control interval, d_k ∈ 1..T the delivery subframe
(T + 1: lost) and a_k the age in intervals, at kΔt, of the content held when the interval
starts: k minus the twin's ``cam_held_interval`` (1 after a reset, when the recipient holds the
initial state as if sent one interval earlier; the same age the RRA observation's ``cam_age``
feature shows, unclipped). The mean over the interval's T samples and the peak of a refresh
(the age just before CAM_k replaces the held content, at the end of subframe d_k) follow in
closed form, so evaluation needs only the delivery subframe and a_k of each interval:

    mean_k = (T + 1)·δ/2 + a_k·Δt·(min(d_k, T + 1) − 1)/T,
    peak_k = a_k·Δt + d_k·δ      (for delivered CAMs only).

Both functions take torch tensors or NumPy arrays.
"""

from __future__ import annotations

from vdtn_marl.sim.backend import as_float


def age_ms(held_age_intervals, delay_subframes, subframe: int, interval_ms: float, subframe_ms):
    """A(k, s) [B, L] (ms): every recipient's AoI after ``subframe`` = s subframes of the
    interval, from a_k [B, L] (``held_age_intervals``) and the delivery subframes so far
    [B, L] (T + 1 while pending)."""
    stale = as_float(delay_subframes > subframe)
    return subframe * subframe_ms + as_float(held_age_intervals) * interval_ms * stale


def interval_age_ms(held_age_intervals, delay_subframes, subframes: int, subframe_ms: float):
    """(mean_k, peak_k) [B, L] each (ms): the AoI averaged over the interval's T subframe ends,
    and the peak AoI of its refresh (meaningful only where ``delay_subframes`` ≤ T)."""
    held_ms = as_float(held_age_intervals) * (subframes * subframe_ms)
    waited = (delay_subframes.clip(max=subframes + 1) - 1) / subframes
    mean = (subframes + 1) * subframe_ms / 2 + held_ms * as_float(waited)
    peak = held_ms + as_float(delay_subframes) * subframe_ms
    return mean, peak
