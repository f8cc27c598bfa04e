"""MAPPO training, the PettingZooWrapper path, checkpoints and resume, RRA reward variants."""

import math
from dataclasses import replace
from pathlib import Path

import pytest
import torch

import vdtn_marl
from vdtn_marl.algos.checkpoint import CheckpointError, load_checkpoint
from vdtn_marl.algos.evaluate import evaluate_system
from vdtn_marl.algos.networks import scalers
from vdtn_marl.algos.ppo import ActorPolicy, PPOTrainer
from vdtn_marl.algos.trainer import ALGORITHMS, Trainer, trainer_class
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RRAConfig,
    RunConfig,
    ScenarioConfig,
    to_dict,
    validate,
)
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import read_csv_rows
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.layout import RRAFeatureLayout
from vdtn_marl.sim.params import ConfigError, TwinParams
from vdtn_marl.voi import TDIVoIEstimator

pytestmark = pytest.mark.slow  # training runs (the fast loop skips them)

TINY_ALGO = AlgoConfig(
    num_envs=8,
    rollout_steps=10,
    rra_num_envs=8,
    rra_rollout_steps=50,
    minibatch_size=128,
    epochs=2,
)
TINY_EXPERIMENT = ExperimentConfig(
    control_iterations=4, rra_iterations=2, eval_episodes=4, eval_intervals=20, checkpoint_every=2
)


def tiny_config(**kw) -> RunConfig:
    base = RunConfig(
        scenario=ScenarioConfig(episode_intervals=40),
        control=ControlConfig(warm_start="none"),  # the imitation has its own tests
        algo=TINY_ALGO,
        experiment=TINY_EXPERIMENT,
        progress=False,
    )
    return replace(base, **kw)


def test_mappo_improves_the_control_return_over_the_untrained_policy():
    torch.manual_seed(0)
    params = TwinParams.from_overrides(episode_intervals=100)
    algo = AlgoConfig(
        num_envs=16,
        rollout_steps=50,
        epochs=10,
        minibatch_size=512,
        lr=1e-3,
        gamma=0.95,
        initial_log_scale=-1.5,
        persistent_envs=False,  # batches from resets: the window this threshold was set on
    )
    env = VDTNTorchRLEnv("control", batch_size=16, seed=0, episode_intervals=100)
    trainer = PPOTrainer(env, "vehicle", algo, seed=0, prior=None)

    def evaluation_return() -> float:
        policy = ActorPolicy(trainer.actor, "vehicle")
        result = evaluate_system(
            params, policy, None, perfect=True, episodes=16, intervals=100, seed=77, gamma=0.95
        )
        return result.metrics["control_return"]

    before = evaluation_return()
    for _ in range(6):
        trainer.train_iteration()
    after = evaluation_return()
    # the untrained policy commands ~0 m/s² and drifts into collisions; a learning loss closes
    # most of that gap within a few iterations, a broken one does not
    assert after > before + 0.3 * abs(before), (before, after)


def test_one_training_iteration_through_pettingzoo_wrapper():
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    env = PettingZooWrapper(
        vdtn_marl.make("vdtn/platoon-control-v0", episode_intervals=30),
        return_state=False,
        use_mask=False,
    )
    trainer = PPOTrainer(env, "vehicle", replace(TINY_ALGO, rollout_steps=20), seed=1)
    before = [p.detach().clone() for p in trainer.actor.parameters()]
    stats = trainer.train_iteration()
    assert stats.frames == 20
    assert torch.isfinite(torch.tensor(stats.loss_critic))
    after = list(trainer.actor.parameters())
    assert any(not torch.equal(a, b) for a, b in zip(before, after, strict=True))


def _actor_params(loop: JointOptimisation) -> list[torch.Tensor]:
    return [p.detach().clone() for p in loop.pi_star.actor.parameters()]


