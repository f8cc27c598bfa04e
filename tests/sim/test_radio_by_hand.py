"""The radio against numbers computed by hand (docs/model.md §4.4–4.5), on every SINR path.

The other radio tests compare the paths with each other, so a bug they share survives them.
These compare each path with arithmetic written out below, on a topology small enough to do by
hand: two V2V links (vehicle 0 → 1 and 2 → 3), two V2I users (vehicle 4 on sub-channel 0,
vehicle 5 on sub-channel 1), every path gain set by hand, the fast fading fixed to 1.

Units: with the noise at −120 dBm (1e-12 mW) and every transmitter at 20 dBm (100 mW), a path
gain of −140 dB delivers exactly one noise power ("1 u"); −130 dB gives 10 u, −120 dB 100 u,
−150 dB 0.1 u. With a 1 MHz sub-channel, a 1 ms subframe carries 1000·log2(1 + SINR) bits and
a V2I uplink runs at 1e6·log2(1 + SINR) bit/s.

The paths (:func:`vdtn_marl.sim.link.subframe_step` picks one by backend and batch size):
``numpy`` (the single-scenario fast path), ``numpy-dense`` (the ``[B, L, M]`` code on NumPy
arrays, the numpy path's fallback), ``torch-dense`` (torch below ``LINK_MAJOR_MIN_BATCH``),
``torch-link-major`` (torch from ``LINK_MAJOR_MIN_BATCH`` scenarios on), and the link-major
path with its other summation branch (``torch-link-major-matmul``: the batched matmul, taken
where torch does not add in link order). Each path builds its own tables from the same gains
in dB (:func:`~vdtn_marl.sim.link.build_interval_tables`) and steps them with its own kernel.

Which bug each test catches (each bug was introduced on purpose, the tests run and seen to
fail on the paths named, and the bug reverted):

- ``test_v2i_interference_is_read_at_the_v2v_receiver``: the V2I user's interference read at
  the V2V transmitter instead of its receiver (``v2i_to_rx`` built from ``v2v_lin[:, v2i_user]
  [:, :, tx]`` instead of ``[:, :, rx]`` in ``build_interval_tables``): link 0 gets 993 bits
  instead of 5672, on every path.
- ``test_cross_gain_runs_from_the_interferers_tx_to_the_victims_rx``: the V2V cross-gain matrix
  not transposed (``cross_gain[i, j]`` the gain from transmitter i to receiver j instead of
  from transmitter j to receiver i: the ``swapaxes`` dropped in ``build_interval_tables``):
  link 0 gets 5603 bits instead of 3222, on every path; also a kernel that reads the matrix
  transposed (fails on that kernel's paths).
- ``test_kernel_reads_cross_gain_row_receiver_column_transmitter``: a kernel that reads
  ``cross_gain`` transposed, on tables written by hand (``swapaxes`` in the dense or NumPy
  matmul, ``transpose(0, 1)`` or ``permute(2, 1, 0)`` in the link-major kernel's two
  branches): fails on that kernel's paths.
- ``test_v2i_sinr_and_rate``: the V2I SINR at the base station (signal over noise plus the V2V
  transmitters on the sub-channel), which the bugs above do not touch: fails when the V2V
  powers at the BS are read at the receiver (``tx_to_bs`` from ``rx``, every path), summed
  over the sub-channels instead of the links (dense and NumPy kernels), or count a link whose
  CAM is delivered (dense and link-major kernels).
- ``test_cam_whose_last_bits_arrive_in_the_deadline_subframe_is_delivered`` (kernels): a kernel
  that does not record a delivery in the interval's last subframe (fails on that kernel's
  paths; mutated in each of the three kernels).
- ``test_twin_counts_a_deadline_subframe_cam_as_delivered`` (twin, and the PettingZoo infos
  built from its record): a CAM whose last bits arrive in subframe T counted as lost (the
  twin's ``delivered = delay <= t`` in ``finish_interval`` written ``delay < t``: the recipient
  keeps its old content, two intervals old instead of one; or the infos' ``t_sub <= limit``
  written ``<``), with both backends.
- ``test_evaluation_counts_a_deadline_subframe_cam_as_delivered``: the same in the evaluation's
  CAM delivery rate and latency (``in_time = delay <= t`` in ``evaluate_system`` written
  ``delay < t``: a delivery rate of 0 instead of 0.5).

Not covered here: the copies of the deadline rule in the TorchRL face's ``cam_delivered`` info
and in the interval engine's ``lost`` flag for the RRA reward.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
import torch

from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.envs.control import interval_infos
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim import link
from vdtn_marl.sim.layout import VEHICLE_OBS_FEATURES
from vdtn_marl.sim.params import RadioParams, TwinParams
from vdtn_marl.sim.topology import Topology
from vdtn_marl.sim.twin import DigitalTwin

# two V2V links 0 → 1 and 2 → 3; sub-channel m carries the V2I uplink of vehicle 4 + m
TOPOLOGY = Topology(predecessor=(-1, 0, -1, 2, -1, -1), v2i_order=(4, 5, 0, 1, 2, 3), name="hand")
N = TOPOLOGY.num_vehicles
RADIO = RadioParams(
    num_subchannels=2,
    subchannel_bandwidth_hz=1e6,
    v2i_power_dbm=20.0,
    v2v_power_levels_dbm=(20.0, 10.0),  # plus "off"
    noise_power_override_dbm=-120.0,
    cam_size_bits=10_000,
)
SUBFRAME_S = 1e-3
# action = sub-channel · 3 + level (level 0: 20 dBm, 1: 10 dBm, 2: off)
CH0, CH1, OFF = 0, 3, 2

NEGLIGIBLE_DB = -300.0  # 1e-30: 1e-16 u at 20 dBm, far below float32's resolution of 1 u
# path gains G[tx, rx] (dB) from every vehicle to every vehicle; the ones the radio reads:
V2V_DB = np.full((N, N), NEGLIGIBLE_DB)
V2V_DB[0, 1] = -120.0  # link 0's own gain: 100 u
V2V_DB[2, 3] = -130.0  # link 1's own gain: 10 u
V2V_DB[4, 1] = -140.0  # V2I user 4 (sub-channel 0) → link 0's receiver: 1 u
V2V_DB[5, 1] = -150.0  # V2I user 5 (sub-channel 1) → link 0's receiver: 0.1 u
V2V_DB[4, 3] = -140.0  # V2I user 4 → link 1's receiver: 1 u
V2V_DB[5, 3] = -150.0  # V2I user 5 → link 1's receiver: 0.1 u
V2V_DB[2, 1] = -130.0  # link 1's transmitter → link 0's receiver: 10 u
V2V_DB[0, 3] = -150.0  # link 0's transmitter → link 1's receiver: 0.1 u
# what a bug that reads the V2I interference at the transmitter would see instead
V2V_DB[4, 0] = -120.0  # V2I user 4 → link 0's transmitter: 100 u
V2V_DB[5, 0] = -130.0
V2V_DB[4, 2] = -120.0  # V2I user 4 → link 1's transmitter: 100 u
V2V_DB[5, 2] = -130.0  # V2I user 5 → link 1's transmitter: 10 u
# gains to the serving base station (dB)
V2I_DB = np.full(N, NEGLIGIBLE_DB)
V2I_DB[4] = -130.0  # V2I user 4's signal: 10 u
V2I_DB[5] = -120.0  # V2I user 5's signal: 100 u
V2I_DB[0] = -140.0  # link 0's transmitter at the BS: 1 u
V2I_DB[2] = -150.0  # link 1's transmitter at the BS: 0.1 u

PATHS = ("numpy", "numpy-dense", "torch-dense", "torch-link-major", "torch-link-major-matmul")


def bits(sinr: float) -> float:
    """Bits in one 1 ms subframe of a 1 MHz sub-channel."""
    return 1e6 * SUBFRAME_S * math.log2(1.0 + sinr)


def rate_bps(sinr: float) -> float:
    return 1e6 * math.log2(1.0 + sinr)


def _batch(path: str) -> int:
    return link.LINK_MAJOR_MIN_BATCH if path.startswith("torch-link-major") else 1


def run_subframes(path: str, actions: list[list[int]], monkeypatch, radio=RADIO):
    """Build the interval's tables of T = len(actions) subframes from the hand-set gains on
    ``path`` (fast fading 1), step its kernel with ``actions[t]`` [L] in every scenario, and
    return the outcomes (NumPy, scenario 0, after checking that every scenario agrees) and the
    final link state."""
    t, batch = len(actions), _batch(path)
    links, subch = TOPOLOGY.num_links, radio.num_subchannels
    width = link.fading_width(links, subch)
    numpy = path.startswith("numpy")
    v2v_db = np.broadcast_to(V2V_DB, (batch, N, N)).astype(np.float32)
    v2i_db = np.broadcast_to(V2I_DB, (batch, N)).astype(np.float32)
    generator = torch.Generator().manual_seed(0)
    if numpy:  # the NumPy path draws its fading itself: |h|² = 1
        monkeypatch.setattr(
            link, "rayleigh_power_gain", lambda shape, gen, numpy: np.ones(shape, np.float32)
        )
        tables = link.build_interval_tables(v2v_db, v2i_db, radio, t, generator, TOPOLOGY)
        assert isinstance(tables.own_gain, np.ndarray)
    else:  # the torch path is handed the interval's fading draws [T, W, B]: |h|² = 1
        in_order = path != "torch-link-major-matmul"
        monkeypatch.setattr(link, "_torch_adds_in_link_order", lambda *args: in_order)
        tables = link.build_interval_tables(
            torch.from_numpy(v2v_db), torch.from_numpy(v2i_db), radio, t, generator, TOPOLOGY,
            drawn=torch.ones(t, width, batch),
        )  # fmt: skip
    assert link.link_major(batch, numpy) == path.startswith("torch-link-major")
    device = None if numpy else torch.device("cpu")
    state = link.new_link_state(batch, links, subch, radio, t, device)
    const = link.KernelConstants.build(radio, SUBFRAME_S, batch, links, "cpu")
    decode = link.ActionTables.build(radio, torch.device("cpu"))
    if numpy:
        const, decode = const.numpy(), decode.numpy()
    step = link._subframe_step_dense if path == "numpy-dense" else link.subframe_step
    outcomes = []
    for s, row in enumerate(actions):
        act = np.tile(np.asarray(row, np.int64), (batch, 1))
        out = step(tables, s, act if numpy else torch.from_numpy(act), state, decode, const)
        outcomes.append({k: _scenario0(v) for k, v in vars(out).items()})
    return outcomes, {k: _scenario0(v) for k, v in vars(state).items()}


def _scenario0(x) -> np.ndarray:
    x = x.numpy() if isinstance(x, torch.Tensor) else np.asarray(x)
    assert (x == x[:1]).all(), "every scenario holds the same gains"
    return x[0]


@pytest.mark.parametrize("path", PATHS)
def test_v2i_interference_is_read_at_the_v2v_receiver(path, monkeypatch):
    """Link 0 on sub-channel 0 and link 1 on sub-channel 1, both at 20 dBm: no V2V
    interference, only each sub-channel's V2I user's, measured at the link's receiver."""
    (out,), _ = run_subframes(path, [[CH0, CH1]], monkeypatch)
    # link 0: 100 u / (1 u noise + 1 u from V2I user 4 at vehicle 1) = 50
    #   → 1000·log2(51) = 5672.43 bits (at its transmitter, vehicle 0, user 4 would give
    #   100 u: SINR 100/101, 993 bits)
    # link 1: 10 u / (1 u + 0.1 u from V2I user 5 at vehicle 3) = 9.0909
    #   → 1000·log2(10.0909) = 3334.98 bits (at vehicle 2: 10 u, SINR 10/11, 933 bits)
    expected = [bits(100 / (1 + 1)), bits(10 / (1 + 0.1))]
    assert expected == pytest.approx([5672.43, 3334.98], abs=0.01)
    np.testing.assert_allclose(out["v2v_bits"], expected, rtol=1e-5)
    np.testing.assert_allclose(out["v2v_power_mw"], [100.0, 100.0], rtol=1e-6)


