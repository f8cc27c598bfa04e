"""The package's imports form a DAG of rooms, bottom to top (docs/layout.md):

errors → data, io → sim → core → policies → voi → scenarios → envs (with their registration) →
algos, integrations → reporting → experiment (config schema, compose, JOCC stages, evaluation,
checkpoints, outputs) → leaderboard → cli.

Every ``import`` counts, deferred ones inside functions included. ``__main__`` modules are entry
scripts that no module imports, so they may reach the command line."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vdtn_marl"

#: room (first part below ``vdtn_marl``; "" is the package's own ``__init__``) → floor
LAYERS = {
    "errors": 0,
    "_lazy": 0,
    "data": 1,
    "io": 1,
    "sim": 2,
    "core": 3,
    "policies": 4,
    "voi": 5,
    "scenarios": 6,
    "envs": 7,
    "": 7,
    "algos": 8,
    "integrations": 8,
    "reporting": 9,
    "experiment": 10,
    "leaderboard": 11,
    "cli": 12,
}

#: Imports that still run up a floor, to be moved by the restructuring. The set must match
#: exactly: a new upward import fails, and so does one that is gone but still listed.
KNOWN_UPWARD: set[tuple[str, str]] = set()

#: Old paths of modules that moved to another room before the first release: they are gone
#: (no shims), so nothing may import them.
GONE = (
    "vdtn_marl.algos.jocc", "vdtn_marl.algos.api", "vdtn_marl.cli_help", "vdtn_marl.cli_prepass",
    "vdtn_marl.cli_errors", "vdtn_marl.config", "vdtn_marl.registry", "vdtn_marl.runs",
    "vdtn_marl.results", "vdtn_marl.benchmarking", "vdtn_marl.rollout",
    "vdtn_marl.algos.baselines", "vdtn_marl.algos.rra_baselines",
    "vdtn_marl.algos.control_baselines", "vdtn_marl.algos.mpc_oracle",
    "vdtn_marl.algos.exact_oracle", "vdtn_marl.envs.policies", "vdtn_marl.envs.rra_reward",
    "vdtn_marl.sim.cacc",
)  # fmt: skip


def _modules() -> dict[str, Path]:
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__main__" or "conf" in parts:
            continue
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


@functools.cache
def import_graph() -> dict[str, set[str]]:
    """module → the package's modules it imports (``from P import name`` counts as importing
    ``P.name`` when that is a module, else ``P``)."""
    modules = _modules()

    def owner(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for module, path in modules.items():
        targets = set()
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[: len(package) - node.level + 1] + [base]).strip(".")
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    targets.add(full if full in modules else base)
        graph[module] = {
            t for t in map(owner, (t for t in targets if t.startswith("vdtn_marl"))) if t
        } - {module}
    return graph


def _room(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_graph_sees_deferred_and_relative_imports():
    graph = import_graph()
    assert "vdtn_marl.errors" in graph["vdtn_marl.sim.params"]  # top-level import
    assert "vdtn_marl.experiment.api" in graph["vdtn_marl.leaderboard.runner"]  # inside a function
    assert "vdtn_marl.sim.channel" in graph["vdtn_marl.sim.twin"]  # from vdtn_marl.sim import
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles():
    assert _cycles(import_graph()) == []


def test_every_room_has_a_floor():
    assert {_room(m) for m in import_graph()} <= set(LAYERS)


def test_no_module_sits_beside_the_rooms():
    """Beside the packages only ``errors`` and ``_lazy`` (the packages' lazy re-exports) are
    files."""
    top = {
        ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        for path in PACKAGE.glob("*.py")
        if path.name != "__init__.py"
    }
    assert top == {"vdtn_marl.errors", "vdtn_marl._lazy"}


@pytest.mark.parametrize("module", ["vdtn_marl.errors", "vdtn_marl._lazy"])
def test_the_bottom_modules_import_nothing_of_ours(module):
    assert import_graph()[module] == set()


@pytest.mark.parametrize("room", sorted(LAYERS, key=LAYERS.get))
def test_imports_run_down_the_floors(room):
    graph = import_graph()
    upward = {
        (module, target)
        for module, targets in graph.items()
        if _room(module) == room
        for target in targets
        if LAYERS[_room(target)] > LAYERS[room]
    }
    known = {pair for pair in KNOWN_UPWARD if _room(pair[0]) == room}
    assert upward == known


@pytest.mark.parametrize("old", GONE)
def test_the_old_path_of_a_moved_module_is_gone(old):
    import importlib

    with pytest.raises(ModuleNotFoundError, match=old.rpartition(".")[2]):
        importlib.import_module(old)
    assert old not in import_graph()
    assert not any(old in targets for targets in import_graph().values())


#: packages whose ``__init__`` gives names on first use (:func:`vdtn_marl._lazy.lazy_exports`)
LAZY_PACKAGES = sorted(
    ".".join(path.parent.relative_to(PACKAGE.parent).parts)
    for path in PACKAGE.glob("**/__init__.py")
    if "lazy_exports(" in path.read_text()
)


def test_the_lazy_packages_are_found():
    assert {"vdtn_marl.sim", "vdtn_marl.core", "vdtn_marl.cli"} <= set(LAZY_PACKAGES)


@pytest.mark.parametrize("package", LAZY_PACKAGES)
def test_a_lazy_package_gives_every_name_it_lists(package):
    """Packages that import their modules on first use (so that their light parts read without
    torch or Hydra) list every name they give, give each lazy one from its module, and define
    the others themselves."""
    import importlib

    module = importlib.import_module(package)
    homes = module._HOMES
    assert set(homes) <= set(module.__all__)
    eager = set(module.__all__) - set(homes)
    assert eager <= set(vars(module)), f"{package} lists names it does not define"
    assert set(module.__all__) <= set(dir(module))
    for name, home in homes.items():
        assert getattr(module, name) is getattr(importlib.import_module(f"{package}.{home}"), name)
    with pytest.raises(AttributeError, match="nope"):
        module.nope  # noqa: B018


def test_registry_entries_point_down_the_floors():
    """Entries given as ``"module:Class"`` are imported by name, out of the import graph's
    sight: each one in the package lies on its registry's floor or below."""
    from vdtn_marl.algos.trainer import ALGORITHMS
    from vdtn_marl.policies.registry import RRA_BASELINES
    from vdtn_marl.voi.registry import IVOI_ESTIMATORS

    for registry, room in (
        (ALGORITHMS, "algos"),
        (RRA_BASELINES, "policies"),
        (IVOI_ESTIMATORS, "voi"),
    ):
        for target in registry.values():
            module = target.partition(":")[0]
            if module.startswith("vdtn_marl."):
                assert module in import_graph() and LAYERS[_room(module)] <= LAYERS[room], target
