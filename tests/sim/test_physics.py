"""Physics of the twin against hand-computed values (docs/model.md §2, §4)."""

import dataclasses
import math

import numpy as np
import pytest
import torch

from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim import channel, link
from vdtn_marl.sim.backend import float32_scalars
from vdtn_marl.sim.params import ConfigError, PlatoonParams, RadioParams, TwinParams
from vdtn_marl.sim.platoon import IntervalIntegrator, PlatoonState, spacing_errors
from vdtn_marl.sim.twin import DigitalTwin

RADIO = RadioParams()
LIANG = RadioParams(v2v_pathloss_form="liang")


def test_v2i_pathloss_at_known_distances():
    d = torch.tensor([1000.0, 500.0, 2000.0])
    # 128.1 + 37.6·log10(d/km): 128.1, 128.1 − 11.3184, 128.1 + 11.3184
    expected = torch.tensor([128.1, 116.7816, 139.4184])
    assert torch.allclose(channel.v2i_pathloss_db(d), expected, atol=1e-3)


def _free_space_db(d_m: float, f_ghz: float = 2.0) -> float:
    return 20 * math.log10(d_m) + 20 * math.log10(f_ghz) + 32.45


def test_default_v2v_pathloss_is_winner_b1_with_a_free_space_floor():
    # f = 2 GHz, h' = h − 1 = 0.5 m: d_bp = 4·0.5·0.5·2e9/3e8 = 6.667 m
    assert RADIO.v2v_pathloss_form == "winner_b1"
    d = torch.tensor([1.0, 5.0, 7.0, 10.0, 100.0])
    expected = torch.tensor(
        [
            _free_space_db(3.0),  # clamped to 3 m; B1 43.871 is below free space 48.013
            _free_space_db(5.0),  # 52.450 (B1 48.907)
            _free_space_db(7.0),  # 55.373 (B1 52.595)
            40 * 1 + 9.45 - 34.6 * math.log10(0.5) + 2.7 * math.log10(0.4),  # 58.791 ≥ 58.471
            40 * 2 + 9.45 - 34.6 * math.log10(0.5) + 2.7 * math.log10(0.4),  # 98.791
        ]
    )
    assert torch.allclose(channel.v2v_pathloss_db(d, RADIO), expected, atol=1e-3)
    assert _free_space_db(7.0) == pytest.approx(55.4, abs=0.05)
    assert _free_space_db(10.0) == pytest.approx(58.5, abs=0.05)


def test_liang_v2v_pathloss_below_and_beyond_breakpoint_is_unchanged():
    d = torch.tensor([1.0, 5.0, 7.0, 10.0, 100.0])
    expected = torch.tensor(
        [
            22.7 * math.log10(3.0) + 41 + 20 * math.log10(0.4),  # clamped to 3 m: 43.871
            22.7 * math.log10(5.0) + 41 + 20 * math.log10(0.4),  # 48.907
            40 * math.log10(7.0) + 9.45 - 34.6 * math.log10(1.5) + 2.7 * math.log10(0.4),
            40 * 1 + 9.45 - 34.6 * math.log10(1.5) + 2.7 * math.log10(0.4),  # 42.283
            40 * 2 + 9.45 - 34.6 * math.log10(1.5) + 2.7 * math.log10(0.4),  # 82.283
        ]
    )
    assert torch.allclose(channel.v2v_pathloss_db(d, LIANG), expected, atol=1e-3)
    assert expected[1] == pytest.approx(48.907, abs=1e-3)
    assert expected[2] == pytest.approx(36.1, abs=0.05)  # 19.3 dB below free space
    assert expected[3] == pytest.approx(42.3, abs=0.05)


def test_winner_b1_is_never_below_free_space_and_equals_it_where_b1_is_lower():
    d = torch.linspace(1.0, 500.0, 49_901)  # 1–500 m in 1 cm steps
    pathloss = channel.v2v_pathloss_db(d, RADIO)
    free_space = 20 * torch.log10(d) + 20 * math.log10(2.0) + 32.45
    assert (pathloss >= free_space - 1e-4).all()
    # B1's far branch, 40·log10(d) + 18.791, crosses free space, 20·log10(d) + 38.471, at
    # d = 10^(19.680/20) = 9.67 m: from 3 m up to there the floor decides
    crossing_m = 10 ** ((38.471 - 18.791) / 20)
    floor = (d >= 3.0) & (d < crossing_m - 0.01)
    torch.testing.assert_close(pathloss[floor], free_space[floor], rtol=0, atol=1e-4)
    b1_far = 40 * torch.log10(d) + 9.45 - 34.6 * math.log10(0.5) + 2.7 * math.log10(0.4)
    above = d > crossing_m + 0.01
    torch.testing.assert_close(pathloss[above], b1_far[above], rtol=0, atol=1e-4)
    at = channel.v2v_pathloss_db(torch.tensor([7.0, 10.0]), RADIO)
    assert float(at[0]) == pytest.approx(55.4, abs=0.1)  # free space (B1: 52.6)
    assert float(at[1]) == pytest.approx(58.8, abs=0.1)  # B1, 0.3 dB above free space 58.5


