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


def _directory(cfg: dict, package: str) -> Path:
    """The folder of ``package``, through the nearest mapped parent of ``package-dir``."""
    mapped = cfg.get("package-dir", {})
    parts = package.split(".")
    for cut in range(len(parts), 0, -1):
        parent = ".".join(parts[:cut])
        if parent in mapped:
            return ROOT / mapped[parent] / Path(*parts[cut:])
    return ROOT / Path(*parts)


def test_every_listed_package_exists():
    """A listed package without a directory (git drops empty ones) breaks the build; a data
    folder is listed so that setuptools does not warn about it, and must hold files."""
    cfg = _setuptools_config()
    for package in cfg["packages"]:
        directory = _directory(cfg, package)
        assert directory.is_dir(), f"{package}: {directory} is not a folder"
        assert any(p.is_file() for p in directory.iterdir()), f"{package}: {directory} is empty"


def test_every_data_folder_is_listed_in_pyproject():
    """setuptools warns at every build about a folder of a package it is not told of."""
    cfg = _setuptools_config()
    listed = set(cfg["packages"])
    folders = {
        f"{package}.{'.'.join(path.relative_to(_directory(cfg, package)).parts)}"
        for package in listed
        for path in _directory(cfg, package).rglob("*")
        if path.is_dir()
        and "__pycache__" not in path.parts
        and any(f.is_file() for f in path.iterdir())  # a folder of folders is not warned about
    }
    missing = sorted(folders - listed)
    assert not missing, f"add to [tool.setuptools] packages in pyproject.toml: {missing}"


def test_hydra_conf_tree_ships_as_vdtn_marl_conf():
    cfg = _setuptools_config()
    assert "vdtn_marl.conf" in cfg["packages"]
    assert cfg["package-dir"]["vdtn_marl.conf"] == "conf"
    assert "**/*.yaml" in cfg["package-data"]["vdtn_marl.conf"]
    # Without __init__.py, an editable install cannot import vdtn_marl.conf.
    assert (ROOT / "conf" / "__init__.py").is_file()
