"""Training the learned completion predictor of :mod:`vdtn_marl.sim.completion` (docs §4.7):
impaired twin rollouts under an RRA policy (random by default) and the linear CACC give
(local-sensing features, the predecessor's true acceleration and command) pairs, and a small
MLP (:class:`~vdtn_marl.sim.completion.CompletionPredictor`) is fitted to them.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import torch

from vdtn_marl.core.interval import IntervalEngine
from vdtn_marl.errors import ConfigError
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.policies.rra import RandomRRAPolicy
from vdtn_marl.sim.completion import (
    CAM_ACCEL,
    CAM_AGE,
    CAM_COMMAND,
    CompletionPredictor,
    LearnedCompletion,
    RecursiveCompletion,
)
from vdtn_marl.sim.params import PlatoonParams, TwinParams
from vdtn_marl.sim.twin import DigitalTwin

__all__ = ["FeatureRecorder", "collect_completion_data", "train_completion_predictor"]


class FeatureRecorder(LearnedCompletion):
    """Runs the feature pipeline of :class:`LearnedCompletion` and keeps the last features."""

    def __init__(self, window: int, params: PlatoonParams):
        RecursiveCompletion.__init__(self, params)
        self.window = window
        self.features: torch.Tensor | None = None

    def _advance(self, state, observation, steps):
        new_state, features = self._features(state, observation, steps)
        self.features = features.float()
        return new_state, observation[..., CAM_ACCEL : CAM_COMMAND + 1].double()


def collect_completion_data(
    params: TwinParams | None = None,
    seed: int = 0,
    *,
    batch_size: int = 128,
    episodes: int = 1,
    intervals: int | None = 100,
    window: int = 6,
    device: str | torch.device = "cpu",
    trace_source=None,
    rra_policy: Callable | None = None,
    command_noise_mps2: float = 0.2,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Impaired twin rollouts → (features [S, D], targets [S, 2], stale [S]) per follower-interval.

    The twin runs ``episodes`` episodes of ``batch_size`` scenarios, the first ``intervals``
    intervals of each (all with ``None``), with ``rra_policy`` (random by default) and linear
    CACC on the impaired observations, plus Gaussian command noise for variety. Targets are the
    predecessor's exact acceleration and command at kΔt; rows of a scenario after a collision
    are dropped.
    """
    params = params or TwinParams()
    length = (
        params.episode_intervals if intervals is None else min(intervals, params.episode_intervals)
    )
    if length < 1 or episodes < 1:
        raise ConfigError(f"intervals={intervals!r} and episodes={episodes!r} must be >= 1")
    twin = DigitalTwin(
        params, batch_size=batch_size, device=device, seed=seed, trace_source=trace_source
    )
    rra = rra_policy or RandomRRAPolicy(params.radio.num_actions, seed)
    controller = CACCController(params.platoon)
    recorder = FeatureRecorder(window, params.platoon)
    gen = torch.Generator(device=twin.device)
    gen.manual_seed(seed + 1)
    feats, targets, stale = [], [], []
    pp = params.platoon
    # the recorder completes nothing: it only keeps the features; the commands are CACC's on
    # the impaired observation plus noise, so the engine closes with explicit commands
    engine = IntervalEngine(twin, perfect=False, rra_policy=rra)
    for episode in range(episodes):
        if episode:
            twin.reset()
        recorder.reset()
        alive = torch.ones(batch_size, dtype=torch.bool, device=twin.device)
        for _ in range(length):
            engine.run_radio()
            obs = engine.observe()
            recorder.complete(obs, twin.interval)
            keep = alive[:, None].expand(-1, twin.num_followers)
            feats.append(recorder.features[keep])
            targets.append(twin.cam_snapshot[keep])
            stale.append((obs[..., CAM_AGE] > 0)[keep])
            noise = command_noise_mps2 * torch.randn(
                obs.shape[:2], generator=gen, device=twin.device
            )
            commands = (controller(obs) + noise).clamp(pp.accel_min_mps2, pp.accel_max_mps2)
            closed = engine.close(commands)
            alive = alive & ~closed.terminated
            engine.advance(radio=False)  # every scenario (a collided one is no longer recorded)
    return torch.cat(feats).cpu(), torch.cat(targets).float().cpu(), torch.cat(stale).cpu()


