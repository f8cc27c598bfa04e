"""``algo.collector_workers``: the vehicle stages' persisting scenarios collected by worker
processes (vdtn_marl/algos/shards.py). Each worker's share is the batch the trainer's own
process would collect from the worker's seed; a sharded run resumes bit for bit."""

import copy
import os
import signal
import sys
from dataclasses import replace

import pytest
import torch
from tensordict.nn import InteractionType, set_interaction_type

from vdtn_marl.algos.params import AlgoConfig
from vdtn_marl.algos.ppo import ActorPolicy, PPOTrainer
from vdtn_marl.algos.shards import ShardedCollector, continue_rollout, shard_seed
from vdtn_marl.errors import ConfigError
from vdtn_marl.experiment.config import validate
from vdtn_marl.experiment.jocc import JointOptimisation, SwitchablePolicy, TrainingEnvFactory
from vdtn_marl.policies import make_rra_baseline
from vdtn_marl.sim.params import TwinParams

sys.path.insert(0, __file__.rsplit("/", 1)[0])
from test_training import (  # noqa: E402
    TINY_ALGO,
    TINY_EXPERIMENT,
    _all_params,
    interrupt_and_resume,
    tiny_config,
)

pytestmark = pytest.mark.slow  # workers and training (the fast loop skips them)

ALGO = AlgoConfig(num_envs=4, rollout_steps=3, minibatch_size=12, epochs=1, collector_workers=2)
ENV_KW = {"seed": 0, "episode_intervals": 20}


def _impaired_trainer(workers: int = 2) -> tuple[PPOTrainer, TrainingEnvFactory]:
    params = TwinParams.from_overrides(episode_intervals=20)
    factory = TrainingEnvFactory("control_impaired", ENV_KW, params, seed=0)
    env = factory(ALGO.num_envs)
    env.rra_policy.policy = make_rra_baseline("random", params, 5)  # JOCC's slot, swapped
    algo = replace(ALGO, collector_workers=workers)
    return PPOTrainer(env, "vehicle", algo, seed=3, env_factory=factory), factory


def test_worker_seeds_are_none_of_the_runs_iteration_seeds():
    from vdtn_marl.algos.ppo import SEED_STRIDE

    for run_seed in (0, 1, 7, 4000):
        own = range(run_seed * SEED_STRIDE, (run_seed + 1) * SEED_STRIDE)
        for k in (0, 1, 499, SEED_STRIDE - 1):
            seeds = [shard_seed(run_seed * SEED_STRIDE + k, i) for i in range(65)]
            assert seeds[0] == (run_seed * SEED_STRIDE + k) % 2**32
            assert len(set(seeds)) == 65
            assert not any(s in own for s in seeds[1:]), (run_seed, k)


@pytest.fixture
def one_thread():  # the workers' (torch's sums split over threads round otherwise)
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_each_worker_collects_what_its_seed_gives_in_one_process(one_thread):
    trainer, factory = _impaired_trainer()
    try:
        first = trainer.collect()
        for process in trainer.shards._processes:  # Ctrl-C is the trainer's, not theirs
            os.kill(process.pid, signal.SIGINT)
        second = trainer.collect()  # the workers' scenarios continue
        assert trainer.shards.last_cpu_s > 0.0  # the workers' CPU seconds of that collection
    finally:
        trainer.close()
    assert first.batch_size == torch.Size([4, 3])
    share = ALGO.num_envs // ALGO.collector_workers
    for worker in range(ALGO.collector_workers):
        seed = shard_seed(trainer.seed_for(0), worker)
        env = factory(share)
        factory.install(env, make_rra_baseline("random", trainer.env.twin.params, 5))
        env.set_seed(seed)  # seeds the slot's random RRA policy too
        torch.manual_seed(seed)
        with torch.no_grad(), set_interaction_type(InteractionType.RANDOM):
            state = env.reset()
            want_first, state = continue_rollout(env, trainer.actor, state, 3)
            want_second, _ = continue_rollout(env, trainer.actor, state, 3)
        rows = slice(worker * share, (worker + 1) * share)
        for got, want in ((first[rows], want_first), (second[rows], want_second)):
            assert (got == want).all(), worker
    # the two workers' scenarios differ
    key = ("next", "vehicle", "observation")
    assert not torch.equal(first.get(key)[:share], first.get(key)[share:])


