"""The logger keys docs/cli.md names (its *Loggers* section) are keys a run's loggers write:
``<stage>/<column>`` of a training row, ``eval/<column>`` of an evaluation row."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

from vdtn_marl.algos.ppo import IterationStats
from vdtn_marl.experiment.jocc import STAGES
from vdtn_marl.experiment.metrics import METRIC_KEYS

ROOT = Path(__file__).resolve().parents[1]


def loggers_section() -> str:
    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    start = text.index("### Loggers")
    following = re.search(r"\n#{2,3} ", text[start + 1 :])
    return text[start : start + 1 + following.start()] if following else text[start:]


def test_the_logger_keys_docs_cli_names_are_written():
    named = re.findall(r"`([a-z_]+)/([a-z0-9_]+)`", loggers_section())
    assert len(named) >= 4
    training_stages = [s for s in STAGES if s != "evaluate"]  # what jocc logs training rows as
    training_columns = {f.name for f in dataclasses.fields(IterationStats)}
    for prefix, column in named:
        key = f"{prefix}/{column}"
        if prefix == "eval":
            assert column in METRIC_KEYS, key
        else:
            assert prefix in training_stages, f"{key}: the stages are {training_stages}"
            assert column in training_columns, key
    assert {prefix for prefix, _ in named} == {*training_stages, "eval"}  # each one shown