def train_completion_predictor(
    params: TwinParams | None = None,
    seed: int = 0,
    *,
    batch_size: int = 128,
    episodes: int = 1,
    intervals: int | None = 100,
    window: int = 6,
    hidden: int = 64,
    epochs: int = 30,
    minibatch: int = 512,
    learning_rate: float = 3e-3,
    device: str | torch.device = "cpu",
    trace_source=None,
    rra_policy: Callable | None = None,
    verbose: bool = False,
) -> CompletionPredictor:
    """Fit a :class:`CompletionPredictor` on impaired twin rollouts (seconds on a CPU).

    Data: :func:`collect_completion_data` (``batch_size`` scenarios × ``episodes`` episodes
    of ``params``, ``intervals`` intervals each; the leader traces of ``trace_source``,
    default ``params.traces``: use the train part of a recorded trace set). Loss: mean squared
    error of the predecessor's acceleration and command over the stale rows (fresh rows are
    never completed). Adam with a cosine learning-rate schedule, ``epochs`` passes in
    minibatches of ``minibatch``, on CPU tensors (the rollouts run on ``device``).
    ``predictor.training_info`` reports the data size, the final training RMSE and the
    seconds spent collecting and fitting.
    """
    params = params or TwinParams()
    start = time.perf_counter()
    torch_gen = torch.Generator().manual_seed(seed)
    features, targets, stale = collect_completion_data(
        params,
        seed,
        batch_size=batch_size,
        episodes=episodes,
        intervals=intervals,
        window=window,
        device=device,
        trace_source=trace_source,
        rra_policy=rra_policy,
    )
    collected = time.perf_counter()
    x, y = features[stale], targets[stale]
    if x.shape[0] < 2:
        raise ValueError(
            f"only {x.shape[0]} stale observations in the rollouts: nothing to learn from; "
            "use more scenarios or longer episodes"
        )
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        predictor = CompletionPredictor(window, hidden, params.platoon.control_interval_s)
    predictor.input_mean.copy_(x.mean(0))
    predictor.input_std.copy_(x.std(0).clamp_min(1e-3))
    optimiser = torch.optim.Adam(predictor.parameters(), lr=learning_rate)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=max(epochs, 1))
    n = x.shape[0]
    threads = torch.get_num_threads()
    # the network is tiny: one thread avoids the intra-op overhead that dominates its steps
    torch.set_num_threads(1)
    try:
        for epoch in range(epochs):
            order = torch.randperm(n, generator=torch_gen)
            total = 0.0
            for i in range(0, n, minibatch):
                idx = order[i : i + minibatch]
                loss = ((predictor(x[idx]) - y[idx]) ** 2).mean()
                optimiser.zero_grad()
                loss.backward()
                optimiser.step()
                total += float(loss.detach()) * len(idx)
            schedule.step()
            if verbose:
                print(f"epoch {epoch + 1}/{epochs}: train MSE {total / n:.5f}")
    finally:
        torch.set_num_threads(threads)
    predictor.eval()
    with torch.no_grad():
        rmse = ((predictor(x) - y) ** 2).mean(0).sqrt()
    predictor.training_info = {
        "stale_rows": int(n),
        "rows": int(features.shape[0]),
        "train_rmse_accel_mps2": float(rmse[0]),
        "train_rmse_command_mps2": float(rmse[1]),
        "collect_seconds": collected - start,
        "fit_seconds": time.perf_counter() - collected,
        "seconds": time.perf_counter() - start,
    }
    return predictor
