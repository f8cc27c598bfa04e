"""Run outputs: the metrics log and its optional TensorBoard writer."""

from __future__ import annotations

import csv
import sys
import types

import pytest

from vdtn_marl.io.metrics import MetricsLog


class _FakeWriter:
    """Stands in for ``SummaryWriter``: creates its folder like the real one and keeps the
    scalars it is given."""

    opened: list = []

    def __init__(self, log_dir: str):
        from pathlib import Path

        Path(log_dir).mkdir(parents=True, exist_ok=True)
        self.scalars: list[tuple[str, float, int]] = []
        _FakeWriter.opened.append(self)

    def add_scalar(self, key, value, step):
        self.scalars.append((key, value, step))

    def flush(self):
        pass

    def close(self):
        pass


@pytest.fixture
def fake_tensorboard(monkeypatch):
    _FakeWriter.opened = []
    module = types.ModuleType("torch.utils.tensorboard")
    module.SummaryWriter = _FakeWriter
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", module)
    return _FakeWriter


def test_a_log_without_scalars_leaves_no_tensorboard_folder(tmp_path, fake_tensorboard):
    log = MetricsLog(tmp_path)
    log.log({"iteration": 0, "stage": "pi_star"})  # no step: CSV only
    log.close()
    assert not (tmp_path / "tensorboard").exists()
    assert fake_tensorboard.opened == []
    with open(tmp_path / "metrics.csv", newline="", encoding="utf-8") as handle:
        assert list(csv.DictReader(handle)) == [{"iteration": "0", "stage": "pi_star"}]


def test_scalars_go_to_one_writer_opened_on_first_use(tmp_path, fake_tensorboard):
    log = MetricsLog(tmp_path)
    log.log({"cost": 0.5, "stage": "rra", "done": True}, step=1)
    log.log({"cost": 0.25, "frames": 64}, step=2)
    log.close()
    assert (tmp_path / "tensorboard").is_dir()
    assert len(fake_tensorboard.opened) == 1
    # strings and bools are not scalars
    assert fake_tensorboard.opened[0].scalars == [
        ("cost", 0.5, 1),
        ("cost", 0.25, 2),
        ("frames", 64, 2),
    ]


def test_tensorboard_off_never_opens_a_writer(tmp_path, fake_tensorboard):
    log = MetricsLog(tmp_path, tensorboard=False)
    log.log({"cost": 0.5}, step=1)
    assert fake_tensorboard.opened == []
    assert not (tmp_path / "tensorboard").exists()


def test_missing_tensorboard_is_not_an_error(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch.utils.tensorboard", None)  # import fails
    log = MetricsLog(tmp_path)
    log.log({"cost": 0.5}, step=1)
    assert (tmp_path / "metrics.csv").exists()
    assert not (tmp_path / "tensorboard").exists()