@pytest.mark.parametrize(
    "algo",
    [TINY_ALGO, replace(TINY_ALGO, lr_schedule="linear", validate_every=2)],
    ids=["constant", "linear-validated"],
)
def test_resume_continues_bit_for_bit(tmp_path, monkeypatch, algo):
    cfg = tiny_config(algo=algo)
    straight = JointOptimisation(cfg, tmp_path / "straight", task="control")
    straight.run()
    reference = _actor_params(straight)

    interrupted = JointOptimisation(cfg, tmp_path / "resumed", task="control")
    original = PPOTrainer.train_iteration
    calls = {"n": 0}

    def crash_after_three(self):
        calls["n"] += 1
        if calls["n"] == 4:
            raise KeyboardInterrupt  # the user pressed Ctrl-C in the 4th iteration
        return original(self)

    monkeypatch.setattr(PPOTrainer, "train_iteration", crash_after_three)
    with pytest.raises(KeyboardInterrupt):
        interrupted.run()
    monkeypatch.setattr(PPOTrainer, "train_iteration", original)
    assert not (tmp_path / "resumed" / "summary.json").exists()

    resumed = JointOptimisation(replace(cfg, resume=True), tmp_path / "resumed", task="control")
    summary = resumed.run()
    assert summary["resumed"] is True
    for a, b in zip(reference, _actor_params(resumed), strict=True):
        assert torch.equal(a, b)
    straight_rows = (tmp_path / "straight" / "metrics.csv").read_text().splitlines()
    resumed_rows = (tmp_path / "resumed" / "metrics.csv").read_text().splitlines()
    assert len(straight_rows) == len(resumed_rows) == 1 + TINY_EXPERIMENT.control_iterations
    strip_seconds = [row.rsplit(",", 1)[0] for row in straight_rows]
    assert strip_seconds == [row.rsplit(",", 1)[0] for row in resumed_rows]


def test_linear_schedule_and_validation_keep_the_best_iterate(monkeypatch):
    algo = replace(TINY_ALGO, lr_schedule="linear", validate_every=2, lr=1e-3)
    trainer = PPOTrainer(VDTNTorchRLEnv("control", batch_size=8, seed=0), "vehicle", algo, seed=0)
    # validated at the start, after iterations 1, 3 and 4 (the stage's last)
    scores = iter([1.5, 0.5, 2.0, 1.0])
    monkeypatch.setattr(PPOTrainer, "validation_return", lambda self: next(scores))
    assert trainer.learning_rate() == pytest.approx(1e-3)  # outside a stage: constant
    trainer.begin_stage(5)
    snapshots, rates, validated = [], [], []
    for _ in range(5):
        stats = trainer.train_iteration()
        rates.append(stats.lr)
        validated.append(stats.validation_return)
        snapshots.append([p.detach().clone() for p in trainer.actor.parameters()])
    assert rates == pytest.approx([1e-3, 8e-4, 6e-4, 4e-4, 2e-4])
    assert validated[0] != validated[0] and validated[2] != validated[2]  # NaN: not scored
    assert validated[1::2] == [0.5, 2.0] and validated[4] == 1.0
    assert trainer.finish_stage() == {"best_iteration": 3, "best_return": 2.0}
    kept = [p.detach() for p in trainer.actor.parameters()]
    assert all(torch.equal(a, b) for a, b in zip(kept, snapshots[3], strict=True))
    assert not all(torch.equal(a, b) for a, b in zip(kept, snapshots[4], strict=True))
    assert trainer.finish_stage() == {"best_iteration": None, "best_return": None}
    with pytest.raises(ValueError, match="stage iterations=0"):
        trainer.begin_stage(0)


def test_validation_keeps_the_starting_weights_unless_ppo_beats_them(monkeypatch):
    algo = replace(TINY_ALGO, validate_every=1, lr=1e-2)
    trainer = PPOTrainer(VDTNTorchRLEnv("control", batch_size=8, seed=0), "vehicle", algo, seed=0)
    trainer.train_iteration()  # the stage starts after iteration 0
    start = [p.detach().clone() for p in trainer.actor.parameters()]
    scores = iter([3.0, 1.0, 2.0])  # the start, then iterations 1 and 2
    monkeypatch.setattr(PPOTrainer, "validation_return", lambda self: next(scores))
    trainer.begin_stage(2)
    trainer.train_iteration()
    trainer.train_iteration()
    assert not all(
        torch.equal(a, b) for a, b in zip(trainer.actor.parameters(), start, strict=True)
    )
    assert trainer.finish_stage() == {"best_iteration": 0, "best_return": 3.0}
    assert all(torch.equal(a, b) for a, b in zip(trainer.actor.parameters(), start, strict=True))


