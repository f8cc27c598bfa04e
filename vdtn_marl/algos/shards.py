"""Sharded collection (``algo.collector_workers=N``): a trainer's persisting scenarios split
over N worker processes, one core each, collected together every PPO iteration.

A run keeps torch on one thread, and the collection of π̃ (an interval of control and 50
subframes of radio, with the RRA policy called every subframe, on small tensors) does not
gain from a second thread (docs/performance.md, *Settings that change the speed*). Processes
do: each worker holds
``B / N`` scenarios of the trainer's environment, built by the trainer's ``env_factory`` in the
worker, and keeps them (and where they continue) from one PPO iteration to the next, as
``algo.persistent_envs`` keeps them in the trainer's own process. Every iteration the trainer
sends each worker the actor's weights (and, where the environment holds a policy that can
change, such as π̃'s RRA slot, that policy when it changes), the workers collect
``rollout_steps`` steps each at the same time, and the trainer updates on their batches joined
along the scenario dimension. The trainer's own environment still serves the observation
scaling's rollouts and the validation.

What moves: the scenarios and the action samples of a sharded run are its own. Worker ``i``
seeds its environment and its torch generator (the actions' samples) with
:func:`shard_seed` ``(seed_for(k), i)`` when its scenarios first start (iteration ``k``), and a
policy that draws (``seed``: the random RRA policy) with that of the iteration it is handed
over in. A run is reproducible by its seed and N, and a checkpoint keeps every worker's
scenarios, where they continue and its generator, so a resumed run continues bit for bit.

Why not TorchRL's ``MultiSyncDataCollector``: the environment here is already batched (a
worker is one environment of B / N scenarios, not a pool of single ones), its RRA slot holds a
second policy that the collector's weight updates do not reach, and a checkpoint needs each
worker's scenarios. The workers are ``spawn``ed processes (a fresh interpreter: the trainer's
process has threads, which ``fork`` does not copy safely); messages are ``torch.save`` bytes
over a pipe, so no tensor of the trainer is ever shared with a worker.
"""

from __future__ import annotations

import io
import multiprocessing as mp
import signal
import time
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import InteractionType, set_interaction_type

from vdtn_marl.algos.params import MAX_COLLECTOR_WORKERS

#: Worker i's seed is shard_seed(seed, i) = (seed + i · SHARD_SEED_STRIDE) mod 2³²: torch's
#: CPU generator keeps a seed's low 32 bits only. For i ≤ 64 the offset stays more than
#: 34.9 M from 0 mod 2³², so a worker's seed is never one of its own run's iteration seeds
#: (seed_for(k) = seed · 1,000,003 + k, k < 1,000,003). The stride is 2³² over the golden ratio.
SHARD_SEED_STRIDE = 0x9E3779B9
SEED_MODULUS = 1 << 32


def shard_seed(seed: int, shard: int) -> int:
    """The seed of worker ``shard``'s scenarios (and its action samples) for ``seed``."""
    return (int(seed) + int(shard) * SHARD_SEED_STRIDE) % SEED_MODULUS


def continue_rollout(env, actor, state: TensorDictBase, steps: int):
    """``steps`` steps of ``env`` under ``actor`` from ``state`` (what ``EnvBase.rollout``
    does, resetting the scenarios that end), keeping where they continue: (the steps stacked
    along the time dimension after the batch, the state to continue from)."""
    out = []
    for _ in range(steps):
        state = actor(state)
        step, state = env.step_and_maybe_reset(state)
        out.append(step)
    return torch.stack(out, dim=len(env.batch_size)).contiguous(), state


def _dumps(obj: Any) -> bytes:
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def _loads(data: bytes) -> Any:
    return torch.load(io.BytesIO(data), weights_only=False)


def _install(factory, env, policy, seed: int) -> None:
    """Hand the worker's environment the policy its factory swaps (see ShardedCollector)."""
    factory.install(env, policy)
    if hasattr(policy, "seed"):
        policy.seed(seed)


