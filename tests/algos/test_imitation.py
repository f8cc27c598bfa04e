"""DAgger warm start of the acceleration policy (vdtn_marl.algos.imitation)."""

from dataclasses import replace

import pytest
import torch

from vdtn_marl.algos.imitation import DistillationStats, distill_teacher, distillation_ticks
from vdtn_marl.algos.ppo import PPOTrainer
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.experiment.config import (
    AlgoConfig,
    ControlConfig,
    ExperimentConfig,
    RunConfig,
    ScenarioConfig,
)
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.policies import OracleController
from vdtn_marl.policies.cacc import CACCController
from vdtn_marl.sim.params import TwinParams
from vdtn_marl.sim.twin import DigitalTwin

pytestmark = pytest.mark.slow  # training runs (the fast loop skips them)

ALGO = AlgoConfig(num_envs=8, rollout_steps=10, minibatch_size=128, epochs=2)
PARAMS = TwinParams.from_overrides(episode_intervals=40)
SMALL = dict(rounds=2, scenarios=8, intervals=40, fit_steps=1000, minibatch_size=256, lr=3e-3)


def make_trainer(seed: int = 0) -> PPOTrainer:
    env = VDTNTorchRLEnv("control", batch_size=8, seed=seed, episode_intervals=40)
    return PPOTrainer(env, "vehicle", ALGO, seed=seed, prior=CACCController())


class SoftCACC:
    """A teacher unlike the policy's CACC prior: 60 % of CACC's command, minus 0.2 m/s²."""

    def __init__(self):
        self.cacc = CACCController(PARAMS.platoon)
        self.resets = 0

    def reset(self):
        self.resets += 1

    def __call__(self, twin: DigitalTwin) -> torch.Tensor:
        return 0.6 * self.cacc(twin.vehicle_observation(perfect=True)) - 0.2


def student_error_mps2(trainer: PPOTrainer, teacher) -> float:
    """RMS gap (m/s²) between the deterministic student and the teacher on fresh states."""
    from vdtn_marl.algos.ppo import ActorPolicy

    twin = DigitalTwin(PARAMS, batch_size=8, seed=12345, radio=False)
    twin.reset(seed=12345)
    student, errors = ActorPolicy(trainer.actor, "vehicle"), []
    for k in range(30):
        if k > 0:
            twin.begin_interval()
        observation = twin.vehicle_observation(perfect=True)
        target = teacher(twin)
        errors.append(student(observation) - target)
        twin.finish_interval(target, perfect=True)
    return float(torch.cat(errors).pow(2).mean().sqrt())