def test_v2v_pathloss_numpy_and_torch_agree_in_both_forms():
    d = np.linspace(0.0, 600.0, 60_001, dtype=np.float32)
    for radio in (RADIO, LIANG):
        got = channel.v2v_pathloss_db(d, radio)
        assert isinstance(got, np.ndarray) and got.dtype == np.float32
        want = channel.v2v_pathloss_db(torch.from_numpy(d), radio).numpy()
        np.testing.assert_array_equal(got, want, err_msg=radio.v2v_pathloss_form)


def test_noise_power_for_180_khz():
    assert RADIO.noise_power_dbm == pytest.approx(-121.447, abs=1e-3)
    assert RadioParams(subchannel_bandwidth_hz=1e6).noise_power_dbm == pytest.approx(-114.0)


def test_noise_power_override_reaches_the_kernel():
    """``noise_power_override_dbm`` replaces the thermal noise per sub-channel wherever the
    twin reads it (the −90 dBm sensitivity scenario, docs/model.md §4.4)."""
    params = TwinParams.from_overrides(noise_power_override_dbm=-90.0)
    assert params.radio.noise_power_dbm == -90.0
    assert RADIO.noise_power_override_dbm is None
    for backend in ("torch", "numpy"):
        twin = DigitalTwin(params, seed=0, backend=backend)
        assert twin._const.noise_mw == pytest.approx(1e-9, rel=1e-12)
        thermal = DigitalTwin(seed=0, backend=backend)._const.noise_mw
        assert thermal == pytest.approx(10 ** (-12.1447), rel=1e-4)


@pytest.mark.parametrize("value", [10.0, -250.0, float("nan"), "loud", True])
def test_bad_noise_power_override_is_rejected(value):
    with pytest.raises(ConfigError, match=r"^noise_power_override_dbm=.*\[-200(\.0)?, 0(\.0)?\]"):
        TwinParams.from_overrides(noise_power_override_dbm=value)


def test_serving_bs_is_nearest():
    x = torch.tensor([0.0, 900.0, -900.0, 2600.0])
    bs = channel.serving_bs_x_m(x, torch.zeros(4), RADIO)
    assert bs.tolist() == [0.0, 1732.0, -1732.0, 3464.0]


def _tables(own, v2i_rx, to_bs, cross, v2i_sig):
    as_t = lambda v: torch.tensor(v, dtype=torch.float32)[None, None]  # noqa: E731  [T=1, B=1, ...]
    return link.IntervalTables(as_t(own), as_t(v2i_rx), as_t(to_bs), as_t(cross), as_t(v2i_sig))


def _two_link_setup(radio):
    const = link.KernelConstants.build(radio, 1e-3, batch=1, links=2, device="cpu")
    decode = link.ActionTables.build(radio, torch.device("cpu"))
    return const, decode


def test_sinr_and_rate_two_link_toy_case():
    radio = RadioParams(num_subchannels=2)
    const, decode = _two_link_setup(radio)
    n = const.noise_mw
    tables = _tables(
        own=[[1e-4, 1e-4], [2e-4, 2e-4]],
        v2i_rx=[[1e-12, 3e-12], [5e-12, 7e-12]],
        to_bs=[[1e-12, 1e-12], [2e-12, 2e-12]],
        cross=[[0.0, 1e-6], [3e-6, 0.0]],
        v2i_sig=[4e-10, 6e-10],
    )
    state = link.new_link_state(1, 2, 2, radio, 1, "cpu")
    p = 10**2.3  # 23 dBm in mW
    # both links on sub-channel 0 at 23 dBm (action 0)
    out = link.subframe_step(tables, 0, torch.tensor([[0, 0]]), state, decode, const)
    sinr1 = p * 1e-4 / (n + 1e-12 + p * 1e-6)
    sinr2 = p * 2e-4 / (n + 5e-12 + p * 3e-6)
    bits = [180e3 * 1e-3 * math.log2(1 + s) for s in (sinr1, sinr2)]
    assert out.v2v_bits[0].tolist() == pytest.approx(bits, rel=1e-5)
    v2i_sinr = [4e-10 / (n + p * 1e-12 + p * 2e-12), 6e-10 / n]
    rates = [180e3 * math.log2(1 + s) for s in v2i_sinr]
    assert out.v2i_rate_bps[0].tolist() == pytest.approx(rates, rel=1e-5)


