"""What a run writes besides its logs and checkpoints: the last evaluation's arrays
(``evaluation_raw.npz``, read by the leaderboard's plots), the run's plots (training curves,
error traces, CAM latency CDF) and the plain metrics table printed at its end."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

from vdtn_marl.io.files import RAW_EVALUATION_FILE, atomic_write_bytes
from vdtn_marl.sim.params import TwinParams


def write_raw_evaluation(
    run_dir: Path,
    params: TwinParams,
    optimal: Any,
    acting: Any,
    scenario_seed: int | None = None,
) -> None:
    """``evaluation_raw.npz``: per-scenario returns of the acting system and of π*, scenario
    0's |gap|/|speed| error traces [K, F] and every delivered CAM's latency (ms), for plots
    across runs (the leaderboard's); and each scenario's metrics
    (:data:`~vdtn_marl.algos.evaluate.PER_SCENARIO_METRICS`) as ``scenario_<metric>`` [E] for
    the acting system and ``optimal_scenario_<metric>`` for π* (its control metrics: π* sees
    perfect observations, without the radio), so that runs pair scenario by scenario as well
    as seed by seed. ``scenario_seed``: the seed of the held-out scenarios (runs of one
    ``seed`` share them; scenario ``i`` is the same in each). ``optimal``/``acting``:
    evaluation results (``optimal`` None where no π* was scored: no ``optimal_*`` arrays)."""
    import numpy as np

    arrays = {
        "interval_s": np.float64(params.platoon.control_interval_s),
        "returns": acting.returns.numpy(),
        **{key: value.numpy() for key, value in acting.traces.items()},
        **{f"scenario_{key}": value.numpy() for key, value in acting.per_scenario.items()},
    }
    if optimal is not None:
        arrays["optimal_returns"] = optimal.returns.numpy()
        arrays.update({f"optimal_scenario_{k}": v.numpy() for k, v in optimal.per_scenario.items()})
    if scenario_seed is not None:
        arrays["scenario_seed"] = np.int64(scenario_seed)
    if acting.cam_latency_ms is not None:
        arrays["cam_latency_ms"] = acting.cam_latency_ms.numpy()
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    atomic_write_bytes(Path(run_dir) / RAW_EVALUATION_FILE, buffer.getvalue())


def write_run_plots(
    run_dir: Path, params: TwinParams, train_log: Path | None, acting: Any, label: str
) -> list[str]:
    """Training curves (from the ``metrics.csv`` at ``train_log``, if any) and, for the last
    evaluation ``acting`` (if any), its error traces and CAM latency CDF; the paths written."""
    from vdtn_marl.reporting import plots

    run_dir = Path(run_dir)
    written = []
    if train_log is not None:
        written.append(plots.plot_training_curves(train_log, run_dir / plots.TRAINING_CURVES_FILE))
    if acting is not None:
        pp = params.platoon
        written.append(
            plots.plot_error_traces(
                acting.traces["gap_error_abs_m"],
                acting.traces["speed_error_abs_mps"],
                pp.control_interval_s,
                run_dir / plots.ERROR_TRACES_FILE,
                vehicle_ids=pp.topology.followers,
            )
        )
        written.append(
            plots.plot_latency_cdf(
                {latency_label(label, acting): acting.cam_latency_ms},
                pp.control_interval_s * 1000.0,
                run_dir / plots.LATENCY_CDF_FILE,
            )
        )
    return [str(p) for p in written]


def latency_label(label: str, acting: Any) -> str:
    """The legend label of a run's latency CDF: how many CAMs it is over (the delivered ones)
    and, where the evaluation reports it, their share of the CAMs sent."""
    latencies = acting.cam_latency_ms
    count = 0 if latencies is None else int(latencies.numel())
    text = f"{label}: {count} delivered CAMs"
    rate = (getattr(acting, "metrics", None) or {}).get("cam_delivery_rate")
    if isinstance(rate, int | float):
        text += f", {100 * rate:.1f}% of those sent"
    return text


def format_table(row: dict[str, Any]) -> str:
    """A run's summary as plain text, grouped with units as the CLI prints it
    (:func:`~vdtn_marl.reporting.tables.format_summary`)."""
    from vdtn_marl.reporting.tables import format_summary

    return format_summary(row)