def test_validation_scores_whole_batches_of_at_least_validation_scenarios():
    algo = replace(TINY_ALGO, validation_scenarios=10)
    trainer = PPOTrainer(VDTNTorchRLEnv("control", batch_size=4, seed=0), "vehicle", algo, seed=3)
    trainer.fit_observation_scaling()
    rollouts = []
    original = trainer.env.rollout
    trainer.env.rollout = lambda *a, **k: rollouts.append(1) or original(*a, **k)
    trainer.validation_return()
    assert len(rollouts) == 3  # ceil(10 / 4) batches of 4 scenarios


def test_validation_return_is_repeatable_and_deterministic():
    trainer = PPOTrainer(
        VDTNTorchRLEnv("control", batch_size=4, seed=0), "vehicle", TINY_ALGO, seed=3
    )
    trainer.fit_observation_scaling()
    first = trainer.validation_return()
    trainer.collect()  # training scenarios in between change nothing
    assert trainer.validation_return() == first
    training_reward = trainer.collect(iteration=0).get(("next", "vehicle", "reward")).mean()
    assert first != float(training_reward)  # not the stochastic policy on the training scenarios


def test_one_jocc_iteration_writes_metrics_and_a_loadable_checkpoint(tmp_path):
    cfg = tiny_config(experiment=replace(TINY_EXPERIMENT, control_iterations=1))
    summary = JointOptimisation(cfg, tmp_path).run()
    for key in (
        "control_cost",
        "gap_error_abs_m",
        "speed_error_abs_mps",
        "cam_delivery_rate",
        "cam_latency_ms_p95",
        "v2i_throughput_mbps_per_link",
        "evoi",
        "evoi_ci_low",
        "evoi_ci_high",
    ):
        assert key in summary, key
    assert summary["evoi_ci_low"] <= summary["evoi"] <= summary["evoi_ci_high"]
    assert summary["trainer_iterations"] == {"pi_star": 1, "pi_tilde": 1, "rra": 2}
    assert (summary["kappa1"], summary["kappa2"]) == (cfg.rra.kappa1, cfg.rra.kappa2_value)
    assert summary["traces"] == cfg.scenario.traces == "cmap"
    assert summary["trace_path"] is None and summary["trace_preprocessing"] is None
    # `task` picks the stage of `vdtn-marl train`: a jocc run's summary does not claim one
    assert summary["task"] == "jocc" and "task" not in summary["config"]
    payload = load_checkpoint(tmp_path / "checkpoints" / "last.pt", to_dict(cfg))
    assert payload["position"]["iteration"] == 1
    # every PPO iteration of every stage logs PPO's health beside its losses
    rows = read_csv_rows(tmp_path / "metrics.csv")
    assert {r["stage"] for r in rows} == {"control_perfect", "control_impaired", "rra"}
    for row in rows:
        assert 0.0 <= float(row["clip_fraction"]) <= 1.0, row
        assert math.isfinite(float(row["kl_approx"])), row
        assert float(row["explained_variance"]) <= 1.0, row


def test_ppo_health_reads_zero_kl_and_no_clipping_when_the_policy_cannot_move():
    """With lr = 0 the updated policy is the collecting one: ratio 1 everywhere, so nothing is
    clipped and TorchRL's approximate KL is 0 (to the rounding of recomputed log-probabilities);
    with a large lr PPO moves and clips."""
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    def stats(lr: float):
        env = PettingZooWrapper(
            vdtn_marl.make("vdtn/platoon-control-v0", episode_intervals=30),
            return_state=False,
            use_mask=False,
        )
        algo = replace(TINY_ALGO, rollout_steps=20, lr=lr, epochs=4)
        return PPOTrainer(env, "vehicle", algo, seed=1).train_iteration()

    frozen = stats(0.0)
    assert abs(frozen.kl_approx) < 1e-6 and frozen.clip_fraction == 0.0
    assert math.isfinite(frozen.explained_variance) and frozen.explained_variance <= 1.0
    moving = stats(0.05)
    assert abs(moving.kl_approx) > 1e-4 and 0.0 < moving.clip_fraction <= 1.0


def test_summary_lists_each_jocc_iterations_evaluation(tmp_path):
    experiment = replace(TINY_EXPERIMENT, control_iterations=1, rra_iterations=1)
    cfg = tiny_config(experiment=replace(experiment, jocc_iterations=2))
    summary = JointOptimisation(cfg, tmp_path).run()
    rows = summary["per_iteration"]
    assert [row["jocc_iteration"] for row in rows] == [0, 1]
    assert rows[-1]["cam_delivery_rate"] == summary["cam_delivery_rate"]
    assert rows[-1]["gap_error_abs_m"] == summary["gap_error_abs_m"]
    assert all(set(row) == set(rows[0]) and len(row) == 8 for row in rows)


