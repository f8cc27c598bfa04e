"""Drawing the next interval's random numbers on a second thread (``DigitalTwin(draw_ahead=
True)``, :class:`~vdtn_marl.sim.link.DrawAhead`) gives the numbers of drawing in place, bit for
bit: across partial resets, extra draws from the twin's generator, snapshots and deep copies."""

import copy
import subprocess
import sys

import pytest
import torch

from vdtn_marl.errors import ConfigError
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim import link
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.snapshot import export_state, import_state
from vdtn_marl.sim.twin import DigitalTwin

PARAMS = TwinParams.from_overrides(episode_intervals=30)
CACC = CACCController(PARAMS.platoon)


def _twin(batch: int, draw_ahead: bool, fading_draws: str = "normal") -> DigitalTwin:
    twin = DigitalTwin(
        PARAMS, batch_size=batch, seed=3, draw_ahead=draw_ahead, fading_draws=fading_draws
    )
    assert twin.draw_ahead is draw_ahead
    return twin


def _interval(twin: DigitalTwin, actions: torch.Generator) -> list[torch.Tensor]:
    shape = (twin.batch_size, twin.num_links)
    observations = []
    for _ in range(twin.subframes_per_interval):
        observations.append(twin.rra_observation().clone())
        twin.step_subframe(torch.randint(0, PARAMS.radio.num_actions, shape, generator=actions))
    record = twin.finish_interval(CACC(twin.vehicle_observation(perfect=False)), perfect=False)
    return [torch.stack(observations), record.reward, record.cam_delay_subframes]


def _episode(twin: DigitalTwin, intervals: int = 7) -> list[torch.Tensor]:
    """Intervals with a partial reset, an extra draw from the twin's generator (as an
    environment's burn-in makes), a full reset and a restart (new episodes in some scenarios,
    the next interval in the others) in between."""
    actions = torch.Generator().manual_seed(1)
    some = torch.arange(twin.batch_size) % 3 == 0
    out = []
    for k in range(intervals):
        if k == 2:
            twin.reset(mask=some)  # begins their interval; the others begin theirs next
            twin.begin_interval(~some)
        elif k == 3:
            out.append(torch.randn(4, generator=twin.generator))
            twin.begin_interval()
        elif k == 4:
            twin.reset()
        elif k == 5:
            twin.restart(some)
        elif k:
            twin.begin_interval()
        out += _interval(twin, actions)
    return out


def _assert_equal(got: list[torch.Tensor], want: list[torch.Tensor]) -> None:
    assert len(got) == len(want)
    for i, (a, b) in enumerate(zip(got, want, strict=True)):
        assert torch.equal(a, b), f"output {i} differs"


@pytest.mark.parametrize("fading_draws", ["normal", "exponential"])
@pytest.mark.parametrize("batch", [link.DRAW_AHEAD_MIN_BATCH, link.LINK_MAJOR_MIN_BATCH])
def test_drawing_ahead_gives_the_numbers_of_drawing_in_place(batch, fading_draws):
    ahead, inline = _twin(batch, True, fading_draws), _twin(batch, False, fading_draws)
    _assert_equal(_episode(ahead), _episode(inline))


class _AtOnce:
    """A stand-in for ``threading.Thread`` that runs its job at ``start()``: the draws ahead are
    then all made before the twin reads this interval's."""

    def __init__(self, target, name=None, daemon=None):
        self._target = target

    def start(self) -> None:
        self._target()

    def join(self) -> None:
        pass


@pytest.mark.parametrize("fading_draws", ["normal", "exponential"])
@pytest.mark.parametrize("batch", [link.DRAW_AHEAD_MIN_BATCH, link.LINK_MAJOR_MIN_BATCH])
def test_draws_ahead_never_overwrite_the_interval_being_built(monkeypatch, batch, fading_draws):
    """The next interval's draws start as soon as this interval's are taken, before its tables
    and observations are built from them: into the other of two buffers. Drawing them at once
    (the slowest main thread a real thread could meet) must change nothing."""
    inline = _episode(_twin(batch, False, fading_draws))
    monkeypatch.setattr(link.threading, "Thread", _AtOnce)
    _assert_equal(_episode(_twin(batch, True, fading_draws)), inline)


