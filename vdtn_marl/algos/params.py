"""Hyper-parameters of the trainers: :class:`AlgoConfig` (MAPPO/IPPO), the ``algo`` group of
the experiment schema (:mod:`vdtn_marl.experiment.config` validates it and re-exports it)."""

from __future__ import annotations

from dataclasses import dataclass

#: values of ``algo.activation``, the hidden layers' activation of every actor and critic
#: (:data:`vdtn_marl.algos.networks.ACTIVATION_CLASSES` builds them): ``tanh`` is torch.tanh;
#: ``tanh_sigmoid`` is the same function computed as 2·sigmoid(2x) − 1, from torch's sigmoid
#: kernel; it differs from torch.tanh by at most a few 1e-7 (absolute), so results differ in
#: the last bits
ACTIVATIONS = ("tanh", "tanh_sigmoid")
#: the most worker processes of ``algo.collector_workers`` (vdtn_marl/algos/shards.py)
MAX_COLLECTOR_WORKERS = 64


@dataclass
class AlgoConfig:
    """MAPPO/IPPO hyper-parameters (TorchRL ClipPPOLoss + GAE)."""

    name: str = "mappo"  # mappo: centralised critic (CTDE); ippo: decentralised critics
    share_params: bool = True  # one network for every agent of a group
    depth: int = 2  # hidden layers
    num_cells: int = 64  # units per hidden layer
    activation: str = "tanh"  # hidden layers: tanh or tanh_sigmoid (ACTIVATIONS above)
    lr: float = 3e-4
    lr_schedule: str = "constant"  # linear: decays to 0 over each training stage
    gamma: float = 0.99  # vehicles: discount per control interval (horizon ≈ 5 s)
    lmbda: float = 0.95  # GAE λ of the vehicles (per control interval)
    # RRA credit (docs/model.md §5): "interval" (the paper's objective, discounted per control
    # interval): rra_gamma is per interval and applies as γ^(1/T) per subframe; "subframe":
    # rra_gamma applies per 1 ms subframe as given (a horizon of ≈ 100 ms at 0.99)
    rra_credit: str = "interval"
    rra_gamma: float = 0.99  # RRA agents: discount (per interval with rra_credit=interval)
    rra_lmbda: float = 0.95  # GAE λ of the RRA agents, per subframe step
    # subframes whose link is silent (its CAM already delivered: the action has no effect)
    # do not train the RRA policy (their advantage is masked out)
    rra_mask_silent: bool = True
    # environments persist across PPO iterations (reset only where an episode ends), so
    # batches sample the whole episode; false: every iteration collects from fresh resets
    persistent_envs: bool = True
    clip_epsilon: float = 0.2
    entropy_coef: float = 1e-3
    initial_log_scale: float = -3.0  # log std (pre-tanh) of the initial acceleration policy
    critic_coef: float = 1.0
    max_grad_norm: float = 1.0
    epochs: int = 4  # PPO epochs per collected batch
    # torch CPU threads of each PPO update (GAE and the minibatch passes), the run's
    # ``threads`` restored after it; 0: the run's ``threads`` throughout. A thread count other
    # than the run's moves results in the last bits (torch splits its sums and products over
    # the threads)
    update_threads: int = 0
    # worker processes that collect the vehicle stages' persisting scenarios (π*, π̃), each
    # num_envs / N of them on one core (vdtn_marl/algos/shards.py); 0: the trainer's process.
    # A sharded run has scenarios and action samples of its own (reproducible by seed and N)
    collector_workers: int = 0
    minibatch_size: int = 512  # transitions (scenario × step) per gradient step
    num_envs: int = 16  # B scenarios collected in parallel (vehicles)
    rollout_steps: int = 200  # control intervals per scenario per batch: whole 10 s episodes
    rra_num_envs: int = 32  # B scenarios collected in parallel (RRA agents)
    # subframes per scenario per collected batch (RRA agents): 5 control intervals, so that
    # the IVoI of later intervals reaches an interval's actions inside the batch
    rra_rollout_steps: int = 250
    # RRA batches start after K ~ U{0..rra_burn_in_intervals} control intervals of the
    # acting system under random RRA (0: at the episode's start, where the platoon is at rest)
    rra_burn_in_intervals: int = 0
    # every N iterations of a stage, score the deterministic policy on fixed validation
    # scenarios and keep the best actor and critic for the stage's end (0: keep the last)
    validate_every: int = 0
    validation_scenarios: int = 64  # scenarios per validation (whole batches of num_envs)

    @property
    def centralised_critic(self) -> bool:
        return self.name == "mappo"

    def rra_subframe_discounts(self, subframes_per_interval: int) -> tuple[float, float]:
        """(γ, λ) per RRA step (one subframe) for ``rra_credit`` (docs/model.md §5)."""
        if self.rra_credit == "subframe":
            return self.rra_gamma, self.rra_lmbda
        return self.rra_gamma ** (1.0 / subframes_per_interval), self.rra_lmbda
