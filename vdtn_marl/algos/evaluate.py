"""Evaluation of a control policy and an RRA policy on fixed scenarios, straight on the twin.

:func:`evaluate_system` drives one :class:`~vdtn_marl.sim.twin.DigitalTwin` (B = ``episodes``
scenarios, batched) for ``intervals`` control intervals: each interval the RRA policy picks
sub-channel × power for every V2V link in every subframe, then the followers decide on what
they observe (impaired, or perfect) and the twin integrates the platoon. A scenario whose
platoon collides stops counting from the colliding interval on (its collision is counted).

The same seed gives every method the same leader traces, initial states and channel draws, so
results of different methods are paired scenario by scenario (EVoI uses that pairing).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from vdtn_marl.core.interval import IntervalEngine
from vdtn_marl.data.traces import TraceSource
from vdtn_marl.io.interrupts import check_interrupt
from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.sim.aoi import interval_age_ms
from vdtn_marl.sim.link import cam_delivered
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin
from vdtn_marl.voi import IVoIEstimator

ControlPolicy = Callable[[torch.Tensor], torch.Tensor]  # observations [B, F, 8] → m/s² [B, F]
RRAPolicy = Callable[[torch.Tensor], torch.Tensor]  # RRA observations [B, L, D] → long [B, L]


@dataclass
class EvalResult:
    """Per-scenario returns (for paired statistics) and aggregate metrics of one evaluation.

    ``returns`` [B]: discounted control return, mean over followers; ``follower_returns``
    [B, F]: the same return of each follower (front to rear). ``ivoi_sums`` [B]:
    Σ_k γ^k ξ_k, mean over followers (when an IVoI estimator was given; its expectation is
    the EVoI for the ``td`` estimator, not for ``rollout``, docs/model.md §5). ``ivoi_delivered``
    and ``ivoi_lost`` [B] (IVoI estimator and radio): per scenario, the mean ξ over the
    follower-intervals whose CAM was delivered within its interval / was not (NaN where there
    were none). Under an RRA policy whose deliveries do not depend on the platoon's state
    (uniformly random) their difference is the effect of delivery on ξ.
    ``metrics``: plain
    floats, keys with units (see :data:`METRIC_DOC`). ``per_scenario``: the metrics of
    :data:`PER_SCENARIO_METRICS` for each scenario, [B] each (the radio's only where the radio
    ran; ``collided`` is 1.0 for a scenario that ended in a collision), for statistics paired
    by scenario. ``traces``: per-interval mean |gap error|
    (m) and |speed error| (m/s) of scenario 0's followers, [K, F] each, when requested.
    """

    returns: torch.Tensor
    metrics: dict[str, float]
    ivoi_sums: torch.Tensor | None = None
    ivoi_delivered: torch.Tensor | None = None
    ivoi_lost: torch.Tensor | None = None
    traces: dict[str, torch.Tensor] = field(default_factory=dict)
    cam_latency_ms: torch.Tensor | None = None  # every delivered CAM's latency (for CDFs)
    per_scenario: dict[str, torch.Tensor] = field(default_factory=dict)
    follower_returns: torch.Tensor | None = None


METRIC_DOC = {
    "control_return": "discounted control return per follower (mean over scenarios)",
    "control_cost": "−(mean control reward) per follower and interval",
    "gap_error_abs_m": "mean |gap error| (m)",
    "speed_error_abs_mps": "mean |speed error| (m/s)",
    "collision_rate": "fraction of scenarios that ended in a collision",
    "cam_delivery_rate": "fraction of CAMs delivered within their interval",
    "cam_latency_ms_mean": "mean latency of delivered CAMs (ms)",
    "cam_latency_ms_p50": "median latency of delivered CAMs (ms)",
    "cam_latency_ms_p95": "95th percentile latency of delivered CAMs (ms)",
    "aoi_ms_mean": "Age of Information of the CAM content at each recipient, averaged over every "
    "subframe (ms; docs/model.md §4.8)",
    "peak_aoi_ms_mean": "peak Age of Information, the age just before each refresh (a delivered "
    "CAM), averaged over refreshes (ms)",
    "v2i_throughput_mbps_per_link": "mean V2I rate per V2I link (Mbps)",
    "ivoi_mean_delivered": "mean IVoI ξ (unscaled) of the follower-intervals whose CAM was "
    "delivered within its interval",
    "ivoi_mean_lost": "mean IVoI ξ (unscaled) of the follower-intervals whose CAM was not",
    "ivoi_mean": "mean IVoI ξ (unscaled) over the live follower-intervals",
    "ivoi_std": "standard deviation of IVoI ξ (unscaled) over the live follower-intervals: the "
    "noise a delivered − lost difference is learned against",
}


#: The metrics of :attr:`EvalResult.per_scenario` (as in :data:`METRIC_DOC`, over one scenario's
#: live intervals; ``collided``: 1.0 where the scenario ended in a collision); the last three
#: only where the radio ran.
PER_SCENARIO_METRICS = (
    "control_cost",
    "gap_error_abs_m",
    "speed_error_abs_mps",
    "collided",
    "cam_delivery_rate",
    "v2i_throughput_mbps_per_link",
    "aoi_ms_mean",
)


class _MaskedMean:
    """Per-scenario sums, sums of squares and counts of the masked entries of [B, F] values."""

    def __init__(self, batch: int, device: torch.device):
        self.total = torch.zeros(batch, dtype=torch.float64, device=device)
        self.total_sq = torch.zeros(batch, dtype=torch.float64, device=device)
        self.count = torch.zeros(batch, dtype=torch.float64, device=device)

    def add(self, values: torch.Tensor, mask: torch.Tensor) -> None:
        masked = torch.where(mask, values, torch.zeros_like(values))
        self.total += masked.sum(-1)
        self.total_sq += masked.square().sum(-1)
        self.count += mask.double().sum(-1)

    def per_scenario(self) -> torch.Tensor:
        """Mean per scenario [B] (NaN where nothing was added)."""
        return torch.where(self.count > 0, self.total / self.count.clamp(min=1), torch.nan)

    def pooled(self) -> float:
        """Mean over every added entry (NaN if none)."""
        count = float(self.count.sum())
        return float(self.total.sum()) / count if count else float("nan")

    def pooled_std(self) -> float:
        """Population standard deviation over every added entry (NaN if none)."""
        count = float(self.count.sum())
        if not count:
            return float("nan")
        mean = float(self.total.sum()) / count
        return max(float(self.total_sq.sum()) / count - mean * mean, 0.0) ** 0.5


def bind_to_twin(policy, twin: DigitalTwin):
    """``policy`` ready to act on ``twin``: policies that need the twin's true state (the
    oracle, the greedy RRA) expose ``bind(twin)``; others are returned as they are."""
    return policy.bind(twin) if hasattr(policy, "bind") else policy


@torch.no_grad()
def evaluate_system(
    params: TwinParams,
    control: ControlPolicy,
    rra: RRAPolicy | None = None,
    *,
    perfect: bool,
    episodes: int,
    intervals: int,
    seed: int,
    gamma: float = 0.99,
    device: str | torch.device = "cpu",
    trace_source: str | TraceSource | None = None,
    ivoi_estimator: IVoIEstimator | None = None,
    record_traces: bool = False,
    completion=None,
    on_interval: Callable | None = None,
) -> EvalResult:
    """Run ``episodes`` scenarios for ``intervals`` intervals; see the module doc.

    With ``perfect=True`` the radio is off (no CAM impairment, no V2I figures) unless ``rra``
    is given, in which case the radio runs for its metrics but the followers still observe
    perfectly. With ``perfect=False`` the radio runs with ``rra`` (default: uniformly random)
    and ``completion`` (a completer of :mod:`vdtn_marl.sim.completion`) fills in stale CAM
    content before the control policy sees it. ``on_interval(twin, record)`` is called after
    every interval (to draw it, for instance); it must not change the twin.
    """
    if intervals > params.episode_intervals:
        raise ValueError(
            f"intervals={intervals} exceeds the model's "
            f"episode_intervals={params.episode_intervals}"
        )
    radio = (not perfect) or rra is not None
    twin = DigitalTwin(
        params, batch_size=episodes, device=device, seed=seed, trace_source=trace_source,
        radio=radio, backend="torch",
    )  # fmt: skip
    twin.reset(seed=seed)
    if radio and rra is None:
        rra = RandomRRAPolicy(params.radio.num_actions, seed)
    control = bind_to_twin(control, twin)
    rra = bind_to_twin(rra, twin) if rra is not None else None
    if hasattr(rra, "reset"):
        rra.reset()
    if completion is not None:
        completion.reset()
    b, f = episodes, twin.num_followers
    dev = twin.device
    alive = torch.ones(b, dtype=torch.bool, device=dev)
    returns = torch.zeros(b, f, dtype=torch.float64, device=dev)
    ivoi_sums = torch.zeros(b, f, dtype=torch.float64, device=dev)
    reward_sum = torch.zeros((), dtype=torch.float64, device=dev)
    gap_sum = torch.zeros((), dtype=torch.float64, device=dev)
    speed_sum = torch.zeros((), dtype=torch.float64, device=dev)
    counted = torch.zeros((), dtype=torch.float64, device=dev)
    v2i_sum = torch.zeros((), dtype=torch.float64, device=dev)
    cams_sent = torch.zeros((), dtype=torch.float64, device=dev)
    cams_delivered = torch.zeros((), dtype=torch.float64, device=dev)
    aoi_sum = torch.zeros((), dtype=torch.float64, device=dev)
    peak_aoi_sum = torch.zeros((), dtype=torch.float64, device=dev)
    # the same sums per scenario [B] (EvalResult.per_scenario)
    scenario_sums = {
        name: torch.zeros(b, dtype=torch.float64, device=dev)
        for name in ("reward", "gap", "speed", "counted", "v2i", "sent", "delivered", "aoi")
    }
    by_delivery = radio and ivoi_estimator is not None  # ξ split by CAM delivery
    xi_delivered = _MaskedMean(b, dev)
    xi_lost = _MaskedMean(b, dev)
    xi_all = _MaskedMean(b, dev)
    latencies = []
    gap_trace, speed_trace = [], []
    t = params.platoon.subframes_per_interval
    subframe_ms = params.platoon.subframe_s * 1000.0
    weight = 1.0

    engine = IntervalEngine(
        twin,
        perfect=perfect,
        rra_policy=rra if radio else None,
        control=control,
        completion=completion,
        ivoi_estimator=ivoi_estimator,
    )
    if radio:
        engine.run_radio()
    for k in range(intervals):
        check_interrupt()  # Ctrl-C stops here, between intervals (vdtn_marl.io.interrupts)
        if k > 0:
            engine.advance()  # every scenario (a collided one is no longer counted)
        if radio:  # a_k: age (intervals) at kΔt of the content each recipient holds, [B, L]
            held_age = twin.interval[:, None] - twin.cam_held_interval
        closed = engine.close()
        record = closed.record
        live = alive[:, None].double()
        reward = record.reward.double()
        returns += weight * live * reward
        xi = None
        if ivoi_estimator is not None:
            xi = closed.xi.double()
            ivoi_sums += weight * live * xi
            xi_all.add(xi, alive[:, None].expand(b, f))
        reward_sum += (live * reward).sum()
        gap_sum += (live * record.gap_error_m.abs().double()).sum()
        speed_sum += (live * record.speed_error_mps.abs().double()).sum()
        counted += live.sum() * f
        scenario_sums["reward"] += (live * reward).sum(-1)
        scenario_sums["gap"] += (live * record.gap_error_m.abs().double()).sum(-1)
        scenario_sums["speed"] += (live * record.speed_error_mps.abs().double()).sum(-1)
        scenario_sums["counted"] += live[:, 0] * f
        if radio:
            v2i_sum += (alive[:, None].double() * record.v2i_rate_bps.double()).mean(-1).sum()
            delay = record.cam_delay_subframes
            in_time = cam_delivered(delay, t)  # [B, L]; link i carries follower i's CAM
            delivered = in_time & alive[:, None]
            cams_sent += alive.double().sum() * delay.shape[-1]
            cams_delivered += delivered.double().sum()
            latencies.append(delay[delivered].double() * subframe_ms)
            aoi_mean, peak_aoi = interval_age_ms(held_age, delay, t, subframe_ms)
            aoi_sum += (live * aoi_mean.double()).sum()
            scenario_sums["v2i"] += (live * record.v2i_rate_bps.double()).mean(-1)
            scenario_sums["sent"] += alive.double() * delay.shape[-1]
            scenario_sums["delivered"] += delivered.double().sum(-1)
            scenario_sums["aoi"] += (live * aoi_mean.double()).sum(-1)
            peak_aoi_sum += peak_aoi.double()[delivered].sum()
            if xi is not None:
                xi_delivered.add(xi, delivered)
                xi_lost.add(xi, ~in_time & alive[:, None])
        if on_interval is not None:
            on_interval(twin, record)
        if record_traces:
            gap_trace.append(record.gap_error_m[0].abs().cpu())
            speed_trace.append(record.speed_error_mps[0].abs().cpu())
        alive &= ~record.collided.any(-1)
        weight *= gamma
    live_intervals = counted / f
    metrics = {
        "control_return": float(returns.mean()),
        "control_cost": float(-reward_sum / counted),
        "gap_error_abs_m": float(gap_sum / counted),
        "speed_error_abs_mps": float(speed_sum / counted),
        "collision_rate": float((~alive).double().mean()),
    }
    if ivoi_estimator is not None:
        metrics["ivoi_mean"] = xi_all.pooled()
        metrics["ivoi_std"] = xi_all.pooled_std()
    latency = torch.cat(latencies) if latencies else torch.zeros(0, dtype=torch.float64)
    if radio:
        metrics["cam_delivery_rate"] = float(cams_delivered / cams_sent)
        if latency.numel():
            q = torch.quantile(latency, latency.new_tensor([0.5, 0.95]))
            metrics["cam_latency_ms_mean"] = float(latency.mean())
            metrics["cam_latency_ms_p50"] = float(q[0])
            metrics["cam_latency_ms_p95"] = float(q[1])
        else:
            metrics.update(
                cam_latency_ms_mean=float("nan"),
                cam_latency_ms_p50=float("nan"),
                cam_latency_ms_p95=float("nan"),
            )
        metrics["aoi_ms_mean"] = float(aoi_sum / cams_sent)
        metrics["peak_aoi_ms_mean"] = (
            float(peak_aoi_sum / cams_delivered) if cams_delivered > 0 else float("nan")
        )
        metrics["v2i_throughput_mbps_per_link"] = float(v2i_sum / live_intervals / 1e6)
        if by_delivery:
            metrics["ivoi_mean_delivered"] = xi_delivered.pooled()
            metrics["ivoi_mean_lost"] = xi_lost.pooled()
    per_scenario = _per_scenario(scenario_sums, ~alive, f, radio)
    traces = {}
    if record_traces:
        traces = {
            "gap_error_abs_m": torch.stack(gap_trace),
            "speed_error_abs_mps": torch.stack(speed_trace),
        }
    return EvalResult(
        returns=returns.mean(-1).float().cpu(),
        metrics=metrics,
        ivoi_sums=ivoi_sums.mean(-1).float().cpu() if ivoi_estimator is not None else None,
        ivoi_delivered=xi_delivered.per_scenario().cpu() if by_delivery else None,
        ivoi_lost=xi_lost.per_scenario().cpu() if by_delivery else None,
        traces=traces,
        cam_latency_ms=latency.cpu() if radio else None,
        per_scenario=per_scenario,
        follower_returns=returns.float().cpu(),
    )


def _per_scenario(
    sums: dict[str, torch.Tensor], collided: torch.Tensor, followers: int, radio: bool
) -> dict[str, torch.Tensor]:
    """:data:`PER_SCENARIO_METRICS` [B] (float64, on the CPU) from the per-scenario sums of
    :func:`evaluate_system` over each scenario's live intervals."""
    counted = sums["counted"]  # live follower-intervals
    out = {
        "control_cost": -sums["reward"] / counted,
        "gap_error_abs_m": sums["gap"] / counted,
        "speed_error_abs_mps": sums["speed"] / counted,
        "collided": collided.double(),
    }
    if radio:
        out["cam_delivery_rate"] = sums["delivered"] / sums["sent"]
        out["v2i_throughput_mbps_per_link"] = sums["v2i"] / (counted / followers) / 1e6
        out["aoi_ms_mean"] = sums["aoi"] / sums["sent"]
    return {name: value.cpu() for name, value in out.items()}
