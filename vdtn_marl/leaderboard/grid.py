"""The benchmark grid: metrics, cells (scenario × method × seed), their composed configs,
and the state of the output directory (which cells are complete, whether it holds this
benchmark).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from vdtn_marl.errors import LeaderboardError
from vdtn_marl.experiment.compose import (
    compose_config,
    job_config,
    to_run_config,
    translate,
)
from vdtn_marl.experiment.config import BenchConfig, BenchmarkConfig, with_submissions
from vdtn_marl.experiment.metrics import REQUIRED_METRIC_KEYS
from vdtn_marl.io.files import SUMMARY_FILE, read_json

MANIFEST_FILE = "benchmark.json"
#: Config keys a resumed cell may change (the rest must match the cell's own run).
FREE_KEYS = (
    "resume", "progress", "device", "threads", "checkpoint", "warm_start_cache",
    "control.pi_star",  # where the shared π* lies (its SHA-256 is in the summary)
)  # fmt: skip
#: where ``share_warm_starts`` keeps the warm starts of π* the cells share, in ``out_dir``
WARM_START_DIR = "warm_starts"


@dataclass(frozen=True)
class Cell:
    """One run of the grid."""

    scenario: str
    method: str
    seed: int
    overrides: tuple[str, ...]

    @property
    def name(self) -> str:
        return f"{self.scenario}/{self.method}/seed{self.seed}"

    def directory(self, out_dir: str | Path) -> Path:
        return Path(out_dir) / self.scenario / self.method / f"seed{self.seed}"


# --- the grid -------------------------------------------------------------------------------


def cell_overrides(
    benchmark: BenchmarkConfig, scenario: str, method: str, seed: int | None = None
) -> list[str]:
    """The ``vdtn-marl jocc`` overrides of one cell (``seed=None``: leave the seed out)."""
    overrides = [
        f"scenario={scenario}",
        f"experiment={benchmark.experiment}",
        *benchmark.overrides,
        *benchmark.methods[method],
        *benchmark.budgets.get(method, ()),
    ]
    if seed is not None:
        overrides.append(f"seed={seed}")
    return [str(o) for o in overrides]


def plan(cfg: BenchConfig) -> list[Cell]:
    """Every cell, seed by seed (so a partial run has every method on the first seeds): the
    cells of ``seeds``, then those of ``extra_seeds``, again seed by seed (each seed in the
    benchmark's order of scenarios and methods; ``submissions`` come after the methods:
    :func:`with_submissions`)."""
    b = with_submissions(cfg).benchmark

    def cell(scenario: str, method: str, seed: int) -> Cell:
        return Cell(scenario, method, int(seed), tuple(cell_overrides(b, scenario, method, seed)))

    cells = [
        cell(scenario, method, seed)
        for seed in b.seeds
        for scenario in b.scenarios
        for method in b.methods
    ]
    extra = b.extra_seeds or {}
    wanted = {
        (scenario, method): {int(s) for s in seeds}
        for scenario, by_method in extra.items()
        for method, seeds in by_method.items()
    }
    for seed in sorted(set().union(*wanted.values()) if wanted else ()):
        cells += [
            cell(scenario, method, seed)
            for scenario in b.scenarios
            for method in b.methods
            if seed in wanted.get((scenario, method), ())
        ]
    return cells


def bench_config(data: Mapping[str, Any]) -> BenchConfig:
    """Plain composed data of ``conf/bench.yaml`` → :class:`BenchConfig` (not yet validated;
    a ``benchmark.target`` mapping becomes a :class:`BenchmarkTargetConfig` there)."""
    values = dict(data)
    benchmark = BenchmarkConfig(**dict(values.pop("benchmark")))
    return BenchConfig(benchmark=benchmark, **values)


def compose_cell(cell: Cell, device: str) -> tuple[dict, Any]:
    """(composed config as plain data, validated RunConfig) of a cell, through the CLI's own
    composition and validation (:func:`vdtn_marl.experiment.compose.to_run_config`)."""
    return compose_run(f"cell {cell.name}", cell.overrides, device, "jocc")


def compose_run(name: str, overrides: Sequence[str], device: str, command: str) -> tuple[dict, Any]:
    """:func:`compose_cell` of any run of the grid (a cell, a shared π*): its ``overrides``
    composed for ``command``; an error names the run."""
    overrides = [*overrides, f"device={device}", "resume=true", "progress=false"]
    try:
        data = job_config(compose_config("config", overrides))
        return data, to_run_config(data, command)
    except Exception as exc:
        raise LeaderboardError(f"{name}: {translate(exc, 'config', overrides)}") from exc


def check_eval_pairing(cells_data: Mapping[Cell, Mapping[str, Any]]) -> None:
    """Every method of a scenario must see the same held-out scenarios (eval budget, model)."""
    from vdtn_marl.reporting.tables import flatten

    reference: dict[str, tuple[Cell, dict]] = {}
    for cell, data in cells_data.items():
        flat = flatten(data)
        keys = {k: v for k, v in flat.items() if k.startswith(("scenario.", "experiment.eval_"))}
        if cell.scenario not in reference:
            reference[cell.scenario] = (cell, keys)
            continue
        first, expected = reference[cell.scenario]
        for key in sorted(set(expected) | set(keys)):
            if expected.get(key) != keys.get(key):
                raise LeaderboardError(
                    f"benchmark method {cell.method!r} sets {key}={keys.get(key)!r} but "
                    f"{first.method!r} has {key}={expected.get(key)!r} on scenario "
                    f"{cell.scenario}: every method of a scenario must be evaluated on the same "
                    "held-out scenarios; allowed: budgets that leave scenario.* and "
                    "experiment.eval_* alone"
                )


# --- state of the output directory ----------------------------------------------------------


#: Fields of a benchmark that decide its runs: an out_dir holds runs of one set of them.
RUN_FIELDS = (
    "experiment", "overrides", "scenarios", "methods", "budgets", "seeds", "extra_seeds",
    "pi_star",
)  # fmt: skip


def manifest(cfg: BenchConfig) -> dict[str, Any]:
    b = cfg.benchmark
    out = {"name": b.name, "version": b.version, "benchmark": asdict(b)}
    if cfg.submissions:  # not part of the definition (check_out_dir ignores them)
        out["submissions"] = {k: list(v) for k, v in cfg.submissions.items()}
    return out


def check_out_dir(cfg: BenchConfig) -> None:
    """``out_dir`` is empty or holds this very benchmark definition (else: bump the version)."""
    path = Path(cfg.out_dir) / MANIFEST_FILE
    if not path.is_file():
        return
    try:
        old = read_json(path)
    except (OSError, ValueError) as exc:
        raise LeaderboardError(
            f"{path} cannot be read ({exc}); remove it or pick another out_dir"
        ) from exc
    new = manifest(cfg)
    from vdtn_marl.reporting.tables import flatten

    a, b = flatten(old.get("benchmark", {})), flatten(new["benchmark"])
    keys = {k for k in set(a) | set(b) if k.split(".")[0] in RUN_FIELDS}
    differ = sorted(k for k in keys if a.get(k) != b.get(k))
    if differ:
        key = differ[0]
        raise LeaderboardError(
            f"out_dir={cfg.out_dir} holds benchmark {old.get('name')!r} version "
            f"{old.get('version')!r} with benchmark.{key}={a.get(key)!r}, not {b.get(key)!r}; "
            "a changed definition needs a new benchmark.version (and so a new out_dir) or "
            "another out_dir"
        )


def with_recorded_submissions(cfg: BenchConfig) -> BenchConfig:
    """``cfg`` with the submissions that ``out_dir``'s manifest records beside its own, so a
    job that adds a submission (or reports) keeps the earlier ones in the grid and the report.
    A recorded submission given again must have the same overrides."""
    path = Path(cfg.out_dir) / MANIFEST_FILE
    recorded = read_json(path).get("submissions", {}) if path.is_file() else {}
    given = {k: list(v) for k, v in (cfg.submissions or {}).items()}
    for name, overrides in recorded.items():
        if name in given and given[name] != list(overrides):
            raise LeaderboardError(
                f"submissions.{name}={given[name]} but out_dir={cfg.out_dir} holds its cells "
                f"run with {list(overrides)}; allowed: the same overrides, another name or "
                "another out_dir"
            )
    if not recorded:
        return cfg
    return replace(cfg, submissions={**{k: list(v) for k, v in recorded.items()}, **given})


def complete_summary(cell_dir: Path, data: Mapping[str, Any]) -> dict | None:
    """The cell's summary if the cell is finished (else None). A finished cell whose config
    differs from ``data`` (outside :data:`FREE_KEYS`) raises :class:`LeaderboardError`."""

    path = cell_dir / SUMMARY_FILE
    if not path.is_file():
        return None
    try:
        summary = read_json(path)
    except (OSError, ValueError):
        return None
    if not isinstance(summary, dict) or not all(k in summary for k in REQUIRED_METRIC_KEYS):
        return None
    iterations = data.get("experiment", {}).get("jocc_iterations")
    if summary.get("iterations") != iterations:
        return None
    check_same_config(path, summary, data)
    return summary


def check_same_config(path: Path, summary: Mapping[str, Any], data: Mapping[str, Any]) -> None:
    """A finished run's config (in its summary at ``path``) is ``data`` outside
    :data:`FREE_KEYS`; else :class:`LeaderboardError` naming the first key that differs."""
    from vdtn_marl.reporting.tables import flatten

    old, new = flatten(summary.get("config") or {}), flatten(dict(data))
    for key in sorted(set(old) & set(new)):
        free = key in FREE_KEYS or key.split(".")[0] in FREE_KEYS
        if not free and old[key] != new[key]:
            raise LeaderboardError(
                f"{path} was run with {key}={old[key]!r}, the benchmark now gives "
                f"{key}={new[key]!r}; bump benchmark.version (a new out_dir) or remove "
                f"{path.parent} to run it again"
            )