@pytest.mark.parametrize("path", PATHS)
def test_cross_gain_runs_from_the_interferers_tx_to_the_victims_rx(path, monkeypatch):
    """Both links on sub-channel 0 at 20 dBm: each hears the other's transmitter at its own
    receiver (G[2, 1] = 10 u at link 0's receiver, G[0, 3] = 0.1 u at link 1's)."""
    (out,), _ = run_subframes(path, [[CH0, CH0]], monkeypatch)
    # link 0: 100 u / (1 u noise + 1 u V2I user 4 + 10 u from vehicle 2) = 8.3333
    #   → 1000·log2(9.3333) = 3222.39 bits (transposed: 0.1 u, SINR 47.62, 5603 bits)
    # link 1: 10 u / (1 u noise + 1 u V2I user 4 + 0.1 u from vehicle 0) = 4.7619
    #   → 1000·log2(5.7619) = 2526.55 bits (transposed: 10 u, SINR 0.8333, 874 bits)
    expected = [bits(100 / (1 + 1 + 10)), bits(10 / (1 + 1 + 0.1))]
    assert expected == pytest.approx([3222.39, 2526.55], abs=0.01)
    np.testing.assert_allclose(out["v2v_bits"], expected, rtol=1e-5)


@pytest.mark.parametrize("path", PATHS)
def test_v2i_sinr_and_rate(path, monkeypatch):
    """The V2I uplinks' SINR at the base station, with one, two and no V2V transmitters on
    their sub-channel, and a silent link that adds nothing."""
    (apart, shared, silent), _ = run_subframes(
        path, [[CH0, CH1], [CH0, CH0], [OFF, CH1]], monkeypatch
    )
    # links apart: sub-channel 0: 10 u / (1 u + link 0's 1 u) = 5 → 1e6·log2(6) = 2.585 Mbit/s
    #              sub-channel 1: 100 u / (1 u + link 1's 0.1 u) = 90.909 → 6.522 Mbit/s
    np.testing.assert_allclose(apart["v2i_rate_bps"], [rate_bps(5.0), rate_bps(100 / 1.1)], 1e-5)
    assert rate_bps(5.0) == pytest.approx(2.584963e6, rel=1e-6)
    assert rate_bps(100 / 1.1) == pytest.approx(6.522136e6, rel=1e-6)
    # both on 0: 10 u / (1 u + 1 u + 0.1 u) = 4.7619 → 2.527 Mbit/s; sub-channel 1:
    #            100 u / 1 u = 100 → 1e6·log2(101) = 6.658 Mbit/s
    np.testing.assert_allclose(
        shared["v2i_rate_bps"], [rate_bps(10 / 2.1), rate_bps(100.0)], rtol=1e-5
    )
    # link 0 silent: sub-channel 0 hears only noise, 10 u / 1 u = 10 → 1e6·log2(11)
    np.testing.assert_allclose(
        silent["v2i_rate_bps"], [rate_bps(10.0), rate_bps(100 / 1.1)], rtol=1e-5
    )
    np.testing.assert_array_equal(silent["v2v_power_mw"], [0.0, 100.0])
    np.testing.assert_array_equal(silent["v2v_bits"][0], 0.0)
    # a link whose CAM is delivered is silent whatever its action: with 5,000-bit CAMs link 0
    # delivers in subframe 1 (5672.43 bits), then adds nothing at the BS in subframe 2
    small = dataclasses.replace(RADIO, cam_size_bits=5_000)
    (first, after), _ = run_subframes(path, [[CH0, CH1], [CH0, CH1]], monkeypatch, small)
    np.testing.assert_array_equal(first["delivered_now"], [True, False])
    np.testing.assert_array_equal(after["v2v_power_mw"], [0.0, 100.0])
    np.testing.assert_allclose(
        after["v2i_rate_bps"], [rate_bps(10.0), rate_bps(100 / 1.1)], rtol=1e-5
    )


