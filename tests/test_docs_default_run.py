"""docs/training.md, "What the default run does", states the defaults the code has."""

from __future__ import annotations

import re
from pathlib import Path

from vdtn_marl.experiment.config import RunConfig

ROOT = Path(__file__).resolve().parents[1]


def _section() -> str:
    text = (ROOT / "docs" / "training.md").read_text(encoding="utf-8")
    start = text.index("## What the default run does")
    end = text.find("\n## ", start + 1)
    return text[start : end if end > 0 else None]


def _default(key: str):
    value = RunConfig()
    for part in key.split("."):
        value = getattr(value, part)
    return value


# the settings the section gives as the default run's (the others it names are alternatives)
DEFAULTS = (
    "experiment.jocc_iterations",
    "control.warm_start",
    "control.pi_star_critic_warmup",
    "experiment.control_iterations",
    "control.pi_star_validate_every",
    "control.augmentation",
    "control.completion",
    "experiment.rra_iterations",
    "rra.kappa1",
    "rra.term_scales",
    "rra.ivoi_estimator",
    "rra.warm_start",
    "rra.value_fit",
    "rra.validate_every",
    "experiment.eval_episodes",
    "experiment.eval_intervals",
)


def _text(value) -> str:
    return str(value).lower() if isinstance(value, bool) else str(value)


def test_the_default_run_section_states_the_code_defaults():
    section = _section()
    for key in DEFAULTS:
        assert f"`{key}={_text(_default(key))}`" in section, key


def test_the_default_run_section_quotes_no_measured_numbers():
    section = _section()
    assert not re.search(r"\bwas\b|earlier runs|gave a", section)
    assert not re.search(r"\d+(\.\d+)? ?%(?! interval)", section)  # no measured percentages
