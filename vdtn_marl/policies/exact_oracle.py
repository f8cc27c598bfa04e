"""The exact control-cost lower bound: a linear program over the known leader trace.

With perfect observation the platoon is deterministic given the leader trace: every follower
command takes force at the interval start and the interval map of the twin's
:class:`~vdtn_marl.sim.platoon.IntervalIntegrator` is linear,
z_{h+1} = Φ_T z_h + G_T u_h with z = [p, v, a] per follower (docs/model.md §2.2). The control
reward of docs/model.md §2.3 is a weighted sum of absolute values of affine functions of the
states and commands, so minimising the episode's control cost over all command sequences
U ∈ [u_min, u_max]^{H×F} is a linear program (each |e| becomes an auxiliary t ≥ ±e). Its
optimum, planned once per episode over the whole remaining trace and replayed open loop, is
the lowest control cost any controller can reach on that trace: the exact oracle. That holds
as stated with ``tail_intervals=0``; by default the program also plans a 6 s tail beyond the
scored intervals so the plan does not exploit the episode's end (see
:class:`ExactOracleController`), and on evaluations much shorter than that tail (say 1 s) a
controller that ignores what comes after can score below it.

The program, per scenario, with N = H·F (H intervals, F followers):

- variables: u, p, v, a (the state after each interval) and t_p, t_v, t_u, t_j, s ≥ 0;
- equalities: the interval map, 3N rows (z_0 = the twin's state);
- inequalities: t_p ≥ ±e_p, t_v ≥ ±e_v, t_u ≥ ±u, t_j ≥ ±(u_h − u_{h−1}) (u_{−1} = the
  command in force), and s ≥ margin − gap (the collision hinge);
- bounds: u within the actuator limits, v ≥ 0 (the twin clamps speeds at 0 m/s at interval
  ends, so the plan never relies on reversing);
- objective: Σ t_p/ê_p + α t_v/ê_v + β t_u/u_max + γ_j t_j/(j_max Δt) + |collision
  penalty|·s (per m of gap below ``margin_m``; the twin's penalty is an indicator, which no
  LP holds, and the margin keeps optimal plans that touch the constraint off gap = 0, which
  the twin counts as a collision).

It is solved with HiGHS (``scipy.optimize.linprog``; interior point with crossover, dual
simplex if that fails, then both without presolve: :data:`LP_ATTEMPTS`). The constraint
matrices depend only on H and the platoon parameters and are built once; scenarios differ in
the right-hand sides (leader trajectory, initial state). Measured (2 CPU cores, one thread):
about 1.2 s per scenario for H = 200 intervals (10 s) and 2.4 s with the default 6 s tail (H =
320), i.e. about 5 min for 128 scenarios of 10 s; the plan replayed in the twin earns the LP's
optimum to float32 precision (tests/policies/test_exact_oracle.py). The loop over scenarios is a
Python loop (one LP each), outside the simulator's hot path.

:class:`~vdtn_marl.policies.mpc_oracle.OracleController`, the receding-horizon MPC with a
subgradient solver, stays above this optimum, so it is not the lower bound its name suggests;
docs/training.md and docs/control_vs_oracle.md give the measured gaps.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import torch
from scipy.optimize import linprog

from vdtn_marl.sim.params import PlatoonParams
from vdtn_marl.sim.twin import DigitalTwin

#: HiGHS methods and options tried in turn until one solves a scenario's program. Presolve
#: can end in "numerical difficulties" (status 4) on programs that solve without it, so the
#: last attempts turn it off (the same optimum under both methods).
LP_ATTEMPTS: tuple[tuple[str, dict], ...] = (
    ("highs-ipm", {}),
    ("highs-ds", {}),
    ("highs-ds", {"presolve": False}),
    ("highs-ipm", {"presolve": False}),
)

ORACLE_HORIZON_INTERVALS = 120
"""How far the oracles look ahead (intervals of 50 ms: 6 s): the receding horizon of
:class:`~vdtn_marl.policies.mpc_oracle.OracleController` and the tail that
:class:`ExactOracleController` plans beyond the intervals it is scored on."""

BLOCKS = ("u", "p", "v", "a", "t_p", "t_v", "t_u", "t_j", "s")
"""Variable blocks of the program, each of N = H·F entries in (interval, follower) order."""
_U, _P, _V, _A, _TP, _TV, _TU, _TJ, _S = range(len(BLOCKS))


@dataclass(frozen=True)
class _Program:
    """The parts of the linear program that do not depend on the scenario."""

    horizon: int
    followers: int
    a_eq: sp.csr_matrix
    a_ub: sp.csr_matrix
    cost: np.ndarray
    bounds: np.ndarray


@dataclass(frozen=True)
class OptimalPlan:
    """An exact plan: commands ``[H, F]`` (m/s²) over the scored intervals and the tail, and
    the control cost it was optimal for (the sum over those intervals and the followers of
    −reward, collision hinge included)."""

    commands_mps2: np.ndarray
    planned_cost: float


def _indices(horizon: int, followers: int) -> tuple[np.ndarray, np.ndarray]:
    step, follower = np.meshgrid(np.arange(horizon), np.arange(followers), indexing="ij")
    return step.ravel(), follower.ravel()


def build_program(
    params: PlatoonParams, phi: np.ndarray, gain: np.ndarray, horizon: int
) -> _Program:
    """Constraint matrices, costs and bounds for ``horizon`` intervals.

    ``phi`` [3, 3] and ``gain`` [3] are the twin's full-interval map Φ_T and input gain G_T.
    """
    f = params.num_followers
    n = horizon * f
    step, follower = _indices(horizon, f)

    def col(block: int, h: np.ndarray, i: np.ndarray) -> np.ndarray:
        return block * n + h * f + i

    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []

    def put(row: np.ndarray, column: np.ndarray, value) -> None:
        rows.append(row)
        cols.append(column)
        vals.append(np.broadcast_to(np.asarray(value, dtype=np.float64), row.shape))

    # interval map: X_c[h] − Σ_d Φ[c, d] X_d[h−1] − G_c u[h] = (Φ z_0)_c at h = 0, else 0
    later = step > 0
    state_blocks = (_P, _V, _A)
    for c, block in enumerate(state_blocks):
        row = c * n + np.arange(n)
        put(row, col(block, step, follower), 1.0)
        for d, other in enumerate(state_blocks):
            if phi[c, d] != 0.0:
                put(row[later], col(other, step[later] - 1, follower[later]), -phi[c, d])
        if gain[c] != 0.0:
            put(row, col(_U, step, follower), -gain[c])
    a_eq = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(3 * n, len(BLOCKS) * n),
    )

    rows, cols, vals = [], [], []
    # the predecessor is a follower (a variable), else a leader (a constant, in the rhs)
    follows_leader = np.asarray(params.topology.follows_leader)
    has_pred = ~follows_leader[follower]
    pred = _predecessor_rows(params)[follower]
    pred_coef = np.where(has_pred, 1.0, 0.0)
    row_count = 0

    def bound_abs(terms, aux_block: int, signs=(1.0, -1.0)) -> None:
        """Rows sign·(Σ coef·x) − aux ≤ rhs; the constants go to the right-hand side."""
        nonlocal row_count
        for sign in signs:
            row = row_count + np.arange(n)
            for column, coef in terms:
                put(row, column, sign * np.asarray(coef))
            put(row, col(aux_block, step, follower), -1.0)
            row_count += n

    hw = params.time_headway_s
    gap_terms = [(col(_P, step, pred), pred_coef), (col(_P, step, follower), -1.0)]
    bound_abs([*gap_terms, (col(_V, step, follower), -hw)], _TP)  # e_p = gap − r − h·v
    speed_terms = [(col(_V, step, pred), pred_coef), (col(_V, step, follower), -1.0)]
    bound_abs(speed_terms, _TV)  # e_v = v_{i−1} − v_i
    bound_abs([(col(_U, step, follower), 1.0)], _TU)
    first = step == 0
    jerk_terms = [
        (col(_U, step, follower), 1.0),
        (col(_U, np.maximum(step - 1, 0), follower), np.where(first, 0.0, -1.0)),
    ]
    bound_abs(jerk_terms, _TJ)
    bound_abs(gap_terms, _S, signs=(-1.0,))  # s ≥ margin − gap
    a_ub = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(row_count, len(BLOCKS) * n),
    )

    cost = np.zeros(len(BLOCKS) * n)
    weights = {
        _TP: 1.0 / params.gap_error_scale_m,
        _TV: params.weight_speed / params.speed_error_scale_mps,
        _TU: params.weight_accel / params.accel_max_mps2,
        _TJ: params.weight_jerk / (params.jerk_max_mps3 * params.control_interval_s),
        _S: abs(params.collision_penalty),
    }
    for block, weight in weights.items():
        cost[block * n : (block + 1) * n] = weight
    bounds = np.zeros((len(BLOCKS) * n, 2))
    bounds[:, 1] = np.inf
    bounds[_U * n : (_U + 1) * n] = (params.accel_min_mps2, params.accel_max_mps2)
    for block in (_P, _A):
        bounds[block * n : (block + 1) * n, 0] = -np.inf
    return _Program(horizon, f, a_eq, a_ub, cost, bounds)


def _predecessor_rows(params: PlatoonParams) -> np.ndarray:
    """For each follower [F], the follower row of its predecessor (0 where it is a leader)."""
    topology = params.topology
    row = {v: f for f, v in enumerate(topology.followers)}
    return np.array([row.get(p, 0) for p in topology.link_tx], dtype=np.int64)


def _right_hand_sides(
    program: _Program,
    params: PlatoonParams,
    phi: np.ndarray,
    leader_position_m: np.ndarray,
    leader_speed_mps: np.ndarray,
    state: np.ndarray,
    command_mps2: np.ndarray,
    margin_m: float,
) -> tuple[np.ndarray, np.ndarray]:
    """b_eq and b_ub of one scenario: the leaders' trajectories [H, Λ] (after each interval,
    each relative to its present position), follower state [F, 3] (p relative to its leader's
    present position, v, a) and commands [F]."""
    h, f = program.horizon, program.followers
    n = h * f
    step, follower = _indices(h, f)
    b_eq = np.zeros(3 * n)
    first = step == 0
    z1 = state @ phi.T  # [F, 3]: Φ z_0, the free part of the first interval
    for c in range(3):
        b_eq[c * n : (c + 1) * n][first] = z1[follower[first], c]
    topology = params.topology
    leads = np.asarray(topology.follows_leader)[follower]  # the predecessor is a leader
    lead = np.asarray(topology.leader_of)[list(topology.followers)][follower]
    lead_p = np.where(leads, leader_position_m[step, lead], 0.0)
    lead_v = np.where(leads, leader_speed_mps[step, lead], 0.0)
    # each |e| ≤ t row pair reads ±(linear part) − t ≤ ∓(constant part)
    gap_const = lead_p - params.vehicle_length_m
    e_p_const = gap_const - params.standstill_gap_m
    jerk_const = np.where(first, -command_mps2[follower], 0.0)
    zeros = np.zeros(n)
    b_ub = np.concatenate(
        [
            -e_p_const, e_p_const,
            -lead_v, lead_v,
            zeros, zeros,
            -jerk_const, jerk_const,
            gap_const - margin_m,
        ]
    )  # fmt: skip
    return b_eq, b_ub


def check_bound_observation(twin: DigitalTwin, observation) -> None:
    """Raise unless ``observation`` is ``[B, F, ...]`` for the bound twin's B and F."""
    expected = (twin.batch_size, twin.num_followers)
    if tuple(observation.shape[:-1]) != expected:
        raise ValueError(
            f"vehicle observation has shape {tuple(observation.shape)}, "
            f"expected {(*expected, 8)} (the bound twin's batch)"
        )