def test_workers_get_the_new_weights_and_a_swapped_policy(one_thread):
    trainer, factory = _impaired_trainer(workers=1)
    params = trainer.env.twin.params
    before = copy.deepcopy(trainer.actor.state_dict())
    try:
        first = trainer.collect()
        assert trainer.shards._sent_policy is trainer.env.rra_policy.policy
        with torch.no_grad():
            for p in trainer.actor.parameters():
                p.mul_(1.5)
        trainer.env.rra_policy.policy = make_rra_baseline("greedy", params, 0)  # JOCC swaps
        second = trainer.collect()
        assert trainer.shards._sent_policy is trainer.env.rra_policy.policy
    finally:
        trainer.close()
    after = copy.deepcopy(trainer.actor.state_dict())
    seed = shard_seed(trainer.seed_for(0), 0)
    env = factory(ALGO.num_envs)
    factory.install(env, make_rra_baseline("random", params, 5))
    env.set_seed(seed)
    torch.manual_seed(seed)
    with torch.no_grad(), set_interaction_type(InteractionType.RANDOM):
        trainer.actor.load_state_dict(before)
        want_first, state = continue_rollout(env, trainer.actor, env.reset(), 3)
        trainer.actor.load_state_dict(after)
        factory.install(env, make_rra_baseline("greedy", params, 0))
        want_second, _ = continue_rollout(env, trainer.actor, state, 3)
    assert (first == want_first).all()
    assert (second == want_second).all()


def test_a_policy_that_cannot_be_sent_is_named():
    trainer, _ = _impaired_trainer(workers=1)
    trainer.env.rra_policy.policy = lambda observation: observation  # not picklable
    with pytest.raises(ValueError, match="algo.collector_workers"):
        trainer.collect()
    trainer.close()


class _Failing:
    def __call__(self, batch_size):
        raise RuntimeError("no environment here")


def test_a_failing_worker_is_reported_with_its_traceback():
    trainer, _ = _impaired_trainer(workers=1)
    trainer.shards.factory = _Failing()
    with pytest.raises(RuntimeError, match="(?s)collector worker 0.*no environment here"):
        trainer.collect()
    assert not trainer.shards.started


def test_checkpoints_of_the_other_collection_are_refused():
    sharded, _ = _impaired_trainer(workers=2)
    try:
        sharded.collect()
        state = sharded.state_dict()
    finally:
        sharded.close()
    assert len(state["shards"]) == 2 and "carry" not in state
    one, _ = _impaired_trainer(workers=1)
    with pytest.raises(ValueError, match="algo.collector_workers=1"):
        one.load_state_dict(state)  # 2 workers' scenarios
    plain = PPOTrainer(one.env, "vehicle", replace(ALGO, collector_workers=0), seed=3)
    with pytest.raises(ValueError, match="algo.collector_workers=0"):
        plain.load_state_dict(state)
    plain.collect()
    with pytest.raises(ValueError, match="algo.collector_workers=1"):
        one.load_state_dict(plain.state_dict())
    with pytest.raises(ValueError, match="algo.collector_workers=3"):
        ShardedCollector(TrainingEnvFactory("control", ENV_KW), 4, 3, one.actor)


@pytest.mark.parametrize(
    "change, key",
    [
        ({"collector_workers": 3}, "algo.collector_workers=3"),  # does not divide num_envs
        ({"collector_workers": -1}, "algo.collector_workers=-1"),
        ({"collector_workers": 65}, "algo.collector_workers=65"),
    ],
)
def test_config_values_out_of_range_are_named(change, key):
    with pytest.raises(ConfigError, match=key):
        validate(tiny_config(algo=replace(TINY_ALGO, **change)))


def test_workers_need_the_cpu():
    with pytest.raises(ConfigError, match="algo.collector_workers=2"):
        validate(tiny_config(algo=replace(TINY_ALGO, collector_workers=2), device="cuda"))


def test_sharded_jocc_resumes_bit_for_bit_under_the_learned_rra(tmp_path, monkeypatch):
    cfg = tiny_config(
        algo=replace(TINY_ALGO, collector_workers=2),
        experiment=replace(TINY_EXPERIMENT, jocc_iterations=2),
    )
    straight = JointOptimisation(cfg, tmp_path / "straight")
    straight.run()
    reference = _all_params(straight)
    assert isinstance(straight.rra_slot, SwitchablePolicy)
    assert isinstance(straight.rra_slot.policy, ActorPolicy)  # π̃ of iteration 1

    # Ctrl-C in π̃'s stage of JOCC iteration 1 (the run's 17th PPO iteration), after a checkpoint
    interrupted = interrupt_and_resume(cfg, tmp_path, monkeypatch, 17, reference)
    assert not interrupted.pi_tilde.shards.started  # the run stopped its workers