def test_truncated_foreign_and_mismatched_checkpoints_raise(tmp_path):
    cfg = tiny_config(experiment=replace(TINY_EXPERIMENT, control_iterations=1))
    summary = JointOptimisation(cfg, tmp_path, task="control").run()
    assert summary["task"] == summary["config"]["task"] == "control"
    good = tmp_path / "checkpoints" / "last.pt"
    data = good.read_bytes()

    truncated = tmp_path / "truncated.pt"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="truncated"):
        load_checkpoint(truncated)

    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    with pytest.raises(CheckpointError, match="not a vdtn-marl checkpoint"):
        load_checkpoint(foreign)

    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "missing.pt")

    # a checkpoint of format 1, whose shared centralised critic gave all agents one value
    older = tmp_path / "older.pt"
    payload = torch.load(good, weights_only=True)
    torch.save({**payload, "format_version": 1}, older)
    with pytest.raises(CheckpointError, match=r"format_version=1; .* reads format_version=2"):
        load_checkpoint(older)

    other = to_dict(cfg)
    other["scenario"]["num_vehicles"] = 6
    with pytest.raises(CheckpointError, match="scenario.num_vehicles"):
        load_checkpoint(good, other)


def _savez(path):
    import numpy as np

    np.savez(path, returns=np.arange(3.0))


@pytest.mark.parametrize(
    "name, write",
    [
        ("config.yaml", lambda p: p.write_text("scenario:\n  num_vehicles: 4\nseed: 0\n")),
        ("metrics.csv", lambda p: p.write_text("iteration,control_cost\n0,1.5\n1,1.25\n")),
        ("hello.txt", lambda p: p.write_text("hello")),  # 'h': a memo lookup (KeyError: 101)
        ("notes.txt", lambda p: p.write_text("(abc\n1,2\n")),  # "(": a mark (IndexError)
        ("evaluation_raw.npz", _savez),  # a zip archive, but not torch's
    ],
)
def test_files_that_are_not_checkpoints_are_named_as_such(name, write, tmp_path):
    path = tmp_path / name
    write(path)
    with pytest.raises(CheckpointError, match="not a vdtn-marl checkpoint") as info:
        load_checkpoint(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)
    assert "truncated" not in str(info.value)


class RecordingEstimator:
    """A TD estimator with a fixed critic that keeps every ξ it returned."""

    def __init__(self):
        self.inner = TDIVoIEstimator(lambda obs: -obs[..., 0].abs(), discount=0.9)
        self.values = []

    def __call__(self, twin, record):
        xi = self.inner(twin, record)
        self.values.append(xi.clone())
        return xi


def _rra_rewards(reward: str, estimator=None, steps: int = 100):
    env = VDTNTorchRLEnv(
        "rra", batch_size=4, seed=3, reward=reward, kappa1=0.3, ivoi_estimator=estimator or "none"
    )
    from vdtn_marl.policies import make_rra_baseline

    greedy = make_rra_baseline("greedy", env.twin.params, 5)  # delivers CAMs (random rarely does)
    td = env.reset()
    rewards = []
    for _ in range(steps):
        td["rra", "action"] = greedy(td["rra", "observation"])
        td = env.step(td)["next"]
        rewards.append(td["rra", "reward"].squeeze(-1))
    return torch.stack(rewards)  # [steps, B, L]


def test_jocc_and_drra_rewards_differ_from_throughput_exactly_as_specified():
    estimator = RecordingEstimator()
    jocc = _rra_rewards("jocc", estimator)
    drra = _rra_rewards("drra")
    throughput = _rra_rewards("throughput")  # κ1·s_g·g only
    closing = torch.zeros(jocc.shape[0], dtype=torch.bool)
    closing[49::50] = True
    # jocc adds κ2·s_ξ·ξ at the last subframe of every interval, nothing elsewhere
    torch.testing.assert_close(jocc[~closing], throughput[~closing])
    xi = torch.stack(estimator.values)
    torch.testing.assert_close(jocc[closing] - throughput[closing], 0.7 * 20.0 * xi)
    assert xi.abs().sum() > 0
    # drra adds κ2·progress ≥ 0 every subframe: κ2 once the CAM is delivered, κ2·log2(1+SINR)/10
    # while it is pending (and −κ2·penalty at the last subframe for a missed CAM)
    extra = drra[~closing] - throughput[~closing]
    assert (extra >= -1e-6).all() and extra.sum() > 0
    assert torch.isclose(extra, torch.tensor(0.7)).any()