def _as_numpy(value) -> np.ndarray:
    return torch.as_tensor(value).detach().to("cpu", torch.float64).numpy()


class ExactOracleController:
    """Open-loop replay of the exact optimum over the known leader trace (perfect observation).

    Bound to a twin (:meth:`bind`, as ``evaluate_system`` does), it solves one linear program
    per scenario when the scenario's episode starts (or whenever a scenario did not advance by
    exactly one interval since the last call, e.g. after a reset), and then replays the plan.

    The program covers ``horizon_intervals`` (the intervals being scored; default: the rest of
    the episode) plus ``tail_intervals`` beyond them. With no tail the plan is the exact
    minimum of the scored cost, but it exploits the episode's end: it stops paying for
    errors whose cost would only come after the end (on 16 synthetic 10 s scenarios its cost
    was 20 % below the plan with a 6 s tail), which no controller that does not know when the
    episode ends can do. The default tail of 6 s (the MPC oracle's horizon) removes that
    artefact: the plan is then the exact optimum of the objective the MPC oracle approximates
    at the end of the episode, and the reference the benchmarks compare with. Either way it
    knows the whole future trace, which no causal controller can match.

    Args:
        horizon_intervals: intervals (50 ms each) being scored; None: the rest of the episode
            (``params.episode_intervals`` minus the present interval). Set it to the number
            of intervals an evaluation runs when that is shorter than the episode.
        tail_intervals: intervals planned beyond them (the twin must hold that much leader
            trace beyond the episode: ``DigitalTwin(lookahead_intervals=...)``, 200 by
            default).
        margin_m: the gap (m) below which the collision hinge starts to cost, > 0.
    """

    def __init__(
        self,
        horizon_intervals: int | None = None,
        tail_intervals: int = ORACLE_HORIZON_INTERVALS,
        margin_m: float = 0.01,
    ):
        if horizon_intervals is not None and (
            isinstance(horizon_intervals, bool)
            or not isinstance(horizon_intervals, int)
            or horizon_intervals < 1
        ):
            raise ValueError(
                f"horizon_intervals={horizon_intervals!r} must be None or an integer >= 1"
            )
        if isinstance(tail_intervals, bool) or not isinstance(tail_intervals, int):
            raise ValueError(f"tail_intervals={tail_intervals!r} must be an integer >= 0")
        if tail_intervals < 0:
            raise ValueError(f"tail_intervals={tail_intervals!r} must be an integer >= 0")
        if not 0.0 < margin_m < 1.0:
            raise ValueError(f"margin_m={margin_m!r} must be in (0, 1) m")
        self.horizon_intervals = horizon_intervals
        self.tail_intervals = tail_intervals
        self.margin_m = float(margin_m)
        self._programs: dict[tuple, _Program] = {}

    def _program(self, twin: DigitalTwin, horizon: int) -> _Program:
        pp = twin.params.platoon
        key = (horizon, pp)
        if key not in self._programs:
            integ = twin.integrator
            phi, gain = _as_numpy(integ.phi_t), _as_numpy(integ.input_gain[-1])
            self._programs = {key: build_program(pp, phi, gain, horizon)}  # keep one
        return self._programs[key]

    def solve(self, twin: DigitalTwin, scenario: int) -> OptimalPlan:
        """The optimal plan of scenario ``scenario`` from the twin's present state."""
        pp = twin.params.platoon
        interval = int(_as_numpy(twin.interval)[scenario])
        episode = twin.params.episode_intervals
        scored = self.horizon_intervals or episode - interval
        if scored < 1:
            raise ValueError(
                f"scenario {scenario} is at interval {interval}, at or past the episode's end "
                f"({episode} intervals): nothing left to plan"
            )
        horizon = scored + self.tail_intervals
        trace_end = episode + twin.lookahead_intervals
        if interval + horizon > trace_end:
            raise ValueError(
                f"the exact oracle plans intervals {interval}..{interval + horizon - 1} "
                f"(horizon_intervals={scored}, tail_intervals={self.tail_intervals}) but the "
                f"twin holds leader trace for intervals 0..{trace_end - 1} (episode "
                f"{episode} + lookahead_intervals={twin.lookahead_intervals}); lower the tail "
                "or raise the twin's lookahead_intervals"
            )
        program = self._program(twin, horizon)
        integ = twin.integrator
        phi = _as_numpy(integ.phi_t)
        state = twin.platoon
        position = _as_numpy(state.position_m[scenario])
        speed = _as_numpy(state.speed_mps[scenario])
        accel = _as_numpy(state.accel_mps2[scenario])
        command = _as_numpy(state.command_mps2[scenario])
        intervals = np.zeros((twin.batch_size, horizon), dtype=np.int64)
        intervals[scenario] = interval + np.arange(horizon)
        lead_a = _as_numpy(twin.leader_accel_mps2(intervals)[scenario])  # [H, Λ]
        # every leader as IntervalIntegrator moves it, relative to its present position (m)
        dt = pp.control_interval_s
        topology = pp.topology
        leaders, followers = list(topology.leaders), list(topology.followers)
        lead_p, lead_v = np.empty((horizon, len(leaders))), np.empty((horizon, len(leaders)))
        p, v = np.zeros(len(leaders)), speed[leaders].astype(np.float64)
        for h in range(horizon):  # float64 recursion with the twin's clamp at 0 m/s
            p = p + dt * v + integ.leader_pos_gain * lead_a[h]
            v = np.maximum(v + dt * lead_a[h], 0.0)
            lead_p[h], lead_v[h] = p, v
        head = position[leaders][list(topology.leader_of)]  # [N]: each vehicle's leader's
        follower_state = np.stack(
            [position[followers] - head[followers], speed[followers], accel[followers]], axis=-1
        )
        b_eq, b_ub = _right_hand_sides(
            program, pp, phi, lead_p, lead_v, follower_state, command[followers], self.margin_m
        )
        args = dict(A_ub=program.a_ub, b_ub=b_ub, A_eq=program.a_eq, b_eq=b_eq)
        failures = []
        for method, options in LP_ATTEMPTS:
            result = linprog(
                program.cost, bounds=program.bounds, method=method, options=options, **args
            )
            if result.status == 0:
                break
            failures.append(f"{method}{f' {options}' if options else ''}: {result.message}")
        else:
            raise RuntimeError(
                f"the exact oracle's linear program failed for scenario {scenario} at interval "
                f"{interval}; tried {'; '.join(failures)}"
            )
        n = horizon * program.followers
        commands = result.x[:n].reshape(horizon, program.followers)
        commands = np.clip(commands, pp.accel_min_mps2, pp.accel_max_mps2)
        return OptimalPlan(commands, float(result.fun))

    def seed(self, seed: int | None) -> None:
        """Deterministic controller (API symmetry)."""

    def bind(self, twin: DigitalTwin, perfect: bool | None = None) -> Callable:
        """A control-module callable: vehicle observations ``[B, F, 8]`` → commands ``[B, F]``.

        Only for perfect observation (the plan assumes every command takes force at the
        interval start): a twin with radio, or ``perfect=False``, raises.
        """
        perfect = (not twin.radio_enabled) if perfect is None else bool(perfect)
        if not perfect:
            raise ValueError(
                "the exact oracle is the perfect-observation lower bound: bind it with "
                "perfect=True to a twin without radio (evaluate_system(..., perfect=True) "
                "and no RRA policy)"
            )
        return _BoundExactOracle(self, twin)


