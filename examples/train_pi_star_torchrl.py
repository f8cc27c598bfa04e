"""Train π* (the followers' control on perfect observations) with plain TorchRL parts on the
batched TorchRL face of vdtn-marl, and compare it with the linear CACC on held-out traces.

    python examples/train_pi_star_torchrl.py                 # about a minute on 2 CPU cores
    python examples/train_pi_star_torchrl.py --iterations 2  # a smoke run

Top to bottom: environment, networks, PPO loss, the collect-and-update loop, evaluation. It is
MAPPO as in TorchRL's multi-agent PPO tutorial (decentralised actors with shared parameters, a
centralised critic, GAE, the clipped loss), with the policy written as a correction to the
CACC. At the default budget π* improves on the CACC by a few per cent of control cost. The
package's trainer (`vdtn-marl train task=control`) adds checkpoints and resume, and warm-starts
π* from the causal MPC.
"""

from __future__ import annotations

import argparse
import copy
import time

import torch
from tensordict.nn import AddStateIndependentNormalScale, TensorDictModule
from torchrl.collectors import Collector
from torchrl.data import LazyTensorStorage, ReplayBuffer, SamplerWithoutReplacement
from torchrl.envs.utils import ExplorationType, set_exploration_type
from torchrl.modules import MultiAgentMLP, ProbabilisticActor, TanhNormal
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from vdtn_marl.data.selection import named_sources
from vdtn_marl.envs.torchrl import VDTNTorchRLEnv
from vdtn_marl.policies.cacc import CACCController

GROUP = "vehicle"  # the followers; one step of the "control" face = one 50 ms control interval
OBS, ACTION, REWARD = (GROUP, "observation"), (GROUP, "action"), (GROUP, "reward")
HEALTH = ("kl_approx", "clip_fraction", "explained_variance")

parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
parser.add_argument("--iterations", type=int, default=60, help="collect-and-update iterations")
parser.add_argument("--num-envs", type=int, default=16, help="B scenarios simulated in a batch")
parser.add_argument("--steps", type=int, default=200, help="control intervals per collection")
parser.add_argument("--eval-episodes", type=int, default=32, help="scenarios per score")
parser.add_argument("--validate-every", type=int, default=5, help="iterations between scores")
parser.add_argument("--traces", default="udds", help="leader trace set (trains on its first part)")
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
args = parser.parse_args()
torch.manual_seed(args.seed)

# --- environment: B platoons, perfect observation, the training part of the leader traces ---
train_traces, eval_traces = named_sources(args.traces)
env = VDTNTorchRLEnv(
    "control", batch_size=args.num_envs, device=args.device, seed=args.seed,
    trace_source=train_traces,
)  # fmt: skip
followers = env.observation_spec[OBS].shape[-2]
obs_dim = env.observation_spec[OBS].shape[-1]
action_box = env.full_action_spec[ACTION].space  # acceleration command bounds, m/s²
low, high = float(action_box.low.min()), float(action_box.high.max())

# Observation features differ in scale (m, m/s, m/s²): centre and scale them with one rollout
# of the CACC. Its errors are tiny (gap error std ≈ 0.12 m), so the scale gets a floor: once the
# policy moves, larger errors would otherwise reach the networks as inputs of 10σ and more.
SCALE_FLOOR = 0.5
cacc = CACCController(env.twin.params.platoon)
cacc_policy = TensorDictModule(lambda obs: cacc(obs).unsqueeze(-1), [OBS], [ACTION])
with torch.no_grad():
    sample = env.rollout(args.steps, cacc_policy, break_when_any_done=False)[OBS]
obs_mean = sample.mean(dim=(0, 1, 2))
obs_std = sample.std(dim=(0, 1, 2)).clamp_min(SCALE_FLOOR)


class Standardise(torch.nn.Module):  # observation → (observation − mean) / std
    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return (obs - obs_mean) / obs_std


def mlp(outputs: int, centralised: bool) -> MultiAgentMLP:
    return MultiAgentMLP(
        n_agent_inputs=obs_dim, n_agent_outputs=outputs, n_agents=followers,
        centralized=centralised, share_params=True, device=args.device,
        depth=2, num_cells=64, activation_class=torch.nn.Tanh,
    )  # fmt: skip


class ResidualOnCACC(torch.nn.Module):
    """(loc, scale) of the TanhNormal over commands: the CACC's command (pre-tanh) plus a learned
    correction that starts at 0; one learned scale for every state (e^-3 at the start)."""

    def __init__(self):
        super().__init__()
        self.body = torch.nn.Sequential(Standardise(), mlp(1, centralised=False))
        layers = self.body[-1].params  # MultiAgentMLP's parameters, one entry per layer
        with torch.no_grad():
            layers[max(layers.keys(), key=int)].zero_()  # the last layer outputs 0
        self.scale = AddStateIndependentNormalScale(1, init_value=-3.0)  # exp(-3)

    def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        unit = (cacc(obs).unsqueeze(-1) - low) / (high - low) * 2 - 1  # command in (-1, 1)
        return self.scale(torch.atanh(unit.clamp(-0.999, 0.999)) + self.body(obs))