def test_impaired_control_training_with_kalman_completion(tmp_path):
    cfg = tiny_config(
        control=ControlConfig(completion="kalman", warm_start="none"),
        experiment=replace(TINY_EXPERIMENT, control_iterations=1),
    )
    summary = JointOptimisation(cfg, tmp_path, task="control_impaired").run()
    assert summary["trainer_iterations"]["pi_tilde"] == 1
    assert 0.0 <= summary["cam_delivery_rate"] <= 1.0
    assert all(p.endswith(".png") for p in summary["plots"])


@pytest.mark.parametrize(
    ("name", "steps", "expected"),
    [("oracle", None, 400), ("oracle", 60, 60), ("causal_mpc", None, 200), ("causal_mpc", 30, 30)],
)
def test_mpc_controls_take_their_solver_steps_from_the_config(tmp_path, name, steps, expected):
    cfg = tiny_config(control=ControlConfig(name=name, augmentation=False, mpc_iterations=steps))
    controller = JointOptimisation(cfg, tmp_path).control_policy()
    assert controller.iterations == expected


@pytest.mark.parametrize(
    "credit, rra_step", [("subframe", (0.97, 0.99)), ("interval", (0.97**0.02, 0.99))]
)
def test_each_group_gets_the_gae_lambda_and_discount_of_its_clock(tmp_path, credit, rra_step):
    """Vehicles discount per control interval; RRA agents per subframe, with the interval's
    γ spread over its T = 50 subframes by default (the paper's objective; λ per step)."""
    algo = replace(
        TINY_ALGO, lmbda=0.9, rra_lmbda=0.99, gamma=0.98, rra_gamma=0.97, rra_credit=credit
    )
    loop = JointOptimisation(tiny_config(algo=algo), tmp_path)
    for name, (gamma, lmbda) in {
        "pi_star": (0.98, 0.9), "pi_tilde": (0.98, 0.9), "rra": rra_step,
    }.items():  # fmt: skip
        estimator = loop.trainers()[name].loss.value_estimator
        assert float(estimator.gamma) == pytest.approx(gamma, rel=1e-6), name
        assert float(estimator.lmbda) == pytest.approx(lmbda, rel=1e-6), name


def test_rra_agents_collect_after_the_configured_burn_in(tmp_path):
    algo = replace(TINY_ALGO, rra_burn_in_intervals=7)
    loop = JointOptimisation(tiny_config(algo=algo), tmp_path)
    env = loop.rra.env
    assert env.burn_in_intervals == 7
    starts = set()
    for iteration in range(6):
        loop.rra.collect(iteration)  # a fresh reset, then the batch
        starts.add(int(env.twin.interval[0]))
    # each batch began after 0..7 intervals (plus the batch's own), not always at 0
    assert len(starts) > 1


def test_jocc_hands_the_configured_ivoi_baseline_to_the_rra_environment(tmp_path):
    """rra.ivoi_baseline=cam_lost: the RRA agents train on the difference reward. With κ1 = 0
    their reward is κ2·s_ξ·ξ at the last subframe of each interval and nothing else, and ξ is
    0 exactly where a CAM missed its interval."""
    rra = RRAConfig(
        kappa1=0.0, ivoi_estimator="rollout", rollout_intervals=2, ivoi_baseline="cam_lost"
    )
    algo = replace(TINY_ALGO, rra_rollout_steps=100)  # at rest in interval 0, ξ is 0 there
    loop = JointOptimisation(tiny_config(rra=rra, algo=algo), tmp_path)
    estimator = loop.rra.env.ivoi_estimator
    assert estimator.baseline == "cam_lost" and estimator.horizon_intervals == 2
    reward = loop.rra.collect(0)["next", "rra", "reward"][..., 0]  # [B, subframes, links]
    t = loop.params.platoon.subframes_per_interval
    closing = torch.arange(reward.shape[1]) % t == t - 1
    assert closing.any()
    assert (reward[:, ~closing] == 0).all()
    at_close = reward[:, closing]
    assert (at_close != 0).any() and (at_close == 0).any()  # delivered and lost CAMs
    assert loop.ivoi_estimator("rollout").baseline == "optimal"  # the default