class _BoundExactOracle:
    """:class:`ExactOracleController` bound to one twin; see :meth:`ExactOracleController.bind`."""

    def __init__(self, oracle: ExactOracleController, twin: DigitalTwin):
        self.oracle = oracle
        self.twin = twin
        self.reset()

    def reset(self) -> None:
        """Forget the plans; every scenario re-plans at its next call."""
        b = self.twin.batch_size
        self._plans: list[np.ndarray | None] = [None] * b
        self._start = np.zeros(b, dtype=np.int64)
        self._expected = np.full(b, -1, dtype=np.int64)  # the interval of the next call

    def __call__(self, observation) -> torch.Tensor:
        twin = self.twin
        check_bound_observation(twin, observation)
        interval = _as_numpy(twin.interval).astype(np.int64)
        commands = np.empty((twin.batch_size, twin.num_followers))
        for b in range(twin.batch_size):  # one LP per scenario, only when a plan starts
            plan = self._plans[b]
            offset = interval[b] - self._start[b]
            # a scenario that did not advance by exactly one interval since the last call
            # (first call, reset, another episode) plans afresh from its present state
            if plan is None or interval[b] != self._expected[b] or offset >= len(plan):
                plan = self._plans[b] = self.oracle.solve(twin, b).commands_mps2
                self._start[b], offset = interval[b], 0
            commands[b] = plan[offset]
        self._expected = interval + 1
        obs = torch.as_tensor(observation)
        dtype = obs.dtype if obs.is_floating_point() else torch.float32
        return torch.as_tensor(commands, dtype=dtype, device=obs.device)