@pytest.mark.parametrize("path", PATHS)
def test_cam_whose_last_bits_arrive_in_the_deadline_subframe_is_delivered(path, monkeypatch):
    """T = 3 subframes, a CAM of 10,000 bits on each link. Link 0 sends 5672.43 bits in
    subframes 1 and 3 (silent in 2): its last bits arrive in subframe 3, the deadline. Link 1
    sends 3334.98 bits in subframes 1 and 2, then stops: 6669.97 bits, lost."""
    outcomes, state = run_subframes(path, [[CH0, CH1], [OFF, CH1], [CH0, OFF]], monkeypatch)
    per_subframe = [bits(50.0), bits(10 / 1.1)]  # test_v2i_interference_is_read_at_the_v2v_receiver
    # link 0: 10000 − 5672.43 = 4327.57 left after subframe 1, still after 2, −1344.85 after 3
    # link 1: 10000 − 3334.98 − 3334.98 = 3330.03 left, never delivered
    np.testing.assert_allclose(
        state["remaining_bits"],
        [10_000 - 2 * per_subframe[0], 10_000 - 2 * per_subframe[1]],
        rtol=1e-5,
    )
    assert [bool(out["delivered_now"][0]) for out in outcomes] == [False, False, True]
    assert not any(bool(out["delivered_now"][1]) for out in outcomes)
    assert [bool(out["was_pending"][0]) for out in outcomes] == [True, True, True]
    # delivery subframe 1..T; T + 1 = 4: lost
    np.testing.assert_array_equal(state["delay_subframes"], [3, 4])