# --- networks: a decentralised TanhNormal actor and a centralised critic (MAPPO) ------------
LOC_SCALE = [(GROUP, "loc"), (GROUP, "scale")]
actor = ProbabilisticActor(
    TensorDictModule(ResidualOnCACC(), in_keys=[OBS], out_keys=LOC_SCALE),
    in_keys=LOC_SCALE, out_keys=[ACTION], distribution_class=TanhNormal,
    distribution_kwargs={"low": low, "high": high},
    return_log_prob=True, log_prob_key=(GROUP, "action_log_prob"),
)  # fmt: skip
critic = TensorDictModule(
    torch.nn.Sequential(Standardise(), mlp(1, centralised=True)),
    in_keys=[OBS], out_keys=[(GROUP, "state_value")],
)  # fmt: skip

# --- the clipped PPO loss with GAE (γ per control interval) ---------------------------------
loss = ClipPPOLoss(
    actor, critic, clip_epsilon=0.2, entropy_coeff=1e-3,
    normalize_advantage=True, normalize_advantage_exclude_dims=(-2,),  # per follower
)  # fmt: skip
loss.set_keys(
    reward=REWARD, action=ACTION, sample_log_prob=(GROUP, "action_log_prob"),
    value=(GROUP, "state_value"), done=(GROUP, "done"), terminated=(GROUP, "terminated"),
)  # fmt: skip
loss.make_value_estimator(ValueEstimators.GAE, gamma=0.99, lmbda=0.95)
optimiser = torch.optim.Adam(loss.parameters(), lr=3e-4)

frames_per_batch = args.num_envs * args.steps
collector = Collector(
    env, actor, frames_per_batch=frames_per_batch,
    total_frames=frames_per_batch * args.iterations, device=args.device,
)  # fmt: skip
buffer = ReplayBuffer(
    storage=LazyTensorStorage(frames_per_batch, device=args.device),
    sampler=SamplerWithoutReplacement(), batch_size=min(1024, frames_per_batch),
)  # fmt: skip


# --- scoring: the deterministic policy on fixed scenarios (same seed, so paired) -----------
def evaluate(policy, traces, episodes: int, seed: int) -> tuple[float, float]:
    """(mean control reward per follower and interval, share of scenarios that collided)."""
    test_env = VDTNTorchRLEnv(
        "control", batch_size=episodes, device=args.device, seed=seed, trace_source=traces
    )
    intervals = test_env.twin.params.episode_intervals
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        rollout = test_env.rollout(intervals, policy, break_when_any_done=False)
    alive = ~rollout.get(("next", "done")).cumsum(1).bool()  # steps before the first end
    alive = torch.cat([torch.ones_like(alive[:, :1]), alive[:, :-1]], dim=1)
    reward = rollout.get(("next", *REWARD)).mean(-2)  # mean over followers
    collided = rollout.get(("next", "terminated")).any(1).float().mean()
    return float(reward[alive].mean()), float(collided)


# --- collect and update ---------------------------------------------------------------------
# PPO's gain over the CACC is small and its iterates noisy: every --validate-every iterations
# the deterministic policy is scored on scenarios of the training traces; the best is kept.
def validate() -> float:
    return evaluate(actor, train_traces, args.eval_episodes, seed=5_000 + args.seed)[0]


best_score, best_state = validate(), copy.deepcopy(actor.state_dict())
print(f"{'iter':>4} {'reward':>9} {'kl':>9} {'clip':>6} {'expl.var':>8} {'valid.':>8} {'s':>6}")
began = time.perf_counter()
for iteration, data in enumerate(collector):  # collects `frames_per_batch` frames
    with torch.no_grad():  # advantages and value targets, written into `data`
        loss.value_estimator(
            data, params=loss.critic_network_params,
            target_params=loss.target_critic_network_params,
        )  # fmt: skip
    buffer.extend(data.reshape(-1))
    health = []  # PPO's health, as ClipPPOLoss returns it per minibatch
    for _ in range(4):  # epochs
        for _ in range(frames_per_batch // buffer.batch_size):
            out = loss(buffer.sample())
            total = out["loss_objective"] + out["loss_critic"] + out["loss_entropy"]
            optimiser.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(loss.parameters(), 1.0)
            optimiser.step()
            health.append([float(out[k].mean()) for k in HEALTH])
    collector.update_policy_weights_()
    kl, clip, explained = torch.tensor(health).mean(0).tolist()
    reward = float(data.get(("next", *REWARD)).mean())
    score = validate() if (iteration + 1) % args.validate_every == 0 else float("nan")
    if score > best_score:
        best_score, best_state = score, copy.deepcopy(actor.state_dict())
    seconds, began = time.perf_counter() - began, time.perf_counter()
    print(f"{iteration:>4} {reward:>9.4f} {kl:>9.2e} {clip:>6.3f} {explained:>8.3f} ", end="")
    print(f"{score:>8.4f} {seconds:>6.1f}")
collector.shutdown()
actor.load_state_dict(best_state)

# --- evaluation: the same held-out scenarios for π* and the CACC -----------------------------
held_out = (eval_traces, args.eval_episodes, 10_000 + args.seed)
learned, cacc_score = evaluate(actor, *held_out), evaluate(cacc_policy, *held_out)
print(f"\nheld-out {args.traces} scenarios ({args.eval_episodes}), mean control reward per "
      "follower and interval (higher is better), share of scenarios with a collision:")  # fmt: skip
print(f"  pi_star (this run)  {learned[0]:9.4f}  {learned[1]:5.2f}")
print(f"  cacc                {cacc_score[0]:9.4f}  {cacc_score[1]:5.2f}")