def test_same_kernel_on_numpy_and_torch():
    radio = RadioParams(num_subchannels=2)
    const, decode = _two_link_setup(radio)
    tables = _tables(
        own=[[1e-4, 3e-4], [2e-4, 5e-5]],
        v2i_rx=[[1e-11, 3e-12], [5e-12, 7e-11]],
        to_bs=[[1e-12, 4e-12], [2e-12, 2e-12]],
        cross=[[0.0, 1e-6], [3e-6, 0.0]],
        v2i_sig=[4e-10, 6e-10],
    )
    actions = torch.tensor([[1, 5]])  # link 1: ch 0 at 15 dBm; link 2: ch 1 at 15 dBm
    out_t = link.subframe_step(
        tables, 0, actions, link.new_link_state(1, 2, 2, radio, 1, "cpu"), decode, const
    )
    state_np = link.new_link_state(1, 2, 2, radio, 1, "cpu").numpy()
    out_n = link.subframe_step(
        tables.numpy(), 0, actions.numpy(), state_np, decode.numpy(), const.numpy()
    )
    np.testing.assert_allclose(out_n.v2v_bits, out_t.v2v_bits.numpy(), rtol=1e-6)
    np.testing.assert_allclose(out_n.v2i_rate_bps, out_t.v2i_rate_bps.numpy(), rtol=1e-6)


def test_cam_delivery_subframe_for_fixed_rate():
    # SINR = 3 ⇒ log2(4) = 2 bit/s/Hz ⇒ 360 bits per 1 ms subframe ⇒ 14,400 bits in 40 subframes
    radio = RadioParams(num_subchannels=2)
    const, decode = _two_link_setup(radio)
    p = 10**2.3
    gain = 3 * const.noise_mw / p
    t = 50
    tables = link.IntervalTables(
        torch.full((t, 1, 2, 2), gain),
        torch.zeros(t, 1, 2, 2),
        torch.zeros(t, 1, 2, 2),
        torch.zeros(t, 1, 2, 2),
        torch.full((t, 1, 2), 1e-9),
    )
    state = link.new_link_state(1, 2, 2, radio, t, "cpu")
    off = radio.num_power_levels - 1
    actions = torch.tensor([[0, off]])  # link 1 at 23 dBm, link 2 silent
    for s in range(t):
        out = link.subframe_step(tables, s, actions, state, decode, const)
        if s == 39:
            assert bool(out.delivered_now[0, 0])
        if s == 40:
            assert float(out.v2v_power_mw[0, 0]) == 0.0  # delivered ⇒ silent
    assert state.delay_subframes[0].tolist() == [40, t + 1]


def _state(pos, speed, accel, command):
    as_t = lambda v: torch.tensor([v], dtype=torch.float32)  # noqa: E731
    return PlatoonState(as_t(pos), as_t(speed), as_t(accel), as_t(command))


def _error_coordinates(state, params):
    e_p, e_v = spacing_errors(state, params)
    return torch.stack([e_p, e_v, state.accel_mps2[:, 1:]], -1)


def test_error_coordinate_matrices_match_integrator_for_single_subframe():
    params = PlatoonParams(num_vehicles=3, subframes_per_interval=1)
    dt, h, tau = params.control_interval_s, params.time_headway_s, params.driveline_lag_s
    a_mat = torch.tensor([[1, dt, -h * dt], [0, 1, -dt], [0, 0, 1 - dt / tau]])
    b_vec = torch.tensor([0, 0, dt / tau])
    c_vec = torch.tensor([0, dt, 0])
    state = _state([0.0, -9.0, -17.5], [25.0, 24.0, 24.6], [0.0, 0.4, -0.3], [0.0, 0.1, -0.2])
    leader_accel, u = torch.tensor([[0.8]]), torch.tensor([[1.2, -0.7]])
    after = IntervalIntegrator(params, "cpu").integrate(
        state, leader_accel, u, torch.zeros(1, 2, dtype=torch.long)
    )
    x, x_next = _error_coordinates(state, params)[0], _error_coordinates(after, params)[0]
    pred_accel = torch.stack([leader_accel[0, 0], state.accel_mps2[0, 1]])
    expected = x @ a_mat.T + u[0, :, None] * b_vec + pred_accel[:, None] * c_vec
    assert torch.allclose(x_next, expected, atol=1e-5)


