"""Figures of the recorded trace sets' train and eval parts, as runs split them.

``python -m vdtn_marl.data.summary`` prints the table of docs/leader_traces.md:
for each part (:func:`~vdtn_marl.data.selection.named_sources`), its total duration, number
of segments, how many disjoint windows of an episode and the twin's look-ahead it holds
(:class:`~vdtn_marl.data.profiles.DisjointWindowSource`: 20 s for the scenarios' 10 s episodes
at Δt = 50 ms), and its speeds over the recorded samples (mean, share below 6.7 m/s, max).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vdtn_marl.data.profiles import DisjointWindowSource, ProfileTraceSource
from vdtn_marl.data.selection import EVAL_LOOKAHEAD_INTERVALS, named_sources

RECORDED_SETS = ("cmap", "udds", "hwfet")
SLOW_MPS = 6.7
"""The "slow" threshold of the table, m/s (15 mph)."""
EPISODE_INTERVALS = 200
CONTROL_INTERVAL_S = 0.05


@dataclass(frozen=True)
class PartSummary:
    trace_set: str
    part: str
    duration_s: float
    segments: int
    vehicles: int
    disjoint_windows: int
    window_s: float
    mean_speed_mps: float
    slow_share: float
    max_speed_mps: float


def summarize(
    name: str,
    episode_intervals: int = EPISODE_INTERVALS,
    control_interval_s: float = CONTROL_INTERVAL_S,
) -> list[PartSummary]:
    """The train and eval parts of the recorded trace set ``name``."""
    num_points = episode_intervals + 1 + EVAL_LOOKAHEAD_INTERVALS
    out = []
    for part, recorded in zip(("train", "eval"), named_sources(name), strict=True):
        if not isinstance(recorded, ProfileTraceSource):
            raise ValueError(f"trace set {name!r} is not recorded")
        source = DisjointWindowSource(recorded)
        speeds = np.concatenate([p.speed_mps for p in source.profiles])
        out.append(
            PartSummary(
                trace_set=name,
                part=part,
                duration_s=float(sum(p.duration_s for p in source.profiles)),
                segments=len(source.profiles),
                vehicles=len({p.vehicle_id.split("#")[0] for p in source.profiles}),
                disjoint_windows=source.count(num_points, control_interval_s),
                window_s=(num_points - 1) * control_interval_s,
                mean_speed_mps=float(speeds.mean()),
                slow_share=float(np.mean(speeds < SLOW_MPS)),
                max_speed_mps=float(speeds.max()),
            )
        )
    return out


def markdown_table(names: tuple[str, ...] = RECORDED_SETS) -> str:
    rows = [s for name in names for s in summarize(name)]
    window = rows[0].window_s
    lines = [
        f"| trace set | part | vehicles | segments | duration | disjoint {window:g} s windows "
        f"| mean speed (m/s) | time below {SLOW_MPS:g} m/s | max speed (m/s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in rows:
        hours = s.duration_s / 3600.0
        duration = f"{hours:.2f} h" if hours >= 1 else f"{s.duration_s:.0f} s"
        lines.append(
            f"| `{s.trace_set}` | {s.part} | {s.vehicles} | {s.segments} | {duration} | "
            f"{s.disjoint_windows} | {s.mean_speed_mps:.1f} | {s.slow_share:.0%} | "
            f"{s.max_speed_mps:.1f} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown_table())
