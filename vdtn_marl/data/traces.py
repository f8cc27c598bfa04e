"""Leader speed traces: the one small interface the digital twin reads (docs/model.md §3).

A :class:`TraceSource` hands out leader speed profiles in m/s on a uniform time grid of step
``dt_s``. The twin asks for profiles on its control-interval grid (Δt = 50 ms), so the leader's
acceleration is piecewise constant per control interval. Sources are looked up by name with
:func:`get_trace_source`; new ones are added with :func:`register_trace_source`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch


@dataclass(frozen=True)
class TraceInfo:
    """Provenance of a trace set, shown in the env registry metadata."""

    name: str
    description: str
    synthetic: bool
    source: str  # where the data comes from (a citation, a package, or "generated")


@runtime_checkable
class TraceSource(Protocol):
    """Anything that can hand out leader speed profiles."""

    info: TraceInfo

    def sample(
        self, num_traces: int, num_points: int, dt_s: float, generator: torch.Generator
    ) -> torch.Tensor:
        """Return ``num_traces`` speed profiles, shape ``[num_traces, num_points]``, in m/s.

        Point ``j`` is the speed at time ``j·dt_s``. Speeds are finite and ≥ 0. All randomness
        comes from ``generator`` so that a seeded twin is reproducible.
        """
        ...


@dataclass(frozen=True)
class SyntheticTraceSource:
    """Stochastic leader profiles: cruising with braking and acceleration events.

    The acceleration (m/s²) is the sum of a mean-reverting Ornstein–Uhlenbeck term (small
    fluctuations, std ``jitter_std_mps2``) and event plateaus: with probability
    ``event_rate_hz·dt`` per step an event starts; it is a braking event (−U(0.5, 1)·
    ``brake_max_mps2``) with probability ``brake_fraction`` and an acceleration event
    (U(0.5, 1)·``accel_max_mps2``) otherwise, and lasts U(1, 4) s. Speeds start uniformly in
    [``speed_min_mps``, ``speed_max_mps``] and are kept inside that band (an event that would
    leave it is cut short) and the acceleration is clipped to [−``brake_max_mps2``,
    ``accel_max_mps2``], inside the followers' actuator bounds, so a perfect follower can track
    the profile.
    """

    info: TraceInfo = TraceInfo(
        name="synthetic",
        description="bounded stochastic accel/brake profile (OU jitter + events)",
        synthetic=True,
        source="generated (vdtn_marl.data.traces.SyntheticTraceSource)",
    )
    speed_min_mps: float = 10.0
    speed_max_mps: float = 30.0
    accel_max_mps2: float = 1.5
    brake_max_mps2: float = 2.5
    event_rate_hz: float = 0.25
    brake_fraction: float = 0.5
    jitter_std_mps2: float = 0.2
    jitter_time_constant_s: float = 1.0

    def sample(
        self, num_traces: int, num_points: int, dt_s: float, generator: torch.Generator
    ) -> torch.Tensor:
        if num_traces < 1 or num_points < 2:
            raise ValueError(
                f"num_traces={num_traces} and num_points={num_points} must be >= 1 and >= 2"
            )
        dev = generator.device

        def uniform(*shape: int) -> torch.Tensor:
            return torch.rand(*shape, generator=generator, device=dev)

        steps = num_points - 1
        # All draws up front (one call each), then one cheap sequential pass.
        start = self.speed_min_mps + (self.speed_max_mps - self.speed_min_mps) * uniform(num_traces)
        event_start = uniform(steps, num_traces) < self.event_rate_hz * dt_s
        is_brake = uniform(steps, num_traces) < self.brake_fraction
        magnitude = 0.5 + 0.5 * uniform(steps, num_traces)
        event_accel = torch.where(
            is_brake, -self.brake_max_mps2 * magnitude, self.accel_max_mps2 * magnitude
        )
        event_steps = ((1.0 + 3.0 * uniform(steps, num_traces)) / dt_s).round()
        noise = torch.randn(steps, num_traces, generator=generator, device=dev)

        decay = float(torch.exp(torch.tensor(-dt_s / self.jitter_time_constant_s)))
        jitter_gain = self.jitter_std_mps2 * (1.0 - decay**2) ** 0.5
        speed = torch.empty(num_points, num_traces, device=dev)
        speed[0] = start
        jitter = torch.zeros(num_traces, device=dev)
        plateau = torch.zeros(num_traces, device=dev)
        remaining = torch.zeros(num_traces, device=dev)
        for j in range(steps):
            new_event = event_start[j] & (remaining <= 0)
            plateau = torch.where(new_event, event_accel[j], plateau)
            remaining = torch.where(new_event, event_steps[j], remaining - 1)
            active = remaining > 0
            jitter = decay * jitter + jitter_gain * noise[j]
            accel = jitter + torch.where(active, plateau, torch.zeros_like(plateau))
            accel = accel.clamp(-self.brake_max_mps2, self.accel_max_mps2)
            nxt = speed[j] + dt_s * accel
            leaving = (nxt < self.speed_min_mps) | (nxt > self.speed_max_mps)
            remaining = torch.where(leaving, torch.zeros_like(remaining), remaining)
            speed[j + 1] = nxt.clamp(self.speed_min_mps, self.speed_max_mps)
        return speed.T.contiguous()


@dataclass(frozen=True)
class ConstantSpeedTraceSource:
    """A leader at constant speed (m/s): the simplest reference for tests and debugging."""

    speed_mps: float = 25.0
    info: TraceInfo = TraceInfo(
        name="constant",
        description="leader at a constant 25 m/s",
        synthetic=True,
        source="generated",
    )

    def sample(
        self, num_traces: int, num_points: int, dt_s: float, generator: torch.Generator
    ) -> torch.Tensor:
        return torch.full((num_traces, num_points), float(self.speed_mps), device=generator.device)


_TRACE_SOURCES: dict[str, Callable[[], TraceSource]] = {
    "synthetic": SyntheticTraceSource,
    "constant": ConstantSpeedTraceSource,
}


def register_trace_source(name: str, factory: Callable[[], TraceSource]) -> None:
    """Make a trace source selectable by ``name`` in env kwargs and configs."""
    _TRACE_SOURCES[name] = factory


def trace_source_names() -> list[str]:
    return sorted(_TRACE_SOURCES)


def get_trace_source(name_or_source: str | TraceSource) -> TraceSource:
    """Look up a trace source by name (or pass an instance through unchanged)."""
    if not isinstance(name_or_source, str):
        if not isinstance(name_or_source, TraceSource):
            raise TypeError(f"traces={name_or_source!r} is neither a name nor a TraceSource")
        return name_or_source
    try:
        return _TRACE_SOURCES[name_or_source]()
    except KeyError:
        raise ValueError(
            f"traces={name_or_source!r} is not a known trace set; known: "
            f"{', '.join(trace_source_names())}"
        ) from None