def test_per_subframe_integration_agrees_with_matrices_to_first_order():
    """Discrepancy to the interval-level Euler map shrinks ~Δt² when Δt halves."""

    def discrepancy(interval_s):
        params = PlatoonParams(
            num_vehicles=2,
            control_interval_s=interval_s,
            subframes_per_interval=round(interval_s / 1e-3),
        )
        dt, h, tau = interval_s, params.time_headway_s, params.driveline_lag_s
        a_mat = torch.tensor(
            [[1, dt, -h * dt], [0, 1, -dt], [0, 0, 1 - dt / tau]], dtype=torch.float64
        )
        state = _state([0.0, -9.0], [25.0, 24.0], [0.0, 0.5], [0.0, 0.5])
        u = torch.tensor([[2.0]])
        after = IntervalIntegrator(params, "cpu").integrate(
            state, torch.tensor([[0.0]]), u, torch.zeros(1, 1, dtype=torch.long)
        )
        x = _error_coordinates(state, params)[0, 0].double()
        euler = a_mat @ x + torch.tensor([0, 0, dt / tau], dtype=torch.float64) * 2.0
        return float((_error_coordinates(after, params)[0, 0].double() - euler).abs().max())

    coarse, fine, finer = discrepancy(0.05), discrepancy(0.025), discrepancy(0.0125)
    # local error O(Δt²): each halving divides it by ≈ 4 (Δt/τ = 0.5 is not small at 50 ms)
    assert 3.0 < coarse / fine < 5.0
    assert 3.0 < fine / finer < 5.0


@pytest.mark.parametrize("switch", [0, 7, 49, 50])
def test_delayed_command_switch_inside_interval(switch):
    params = PlatoonParams(num_vehicles=2)
    t, dt, tau = params.subframes_per_interval, params.subframe_s, params.driveline_lag_s
    state = _state([0.0, -9.0], [20.0, 20.5], [0.3, -0.4], [0.3, -1.0])
    u_new = 1.5
    after = IntervalIntegrator(params, "cpu").integrate(
        state, torch.tensor([[0.3]]), torch.tensor([[u_new]]), torch.tensor([[switch]])
    )
    p, v, a = -9.0, 20.5, -0.4  # brute-force reference: explicit Euler with a ZOH switch
    for s in range(t):
        u = -1.0 if s < switch else u_new
        p, v, a = p + dt * v, v + dt * a, a + dt / tau * (u - a)
    assert after.position_m[0, 1].item() == pytest.approx(p, abs=1e-4)
    assert after.speed_mps[0, 1].item() == pytest.approx(v, abs=1e-5)
    assert after.accel_mps2[0, 1].item() == pytest.approx(a, abs=1e-5)
    assert after.command_mps2[0, 1].item() == u_new


def test_collision_ends_in_penalty():
    twin = DigitalTwin(
        TwinParams.from_overrides(num_vehicles=2), seed=0, radio=False, trace_source="constant"
    )
    for _ in range(200):
        record = twin.finish_interval(torch.tensor([[2.6]]), perfect=True)
        twin.begin_interval()
        if record.collided.any():
            break
    assert bool(record.collided[0, 0])
    assert record.reward[0, 0].item() < -100.0 + 1e-6
    assert record.gap_error_m[0, 0].item() < -2.0  # gap ≤ 0 ⇒ e_p ≤ −(r + h·v)


def test_seeded_twins_are_identical_and_seeds_differ():
    def run(seed):
        twin = DigitalTwin(batch_size=3, seed=seed)
        gen = torch.Generator().manual_seed(5)
        for _ in range(twin.subframes_per_interval):
            twin.step_subframe(torch.randint(0, 16, (3, 3), generator=gen))
        return twin.finish_interval(torch.zeros(3, 3), perfect=False)

    a, b, c = run(1), run(1), run(2)
    assert torch.equal(a.v2i_rate_bps, b.v2i_rate_bps) and torch.equal(a.reward, b.reward)
    assert not torch.equal(a.v2i_rate_bps, c.v2i_rate_bps)