def test_jocc_trains_the_rra_agents_on_minus_the_age_of_information(tmp_path):
    """rra=aoi with κ1 = 0: every subframe the trainer's reward is −s_A·A, A = s ms where the
    link's CAM has arrived by subframe s and a·Δt + s ms where it is still pending, read back
    from the RRA observation (time left, the held content's age a in intervals, the bits left
    after the subframe); then one PPO iteration of the same trainer as every RRA reward."""
    rra = RRAConfig(name="aoi", kappa1=0.0, aoi_scale=0.01)
    loop = JointOptimisation(tiny_config(rra=rra), tmp_path)
    batch = loop.rra.collect(0)
    lay = loop.rra.env.twin.rra_layout
    t = loop.params.platoon.subframes_per_interval
    obs, nxt = batch["rra", "observation"], batch["next", "rra", "observation"]
    reward = batch["next", "rra", "reward"][..., 0]
    s = torch.round(t * (1.0 - obs[..., lay.time_left])) + 1.0  # subframes run, 1..T
    age = obs[..., lay["cam_age"]][..., 0]
    pending = nxt[..., lay.bits_left] > 0
    keep = (s < t) & (age < 10.0)  # the next observation is the same interval's; age unclipped
    expected = -0.01 * (s + age * 50.0 * pending)
    assert keep.sum() > 100 and pending[keep].any() and (~pending[keep]).any()
    torch.testing.assert_close(reward[keep], expected[keep], rtol=1e-5, atol=1e-6)
    stats = loop.rra.train_iteration()
    assert loop.rra.iteration == 1 and math.isfinite(stats.reward_mean) and stats.reward_mean < 0


def test_rra_observation_scaling_keeps_mid_episode_control_errors_in_range(tmp_path):
    """The RRA scaler is fitted on a rollout of a few subframes; from a reset alone the
    followers' control errors in the RRA observation barely move there, and their scaled
    values on mid-episode states came out ~30× their spread. The fit also sees mid-episode
    states, so those features stay on the scale of the others."""
    loop = JointOptimisation(tiny_config(), tmp_path)
    trainer = loop.rra
    trainer.fit_observation_scaling()
    env = trainer.env
    with env.burned_in(30):  # states the fit did not see (other scenarios, another interval)
        env.set_seed(12345)
        observation = env.reset().get(("rra", "observation"))
    scaler = scalers(trainer.actor)[0]
    control = RRAFeatureLayout.for_subchannels(4).control
    z = scaler(observation)[..., control]
    rms = z.pow(2).mean(dim=(0, 1)).sqrt()  # per feature
    assert (rms < 3.0).all(), rms
    assert float(env.twin.interval[0]) == 30


def test_burned_in_is_refused_outside_rra_mode_and_range(tmp_path):
    loop = JointOptimisation(tiny_config(), tmp_path)
    with pytest.raises(ConfigError, match=r"intervals=40 must be in \[0, 39\]"):
        with loop.rra.env.burned_in(40):
            pass
    with pytest.raises(ConfigError, match="only used with mode='rra'"):
        with loop.pi_star.env.burned_in(3):
            pass


def test_a_saved_config_without_newer_keys_keeps_the_behaviour_it_was_run_with():
    from vdtn_marl.experiment.config import ABSENT_KEY_BEHAVIOUR, from_saved_dict

    saved = to_dict(RunConfig())
    for group, key in ABSENT_KEY_BEHAVIOUR:
        del saved[group][key]
    old = from_saved_dict(saved)
    for (group, key), value in ABSENT_KEY_BEHAVIOUR.items():
        assert getattr(getattr(old, group), key) == value, key
    assert old.algo.rra_credit != RunConfig().algo.rra_credit  # not today's default
    assert from_saved_dict(to_dict(RunConfig())) == RunConfig()  # present keys are kept