def test_draws_ahead_are_used_when_nothing_drew_and_redrawn_when_something_did(monkeypatch):
    twin = _twin(link.DRAW_AHEAD_MIN_BATCH, True)
    taken = []
    take = link.DrawAhead.take

    def recorded(self, generator):
        taken.append(take(self, generator))
        return taken[-1]

    monkeypatch.setattr(link.DrawAhead, "take", recorded)
    _episode(twin)
    # interval 1: the draws made ahead; 2: the partial reset drew first, so the reset
    # scenarios' start draws again, and the others' start takes the draws made after it; 3:
    # an extra draw came first; 4: the full reset drew first; 5: the restart takes the
    # interval's draws before its new episodes draw; 6: the draws made ahead after them
    assert [draws is not None for draws in taken] == [True, False, True, False, False, True, True]


def test_a_snapshot_or_a_copy_with_draws_pending_continues_as_the_twin_does():
    actions = torch.Generator().manual_seed(5)
    twin = _twin(link.DRAW_AHEAD_MIN_BATCH, True)
    _interval(twin, actions)
    twin.begin_interval()  # the next interval's draws are now being made ahead
    assert twin._workspace.ahead is not None
    snapshot, duplicate = export_state(twin), copy.deepcopy(twin)
    restored = _twin(link.DRAW_AHEAD_MIN_BATCH, True)
    _interval(restored, torch.Generator().manual_seed(9))
    import_state(restored, snapshot)
    runs = []
    for other in (twin, duplicate, restored):
        gen = torch.Generator().manual_seed(7)
        out = []
        for _ in range(3):
            out += _interval(other, gen)
            other.begin_interval()
        runs.append(out)
    _assert_equal(runs[1], runs[0])
    _assert_equal(runs[2], runs[0])


def test_an_error_while_drawing_ahead_is_raised_by_the_next_interval(monkeypatch):
    twin = _twin(link.DRAW_AHEAD_MIN_BATCH, True)

    def broken(*args):
        raise RuntimeError("draw failed")

    twin._workspace.ahead._thread.join()  # the draws made at the reset are done
    monkeypatch.setattr(link, "draw_fading", broken)
    _interval(twin, torch.Generator().manual_seed(1))
    twin.begin_interval()  # takes those draws and starts one that fails
    twin._workspace.ahead._thread.join()
    monkeypatch.undo()
    _interval(twin, torch.Generator().manual_seed(1))
    with pytest.raises(RuntimeError, match="draw failed"):
        twin.begin_interval()


def test_draw_ahead_only_where_it_pays():
    below = link.DRAW_AHEAD_MIN_BATCH - 1
    assert not DigitalTwin(PARAMS, batch_size=below, draw_ahead=True).draw_ahead
    assert not DigitalTwin(PARAMS, batch_size=1, backend="numpy", draw_ahead=True).draw_ahead
    assert DigitalTwin(PARAMS, batch_size=link.DRAW_AHEAD_MIN_BATCH).draw_ahead  # the default
    with pytest.raises(ConfigError, match="draw_ahead"):
        DigitalTwin(PARAMS, batch_size=1, draw_ahead="no")


def test_the_interpreter_exits_cleanly_with_draws_pending():
    """A draw still running at exit is waited for: finalizing the interpreter under a running
    torch kernel aborts the process ('terminate called without an active exception')."""
    code = (
        "from vdtn_marl.sim.twin import DigitalTwin\n"
        "twin = DigitalTwin(batch_size=4096, seed=1)\n"
        "assert twin._workspace.ahead is not None\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "terminate" not in done.stderr