def test_radio_matches_spec_sanity_figures():
    """docs/model.md §4: ≈ 2.2 Mbps per V2I link without V2V traffic, ≈ 1.5 at 5 dBm."""
    twin = DigitalTwin(batch_size=256, seed=3, trace_source="constant")
    levels, m, links = twin.params.radio.num_power_levels, twin.num_subchannels, twin.num_links

    def mean_rate(level):
        rates = []
        for _ in range(twin.subframes_per_interval):
            channel_idx = torch.randint(0, m, (256, links), generator=twin.generator)
            rates.append(twin.step_subframe(channel_idx * levels + level).v2i_rate_bps.mean())
        twin.reset()
        return float(torch.stack(rates).mean()) / 1e6

    assert 1.8 < mean_rate(levels - 1) < 2.6
    assert 1.2 < mean_rate(2) < 1.8


def test_extreme_speeds_keep_everything_finite():
    params = TwinParams.from_overrides(num_vehicles=4)
    twin = DigitalTwin(params, batch_size=8, seed=0)
    twin.platoon.speed_mps[:] = 0.0  # standstill, then full braking commands
    for _ in range(3):
        for _ in range(twin.subframes_per_interval):
            twin.step_subframe(torch.zeros(8, 3, dtype=torch.long))
            assert torch.isfinite(twin.rra_observation()).all()
        rec = twin.finish_interval(torch.full((8, 3), -2.6), perfect=False)
        twin.begin_interval()
        assert torch.isfinite(rec.reward).all() and (rec.state_after.speed_mps >= 0).all()
    assert torch.isfinite(twin.vehicle_observation(perfect=False)).all()


@pytest.mark.parametrize(
    "kwargs, fragment",
    [
        ({"batch_size": 0}, "batch_size=0"),
        ({"batch_size": -3}, "batch_size=-3"),
        (
            {"device": "cuda:7"} if not torch.cuda.is_available() else {"device": "nonsense"},
            "device=",
        ),
        ({"backend": "jax"}, "backend='jax'"),
    ],
)
def test_bad_twin_arguments_name_the_value(kwargs, fragment):
    with pytest.raises(ConfigError, match=fragment.replace("(", r"\(")):
        DigitalTwin(**kwargs)


@pytest.mark.parametrize(
    "override, fragment",
    [
        ({"num_vehicles": 1}, "num_vehicles=1"),
        ({"driveline_lag_s": -0.1}, "driveline_lag_s=-0.1"),
        ({"cam_size_bits": 0}, "cam_size_bits=0"),
        ({"no_such_key": 1}, "unknown model parameter 'no_such_key'; known: "),
        ({"num_vehicle": 4}, "unknown model parameter 'num_vehicle'; did you mean 'num_vehicles'"),
    ],
)
def test_bad_model_parameters_name_key_and_range(override, fragment):
    with pytest.raises(ConfigError, match=fragment):
        TwinParams.from_overrides(**override)


@pytest.mark.parametrize("backend", ["torch", "numpy"])
def test_bad_rra_actions_raise_with_range(backend):
    twin = DigitalTwin(seed=0, backend=backend)

    def step(actions):
        twin.step_subframe(twin.ns.from_torch(torch.tensor(actions)))

    with pytest.raises(ValueError, match=r"\[0, 15\]"):
        step([[0, 16, 1]])
    with pytest.raises(ValueError, match=r"\[0, 15\]"):
        step([[0, -1, 1]])
    with pytest.raises(ValueError, match="shape"):
        step([[0, 1]])
    with pytest.raises(ValueError, match="integers"):
        step([[0.5, 1.0, 2.0]])
    with pytest.raises(ValueError, match="integers"):
        step([[False, True, False]])


def test_masked_subframe_advances_only_masked_scenarios():
    twin = DigitalTwin(batch_size=2, seed=0, trace_source="constant")
    actions = torch.zeros(2, 3, dtype=torch.long)  # sub-channel 0 at 23 dBm on every link
    twin.step_subframe(actions)
    bits_before = twin.link_state.remaining_bits.clone()
    rate_before = twin._v2i_rate_sum.clone()
    twin.step_subframe(actions, mask=torch.tensor([True, False]))
    assert (twin.link_state.remaining_bits[0] < bits_before[0]).all()
    assert torch.equal(twin.link_state.remaining_bits[1], bits_before[1])
    assert (twin._v2i_rate_sum[0] > rate_before[0]).all()
    assert torch.equal(twin._v2i_rate_sum[1], rate_before[1])


