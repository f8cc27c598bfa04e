"""Disjoint evaluation windows (DisjointWindowSource) and the scenario.eval_windows switch."""

from __future__ import annotations

import inspect
from dataclasses import replace

import numpy as np
import pytest
import torch

from vdtn_marl.data import (
    DisjointWindowSource,
    ProfileTraceSource,
    SpeedProfile,
    TooFewWindowsError,
)
from vdtn_marl.data.selection import (
    EVAL_LOOKAHEAD_INTERVALS,
    EVAL_WINDOWS,
    check_eval_windows,
    file_sources,
    named_sources,
)
from vdtn_marl.experiment.config import RunConfig, ScenarioConfig, validate
from vdtn_marl.sim.params import ConfigError

DT = 0.05


def _clock(durations: list[float]) -> ProfileTraceSource:
    """Profiles whose speed is 1000·i + time since the profile's start: a sample's value tells
    which profile and which instant it came from."""
    profiles = []
    for i, d in enumerate(durations):
        t = np.arange(0.0, d + 1e-9, 1.0)
        profiles.append(SpeedProfile(t + 50.0, 1000.0 * i + t, f"veh{i}", "clock"))
    return ProfileTraceSource(profiles)


def _windows(x: torch.Tensor) -> list[tuple[int, float, float]]:
    """(profile, start s, end s) of each sampled row of a :func:`_clock` source."""
    out = []
    for row in x.double().numpy():
        profile = int(row[0] // 1000)
        out.append((profile, row[0] - 1000 * profile, row[-1] - 1000 * profile))
    return out


def _gen(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


def test_window_count_follows_the_tiling_rule():
    # 401 points at 50 ms: 20 s windows, 20.05 s apart
    src = DisjointWindowSource(_clock([19.0, 20.0, 40.0, 41.0, 100.0]))
    assert src.windows_per_profile(401, DT).tolist() == [0, 1, 1, 2, 4]
    assert src.count(401, DT) == 8
    assert src.count(2, 1.0) == 10 + 10 + 20 + 21 + 50  # 1 s windows, 2 s apart


def test_windows_are_disjoint_of_the_right_length_and_inside_their_profile():
    durations = [60.0, 100.0, 33.0, 250.0]
    src = DisjointWindowSource(_clock(durations))
    total = src.count(401, DT)
    assert total == 2 + 4 + 1 + 12
    x = src.sample(total, 401, DT, _gen(3))
    assert x.shape == (total, 401) and torch.isfinite(x).all()
    # consecutive points 50 ms apart (speed = time), so every window lasts 20 s
    np.testing.assert_allclose(x.double().diff(dim=1).numpy(), DT, atol=1e-3)
    windows = _windows(x)
    assert len(set(windows)) == total
    for profile, start, end in windows:
        assert end - start == pytest.approx(20.0, abs=1e-3)
        assert 0.0 <= start and end <= durations[profile] + 1e-6
    for a in windows:
        for b in windows:
            if a != b and a[0] == b[0]:
                assert a[2] < b[1] or b[2] < a[1], (a, b)  # not even one shared instant
    # every window of every profile is handed out once
    per_profile = np.bincount([w[0] for w in windows], minlength=len(durations))
    assert per_profile.tolist() == src.windows_per_profile(401, DT).tolist()


def test_windows_and_their_order_are_fixed_by_the_seed():
    src = DisjointWindowSource(_clock([300.0, 200.0]))
    a = src.sample(6, 401, DT, _gen(7))
    assert torch.equal(a, src.sample(6, 401, DT, _gen(7)))
    assert not torch.equal(a, src.sample(6, 401, DT, _gen(8)))
    # a batch of 6 is a prefix of the seed's order: same seed, more traces, same first rows
    # (the per-profile shift is drawn first, then the order)
    assert torch.equal(src.sample(8, 401, DT, _gen(7))[:6], a)


def test_too_few_windows_is_one_line_naming_available_and_needed():
    src = DisjointWindowSource(_clock([60.0, 45.0]))
    assert src.count(401, DT) == 2 + 2
    src.sample(4, 401, DT, _gen(0))
    with pytest.raises(TooFewWindowsError) as info:
        src.sample(5, 401, DT, _gen(0))
    message = str(info.value)
    assert "\n" not in message
    assert "4 disjoint windows of 20 s" in message and "5 needed" in message
    assert (info.value.available, info.value.needed) == (4, 5)
    assert isinstance(info.value, ValueError)
    with pytest.raises(TooFewWindowsError, match="0 disjoint windows of 99.95 s"):
        src.sample(1, 2000, DT, _gen(0))


def test_disjoint_keeps_the_name_and_says_so():
    base = _clock([100.0])
    src = DisjointWindowSource(base)
    assert src.info.name == base.info.name and "disjoint windows" in src.info.description
    assert src.profiles == base.profiles and len(src) == 1
    with pytest.raises(TypeError):
        DisjointWindowSource("udds")  # type: ignore[arg-type]


# ------------------------------------------------------------------ selection and config


def test_selection_wraps_only_a_recorded_eval_part():
    for name in ("udds", "cmap"):
        train, evaluation = named_sources(name, "disjoint")
        assert isinstance(train, ProfileTraceSource)
        assert isinstance(evaluation, DisjointWindowSource)
        assert isinstance(named_sources(name)[1], ProfileTraceSource)
    assert named_sources("synthetic", "disjoint") == ("synthetic", "synthetic")
    with pytest.raises(ConfigError, match="scenario.eval_windows='overlap'"):
        named_sources("udds", "overlap")


def test_file_sources_take_the_switch(tmp_path):
    path = tmp_path / "drive.csv"
    t = np.arange(0, 301)
    path.write_text("time_s,speed_mps\n" + "".join(f"{s},{10 + s % 7}\n" for s in t))
    _, evaluation = file_sources("csv", str(path), "disjoint")
    assert isinstance(evaluation, DisjointWindowSource)
    assert evaluation.count(401, DT) == 2  # the last 20 % (60 s) of one drive
    assert isinstance(file_sources("csv", str(path))[1], ProfileTraceSource)


def test_eval_lookahead_is_the_twins_default():
    from vdtn_marl.sim.twin import DigitalTwin

    default = inspect.signature(DigitalTwin).parameters["lookahead_intervals"].default
    assert EVAL_LOOKAHEAD_INTERVALS == default


def test_config_switch_defaults_to_disjoint_and_is_validated():
    assert ScenarioConfig().eval_windows == "disjoint" and EVAL_WINDOWS == ("random", "disjoint")
    cfg = RunConfig()
    validate(replace(cfg, scenario=replace(cfg.scenario, traces="cmap", eval_windows="disjoint")))
    with pytest.raises(ConfigError, match="scenario.eval_windows='all' is not allowed"):
        validate(replace(cfg, scenario=replace(cfg.scenario, eval_windows="all")))
    # the EPA city cycle's last 20 % holds 13 disjoint 20 s windows, not the 16 evaluated
    udds = replace(cfg, scenario=replace(cfg.scenario, traces="udds", eval_windows="disjoint"))
    with pytest.raises(ConfigError) as info:
        validate(udds)
    assert "13 disjoint windows of 20 s" in str(info.value)
    assert "experiment.eval_episodes=16" in str(info.value) and "\n" not in str(info.value)
    validate(replace(udds, experiment=replace(cfg.experiment, eval_episodes=13)))
    check_eval_windows(
        "synthetic", None, "disjoint", episodes=10**6, episode_intervals=200,
        control_interval_s=DT,
    )  # fmt: skip


def test_jocc_evaluates_on_disjoint_windows_when_asked():
    from vdtn_marl.experiment.jocc import trace_sources
    from vdtn_marl.sim.twin import DigitalTwin

    cfg = RunConfig()
    cfg = replace(cfg, scenario=replace(cfg.scenario, traces="cmap", eval_windows="disjoint"))
    train, evaluation = trace_sources(cfg)
    assert isinstance(train, ProfileTraceSource)
    assert isinstance(evaluation, DisjointWindowSource)
    default = replace(cfg, scenario=replace(cfg.scenario, eval_windows="random"))
    assert isinstance(trace_sources(default)[1], ProfileTraceSource)
    twin = DigitalTwin(batch_size=16, seed=5, trace_source=evaluation, radio=False)
    leader = twin.leader_speed_mps[:, 0]  # [B, Λ, K]: the platoon's one leader
    assert leader.shape == (16, twin.params.episode_intervals + 1 + EVAL_LOOKAHEAD_INTERVALS)
    assert len({tuple(row.tolist()) for row in leader}) == 16


def test_readme_table_is_the_summary_output():
    from pathlib import Path

    from vdtn_marl.data.summary import markdown_table, summarize

    assert [s.disjoint_windows for s in summarize("udds")] == [54, 13]
    assert [s.disjoint_windows for s in summarize("hwfet")] == [30, 7]
    doc = (Path(__file__).resolve().parents[2] / "docs" / "leader_traces.md").read_text()
    assert markdown_table() in doc  # regenerate: python -m vdtn_marl.data.summary
