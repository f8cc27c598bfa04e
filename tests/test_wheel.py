"""A wheel built from the repository works when installed, from a directory outside the repo.

The wheel is built from a copy of the sources (so the build leaves nothing in the checkout) and
installed into a fresh virtual environment. That environment reaches the dependencies (torch,
hydra, ...) through a ``.pth`` file pointing at the test interpreter's site-packages, which
adds the folder to ``sys.path`` without running its ``.pth`` files: the editable install of
the checkout stays invisible, so ``vdtn_marl`` and its Hydra configs come from the wheel only.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.slow  # runs of the CLI or of training (the fast loop skips them)

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "conf", "vdtn_marl")


def _run(args, cwd: Path, env: dict | None = None, timeout: float = 300):
    return subprocess.run(
        [str(a) for a in args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(bin dir of a fresh venv with the wheel installed, a work dir outside the repo, env)."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info")
    for name in SOURCES:
        path = ROOT / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=ignore)
        elif path.exists():
            shutil.copy2(path, src / name)

    dist = tmp / "dist"
    build = _run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation",
         "--disable-pip-version-check", "-w", dist, src],
        cwd=tmp,
    )  # fmt: skip
    assert build.returncode == 0, build.stdout + build.stderr
    # a first install is quiet: no setuptools banner (e.g. a data folder not in `packages`)
    assert "Warning" not in build.stdout + build.stderr, build.stdout + build.stderr
    (wheel,) = dist.glob("vdtn_marl-*.whl")

    venv = tmp / "venv"
    made = _run([sys.executable, "-m", "venv", "--without-pip", venv], cwd=tmp)
    assert made.returncode == 0, made.stderr
    python = venv / "bin" / "python"
    purelib = _run(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=tmp
    ).stdout.strip()
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    Path(purelib, "_vdtn_marl_test_deps.pth").write_text("\n".join(sorted(deps)) + "\n")
    install = _run(
        [sys.executable, "-m", "pip", "--python", python, "install", "--no-deps",
         "--disable-pip-version-check", "-q", wheel],
        cwd=tmp,
    )  # fmt: skip
    assert install.returncode == 0, install.stdout + install.stderr

    work = tmp / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    env["COLUMNS"] = "200"
    return {"wheel": wheel, "bin": venv / "bin", "work": work, "env": env}


def test_wheel_ships_every_config(installed):
    with zipfile.ZipFile(installed["wheel"]) as wheel:
        names = set(wheel.namelist())
    on_disk = {
        "vdtn_marl/conf/" + p.relative_to(ROOT / "conf").as_posix()
        for p in (ROOT / "conf").rglob("*.yaml")
    }
    assert on_disk, "conf/ holds no yaml"
    assert on_disk <= names, sorted(on_disk - names)
    assert "vdtn_marl/conf/hydra/launcher/joblib.yaml" in names
    tasks = {
        p.relative_to(ROOT).as_posix()
        for p in (ROOT / "vdtn_marl/integrations/benchmarl/conf").rglob("*.yaml")
    }
    assert tasks and tasks <= names, sorted(tasks - names)  # the BenchMARL task configs
    assert {"vdtn_marl/reporting/tables.py", "vdtn_marl/io/files.py"} <= names
    cycles = {f"vdtn_marl/data/cycles/{p.name}" for p in (ROOT / "vdtn_marl/data/cycles").glob("*")}
    assert cycles == {"vdtn_marl/data/cycles/udds.csv", "vdtn_marl/data/cycles/hwfet.csv"}
    assert cycles <= names, sorted(cycles - names)
    drives = {f"vdtn_marl/data/drives/{p.name}" for p in (ROOT / "vdtn_marl/data/drives").glob("*")}
    assert {f"vdtn_marl/data/drives/{n}" for n in ("LICENSE", "NOTICE", "README.md")} <= drives
    assert len([n for n in drives if n.endswith(".csv")]) == 22
    assert drives <= names, sorted(drives - names)


def test_installed_package_comes_from_the_wheel(installed):
    """The installed package, its configs and its bundled driving cycles come from the wheel."""
    result = _run(
        [installed["bin"] / "python", "-c",
         "import vdtn_marl, vdtn_marl.conf; print(vdtn_marl.__file__); "
         "print(vdtn_marl.conf.__file__); from vdtn_marl.data import load_driving_cycle; "
         "print(load_driving_cycle('hwfet').duration_s)"],
        cwd=installed["work"], env=installed["env"],
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    *files, duration = result.stdout.split()
    for line in files:
        assert Path(line).is_relative_to(installed["bin"].parent), line
    assert float(duration) == 765.0


def test_installed_cli_lists_envs(installed):
    result = _run([installed["bin"] / "vdtn-marl", "envs"], installed["work"], installed["env"])
    assert result.returncode == 0, result.stderr
    assert "vdtn/vdtn-joint-v1" in result.stdout


def test_installed_cli_composes_configs_from_the_wheel(installed):
    result = _run(
        [installed["bin"] / "vdtn-marl", "jocc", "experiment=smoke", "scenario=platoon4_1mhz",
         "--cfg", "job"],
        installed["work"], installed["env"],
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    cfg = yaml.safe_load(result.stdout)
    assert cfg["scenario"]["subchannel_bandwidth_hz"] == 1e6
    assert cfg["experiment"]["name"] == "smoke"
    bad = _run(
        [installed["bin"] / "vdtn-marl", "jocc", "rra.kappa1=2"],
        installed["work"], installed["env"],
    )  # fmt: skip
    assert bad.returncode == 2 and bad.stderr.startswith("error: rra.kappa1=2")
    assert list(installed["work"].iterdir()) == []


def test_installed_cli_smoke_run(installed):
    result = _run(
        [installed["bin"] / "vdtn-marl", "jocc", "experiment=smoke"],
        installed["work"], installed["env"], timeout=600,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    (run_dir,) = (installed["work"] / "outputs" / "jocc").iterdir()
    assert (run_dir / "summary.json").is_file() and (run_dir / "config.yaml").is_file()