def test_symmetric_shadowing_draws_have_unit_variance_on_and_off_the_diagonal():
    """Reciprocal V2V shadowing: X[i, j] = X[j, i], every entry N(0, 1) (the diagonal is the
    vehicle-to-itself path a V2I user's receiver sees, docs/model.md §4.2-4.3)."""
    g = torch.Generator().manual_seed(0)
    x = channel.symmetric_normal((40_000, 4, 4), g)
    torch.testing.assert_close(x, x.transpose(-1, -2), rtol=0, atol=0)
    variance = x.var(0)
    assert ((variance - 1.0).abs() < 0.05).all(), variance
    g = torch.Generator().manual_seed(0)
    np.testing.assert_array_equal(channel.symmetric_normal((40_000, 4, 4), g, numpy=True), x)


def test_v2v_pathloss_jumps_down_at_the_breakpoint_in_liangs_form():
    """Liang's form puts the antenna heights h, not h − 1, in the beyond-breakpoint formula, so
    the loss falls by 16.5 dB at d_bp = 6.67 m (docs/model.md §4.2): a platoon's V2V links,
    L + r + h·v long, are that much weaker below about 6.7 m/s."""
    d_bp = 4 * 0.5**2 * 2e9 / 3e8  # c = 3·10⁸ m/s, as in Liang et al.'s simulator
    near, far = channel.v2v_pathloss_db(torch.tensor([d_bp - 1e-3, d_bp + 1e-3]), LIANG)
    assert float(near - far) == pytest.approx(16.50, abs=0.02)


def test_winner_b1_form_is_continuous_at_the_breakpoint():
    radio = TwinParams.from_overrides(v2v_pathloss_form="winner_b1").radio
    assert radio == RADIO
    d_bp = 4 * 0.5**2 * 2e9 / 3e8
    near, far = channel.v2v_pathloss_db(torch.tensor([d_bp - 1e-3, d_bp + 1e-3]), radio)
    assert float(far - near) == pytest.approx(0.0, abs=0.02)
    assert float(near) == pytest.approx(_free_space_db(d_bp - 1e-3), abs=1e-3)  # floor, 54.95 dB
    # without the floor B1 itself is continuous there too (51.74 / 51.75 dB)
    b1_near = 22.7 * math.log10(d_bp) + 41 + 20 * math.log10(0.4)
    b1_far = 40 * math.log10(d_bp) + 9.45 - 34.6 * math.log10(0.5) + 2.7 * math.log10(0.4)
    assert b1_near == pytest.approx(b1_far, abs=0.01)
    # beyond the floor's reach WINNER+ B1 is 34.6·log10(3) = 16.5 dB lossier than Liang's form
    d = torch.tensor([20.0, 100.0])
    gap = channel.v2v_pathloss_db(d, radio) - channel.v2v_pathloss_db(d, LIANG)
    assert torch.allclose(gap, torch.full((2,), 34.6 * math.log10(3.0)), atol=1e-3)
    with pytest.raises(ConfigError, match="v2v_pathloss_form='winner' must be one of 'liang'"):
        TwinParams.from_overrides(v2v_pathloss_form="winner")


def _subframe_reference(tables, subframe, actions, state, decode, const):
    """The torch kernel in its [B, L, M] formulation (batched matmul, sum over the link axis):
    the numbers the link-major kernel must reproduce bit for bit."""
    pending = state.remaining_bits > 0
    channel = decode.subchannel[actions]
    power = decode.power_mw[actions] * pending
    tx_onehot = decode.onehot[actions] * (power > 0)[..., None]
    power_onehot = tx_onehot * power[..., None]
    flat = const.row_offset + channel
    own = tables.own_gain[subframe].contiguous().take(flat)
    from_v2i = tables.v2i_to_rx_mw[subframe].contiguous().take(flat)
    rx = torch.matmul(tables.cross_gain[subframe].contiguous(), power_onehot)
    from_v2v = rx.take(flat)
    v2v_bits = torch.log1p(power * own / (const.noise_mw + from_v2i + from_v2v)) * (
        const.bandwidth_hz * const.subframe_s / math.log(2.0)
    )
    to_bs = (power_onehot * tables.tx_to_bs_gain[subframe].contiguous()).sum(1)
    v2i_sinr = tables.v2i_signal_mw[subframe] / (const.noise_mw + to_bs)
    v2i_rate = torch.log1p(v2i_sinr) * (const.bandwidth_hz / math.log(2.0))
    return v2i_rate, v2v_bits, power