@pytest.mark.parametrize("name", sorted(ALGORITHMS))
def test_every_registered_algorithm_trains_through_the_trainer_protocol(name):
    """Each entry of the registry: a trainer with the members the JOCC loop uses, whose
    iteration updates the policy and reports finite losses; its YAML selects it and the config
    accepts the name."""
    import yaml

    cls = trainer_class(name)
    env = VDTNTorchRLEnv("control", batch_size=4, seed=0, episode_intervals=20)
    trainer = cls(env, "vehicle", replace(TINY_ALGO, name=name, rollout_steps=10), seed=2)
    assert isinstance(trainer, Trainer)
    before = [p.detach().clone() for p in trainer.actor.parameters()]
    trainer.begin_stage(1)
    stats = trainer.train_iteration()
    trainer.finish_stage()
    assert trainer.iteration == 1 and math.isfinite(stats.loss_objective)
    after = list(trainer.actor.parameters())
    assert any(not torch.equal(a, b) for a, b in zip(before, after, strict=True))
    conf = Path(__file__).resolve().parents[2] / "conf" / "algo" / f"{name}.yaml"
    assert yaml.safe_load(conf.read_text())["name"] == name
    validate(replace(RunConfig(), algo=replace(RunConfig().algo, name=name)))
    with pytest.raises(ConfigError, match="algo.name='nope'"):
        trainer_class("nope")


def _all_params(loop: JointOptimisation) -> list[torch.Tensor]:
    return [
        p.detach().clone()
        for trainer in loop.trainers().values()
        for module in (trainer.actor, trainer.critic)
        for p in module.parameters()
    ]


# calls of train_iteration in a 2-iteration JOCC run of TINY_EXPERIMENT: per JOCC iteration
# 4 π*, 4 π̃ and 2 RRA; each crash comes after a checkpoint of its stage (every 2 iterations)
@pytest.mark.parametrize(
    "crash_at", [7, 10, 13, 17, 20], ids=["pi_tilde0", "rra0", "pi_star1", "pi_tilde1", "rra1"]
)
def test_jocc_resumes_bit_for_bit_in_each_stage_of_two_iterations(tmp_path, monkeypatch, crash_at):
    cfg = tiny_config(experiment=replace(TINY_EXPERIMENT, jocc_iterations=2))
    straight = JointOptimisation(cfg, tmp_path / "straight")
    straight.run()
    reference = _all_params(straight)
    # the finished run's checkpoint loads too (eval, the scripts that read checkpoints)
    loaded = JointOptimisation.from_checkpoint(straight.checkpoint_path, tmp_path / "loaded")
    for a, b in zip(reference, _all_params(loaded), strict=True):
        assert torch.equal(a, b)

    interrupt_and_resume(cfg, tmp_path, monkeypatch, crash_at, reference)


def interrupt_and_resume(cfg, root: Path, monkeypatch, crash_at: int, reference) -> object:
    """Run ``cfg``'s JOCC in ``root/resumed``, stopped by Ctrl-C in the ``crash_at``-th PPO
    iteration, then resumed; assert that it ends with the weights ``reference`` and the
    metrics rows of the straight run in ``root/straight``. Returns the interrupted loop."""
    interrupted = JointOptimisation(cfg, root / "resumed")
    original = PPOTrainer.train_iteration
    calls = {"n": 0}

    def crash(self):
        calls["n"] += 1
        if calls["n"] == crash_at:
            raise KeyboardInterrupt
        return original(self)

    monkeypatch.setattr(PPOTrainer, "train_iteration", crash)
    with pytest.raises(KeyboardInterrupt):
        interrupted.run()
    monkeypatch.setattr(PPOTrainer, "train_iteration", original)

    resumed = JointOptimisation(replace(cfg, resume=True), root / "resumed")
    assert resumed.run()["resumed"] is True
    for a, b in zip(reference, _all_params(resumed), strict=True):
        assert torch.equal(a, b)
    strip = [r.rsplit(",", 1)[0] for r in (root / "straight" / "metrics.csv").open()]
    assert strip == [r.rsplit(",", 1)[0] for r in (root / "resumed" / "metrics.csv").open()]
    return interrupted