def tensor_state(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    """Copies of the tensors of ``module.state_dict()``: tensordict 0.11's ``MultiAgentMLP``
    puts its ``__batch_size`` (a ``torch.Size``) and ``__device`` there too."""
    return {k: v.clone() for k, v in module.state_dict().items() if isinstance(v, torch.Tensor)}


def test_distillation_copies_the_teacher_into_the_actor_and_nothing_else():
    trainer = make_trainer()
    teacher = SoftCACC()
    trainer.fit_observation_scaling()
    before = student_error_mps2(trainer, teacher)
    critic = tensor_state(trainer.critic)
    ticks = []
    stats = distill_teacher(trainer, teacher, PARAMS, progress=ticks.append, **SMALL)
    after = student_error_mps2(trainer, teacher)
    assert before > 0.1  # the CACC prior is far from the teacher ...
    assert after < 0.3 * before  # ... and the distilled actor is close to it
    assert stats.rounds == 2 and stats.samples == 2 * 8 * 40 * PARAMS.platoon.num_followers
    assert stats.rms_error_mps2 < before
    assert teacher.resets == 2
    assert len(ticks) == distillation_ticks(rounds=2, intervals=40, fit_steps=1000)
    after_critic = tensor_state(trainer.critic)
    assert after_critic.keys() == critic.keys()
    for key, value in after_critic.items():
        assert torch.equal(value, critic[key]), f"critic {key} changed"


def test_distillation_is_repeatable_and_leaves_the_global_rng_alone():
    weights = []
    for _ in range(2):
        torch.manual_seed(7)  # the networks' initialisation
        trainer = make_trainer(seed=3)
        trainer.fit_observation_scaling()
        torch.manual_seed(99)
        rng = torch.get_rng_state()
        distill_teacher(trainer, SoftCACC(), PARAMS, **{**SMALL, "fit_steps": 50})
        assert torch.equal(torch.get_rng_state(), rng)
        weights.append([p.detach().clone() for p in trainer.actor.parameters()])
    assert all(torch.equal(a, b) for a, b in zip(*weights, strict=True))


@pytest.mark.parametrize(
    "kwargs,message",
    [
        ({"rounds": 0}, "rounds=0"),
        ({"rounds": 65}, "rounds=65"),
        ({"scenarios": 0}, "scenarios=0"),
        ({"intervals": 41}, "intervals=41"),
        ({"fit_steps": -1}, "fit_steps=-1"),
        ({"lr": 0.0}, "lr=0.0"),
        ({"exploration_std_mps2": -0.1}, "exploration_std_mps2=-0.1"),
    ],
)
def test_bad_distillation_settings_raise_with_the_allowed_range(kwargs, message):
    with pytest.raises(ValueError, match=message) as err:
        distill_teacher(make_trainer(), SoftCACC(), PARAMS, **{**SMALL, **kwargs})
    assert any(word in str(err.value) for word in ("must be", ">=", "<="))


def test_jocc_warm_start_imitates_the_causal_mpc_before_the_first_pi_star_stage(
    tmp_path, monkeypatch
):
    calls = []

    def fake_distill(trainer, teacher, params, **kwargs):
        calls.append((trainer, teacher, trainer.iteration, kwargs))
        return DistillationStats(rounds=3, samples=6, rms_error_mps2=0.25, seconds=0.0)

    monkeypatch.setattr("vdtn_marl.experiment.jocc.distill_teacher", fake_distill)
    experiment = ExperimentConfig(
        control_iterations=1, rra_iterations=1, eval_episodes=2, eval_intervals=10,
        checkpoint_every=0, jocc_iterations=2,
    )  # fmt: skip
    cfg = RunConfig(
        scenario=ScenarioConfig(episode_intervals=40),
        algo=replace(ALGO, rra_num_envs=8, rra_rollout_steps=20),
        experiment=experiment,
        control=ControlConfig(warm_start="causal_mpc"),
        progress=False,
    )
    run = JointOptimisation(cfg, tmp_path / "warm", task="control")
    summary = run.run()
    assert len(calls) == 1  # before the first π* stage only, not in JOCC iteration 1
    trainer, teacher, iteration, kwargs = calls[0]
    assert trainer is run.pi_star and iteration == 0
    assert isinstance(teacher, OracleController) and teacher.preview_intervals == 0
    assert kwargs["intervals"] == 40
    assert summary["warm_start"] == {
        "teacher": "causal_mpc", "rounds": 3, "samples": 6, "rms_error_mps2": 0.25, "seconds": 0.0
    }  # fmt: skip

    calls.clear()
    cold_control = ControlConfig(warm_start="none")
    cold = JointOptimisation(replace(cfg, control=cold_control), tmp_path / "cold", "control")
    assert cold.run()["warm_start"] is None and calls == []


# ------------------------------------------------------------------------------ RRA agents
def _rra_trainer(seed: int = 0) -> PPOTrainer:
    env = VDTNTorchRLEnv(
        "rra", batch_size=4, seed=seed, episode_intervals=40,
        control_module=CACCController(PARAMS.platoon), reward="jocc",
    )  # fmt: skip
    return PPOTrainer(env, "rra", ALGO, seed=seed, rollout_steps=50)


def test_rra_agents_learn_to_act_as_the_opportunistic_baseline():
    """distill_rra_teacher: the student's deterministic action is the teacher's on most of the
    (link, subframe) pairs with a CAM pending, and on the held-out twin it delivers CAMs and
    carries V2I as the teacher does."""
    from vdtn_marl.algos.evaluate import evaluate_system
    from vdtn_marl.algos.imitation import distill_rra_teacher
    from vdtn_marl.algos.ppo import ActorPolicy
    from vdtn_marl.policies import make_rra_baseline

    trainer = _rra_trainer()
    cacc = CACCController(PARAMS.platoon)
    untrained = ActorPolicy(trainer.actor, "rra")
    common = dict(perfect=False, episodes=8, intervals=40, seed=123)
    before = evaluate_system(PARAMS, cacc, untrained, **common).metrics
    stats = distill_rra_teacher(
        trainer, make_rra_baseline("opportunistic", PARAMS), PARAMS, cacc,
        rounds=2, scenarios=8, intervals=20, fit_steps=600,
    )  # fmt: skip
    assert stats.rounds == 2 and stats.samples > 0 and stats.agreement > 0.8
    student = evaluate_system(PARAMS, cacc, ActorPolicy(trainer.actor, "rra"), **common).metrics
    teacher = evaluate_system(
        PARAMS, cacc, make_rra_baseline("opportunistic", PARAMS), **common
    ).metrics
    assert before["cam_delivery_rate"] < 0.5  # the untrained policy delivers few CAMs
    assert student["cam_delivery_rate"] >= teacher["cam_delivery_rate"] - 0.05
    rel = student["v2i_throughput_mbps_per_link"] / teacher["v2i_throughput_mbps_per_link"]
    assert abs(rel - 1.0) < 0.03


def test_rra_distillation_refuses_the_vehicle_group_and_bad_sizes():
    from vdtn_marl.algos.imitation import distill_rra_teacher
    from vdtn_marl.policies import make_rra_baseline

    teacher, cacc = make_rra_baseline("greedy", PARAMS), CACCController(PARAMS.platoon)
    with pytest.raises(ValueError, match="'rra' group"):
        distill_rra_teacher(make_trainer(), teacher, PARAMS, cacc)
    with pytest.raises(ValueError, match="intervals"):
        distill_rra_teacher(_rra_trainer(), teacher, PARAMS, cacc, intervals=41)
