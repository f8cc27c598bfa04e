"""Data completion and prediction of the predecessor's state in stale observations (docs §4.7).

When CAM_k is late (delivered in the last subframe) or lost, a follower decides on the newest
CAM it holds, whose content (the predecessor's acceleration and command, observation features
3 and 4) is ``cam_age_ms`` old. A *completer* replaces that stale content by a prediction of
its value at the interval start kΔt, from the stale CAM and the follower's local sensing:

- ``"none"``: the observation as the twin makes it (no completer runs).
- ``"hold"``: zero-order hold of the newest CAM content. The twin's observation rule already
  shows the newest CAM the follower holds, so ``hold`` gives the same numbers as ``none``; it
  is the explicit baseline predictor (and what a wrapper that blanks stale content would need).
- ``"kalman"``: a batched Kalman filter per follower over the predecessor's acceleration and
  jerk (:class:`KalmanCompletion`).
- ``"learned"``: a small MLP over a window of local-sensing features, trained on twin rollouts
  with :func:`vdtn_marl.algos.completion.train_completion_predictor`
  (:class:`LearnedCompletion`).

Protocol (:class:`Completion`): ``complete(observation [B, F, 8], interval [B] | None,
mask [B] | None) -> observation`` and ``reset(mask [B] | None)``. Only features 3 and 4 of
stale entries (``cam_age_ms > 0``) change; fresh entries, all other features, the age and the
delay are returned as they are. Completers are stateful and batched over [B, F] on the
observation's device; ``complete`` is called once (or more) per control interval with the
twin's interval index, and repeated calls for the same interval recompute that interval's step
from the state before it ("the last call for an interval wins"), so an environment may refresh
an observation within an interval without advancing the filter twice.

Local sensing: the follower measures its speed error e_v = v_{i−1} − v_i (radar range rate)
and knows its own acceleration, its commands and when each took force (the ``cam_delay_ms`` of
its previous observation), so it can reconstruct its own speed change over the last interval
exactly (:class:`~vdtn_marl.sim.platoon.IntervalIntegrator`) and hence the predecessor's mean
acceleration over that interval: z = (Δe_v + Δv_i)/Δt. The twin's sensing is noise-free.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import torch
from torch import nn

from vdtn_marl.errors import ConfigError
from vdtn_marl.sim.layout import VEHICLE_OBS_FEATURES
from vdtn_marl.sim.params import PlatoonParams
from vdtn_marl.sim.platoon import IntervalIntegrator

__all__ = [
    "COMPLETION_MODES",
    "Completion",
    "CompletionPredictor",
    "HoldCompletion",
    "KalmanCompletion",
    "LearnedCompletion",
    "NoCompletion",
    "load_completion_predictor",
    "make_completion",
    "save_completion_predictor",
]

COMPLETION_MODES = ("none", "hold", "kalman", "learned")

SPEED_ERROR = VEHICLE_OBS_FEATURES.index("speed_error_mps")
GAP_ERROR = VEHICLE_OBS_FEATURES.index("gap_error_m")
ACCEL = VEHICLE_OBS_FEATURES.index("accel_mps2")
CAM_ACCEL = VEHICLE_OBS_FEATURES.index("cam_pred_accel_mps2")
CAM_COMMAND = VEHICLE_OBS_FEATURES.index("cam_pred_command_mps2")
CAM_DELAY = VEHICLE_OBS_FEATURES.index("cam_delay_ms")
CAM_AGE = VEHICLE_OBS_FEATURES.index("cam_age_ms")
PREV_COMMAND = VEHICLE_OBS_FEATURES.index("prev_command_mps2")

CHECKPOINT_FORMAT = "vdtn_marl.completion_predictor"
CHECKPOINT_VERSION = 1

State = dict[str, torch.Tensor]


@runtime_checkable
class Completion(Protocol):
    """What an environment needs from a completer (see the module docstring)."""

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Forget the history of every scenario, or of those where ``mask`` [B] is True."""
        ...

    def complete(
        self,
        observation: torch.Tensor,
        interval: torch.Tensor | None = None,
        mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Vehicle observations [B, F, 8] of interval ``interval`` [B] → completed copy."""
        ...


class NoCompletion:
    """``"none"``: returns the observation object itself, untouched."""

    name = "none"

    def reset(self, mask: torch.Tensor | None = None) -> None:
        pass

    def complete(self, observation, interval=None, mask=None):
        return observation

    __call__ = complete


class HoldCompletion:
    """``"hold"``: zero-order hold of the newest CAM content the follower holds.

    The twin's observation already carries the newest held content in features 3 and 4, so the
    result equals the input (a copy). Stateless.
    """

    name = "hold"

    def reset(self, mask: torch.Tensor | None = None) -> None:
        pass

    def complete(self, observation, interval=None, mask=None):
        return observation.clone()

    __call__ = complete


def _where(mask: torch.Tensor, new: State, old: State) -> State:
    """Per scenario: ``new`` where ``mask`` [B] is True, else ``old`` (every tensor [B, ...])."""
    out = {}
    for key, value in new.items():
        m = mask.view(-1, *([1] * (value.dim() - 1)))
        out[key] = torch.where(m, value, old[key])
    return out


class RecursiveCompletion:
    """Base of the stateful completers: per-scenario history, masks and interval bookkeeping.

    Subclasses define :meth:`_initial_state` and :meth:`_advance`; the base keeps, per
    scenario, the state after the last interval seen and the state before it, so that a second
    call for the same interval recomputes it instead of advancing twice.
    """

    name = "recursive"

    def __init__(self, params: PlatoonParams | None = None):
        self.params = params or PlatoonParams()
        self.dt = float(self.params.control_interval_s)
        self.subframe_ms = float(self.params.subframe_s * 1000.0)
        self.interval_ms = float(self.dt * 1000.0)
        self._state: State | None = None  # after the last interval seen
        self._base: State | None = None  # before it
        self._shape: tuple[int, int, torch.device] | None = None
        self._sensing: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None

    # -- to define
    def _initial_state(self, b: int, f: int, device: torch.device) -> State:
        raise NotImplementedError

    def _advance(
        self, state: State, observation: torch.Tensor, steps: torch.Tensor
    ) -> tuple[State, torch.Tensor]:
        """State after interval k from the state before it, and the estimate [B, F, 2]."""
        raise NotImplementedError

    # -- protocol
    def reset(self, mask: torch.Tensor | None = None) -> None:
        if self._state is None:
            return
        if mask is None:
            self._state = self._base = None
            return
        b, f, dev = self._shape
        mask = torch.as_tensor(mask, device=dev).reshape(b).bool()
        init = self._initial_state(b, f, dev)
        self._state = _where(mask, init, self._state)
        self._base = _where(mask, init, self._base)

    def complete(
        self,
        observation: torch.Tensor,
        interval: torch.Tensor | None = None,
        mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        if observation.dim() != 3 or observation.shape[-1] != len(VEHICLE_OBS_FEATURES):
            raise ValueError(
                f"vehicle observations have shape {tuple(observation.shape)}, expected "
                f"[B, F, {len(VEHICLE_OBS_FEATURES)}]"
            )
        b, f = observation.shape[:2]
        dev = observation.device
        if self._state is None or self._shape != (b, f, dev):
            self._shape = (b, f, dev)
            self._state = self._initial_state(b, f, dev)
            self._base = {k: v.clone() for k, v in self._state.items()}
        last = self._state["interval"]
        if interval is None:
            interval = last + 1
        interval = torch.as_tensor(interval, device=dev).long().reshape(-1).expand(b)
        update = (
            torch.ones(b, dtype=torch.bool, device=dev)
            if mask is None
            else torch.as_tensor(mask, device=dev).reshape(b).bool()
        )
        restarted = interval < last  # a new episode the completer was not told about
        if bool(restarted.any()):
            self.reset(restarted)
            last = self._state["interval"]
        new = interval != last
        base = _where(new, self._state, self._base)
        steps = (interval - base["interval"]).clamp_min(1)
        with torch.no_grad():
            state, estimate = self._advance(base, observation.detach(), steps)
        state["interval"] = interval
        self._base = _where(update, base, self._base)
        self._state = _where(update, state, self._state)

        lo, hi = self.params.accel_min_mps2, self.params.accel_max_mps2
        stale = (observation[..., CAM_AGE] > 0) & update[:, None]
        out = observation.clone()
        estimate = estimate.to(observation.dtype).clamp(lo, hi)
        out[..., CAM_ACCEL : CAM_COMMAND + 1] = torch.where(
            stale[..., None], estimate, observation[..., CAM_ACCEL : CAM_COMMAND + 1]
        )
        return out

    __call__ = complete

    # -- shared local sensing
    def _sensing_tables(self, device: torch.device):
        if self._sensing is None or self._sensing[0].device != device:
            integ = IntervalIntegrator(self.params, device, dtype=torch.float64)
            self._sensing = (
                integ.phi_t[1, 2].clone(),  # Δv from the initial acceleration
                integ.input_gain[:, 1].clone(),  # [T+1]: Δv from a command held n subframes
                torch.tensor(float(self.params.subframes_per_interval), device=device),
            )
        return self._sensing

    def _relative_measurement(
        self, previous: torch.Tensor, observation: torch.Tensor
    ) -> torch.Tensor:
        """Predecessor's mean acceleration over the last interval, [B, F] (float64).

        ``previous`` holds the speed error, acceleration, command in force and switch subframe
        of the previous observation ([B, F, 4]).
        """
        va, gain, t = self._sensing_tables(observation.device)
        obs = observation.double()
        e_v0, a0, u_old, switch = previous.unbind(-1)
        u_new = obs[..., PREV_COMMAND]
        left = (t - switch).clamp(0, t).long()
        own_dv = va * a0 + (gain[-1] - gain[left]) * u_old + gain[left] * u_new
        return (obs[..., SPEED_ERROR] - e_v0 + own_dv) / self.dt

    def _sensing_memory(self, observation: torch.Tensor) -> torch.Tensor:
        obs = observation.double()
        switch = (obs[..., CAM_DELAY] / self.subframe_ms).round()
        return torch.stack(
            [obs[..., SPEED_ERROR], obs[..., ACCEL], obs[..., PREV_COMMAND], switch], dim=-1
        )


class KalmanCompletion(RecursiveCompletion):
    """Batched Kalman filter over the predecessor's [acceleration, jerk], one per follower.

    Model (per follower, float64): Singer-type jerk, x = [a, j] at the interval start,
    a' = a + τ_j(1 − ρ)·j, j' = ρ·j with ρ = exp(−nΔt/τ_j) over n intervals, process noise
    q·[[T³/3, T²/2], [T²/2, T]] (T = nΔt). Measurements, applied in this order:

    1. local sensing z (the predecessor's mean acceleration over the last interval), H = [1,
       −ℓΔt] with ℓ = 0 for a follower of a leader (a leader's acceleration is constant within
       an interval and its sample at kΔt is that of interval k−1) and ½ for the others;
       variance ``sensing_std_mps2``².
    2. a CAM not used before (its stamp k − age/Δt is newer than the last one used): its
       acceleration, H = [1, −age]; and for a predecessor that is a follower its command
       u = a + τ·j, H = [1, τ − age]; variance ``cam_std_mps2``² + q·age³/3.

    Prediction at kΔt: acceleration a, command a + τ·j (a for the leader, whose command is its
    acceleration).
    """

    name = "kalman"

    def __init__(
        self,
        params: PlatoonParams | None = None,
        *,
        jerk_noise: float = 1000.0,
        jerk_time_constant_s: float = 1.0,
        sensing_std_mps2: float = 0.02,
        cam_std_mps2: float = 0.01,
        initial_std_mps2: float = 0.5,
    ):
        super().__init__(params)
        for name, value in (
            ("jerk_noise", jerk_noise),
            ("jerk_time_constant_s", jerk_time_constant_s),
            ("sensing_std_mps2", sensing_std_mps2),
            ("cam_std_mps2", cam_std_mps2),
            ("initial_std_mps2", initial_std_mps2),
        ):
            if not (isinstance(value, int | float) and value > 0):
                raise ConfigError(f"{name}={value!r} must be a positive number")
        self.jerk_noise = float(jerk_noise)
        self.jerk_time_constant_s = float(jerk_time_constant_s)
        self.sensing_var = float(sensing_std_mps2) ** 2
        self.cam_var = float(cam_std_mps2) ** 2
        self.initial_var = float(initial_std_mps2) ** 2
        self.lag_s = float(self.params.driveline_lag_s)

    def _initial_state(self, b: int, f: int, device: torch.device) -> State:
        p0 = torch.diag(
            torch.tensor(
                [self.initial_var, self.initial_var / self.lag_s**2],
                dtype=torch.float64,
                device=device,
            )
        )
        return {
            "interval": torch.full((b,), -1, dtype=torch.long, device=device),
            "x": torch.zeros(b, f, 2, dtype=torch.float64, device=device),
            "P": p0.expand(b, f, 2, 2).clone(),
            "previous": torch.zeros(b, f, 4, dtype=torch.float64, device=device),
            "has_previous": torch.zeros(b, f, dtype=torch.bool, device=device),
            "cam_stamp": torch.full((b, f), -1e9, dtype=torch.float64, device=device),
        }

    @staticmethod
    def _update(x, P, h, z, var, use):
        """Scalar measurement z = h·x + noise(var) where ``use``; everything batched [B, F]."""
        ph = (P @ h[..., None]).squeeze(-1)  # [B, F, 2]
        s = (h * ph).sum(-1) + var
        gain = ph / s[..., None]
        innovation = z - (h * x).sum(-1)
        x_new = x + gain * innovation[..., None]
        p_new = P - gain[..., :, None] * ph[..., None, :]
        p_new = 0.5 * (p_new + p_new.transpose(-1, -2))
        return (
            torch.where(use[..., None], x_new, x),
            torch.where(use[..., None, None], p_new, P),
        )

    def _advance(self, state, observation, steps):
        b, f = observation.shape[:2]
        dev = observation.device
        obs = observation.double()
        x, P = state["x"], state["P"]

        # predict over n intervals
        span = steps.double()[:, None] * self.dt  # [B, 1]
        rho = torch.exp(-span / self.jerk_time_constant_s)
        trans = torch.zeros(b, 1, 2, 2, dtype=torch.float64, device=dev)
        trans[..., 0, 0] = 1.0
        trans[..., 0, 1] = self.jerk_time_constant_s * (1.0 - rho)
        trans[..., 1, 1] = rho
        q = self.jerk_noise
        noise = torch.stack(
            [
                torch.stack([q * span**3 / 3.0, q * span**2 / 2.0], -1),
                torch.stack([q * span**2 / 2.0, q * span], -1),
            ],
            -2,
        )  # [B, 1, 2, 2]
        x = (trans @ x[..., None]).squeeze(-1)
        P = trans @ P @ trans.transpose(-1, -2) + noise

        # 1. local sensing over the last interval
        # followers whose predecessor leads: their sensing sees the leader's constant
        # acceleration, and the leader's CAM carries no command of its own
        is_first = torch.tensor(self.params.topology.follows_leader, device=dev)
        lag = torch.where(is_first, 0.0, 0.5).double() * self.dt
        z = self._relative_measurement(state["previous"], observation)
        use = state["has_previous"] & (steps[:, None] == 1)
        h = torch.stack([torch.ones(b, f, dtype=torch.float64, device=dev), -lag.expand(b, f)], -1)
        x, P = self._update(x, P, h, z, self.sensing_var, use)

        # 2. a CAM not used before
        age_s = obs[..., CAM_AGE] / 1000.0
        stamp = state["interval"][:, None].double() + steps[:, None].double() - age_s / self.dt
        new_cam = (stamp > state["cam_stamp"] + 0.5) & (age_s < 9.99)
        var = self.cam_var + q * age_s**3 / 3.0
        ones = torch.ones_like(age_s)
        x, P = self._update(
            x, P, torch.stack([ones, -age_s], -1), obs[..., CAM_ACCEL], var, new_cam
        )
        x, P = self._update(
            x,
            P,
            torch.stack([ones, self.lag_s - age_s], -1),
            obs[..., CAM_COMMAND],
            var,
            new_cam & ~is_first,
        )
        cam_stamp = torch.where(new_cam, stamp, state["cam_stamp"])

        accel = x[..., 0]
        command = torch.where(is_first, accel, accel + self.lag_s * x[..., 1])
        new_state = {
            "interval": state["interval"],
            "x": x,
            "P": P,
            "previous": self._sensing_memory(observation),
            "has_previous": torch.ones_like(state["has_previous"]),
            "cam_stamp": cam_stamp,
        }
        return new_state, torch.stack([accel, command], -1)


# ---------------------------------------------------------------------------- learned
@dataclass(frozen=True)
class PredictorConfig:
    window: int = 6
    hidden: int = 64
    control_interval_s: float = 0.05


class CompletionPredictor(nn.Module):
    """MLP: local-sensing window and stale CAM → predecessor's [acceleration, command] at kΔt.

    Inputs (per follower, :data:`LearnedCompletion` builds them): the last ``window`` sensing
    measurements and their validity flags, own acceleration and last command, the stale CAM's
    acceleration and command, its age (s), speed and gap error, and whether the predecessor is
    the leader. Inputs are standardised with statistics fitted on the training data (buffers).
    """

    def __init__(self, window: int = 6, hidden: int = 64, control_interval_s: float = 0.05):
        super().__init__()
        if not (isinstance(window, int) and window >= 1):
            raise ConfigError(f"window={window!r} must be an integer >= 1")
        if not (isinstance(hidden, int) and hidden >= 1):
            raise ConfigError(f"hidden={hidden!r} must be an integer >= 1")
        self.config = PredictorConfig(int(window), int(hidden), float(control_interval_s))
        self.num_inputs = 2 * window + 8
        self.register_buffer("input_mean", torch.zeros(self.num_inputs))
        self.register_buffer("input_std", torch.ones(self.num_inputs))
        self.net = nn.Sequential(
            nn.Linear(self.num_inputs, hidden),
            nn.SiLU(),
            nn.Linear(hidden, hidden),
            nn.SiLU(),
            nn.Linear(hidden, 2),
        )

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        x = (features - self.input_mean) / self.input_std
        # the network predicts a correction to the newest sensing measurement
        return features[..., :1] + self.net(x)


class LearnedCompletion(RecursiveCompletion):
    """Completion by a :class:`CompletionPredictor` (a module or a file saved by
    :func:`save_completion_predictor`)."""

    name = "learned"

    def __init__(
        self,
        predictor: CompletionPredictor | str | os.PathLike | None,
        params: PlatoonParams | None = None,
    ):
        super().__init__(params)
        if predictor is None:
            raise ConfigError(
                "completion='learned' needs a predictor: completion_predictor=<path or "
                "CompletionPredictor>; train one with "
                "vdtn_marl.sim.completion.train_completion_predictor(...)"
            )
        if isinstance(predictor, str | os.PathLike):
            predictor = load_completion_predictor(predictor)
        if not isinstance(predictor, CompletionPredictor):
            raise ConfigError(
                f"completion_predictor={predictor!r} must be a CompletionPredictor or the path "
                "of one saved with save_completion_predictor"
            )
        trained_dt = predictor.config.control_interval_s
        if abs(trained_dt - self.dt) > 1e-9:
            raise ConfigError(
                f"the completion predictor was trained with control_interval_s={trained_dt}, "
                f"but this model uses control_interval_s={self.dt}; train one for it"
            )
        self.predictor = predictor.eval()
        self.window = predictor.config.window

    def _initial_state(self, b: int, f: int, device: torch.device) -> State:
        return {
            "interval": torch.full((b,), -1, dtype=torch.long, device=device),
            "previous": torch.zeros(b, f, 4, dtype=torch.float64, device=device),
            "has_previous": torch.zeros(b, f, dtype=torch.bool, device=device),
            "sensed": torch.zeros(b, f, self.window, dtype=torch.float64, device=device),
            "valid": torch.zeros(b, f, self.window, dtype=torch.float64, device=device),
        }

    def _features(self, state: State, observation: torch.Tensor, steps: torch.Tensor):
        obs = observation.double()
        z = self._relative_measurement(state["previous"], observation)
        use = state["has_previous"] & (steps[:, None] == 1)
        z = torch.where(use, z, torch.zeros_like(z))
        sensed = torch.cat([z[..., None], state["sensed"][..., :-1]], -1)
        valid = torch.cat([use[..., None].double(), state["valid"][..., :-1]], -1)
        follows_leader = self.params.topology.follows_leader
        leader = torch.tensor(follows_leader, dtype=z.dtype, device=z.device).expand_as(z)
        features = torch.cat(
            [
                sensed,
                valid,
                torch.stack(
                    [
                        obs[..., ACCEL],
                        obs[..., PREV_COMMAND],
                        obs[..., CAM_ACCEL],
                        obs[..., CAM_COMMAND],
                        (obs[..., CAM_AGE] / 1000.0).clamp(max=2.0),
                        obs[..., SPEED_ERROR],
                        obs[..., GAP_ERROR].clamp(-20.0, 20.0),
                        leader,
                    ],
                    -1,
                ),
            ],
            -1,
        )
        new_state = {
            "interval": state["interval"],
            "previous": self._sensing_memory(observation),
            "has_previous": torch.ones_like(state["has_previous"]),
            "sensed": sensed,
            "valid": valid,
        }
        return new_state, features

    def _advance(self, state, observation, steps):
        new_state, features = self._features(state, observation, steps)
        module = self.predictor
        param = next(module.parameters())
        if param.device != observation.device:
            module.to(observation.device)
            param = next(module.parameters())
        estimate = module(features.to(param.dtype))
        return new_state, estimate


# ---------------------------------------------------------------------------- files
def save_completion_predictor(predictor: CompletionPredictor, path: str | os.PathLike) -> Path:
    """Save ``predictor`` (config and weights) atomically; load it with
    :func:`load_completion_predictor` or ``completion_predictor=path``."""
    path = Path(path)
    c = predictor.config
    payload = {
        "format": CHECKPOINT_FORMAT,
        "version": CHECKPOINT_VERSION,
        "config": {
            "window": c.window,
            "hidden": c.hidden,
            "control_interval_s": c.control_interval_s,
        },
        "state_dict": {k: v.detach().cpu() for k, v in predictor.state_dict().items()},
    }
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)
    return path


def load_completion_predictor(
    path: str | os.PathLike, device: str | torch.device = "cpu"
) -> CompletionPredictor:
    """Load a predictor saved by :func:`save_completion_predictor` (``weights_only=True``).

    A missing file, a file that is not such a checkpoint, or weights that do not fit raise a
    ``ConfigError`` naming the file and the problem.
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"completion predictor file {str(path)!r} does not exist")
    try:
        payload = torch.load(path, map_location=device, weights_only=True)
    except Exception as exc:
        raise ConfigError(
            f"completion predictor file {str(path)!r} could not be read as a torch checkpoint "
            f"(weights only): {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        ) from exc
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise ConfigError(
            f"completion predictor file {str(path)!r} is not a {CHECKPOINT_FORMAT!r} checkpoint "
            "(save one with save_completion_predictor)"
        )
    if payload.get("version") != CHECKPOINT_VERSION:
        raise ConfigError(
            f"completion predictor file {str(path)!r} has checkpoint version "
            f"{payload.get('version')!r}; this code reads version {CHECKPOINT_VERSION}"
        )
    config = payload.get("config")
    state_dict = payload.get("state_dict")
    if not isinstance(config, dict) or not isinstance(state_dict, dict):
        raise ConfigError(f"completion predictor file {str(path)!r} lacks 'config'/'state_dict'")
    try:
        predictor = CompletionPredictor(**config)
        predictor.load_state_dict(state_dict)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise ConfigError(
            f"completion predictor file {str(path)!r} does not fit a CompletionPredictor: "
            f"{type(exc).__name__}: {str(exc).splitlines()[0]}"
        ) from exc
    return predictor.to(device).eval()


# ------------------------------------------------------------- moved to the trainers
_MOVED = {
    "collect_completion_data": "vdtn_marl.algos.completion",
    "train_completion_predictor": "vdtn_marl.algos.completion",
}


def __getattr__(name: str):
    """Training the learned predictor runs policies on the twin, so it lives with the trainers
    (:mod:`vdtn_marl.algos.completion`); the old names say where it went."""
    if name in _MOVED:
        raise AttributeError(
            f"vdtn_marl.sim.completion.{name} moved to {_MOVED[name]}.{name}; import it from there"
        )
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ---------------------------------------------------------------------------- factory
def make_completion(
    completion: str | Completion | None = "none",
    predictor: CompletionPredictor | str | os.PathLike | None = None,
    params: PlatoonParams | None = None,
) -> Any:
    """The completer for an environment's ``completion=`` / ``completion_predictor=`` kwargs.

    ``completion`` is one of :data:`COMPLETION_MODES` or an object with ``reset`` and
    ``complete`` (used as it is); ``predictor`` is only for ``"learned"``.
    """
    if completion is None:
        completion = "none"
    if isinstance(completion, str):
        if completion not in COMPLETION_MODES:
            raise ConfigError(
                f"completion={completion!r} is not a completion mode; allowed: "
                f"{', '.join(repr(m) for m in COMPLETION_MODES)} (or a completer object)"
            )
        if predictor is not None and completion != "learned":
            raise ConfigError(
                f"completion_predictor is only used with completion='learned', "
                f"not completion={completion!r}"
            )
        if completion == "none":
            return NoCompletion()
        if completion == "hold":
            return HoldCompletion()
        if completion == "kalman":
            return KalmanCompletion(params)
        return LearnedCompletion(predictor, params)
    if not (
        callable(getattr(completion, "complete", None))
        and callable(getattr(completion, "reset", None))
    ):
        raise ConfigError(
            f"completion={completion!r} is neither a completion mode "
            f"({', '.join(repr(m) for m in COMPLETION_MODES)}) nor an object with "
            "reset(mask) and complete(observation, interval, mask)"
        )
    if predictor is not None:
        raise ConfigError("completion_predictor is only used with completion='learned'")
    return completion
