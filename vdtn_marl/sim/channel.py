"""Large-scale and fast fading channel model (docs/model.md §4.2–4.3).

Geometry: a straight highway along x; vehicles drive at height ``vehicle_height_m`` in lanes
across the road (y = 0, or the scenario topology's lateral offsets, docs/model.md §6); base
stations stand every ``inter_site_distance_m`` at y = ``bs_road_offset_m``, height
``bs_height_m``. All functions are batched over leading dimensions
and return float tensors in dB (path loss, shadowing) or linear power gain (fast fading). The
deterministic ones also run on NumPy arrays (:mod:`vdtn_marl.sim.backend`); random draws are
always made with the twin's torch generator.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from vdtn_marl.sim.backend import clamp, exp, exp10, log10, sqrt, xp
from vdtn_marl.sim.params import RadioParams

SPEED_OF_LIGHT_MPS = 3e8


def v2i_pathloss_db(distance_3d_m: torch.Tensor) -> torch.Tensor:
    """V2I path loss 128.1 + 37.6·log10(d/km) in dB (TR 36.885 macro; docs/model.md §4.2)."""
    return 128.1 + 37.6 * log10(clamp(distance_3d_m, 1.0) / 1000.0)


def v2v_pathloss_db(distance_m: torch.Tensor, radio: RadioParams) -> torch.Tensor:
    """WINNER+ B1 line-of-sight path loss in dB (docs/model.md §4.2).

    PL_B1 = 22.7·log10(d) + 41 + 20·log10(f/5 GHz) for 3 m < d < d_bp, with d clamped to 3 m
    below; PL_B1 = 40·log10(d) + 9.45 − 17.3·log10(h'_tx) − 17.3·log10(h'_rx) + 2.7·log10(f/5 GHz)
    beyond the breakpoint d_bp = 4·h'_tx·h'_rx·f/c, with the effective antenna heights
    h' = h − 1 m (both antennas at ``vehicle_height_m``).

    ``radio.v2v_pathloss_form == "winner_b1"`` (the default): PL = max(PL_B1, FSPL) with the
    free-space loss FSPL = 20·log10(d) + 20·log10(f/GHz) + 32.45 (the highway V2V LOS model of
    3GPP TR 36.885); at 2 GHz the floor decides from 3 m up to about 9.7 m, e.g. 55.4 dB at 7 m,
    and the loss is continuous at d_bp. ``"liang"``: the form of Liang et al.'s simulator, the
    real heights h in the far branch and no floor; the loss drops 16.5 dB at d_bp and lies
    10–20 dB below free space at 7–20 m (36.1 dB at 7 m).
    """
    f_ghz = radio.carrier_ghz
    h = radio.vehicle_height_m
    liang = radio.v2v_pathloss_form == "liang"
    breakpoint_m = 4.0 * (h - 1.0) ** 2 * f_ghz * 1e9 / SPEED_OF_LIGHT_MPS
    far_height_m = h if liang else h - 1.0
    d = clamp(distance_m, 3.0)
    log_d = log10(d)
    near = 22.7 * log_d + 41.0 + 20.0 * math.log10(f_ghz / 5.0)
    far = 40.0 * log_d + 9.45 - 2 * 17.3 * math.log10(far_height_m) + 2.7 * math.log10(f_ghz / 5.0)
    pathloss = xp(d).where(d < breakpoint_m, near, far)
    if liang:
        return pathloss
    free_space = 20.0 * log_d + (20.0 * math.log10(f_ghz) + 32.45)
    return xp(d).maximum(pathloss, free_space)


def serving_bs_x_m(
    centroid_x_m: torch.Tensor, bs_offset_m: torch.Tensor, radio: RadioParams
) -> torch.Tensor:
    """Along-road position of the base station nearest to ``centroid_x_m`` (m), shape [B]."""
    isd = radio.inter_site_distance_m
    return bs_offset_m + isd * xp(centroid_x_m).round((centroid_x_m - bs_offset_m) / isd)


def v2i_distance_m(
    vehicle_x_m: torch.Tensor,
    bs_x_m: torch.Tensor,
    radio: RadioParams,
    lateral_offset_m: torch.Tensor | None = None,
) -> torch.Tensor:
    """3-D vehicle-to-BS distance in m; ``vehicle_x_m`` [B, N], ``bs_x_m`` [B] → [B, N].

    ``lateral_offset_m`` [N]: each vehicle's lane centre across the road, towards the base
    stations (None: every vehicle at 0, ``bs_road_offset_m`` from the BS row).
    """
    dx = vehicle_x_m - bs_x_m[:, None]
    dz = radio.bs_height_m - radio.vehicle_height_m
    if lateral_offset_m is None:
        return sqrt(dx * dx + radio.bs_road_offset_m**2 + dz * dz)
    dy = radio.bs_road_offset_m - lateral_offset_m
    return sqrt(dx * dx + dy * dy + dz * dz)


def v2v_distance_m(
    vehicle_x_m: torch.Tensor, lateral_offset_m: torch.Tensor | None = None
) -> torch.Tensor:
    """Pairwise vehicle distance in m (same height), [B, N] → [B, N, N].

    ``lateral_offset_m`` [N]: lane centres across the road (None: one lane, |Δx|).
    """
    dx = vehicle_x_m[:, :, None] - vehicle_x_m[:, None, :]
    if lateral_offset_m is None:
        return abs(dx)
    dy = lateral_offset_m[:, None] - lateral_offset_m[None, :]
    return sqrt(dx * dx + dy * dy)


def symmetric_normal(
    shape: tuple[int, ...], generator: torch.Generator, numpy: bool = False
) -> torch.Tensor | np.ndarray:
    """Standard normal [..., N, N] with X[i, j] = X[j, i] (reciprocal links), unit variance.

    Off the diagonal X[i, j] = (x[i, j] + x[j, i])/√2; on it X[i, i] = x[i, i] (the symmetric
    sum would have variance 2 there). ``numpy=True``: the same draws and numbers as a NumPy
    array (CPU generator).
    """
    return symmetrize(torch.randn(shape, generator=generator, device=generator.device), numpy)


def symmetrize(x: torch.Tensor, numpy: bool = False) -> torch.Tensor | np.ndarray:
    """:func:`symmetric_normal` of the standard normal draws ``x`` [..., N, N]."""
    if numpy:
        x = x.numpy()
        diagonal = np.eye(x.shape[-1], dtype=bool)
        return np.where(diagonal, x, (x + x.swapaxes(-1, -2)) * (0.5**0.5))
    diagonal = torch.eye(x.shape[-1], dtype=torch.bool, device=x.device)
    return torch.where(diagonal, x, (x + x.transpose(-1, -2)) * (0.5**0.5))


def shadowing_update_db(
    shadow_db: torch.Tensor,
    moved_m: torch.Tensor,
    std_db: float,
    decorrelation_m: float,
    innovation: torch.Tensor,
) -> torch.Tensor:
    """Gudmundson AR(1) log-normal shadowing update (docs/model.md §4.3).

    s' = ρ·s + sqrt(1 − ρ²)·σ·n with ρ = exp(−Δd/d_corr); ``moved_m`` broadcasts to ``shadow_db``
    and ``innovation`` is a standard normal draw of the same shape.
    """
    rho = exp(-moved_m / decorrelation_m)
    return rho * shadow_db + sqrt(clamp(1.0 - rho * rho, 0.0)) * std_db * innovation


def rayleigh_power_gain(
    shape: tuple[int, ...], generator: torch.Generator, numpy: bool = False
) -> torch.Tensor | np.ndarray:
    """Rayleigh fast-fading power gains |h|² = (x² + y²)/2 with x, y ~ N(0, 1); mean 1.

    ``numpy=True``: the same draws and numbers as a NumPy array (CPU generator).
    """
    xy = torch.randn((2, *shape), generator=generator, device=generator.device)
    if numpy:
        xy = xy.numpy()
    return 0.5 * (xy[0] * xy[0] + xy[1] * xy[1])


#: how a twin draws its Rayleigh fast fading (:func:`draw_fading`)
FADING_DRAWS = ("normal", "exponential")


def rayleigh_power_gain_exponential(
    shape: tuple[int, ...], generator: torch.Generator, out: np.ndarray | None = None
) -> np.ndarray:
    """Rayleigh fast-fading power gains |h|² ~ Exp(1) (the law of (x² + y²)/2 with x, y ~
    N(0, 1)), one draw per gain: float32 from NumPy's ziggurat on an SFC64 generator seeded by
    one 63-bit draw from ``generator``, so that the twin's torch generator
    stays the only random state. About four times fewer generator cycles than
    :func:`rayleigh_power_gain` (half the draws, each faster); other numbers than it."""
    seed = int(torch.randint(0, 2**63 - 1, (), generator=generator, device=generator.device))
    rng = np.random.Generator(np.random.SFC64(seed))
    if out is None:
        out = np.empty(shape, np.float32)
    rng.standard_exponential(out=out, dtype=np.float32)
    return out


def db_to_linear(db: torch.Tensor | np.ndarray | float) -> torch.Tensor | np.ndarray | float:
    if isinstance(db, torch.Tensor | np.ndarray):
        return exp10(db / 10.0)
    return 10.0 ** (db / 10.0)