def _hand_tables(backend: str, t: int, own_gain: list[float], batch: int = 1):
    """Tables written directly in the documented [T, B, ...] layout: link l's own gain
    ``own_gain[l]`` on every sub-channel, nothing else (no V2I interference, no cross gain,
    V2I signals 1 mW)."""
    links, subch = len(own_gain), 2
    own = np.broadcast_to(np.asarray(own_gain, np.float32)[:, None], (t, batch, links, subch))
    zeros = np.zeros((t, batch, links, subch), np.float32)
    tables = link.IntervalTables(
        np.ascontiguousarray(own), zeros, zeros.copy(),
        np.zeros((t, batch, links, links), np.float32), np.ones((t, batch, subch), np.float32),
    )  # fmt: skip
    if backend == "numpy":
        return tables
    return link.IntervalTables(*(torch.from_numpy(np.array(x)) for x in vars(tables).values()))


@pytest.mark.parametrize("path", PATHS)
def test_kernel_reads_cross_gain_row_receiver_column_transmitter(path, monkeypatch):
    """:class:`~vdtn_marl.sim.link.IntervalTables` says ``cross_gain[t, b, i, j]`` is the gain
    from link j's transmitter to link i's receiver: on tables written by hand with an
    asymmetric cross gain, each kernel must read it that way."""
    batch, numpy = _batch(path), path.startswith("numpy")
    radio = RadioParams(
        num_subchannels=2, subchannel_bandwidth_hz=1e6, v2v_power_levels_dbm=(20.0, 10.0),
        noise_power_override_dbm=-120.0,
    )  # fmt: skip
    tables = _hand_tables("numpy" if numpy else "torch", 1, [1e-12, 1e-13], batch)
    tables.cross_gain[..., 0, 1] = 1e-13  # tx of link 1 → rx of link 0: 10 u at 20 dBm
    tables.cross_gain[..., 1, 0] = 1e-16  # tx of link 0 → rx of link 1: 0.01 u
    if not numpy:
        in_order = path != "torch-link-major-matmul"
        monkeypatch.setattr(link, "_torch_adds_in_link_order", lambda *args: in_order)
        tables = link.IntervalTables(*(x.contiguous() for x in vars(tables).values()))
    device = None if numpy else torch.device("cpu")
    state = link.new_link_state(batch, 2, 2, radio, 1, device)
    const = link.KernelConstants.build(radio, SUBFRAME_S, batch, 2, "cpu")
    decode = link.ActionTables.build(radio, torch.device("cpu"))
    act = np.zeros((batch, 2), np.int64)  # both on sub-channel 0 at 20 dBm
    if numpy:
        const, decode = const.numpy(), decode.numpy()
    else:
        act = torch.from_numpy(act)
    step = link._subframe_step_dense if path == "numpy-dense" else link.subframe_step
    out = step(tables, 0, act, state, decode, const)
    # link 0: 100 u / (1 u + 10 u) = 9.0909 → 3334.98 bits (transposed: 100/1.01, 6644 bits)
    # link 1: 10 u / (1 u + 0.01 u) = 9.9010 → 3446.39 bits (transposed: 10/11, 933 bits)
    expected = [bits(100 / 11), bits(10 / 1.01)]
    assert expected == pytest.approx([3334.98, 3446.39], abs=0.01)
    np.testing.assert_allclose(_scenario0(out.v2v_bits), expected, rtol=1e-5)


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_twin_counts_a_deadline_subframe_cam_as_delivered(backend):
    """A 3-vehicle platoon (links 0 → 1 and 1 → 2) with T = 50 and a CAM of 49,500 bits. Hand
    tables give link 0 SINR 1 (100 mW × 1e-14 = 1e-12 mW over a noise of 1e-12 mW): 1000 bits
    per subframe, so 49,000 after 49 subframes and the last 500 in subframe 50, the deadline.
    Link 1 stays silent: its CAM is lost. The twin must take link 0's CAM (its recipient then
    holds content one interval old at the next interval, not two) and record delay T."""
    params = TwinParams.from_overrides(
        num_vehicles=3, num_subchannels=2, subchannel_bandwidth_hz=1e6,
        v2v_power_levels_dbm=(20.0, 10.0), noise_power_override_dbm=-120.0,
        cam_size_bits=49_500,
    )  # fmt: skip
    twin = DigitalTwin(params, seed=0, backend=backend, trace_source="constant")
    t = twin.subframes_per_interval
    assert t == 50
    twin.tables = _hand_tables(backend, t, [1e-14, 1e-14])
    actions = np.array([[CH0, OFF]], np.int64)
    for _ in range(t):
        out = twin.step_subframe(actions if backend == "numpy" else torch.from_numpy(actions))
    np.testing.assert_allclose(np.asarray(out.v2v_bits)[0], [1000.0, 0.0], rtol=1e-5)
    assert bool(np.asarray(out.delivered_now)[0, 0])
    commands = torch.zeros(1, twin.num_followers)
    record = twin.finish_interval(commands, perfect=False)
    assert record.cam_delay_subframes[0].tolist() == [t, t + 1]  # delivered in 50; lost
    infos = interval_infos(record, ["vehicle_1", "vehicle_2"], twin.interval_ms, twin.subframe_ms)
    assert infos["vehicle_1"]["cam_delivered"] is True
    assert infos["vehicle_1"]["cam_delay_ms"] == pytest.approx(50.0)
    assert infos["vehicle_2"]["cam_delivered"] is False
    twin.begin_interval()
    age = twin.vehicle_observation(perfect=False)[0, :, VEHICLE_OBS_FEATURES.index("cam_age_ms")]
    # follower 1 holds CAM_0 (one interval, 50 ms, old); follower 2 still the initial content,
    # counted as sent one interval before CAM_0: 100 ms
    assert age.tolist() == pytest.approx([50.0, 100.0])


