"""The tested sets: constraints.txt, constraints-<extra>.txt for each extra that needs its own
environment (scripts/benchmarl_check.sh and scripts/ray_check.sh build them), and
constraints-extras.txt for the loggers' and the video's extras (scripts/extras_check.sh).

Every requirement of the package, and of the extras a set is for, is pinned there to a version
the requirement accepts; an extra's set keeps the pins of constraints.txt, except the ones its
library forces down (BenchMARL 1.5.x requires torchrl<0.12, and tensordict goes with it; mlflow
requires importlib_metadata<10)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

tomllib = pytest.importorskip("tomllib")

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
#: constraints-<name>.txt → the extras it is the tested set of
EXTRA_SETS = {
    extra: (extra,)
    for extra in PYPROJECT["optional-dependencies"]
    if (ROOT / f"constraints-{extra}.txt").is_file()
}
EXTRA_SETS["extras"] = ("tensorboard", "wandb", "mlflow", "video")  # scripts/extras_check.sh
#: pins of constraints.txt that an extra's set may move, and why
MOVED_BY = {
    "benchmarl": {"torchrl", "tensordict"},  # BenchMARL 1.5.x: torchrl<0.12
    "extras": {"importlib-metadata"},  # mlflow 3.x: importlib_metadata<10
}


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
    assert {"benchmarl", "ray", "extras"} <= set(EXTRA_SETS)
    assert {extra for extras in EXTRA_SETS.values() for extra in extras} <= set(
        PYPROJECT["optional-dependencies"]
    )
    # every constraints-*.txt is one of these sets, so that the tests below check it
    assert {path.name for path in ROOT.glob("constraints-*.txt")} == {
        f"constraints-{name}.txt" for name in EXTRA_SETS
    }


def test_constraints_pin_the_package_and_its_test_extra():
    pinned = pins("constraints.txt")
    check_pinned(PYPROJECT["dependencies"], pinned, "constraints.txt")
    check_pinned(PYPROJECT["optional-dependencies"]["test"], pinned, "constraints.txt")


@pytest.mark.parametrize("extra", sorted(EXTRA_SETS))
def test_an_extra_set_pins_the_package_and_its_extras(extra):
    optional = PYPROJECT["optional-dependencies"]
    groups = [PYPROJECT["dependencies"], optional["test"]]
    groups += [optional[name] for name in EXTRA_SETS[extra]]
    for requirements in groups:
        check_pinned(requirements, pins(f"constraints-{extra}.txt"), f"constraints-{extra}.txt")


@pytest.mark.parametrize("extra", sorted(EXTRA_SETS))
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


def test_the_extras_set_holds_importlib_metadata_below_10_for_mlflow():
    """mlflow 3.x requires importlib_metadata<10, below constraints.txt's pin; lazy-importer,
    which only importlib_metadata 10 needs, is not in the set."""
    main, extras = pins("constraints.txt"), pins("constraints-extras.txt")
    assert int(main["importlib-metadata"].split(".")[0]) >= 10
    assert int(extras["importlib-metadata"].split(".")[0]) < 10
    assert "lazy-importer" in main and "lazy-importer" not in extras
