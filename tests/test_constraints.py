"""The tested sets: constraints.txt, and constraints-<extra>.txt for each extra that needs its own
environment (scripts/benchmarl_check.sh and scripts/ray_check.sh build them).

Every requirement of the package, and of the extras a set is for, is pinned there to a version
the requirement accepts; an extra's set keeps the pins of constraints.txt, except the ones its
library forces down (BenchMARL 1.5.x requires torchrl<0.12, and tensordict goes with it)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

tomllib = pytest.importorskip("tomllib")

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
EXTRA_SETS = sorted(
    extra
    for extra in PYPROJECT["optional-dependencies"]
    if (ROOT / f"constraints-{extra}.txt").is_file()
)
#: pins of constraints.txt that an extra's set may move, and why
MOVED_BY = {"benchmarl": {"torchrl", "tensordict"}}  # BenchMARL 1.5.x: torchrl<0.12


def pins(name: str) -> dict[str, str]:
    """Package (canonical name) → pinned version of the constraints file ``name``."""
    out = {}
    for line in (ROOT / name).read_text().splitlines():
        match = re.match(r"^([A-Za-z0-9_.-]+)==(\S+)$", line.strip())
        if match:
            out[canonicalize_name(match.group(1))] = match.group(2)
        else:
            assert not line.strip() or line.startswith("#"), f"{name}: {line!r} is not a pin"
    return out


def check_pinned(requirements: list[str], pinned: dict[str, str], where: str) -> None:
    for text in requirements:
        requirement = Requirement(text)
        name = canonicalize_name(requirement.name)
        assert name in pinned, f"{where} does not pin {requirement.name}"
        assert requirement.specifier.contains(pinned[name], prereleases=True), (
            f"{where} pins {name}=={pinned[name]}, outside {text!r}"
        )


def test_there_are_extra_sets():
    assert {"benchmarl", "ray"} <= set(EXTRA_SETS)


def test_constraints_pin_the_package_and_its_test_extra():
    pinned = pins("constraints.txt")
    check_pinned(PYPROJECT["dependencies"], pinned, "constraints.txt")
    check_pinned(PYPROJECT["optional-dependencies"]["test"], pinned, "constraints.txt")


@pytest.mark.parametrize("extra", EXTRA_SETS)
def test_an_extra_set_pins_the_package_and_its_extras(extra):
    optional = PYPROJECT["optional-dependencies"]
    for requirements in (PYPROJECT["dependencies"], optional["test"], optional[extra]):
        check_pinned(requirements, pins(f"constraints-{extra}.txt"), f"constraints-{extra}.txt")


@pytest.mark.parametrize("extra", EXTRA_SETS)
def test_an_extra_set_keeps_the_main_pins(extra):
    main = pins("constraints.txt")
    pinned = pins(f"constraints-{extra}.txt")
    allowed = MOVED_BY.get(extra, set())
    moved = {n: (v, pinned[n]) for n, v in main.items() if n in pinned and pinned[n] != v}
    assert set(moved) == allowed, moved
    if not allowed:  # a set that moves nothing drops nothing (benchmarl's drops hoptorch,
        assert set(main) <= set(pinned)  # which only torchrl 0.14 needs)


def test_the_ray_set_keeps_what_hydra_ray_launchers_own_resolve_would_downgrade():
    """Resolved with its dependencies, hydra-ray-launcher 1.2.2 pulls cloudpickle<3 and (through
    boto3) python-dateutil<3; installed with --no-deps it leaves our pins alone."""
    main, ray = pins("constraints.txt"), pins("constraints-ray.txt")
    for name in ("cloudpickle", "python-dateutil"):
        assert ray[name] == main[name]
    assert "boto3" not in ray and ray["hydra-ray-launcher"] == "1.2.2"
