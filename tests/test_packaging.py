"""pyproject.toml lists packages explicitly (so conf/ can ship as vdtn_marl.conf): keep it whole."""

from __future__ import annotations

from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib")

ROOT = Path(__file__).resolve().parents[1]


def _setuptools_config() -> dict:
    with open(ROOT / "pyproject.toml", "rb") as f:
        return tomllib.load(f)["tool"]["setuptools"]


def test_every_python_package_is_listed_in_pyproject():
    listed = set(_setuptools_config()["packages"])
    on_disk = {
        ".".join(path.parent.relative_to(ROOT).parts)
        for path in (ROOT / "vdtn_marl").rglob("*.py")
        if "__pycache__" not in path.parts
    }
    missing = sorted(on_disk - listed)
    assert not missing, f"add to [tool.setuptools] packages in pyproject.toml: {missing}"


def test_every_listed_package_exists():
    """A listed package without a directory (git drops empty ones) breaks the build."""
    cfg = _setuptools_config()
    for package in cfg["packages"]:
        directory = cfg.get("package-dir", {}).get(package, package.replace(".", "/"))
        assert list((ROOT / directory).glob("*.py")), f"{package}: no .py files in {directory}/"


def test_hydra_conf_tree_ships_as_vdtn_marl_conf():
    cfg = _setuptools_config()
    assert "vdtn_marl.conf" in cfg["packages"]
    assert cfg["package-dir"]["vdtn_marl.conf"] == "conf"
    assert "**/*.yaml" in cfg["package-data"]["vdtn_marl.conf"]
    # Without __init__.py, an editable install cannot import vdtn_marl.conf.
    assert (ROOT / "conf" / "__init__.py").is_file()
