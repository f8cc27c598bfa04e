"""docs/cli.md quotes exactly the `pip check` lines that scripts/ray_check.sh allows after the
documented `--no-deps` step of the Ray plugin, with the versions of constraints-ray.txt."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _expected_lines() -> list[str]:
    script = (ROOT / "scripts" / "ray_check.sh").read_text(encoding="utf-8")
    block = re.search(r"EXPECTED_PIP_CHECK=\(\n(.*?)\n\)", script, re.S)
    assert block, "scripts/ray_check.sh lists the pip check lines it allows"
    return re.findall(r'^\s*"(.*)"\s*$', block.group(1), re.M)


def _pins() -> dict[str, str]:
    text = (ROOT / "constraints-ray.txt").read_text(encoding="utf-8")
    return dict(re.findall(r"^([A-Za-z0-9_.-]+)==(\S+)", text, re.M))


def test_the_docs_quote_the_pip_check_lines_the_ray_check_allows():
    lines = _expected_lines()
    assert len(lines) == 2
    docs = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    block = re.search(r"\$ pip check\n(.*?)\n```", docs, re.S)
    assert block, "docs/cli.md shows what pip check prints in the Ray environment"
    assert block.group(1).splitlines() == lines


def test_the_allowed_pip_check_lines_name_the_pinned_versions():
    pins = _pins()
    plugin = f"hydra-ray-launcher {pins['hydra-ray-launcher']} "
    boto, cloudpickle = _expected_lines()
    assert boto == f"{plugin}requires boto3, which is not installed."
    assert cloudpickle == (
        f"{plugin}has requirement cloudpickle<3, but you have cloudpickle {pins['cloudpickle']}."
    )
    assert "boto3" not in pins  # the --no-deps step leaves it out