def test_evaluation_counts_a_deadline_subframe_cam_as_delivered(monkeypatch):
    """The evaluation's CAM delivery rate and latency on the twin of
    :func:`test_twin_counts_a_deadline_subframe_cam_as_delivered` (its hand tables in every
    interval, link 0 at 20 dBm on sub-channel 0, link 1 silent): link 0's CAM arrives in
    subframe 50 of every interval, link 1's never, so half the CAMs are delivered, each 50 ms
    after it was generated."""
    params = TwinParams.from_overrides(
        num_vehicles=3, num_subchannels=2, subchannel_bandwidth_hz=1e6,
        v2v_power_levels_dbm=(20.0, 10.0), noise_power_override_dbm=-120.0,
        cam_size_bits=49_500, episode_intervals=3,
    )  # fmt: skip
    t = params.platoon.subframes_per_interval
    monkeypatch.setattr(
        link, "build_interval_tables", lambda *args, **kwargs: _hand_tables("torch", t, [1e-14] * 2)
    )
    result = evaluate_system(
        params, CACCController(params.platoon), lambda obs: torch.tensor([[CH0, OFF]]),
        perfect=False, episodes=1, intervals=3, seed=0, trace_source="constant",
    )  # fmt: skip
    assert result.metrics["cam_delivery_rate"] == pytest.approx(0.5)
    assert result.metrics["cam_latency_ms_mean"] == pytest.approx(50.0)
    assert result.cam_latency_ms.tolist() == [50.0] * 3