def _serve(conn, factory, batch_size: int, actor_bytes: bytes, threads: int) -> None:
    """A worker: build the environment, then answer the trainer's messages until ``stop``.
    Ctrl-C is the trainer's to act on (it stops after its iteration and checkpoint,
    vdtn_marl/io/interrupts.py), so the worker ignores SIGINT, and SIGTERM (which SLURM sends
    to every process of a job); it ends when the trainer's process does (its pipe closes)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        torch.set_num_threads(threads)
        env = factory(batch_size)
        actor = _loads(actor_bytes)
        carry: TensorDictBase | None = None
        conn.send(("ready", None))
    except BaseException:  # noqa: BLE001 - reported to the trainer, which raises
        conn.send(("error", traceback.format_exc()))
        return
    while True:
        try:
            command, argument = conn.recv()
        except EOFError:  # the trainer's process is gone
            return
        try:
            if command == "collect":
                began = time.process_time()
                weights, policy, seed, steps = argument
                actor.load_state_dict(_loads(weights))
                if policy is not None:
                    _install(factory, env, _loads(policy), seed)
                if carry is None:
                    env.set_seed(seed)
                    torch.manual_seed(seed)
                    carry = env.reset()
                with torch.no_grad(), set_interaction_type(InteractionType.RANDOM):
                    data, carry = continue_rollout(env, actor, carry, steps)
                conn.send(("ok", (_dumps(data), time.process_time() - began)))
            elif command == "state":
                state = None
                if carry is not None:
                    state = {
                        "env": env.state_dict(),
                        "carry": carry.to_dict(),
                        "rng": torch.get_rng_state(),
                    }
                conn.send(("ok", _dumps(state)))
            elif command == "load":
                policy, state = argument
                if policy is not None:
                    factory.install(env, _loads(policy))
                state = _loads(state)
                carry = env.reset()  # a tensordict of the right structure (nested batch sizes)
                env.load_state_dict(state["env"])
                carry.update(state["carry"])
                torch.set_rng_state(state["rng"])
                conn.send(("ok", None))
            elif command == "stop":
                conn.send(("ok", None))
                return
            else:
                raise ValueError(f"unknown command {command!r}")
        except BaseException:  # noqa: BLE001
            conn.send(("error", traceback.format_exc()))


class ShardedCollector:
    """``workers`` processes of ``batch_size / workers`` scenarios each, built by ``factory``
    (a picklable callable ``batch_size → environment``; its optional ``install(env, policy)``
    puts a policy into the environment, and its optional ``policy_of(env)`` reads that policy
    from the trainer's environment, sent to the workers whenever it is another object).

    The processes start at the first :meth:`collect` (or :meth:`load`) and stop at
    :meth:`close`, or with the trainer's process.
    """

    def __init__(
        self,
        factory: Callable[[int], Any],
        batch_size: int,
        workers: int,
        actor,
        threads: int = 1,
    ):
        if isinstance(workers, bool) or not isinstance(workers, int):
            raise ValueError(f"algo.collector_workers={workers!r} must be an integer")
        if not 1 <= workers <= MAX_COLLECTOR_WORKERS:
            raise ValueError(
                f"algo.collector_workers={workers} must be in [1, {MAX_COLLECTOR_WORKERS}]"
            )
        if batch_size % workers:
            raise ValueError(
                f"algo.collector_workers={workers} must divide the batch of {batch_size} "
                "scenarios (each worker collects an equal share)"
            )
        self.factory = factory
        self.batch_size = int(batch_size)
        self.workers = workers
        self.threads = int(threads)
        self._actor = actor
        self._connections: list = []
        self._processes: list = []
        self._sent_policy = None  # the policy object the workers hold (identity)
        self._pending: list | None = None  # worker states to load when they start
        #: the workers' CPU seconds of the last collect() (all of them together)
        self.last_cpu_s = 0.0

    # ------------------------------------------------------------------ processes
    @property
    def started(self) -> bool:
        return bool(self._processes)

    def _start(self, env=None) -> None:
        context = mp.get_context("spawn")
        actor = _dumps(self._actor)
        share = self.batch_size // self.workers
        for _ in range(self.workers):
            parent, child = context.Pipe()
            process = context.Process(
                target=_serve,
                args=(child, self.factory, share, actor, self.threads),
                daemon=True,
            )
            process.start()
            child.close()
            self._connections.append(parent)
            self._processes.append(process)
        self._receive_all("start")
        if self._pending is not None:
            states, self._pending = self._pending, None
            self.load(states, env)

    def _receive(self, index: int, what: str):
        try:
            status, payload = self._connections[index].recv()
        except (EOFError, OSError) as error:
            code = self._processes[index].exitcode
            self.close()
            raise RuntimeError(
                f"collector worker {index} ended during {what} (exit code {code})"
            ) from error
        if status == "error":
            self.close()
            raise RuntimeError(f"collector worker {index} failed during {what}:\n{payload}")
        return payload

    def _receive_all(self, what: str) -> list:
        return [self._receive(i, what) for i in range(self.workers)]

    def close(self) -> None:
        """Stop the workers (a later :meth:`collect` starts new ones from fresh scenarios)."""
        for connection in self._connections:
            try:
                connection.send(("stop", None))
            except (BrokenPipeError, OSError):
                pass
        for process in self._processes:
            process.join(timeout=10)
            if process.is_alive():
                process.kill()
                process.join()
        for connection in self._connections:
            connection.close()
        self._connections, self._processes, self._sent_policy = [], [], None

    def __del__(self):  # a trainer dropped without close(): its workers go with it
        try:
            self.close()
        except Exception:  # noqa: BLE001 - the interpreter may be shutting down
            pass

    # ------------------------------------------------------------------ work
    def _policy_message(self, env) -> bytes | None:
        """The trainer environment's swappable policy, if the workers do not hold it yet."""
        policy_of = getattr(self.factory, "policy_of", None)
        if policy_of is None:
            return None
        policy = policy_of(env)
        if policy is self._sent_policy:
            return None
        try:
            message = _dumps(policy)
        except Exception as error:  # noqa: BLE001 - pickling fails in many ways
            raise ValueError(
                f"algo.collector_workers={self.workers}: the environment's policy "
                f"{type(policy).__name__} cannot be sent to the worker processes ({error}); "
                "set algo.collector_workers=0"
            ) from error
        self._sent_policy = policy
        return message

    def collect(self, env, seed: int, steps: int) -> TensorDictBase:
        """One batch of ``steps`` steps of every worker's scenarios under the actor's current
        weights, joined along the scenario dimension (worker 0's first). ``env`` is the
        trainer's environment (for ``policy_of``); ``seed`` is the iteration's
        (``seed_for(k)``), which each worker turns into its own with :func:`shard_seed`."""
        if not self.started:
            self._start(env)
        weights = _dumps(self._actor.state_dict())
        policy = self._policy_message(env)
        for index, connection in enumerate(self._connections):
            connection.send(("collect", (weights, policy, shard_seed(seed, index), steps)))
        replies = self._receive_all("collect")
        self.last_cpu_s = sum(cpu for _, cpu in replies)
        return torch.cat([_loads(data) for data, _ in replies], dim=0)

    def state(self) -> list | None:
        """Every worker's scenarios, where they continue and its generator (None before the
        first collection): what :meth:`load` restores."""
        if not self.started:
            return self._pending
        for connection in self._connections:
            connection.send(("state", None))
        states = [_loads(data) for data in self._receive_all("state")]
        return None if any(s is None for s in states) else states

    def load(self, states: Sequence[dict] | None, env=None) -> None:
        """Restore :meth:`state` (the workers start with it; ``None``: fresh scenarios)."""
        if states is not None and len(states) != self.workers:
            raise ValueError(
                f"algo.collector_workers={self.workers} cannot continue a checkpoint collected "
                f"by {len(states)} worker processes; set algo.collector_workers={len(states)}"
            )
        if not self.started:
            self._pending = None if states is None else list(states)
            return
        if states is None:
            self.close()
            return
        policy = self._policy_message(env) if env is not None else None
        for connection, state in zip(self._connections, states, strict=True):
            connection.send(("load", (policy, _dumps(state))))
        self._receive_all("load")
