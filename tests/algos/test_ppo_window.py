"""The RRA learning problem's window and credit (docs/model.md §5): scenarios persist across
PPO iterations, a resumed trainer continues them bit for bit, and subframes of a silent link
do not train the policy."""

from __future__ import annotations

import io

import torch

from vdtn_marl.algos.ppo import PPOTrainer
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.experiment.config import AlgoConfig

ALGO = AlgoConfig(rra_num_envs=4, rra_rollout_steps=30, minibatch_size=64, epochs=1)
EPISODE_INTERVALS = 3  # 150 subframes


def rra_trainer(**algo_changes) -> PPOTrainer:
    from dataclasses import replace

    env = VDTNTorchRLEnv(
        "rra", batch_size=4, seed=0, episode_intervals=EPISODE_INTERVALS, reward="drra",
        ivoi_estimator="none",
    )  # fmt: skip
    bits_left = env.twin.rra_layout.bits_left
    return PPOTrainer(
        env,
        "rra",
        replace(ALGO, **algo_changes),
        seed=1,
        rollout_steps=30,
        active=lambda obs: obs[..., bits_left] > 0,
    )


def test_scenarios_persist_across_iterations_and_reset_only_at_episode_end():
    trainer = rra_trainer()
    twin = trainer.env.twin
    seen, dones = [], []
    for _ in range(6):  # 180 subframes: one whole episode and 30 subframes of the next
        data = trainer.collect()
        seen.append((int(twin.interval[0]), twin.subframe))
        dones.append(data.get(("next", "done")).squeeze(-1))  # [B, steps]
    # 30 subframes per batch: the clock runs on instead of starting at 0 every batch
    assert seen[:4] == [(0, 30), (1, 10), (1, 40), (2, 20)]
    assert not any(bool(done.any()) for i, done in enumerate(dones) if i != 4)
    assert bool(dones[4][:, -1].all()) and not bool(dones[4][:, :-1].any())  # subframe 149
    assert seen[5] == (0, 30)  # the next episode


def test_fresh_batches_with_persistent_envs_off():
    trainer = rra_trainer(persistent_envs=False)
    for _ in range(3):
        trainer.collect()
        assert (int(trainer.env.twin.interval[0]), trainer.env.twin.subframe) == (0, 30)


def test_a_restored_trainer_continues_the_persisting_scenarios_bit_for_bit():
    torch.manual_seed(0)
    first = rra_trainer()
    for _ in range(3):
        first.train_iteration()
    buffer = io.BytesIO()
    torch.save(first.state_dict(), buffer)  # what a checkpoint holds, read back safely
    buffer.seek(0)
    state = torch.load(buffer, weights_only=True)
    rng = torch.get_rng_state()
    expected = [first.collect() for _ in range(3)]
    second = rra_trainer()
    second.load_state_dict(state)
    torch.set_rng_state(rng)
    for want in expected:
        got = second.collect()
        for key in (("rra", "observation"), ("rra", "action"), ("next", "rra", "reward")):
            assert torch.equal(got.get(key), want.get(key)), key


def test_validation_does_not_disturb_the_persisting_scenarios():
    trainer = rra_trainer()
    trainer.collect()
    before = trainer.env.state_dict()
    trainer.validation_return()  # resets and steps the same environment
    after = trainer.env.state_dict()
    assert torch.equal(
        after["twin"]["__object__"]["_rra_obs"], before["twin"]["__object__"]["_rra_obs"]
    )
    assert after["twin"]["__object__"]["subframe"] == before["twin"]["__object__"]["subframe"]


def test_silent_subframes_get_no_advantage_and_active_ones_are_standardised():
    trainer = rra_trainer()
    time_left = trainer.env.twin.rra_layout.time_left
    trainer.active = lambda obs: obs[..., time_left] > 0.7  # a known mix of active steps
    trainer.fit_observation_scaling()
    data = trainer.collect()
    with torch.no_grad():
        trainer.loss.value_estimator(
            data,
            params=trainer.loss.critic_network_params,
            target_params=trainer.loss.target_critic_network_params,
        )
    trainer._mask_advantage(data)
    advantage = data.get(trainer.loss.tensor_keys.advantage).squeeze(-1)  # [B, steps, L]
    active = trainer.active(data.get(("rra", "observation")))
    assert bool(active.any()) and bool((~active).any())
    assert float(advantage[~active].abs().max()) == 0.0
    for link in range(advantage.shape[-1]):
        values = advantage[..., link][active[..., link]]
        assert abs(float(values.mean())) < 1e-5
        assert abs(float(values.std()) - 1.0) < 1e-4