@pytest.mark.parametrize(
    "vehicles,subchannels",
    [(3, 1), (4, 4), (6, 3), (8, 4), (16, 4), (20, 4), (9, 5), (8, 8), (4, 12), (21, 1)],
)
def test_link_major_kernel_equals_the_batched_formulation_bit_for_bit(vehicles, subchannels):
    # heavy-tailed gains and many links on few sub-channels: sums of several interferers, in
    # which any other order of addition shows in the last bits
    params = TwinParams.from_overrides(num_vehicles=vehicles, num_subchannels=subchannels)
    batch = link.LINK_MAJOR_MIN_BATCH + 3
    twin = DigitalTwin(params, batch_size=batch, seed=11)
    assert link.link_major(batch)
    g = torch.Generator().manual_seed(3)
    checked = 0
    for t in range(twin.subframes_per_interval):
        actions = torch.randint(0, params.radio.num_actions, (batch, twin.num_links), generator=g)
        state = link.LinkState(*(x.clone() for x in dataclasses.astuple(twin.link_state)))
        want = _subframe_reference(twin.tables, t, actions, state, twin._decode, twin._const)
        out = twin.step_subframe(actions)
        for a, b in zip(want, (out.v2i_rate_bps, out.v2v_bits, out.v2v_power_mw), strict=True):
            assert torch.equal(a, b)
        checked += int((out.v2v_power_mw > 0).sum())
    assert checked > 0


@pytest.mark.parametrize(
    "vehicles,subchannels,batch", [(4, 4, 1), (8, 2, 1), (6, 3, 5), (9, 1, 2), (4, 12, 3)]
)
def test_numpy_kernel_equals_the_dense_formulation_bit_for_bit(vehicles, subchannels, batch):
    """The NumPy kernel (fewer calls) gives the dense [B, L, M] code's numbers and state bit
    for bit: links that send, that are silent (the off level), and that delivered already."""
    params = TwinParams.from_overrides(num_vehicles=vehicles, num_subchannels=subchannels)
    twin = DigitalTwin(params, batch_size=batch, seed=12, backend="numpy")
    rng = np.random.default_rng(4)
    outcomes = {"delivered": 0, "silent": 0, "sending": 0}
    for t in range(twin.subframes_per_interval):
        actions = rng.integers(0, params.radio.num_actions, (batch, twin.num_links))
        start = twin.link_state
        # some CAMs delivered already, the others with any number of bits left
        scale = rng.uniform(-0.3, 1.0, start.remaining_bits.shape).astype(np.float32)
        start.remaining_bits = start.remaining_bits * scale
        states = [dataclasses.replace(start) for _ in range(2)]
        args = (twin.tables, t, actions)
        want = link._subframe_step_dense(*args, states[0], twin._decode, twin._const)
        got = link._subframe_step_numpy(*args, states[1], twin._decode, twin._const)
        for a, b in [
            *zip(dataclasses.astuple(want), dataclasses.astuple(got), strict=True),
            *zip(dataclasses.astuple(states[0]), dataclasses.astuple(states[1]), strict=True),
        ]:
            assert a.dtype == b.dtype and a.shape == b.shape
            assert a.tobytes() == b.tobytes()
        outcomes["delivered"] += int((~got.was_pending).sum())
        outcomes["silent"] += int((got.was_pending & (got.v2v_power_mw == 0)).sum())
        outcomes["sending"] += int((got.v2v_power_mw > 0).sum())
        twin.step_subframe(actions)
    assert min(outcomes.values()) > 0, outcomes