def test_fit_critic_learns_the_start_policys_returns_and_leaves_the_actor_alone():
    """PPOTrainer.fit_critic: on a held-out batch of the start policy (the CACC prior) the
    critic's mean error against its TD(λ) targets falls to a fraction, the targets' variance it
    explains grows, and the actor, the iteration count and the stage stay as they were."""
    algo = replace(TINY_ALGO, rollout_steps=100, minibatch_size=256)
    env = VDTNTorchRLEnv("control", batch_size=8, seed=0)
    trainer = PPOTrainer(
        env, "vehicle", algo, seed=0, prior=CACCController(env.twin.params.platoon)
    )
    trainer.fit_observation_scaling()
    held_out = trainer.collect(iteration=77)

    def critic_error() -> tuple[float, float]:
        data = held_out.clone()
        with torch.no_grad():
            trainer._value_targets(data)
        error = data.get(trainer.loss.tensor_keys.value_target) - data.get(
            ("vehicle", "state_value")
        )
        explained = 1.0 - float(error.var() / data.get(trainer.loss.tensor_keys.value_target).var())
        return abs(float(error.mean())), explained

    actor = [p.detach().clone() for p in trainer.actor.parameters()]
    bias_before, explained_before = critic_error()
    stats = trainer.fit_critic(10)
    bias_after, explained_after = critic_error()
    assert bias_after < 0.3 * bias_before and explained_after > explained_before
    assert math.isfinite(stats["loss_critic"]) and math.isfinite(stats["explained_variance"])
    assert all(torch.equal(a, b) for a, b in zip(trainer.actor.parameters(), actor, strict=True))
    assert (trainer.iteration, trainer.stage) == (0, None)
    with pytest.raises(ValueError, match="iterations"):
        trainer.fit_critic(-1)


def test_pi_star_has_its_own_validation_and_a_warmed_critic(tmp_path):
    """control.pi_star_validate_every is π*'s algo.validate_every (the others keep theirs), and
    control.pi_star_critic_warmup batches run before its first PPO update."""
    cfg = tiny_config(
        control=ControlConfig(warm_start="none", pi_star_validate_every=2, pi_star_critic_warmup=2)
    )
    loop = JointOptimisation(cfg, tmp_path, task="control")
    assert loop.pi_star.algo.validate_every == 2 and loop.pi_tilde.algo.validate_every == 0
    calls = []
    loop.pi_star.fit_critic = lambda n: calls.append((n, loop.pi_star.iteration)) or {}
    bar = type("Bar", (), {"update": lambda self, n: None, "set_postfix": lambda self, **kw: None})
    loop._train_stage("control_perfect", bar())
    assert calls == [(2, 0)]
    assert loop.position["critic_warmup"] == {"batches": 2}
    assert loop.position["selected_iterations"]["control_perfect"] >= -1


def test_spread_term_scales_pay_the_rra_agents_and_survive_a_resume(tmp_path, monkeypatch):
    """rra.term_scales=spread: the scales measured before an RRA stage (here from stand-in
    measurements of the silent and the greedy policy) are the RRA environment's reward's,
    recorded in the position, and put back after a resume."""
    from types import SimpleNamespace

    from vdtn_marl.experiment import jocc
    from vdtn_marl.experiment.config import RRAConfig

    measured = {"SilentRRAPolicy": (2.5, -0.02), "GreedyRRAPolicy": (2.0, -0.01)}

    def stand_in(params, control, rra, **kw):
        v2i, xi = measured[type(rra).__name__]
        return SimpleNamespace(metrics={"v2i_throughput_mbps_per_link": v2i, "ivoi_mean": xi})

    monkeypatch.setattr(jocc, "evaluate_system", stand_in)
    cfg = tiny_config(rra=RRAConfig(term_scales="spread"))
    loop = JointOptimisation(cfg, tmp_path, task="jocc")
    loop._scale_rra_terms()
    (entry,) = loop.position["term_scales"]
    reward = loop.rra.env.reward_fn
    assert (reward.throughput_scale, reward.ivoi_scale) == (
        entry["throughput_scale"],
        entry["ivoi_scale"],
    )
    # 4 V2I uplinks × 50 subframes × 0.5 Mbps of spread, and 0.01 of ξ
    assert entry["throughput_scale"] == pytest.approx(1 / 100.0)
    assert entry["ivoi_scale"] == pytest.approx(1 / 0.01)
    fresh = JointOptimisation(cfg, tmp_path / "other", task="jocc")
    assert fresh.rra.env.reward_fn.throughput_scale == RRAConfig().throughput_scale
    fresh.position["term_scales"] = loop.position["term_scales"]
    fresh._apply_term_scales()
    assert fresh.rra.env.reward_fn == reward