def test_exponential_fading_draws_have_the_rayleigh_law_and_reproduce_by_seed():
    """fading_draws="exponential": |h|² ~ Exp(1) (mean 1, variance 1, P(|h|² > 2) = e⁻²),
    the same tables on both backends and for the same seed, other numbers than "normal"."""
    gains = {}
    for draws in ("normal", "exponential"):
        twin = DigitalTwin(batch_size=512, seed=5, fading_draws=draws)
        # own gain / its large-scale factor: the fading alone, 50 × 512 × 3 × 4 draws
        own = twin.tables.own_gain.double()
        gains[draws] = fading = own / own.mean(dim=0, keepdim=True)
        assert fading.mean().item() == pytest.approx(1.0, abs=0.01)
    exponential = DigitalTwin(batch_size=512, seed=5, fading_draws="exponential").tables
    again = DigitalTwin(batch_size=512, seed=5, fading_draws="exponential").tables
    assert torch.equal(exponential.cross_gain, again.cross_gain)
    assert not torch.equal(gains["normal"], gains["exponential"])
    raw = DigitalTwin(batch_size=1, seed=9, fading_draws="exponential")
    draws = channel.rayleigh_power_gain_exponential((400_000,), raw.generator).astype(np.float64)
    assert draws.mean() == pytest.approx(1.0, abs=0.01)
    assert draws.var() == pytest.approx(1.0, abs=0.02)
    assert (draws > 2.0).mean() == pytest.approx(math.exp(-2.0), abs=0.003)
    numpy_twin = DigitalTwin(batch_size=1, seed=6, backend="numpy", fading_draws="exponential")
    torch_twin = DigitalTwin(batch_size=1, seed=6, backend="torch", fading_draws="exponential")
    for field in dataclasses.fields(link.IntervalTables):
        np.testing.assert_array_equal(
            getattr(numpy_twin.tables, field.name), getattr(torch_twin.tables, field.name).numpy()
        )
    with pytest.raises(ConfigError, match="fading_draws"):
        DigitalTwin(batch_size=1, fading_draws="uniform")


@pytest.mark.parametrize("fading_draws", ["normal", "exponential"])
def test_link_major_twin_equals_the_batch_first_twin(monkeypatch, fading_draws):
    """Above LINK_MAJOR_MIN_BATCH the torch twin holds its tables and link state link-major;
    observations, outcomes and interval records are those of the [B, ...] code bit for bit
    (two intervals, a partial reset between them)."""
    batch = link.LINK_MAJOR_MIN_BATCH + 5

    def run(threshold: int) -> list[torch.Tensor]:
        monkeypatch.setattr(link, "LINK_MAJOR_MIN_BATCH", threshold)
        twin = DigitalTwin(batch_size=batch, seed=2, fading_draws=fading_draws)
        g = torch.Generator().manual_seed(4)
        cacc = CACCController(twin.params.platoon)
        seen = []
        for k in range(3):
            for _ in range(twin.subframes_per_interval):
                seen.append(twin.rra_observation().clone())
                n_act = twin.params.radio.num_actions
                out = twin.step_subframe(torch.randint(0, n_act, (batch, 3), generator=g))
                seen += [x.clone() for x in dataclasses.astuple(out)]
            record = twin.finish_interval(cacc(twin.vehicle_observation(False)), perfect=False)
            seen += [record.reward, record.cam_delay_subframes, record.v2i_rate_bps]
            if k == 0:
                twin.reset(mask=torch.arange(batch) % 3 == 0)
            else:
                twin.begin_interval()
        return seen

    reference = run(10**9)
    linked = run(link.LINK_MAJOR_MIN_BATCH)
    assert len(reference) == len(linked)
    for a, b in zip(reference, linked, strict=True):
        assert torch.equal(a, b)


def test_numpy_kernel_with_numpy_scalar_constants_gives_the_dense_codes_numbers():
    """Kernel constants that are NumPy float64 scalars keep their dtype in NumPy's arithmetic:
    the NumPy kernel then runs the dense code, and backend.float32_scalars refuses them."""
    assert float32_scalars(x=np.float64(0.5)) is None
    assert float32_scalars(x=0.5, n=3).x.dtype == np.float32
    twin = DigitalTwin(batch_size=1, seed=12, backend="numpy")
    const = dataclasses.replace(twin._const, bandwidth_hz=np.float64(twin._const.bandwidth_hz))
    actions = np.random.default_rng(5).integers(0, twin.params.radio.num_actions, (1, 3))
    states = [dataclasses.replace(twin.link_state) for _ in range(2)]
    want = link._subframe_step_dense(twin.tables, 0, actions, states[0], twin._decode, const)
    got = link._subframe_step_numpy(twin.tables, 0, actions, states[1], twin._decode, const)
    assert want.v2v_bits.dtype == np.float64  # float64 arithmetic, as the dense code does it
    for a, b in zip(dataclasses.astuple(want), dataclasses.astuple(got), strict=True):
        assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
