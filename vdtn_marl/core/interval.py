"""The interval protocol, written once: T subframes under an RRA policy → observe → complete →
close the interval → IVoI → rewards → done / partial reset → the next interval.

Every face of the benchmark runs on an :class:`IntervalEngine`: the PettingZoo environments
(``B = 1``, dicts at the edge), the TorchRL environment (``B`` scenarios, TensorDicts at the
edge), the evaluation, the training data of the completion predictor and the benchmarks. The
engine holds the twin and what acts around it, all optional:

- ``rra_policy``: a callable, RRA observations [B, L, D] → actions [B, L], that drives the
  radio for a whole interval (``run_radio``) when the twin has one; without it the caller
  steps the subframes (``step_subframe``), as the RRA agents of the two-clock faces do;
- ``control``: a callable, vehicle observations [B, F, 8] → commands [B, F], used when the
  caller gives no commands at the interval's end (``close()``), and for the command had the CAM
  been lost when the IVoI estimator compares with that;
- ``completion``: a completer (:mod:`vdtn_marl.sim.completion`) of stale CAM content;
- ``ivoi_estimator``: ξ at each interval's end (an object with ``__call__(twin, record)`` and
  optionally ``needs_command_if_lost``, :mod:`vdtn_marl.voi`);
- ``reward_fn``: the RRA reward (``per_subframe(outcome, bandwidth_hz, subframe_s)`` and
  ``at_interval_end(xi, lost)``, :class:`vdtn_marl.core.reward.RRAReward`); one whose
  ``uses_aoi`` is true also gets ``cam_age_ms=``, the recipients' Age of Information.

The engine is backend-agnostic: it hands the twin what its backend takes (torch tensors, or
what a policy returns on the NumPy backend) and never converts the state. Masks are bool
tensors [B]: only the masked scenarios reset, start an interval or replay one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from vdtn_marl.errors import ConfigError
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord


def check_callable(name: str, value, signature: str) -> None:
    """Raise :class:`TypeError` naming ``name`` when ``value`` is given but not callable."""
    if value is not None and not callable(value):
        raise TypeError(f"{name}={value!r} must be callable: {signature}")


def check_burn_in(burn_in_intervals, episode_intervals: int) -> int:
    """``burn_in_intervals`` as an int in [0, episode_intervals − 1], or :class:`ConfigError`."""
    if isinstance(burn_in_intervals, bool) or not isinstance(burn_in_intervals, int):
        raise ConfigError(f"burn_in_intervals={burn_in_intervals!r} must be an integer")
    if not 0 <= burn_in_intervals < episode_intervals:
        raise ConfigError(
            f"burn_in_intervals={burn_in_intervals!r} must be in "
            f"[0, {episode_intervals - 1}] (episode_intervals − 1)"
        )
    return burn_in_intervals


def check_estimator_has_control(estimator, vehicles_are_agents: bool, hint: str) -> None:
    """An estimator that compares with a lost CAM needs a control module to ask what a follower
    would have done then; with the vehicles as agents there is none (:class:`ConfigError`)."""
    if vehicles_are_agents and getattr(estimator, "needs_command_if_lost", False):
        raise ConfigError(
            "an IVoI estimator with the cam_lost baseline needs a control module to ask what a "
            f"follower would have done had its CAM been lost; {hint}"
        )


def close_interval(
    twin: DigitalTwin,
    estimator,
    decide: Callable[[bool], torch.Tensor] | None,
    perfect: bool = False,
    commands: torch.Tensor | None = None,
) -> IntervalRecord:
    """Finish the twin's interval for ``estimator``: the followers' commands are ``commands``
    or ``decide(False)`` (the acting policy on the observation of the actual CAMs); when the
    estimator compares with a lost CAM (``needs_command_if_lost``), ``decide(True)`` (the same
    policy on the observation had the CAMs been lost) is recorded too, and called first, so
    that a stateful completer ends on the actual CAMs."""
    command_if_lost = None
    if not perfect and getattr(estimator, "needs_command_if_lost", False):
        if decide is None:
            raise ValueError(
                "this IVoI estimator needs the command each follower would have taken had its "
                "CAM been lost, which only a control module can give: the followers' commands "
                "here come from the vehicle agents"
            )
        command_if_lost = decide(True)
    if commands is None:
        commands = decide(False)
    return twin.finish_interval(commands, perfect, command_if_lost_mps2=command_if_lost)


@dataclass
class IntervalOutcome:
    """What closing one interval gives, for every scenario [B].

    ``xi`` [B, F]: the IVoI (None without an estimator); ``rra_reward`` [B, L]: the RRA reward
    paid at the interval's end (None without a reward function); ``terminated`` [B]: a
    collision; ``truncated`` [B]: the episode's length reached without a collision.
    """

    record: IntervalRecord
    xi: torch.Tensor | None
    rra_reward: torch.Tensor | None
    terminated: torch.Tensor
    truncated: torch.Tensor

    @property
    def going(self) -> torch.Tensor:
        """[B] bool: the scenarios that go on to the next interval."""
        return ~(self.terminated | self.truncated)


class IntervalEngine:
    """The interval protocol on one twin (see the module doc)."""

    def __init__(
        self,
        twin: DigitalTwin,
        *,
        perfect: bool,
        rra_policy: Callable | None = None,
        control: Callable | None = None,
        completion=None,
        ivoi_estimator=None,
        reward_fn=None,
        validate_rra: bool = True,
    ):
        check_callable("rra_policy", rra_policy, "observations [B, L, D] -> actions [B, L]")
        check_callable("control_module", control, "observations -> commands")
        self.twin = twin
        self.perfect = perfect
        self.rra_policy = rra_policy
        self.control = control
        self.completion = completion
        self.ivoi_estimator = ivoi_estimator
        self.reward_fn = reward_fn
        self.validate_rra = validate_rra
        self._torch = twin.backend == "torch"
        self._bandwidth_hz = twin.params.radio.subchannel_bandwidth_hz
        self._subframe_s = twin.params.platoon.subframe_s

    @property
    def drives_radio(self) -> bool:
        """Whether the engine runs each interval's radio itself (an ``rra_policy`` on a twin
        with radio); otherwise the caller steps the subframes."""
        return self.rra_policy is not None and self.twin.radio_enabled

    # ------------------------------------------------------------------ start
    def reset(
        self,
        mask: torch.Tensor | None = None,
        seed: int | None = None,
        keep_clock: bool = False,
    ) -> None:
        """Reset the (masked) scenarios and their completer; with an ``rra_policy`` run their
        first interval's radio. ``keep_clock``: after a partial reset the shared subframe clock
        stays where the other scenarios are (faces whose RRA agents step every subframe)."""
        twin = self.twin
        subframe = twin.subframe
        twin.reset(seed=seed, mask=mask)
        if self.completion is not None:
            self.completion.reset(mask)
        if self.drives_radio:
            self.run_radio(mask)
        elif keep_clock and mask is not None and subframe < twin.subframes_per_interval:
            twin.subframe = subframe

    def restart_ended(self, going: torch.Tensor) -> None:
        """The next interval of the ``going`` scenarios [B] and new episodes in the others, in
        one start: what :meth:`advance` ``(going)`` and :meth:`reset` ``(~going)`` do, with one
        interval start and one radio run of the whole batch instead of a masked start and
        radio run for each group. A run's scenarios persist across PPO iterations, so their
        episodes end at different intervals (a collision, the episode's length).

        The same model, other random numbers: the interval's draws come first (those made
        ahead on the twin's second thread are kept) and the new episodes' (traces, initial
        state, shadowing) after them (:meth:`~vdtn_marl.sim.twin.DigitalTwin.restart`), and the
        whole batch's fading is drawn once instead of twice. With every scenario going this is
        :meth:`advance`; with none, :meth:`reset`."""
        twin = self.twin
        ended = ~torch.as_tensor(going, dtype=torch.bool, device=twin.device)
        if not bool(ended.any()):
            self.advance()
            return
        if bool(ended.all()):
            self.reset()
            return
        twin.restart(ended)
        if self.completion is not None:
            self.completion.reset(ended)
        if self.drives_radio:
            self.run_radio()

    def run_radio(self, mask: torch.Tensor | None = None, policy: Callable | None = None) -> None:
        """Run the interval's T subframes with ``policy`` (default ``rra_policy``); with
        ``mask`` [B] only the masked scenarios keep the result (the others had already run this
        interval).

        A policy whose ``rowwise`` is true (each scenario's actions depend on its own
        observation only, and a call draws no random numbers: the deterministic learned policy,
        :class:`~vdtn_marl.algos.ppo.ActorPolicy`) is asked for the masked scenarios' actions
        alone; the others act 0, which the masked step discards. When they are at most half
        the batch (a partial reset's few scenarios) the whole interval runs for them alone
        (:meth:`~vdtn_marl.sim.twin.DigitalTwin.run_subframes`: observations and kernel on b
        scenarios, not B), with the same numbers. A policy with a ``bound()`` method is asked
        for its callable once per interval and that is called every subframe (a learned
        policy reads its weights once: :meth:`~vdtn_marl.algos.ppo.ActorPolicy.bound`)."""
        twin = self.twin
        policy = policy or self.rra_policy
        validated = not self.validate_rra
        rows = self._policy_rows(mask, policy)
        # the weights cannot change during one interval's radio: a policy that can read them
        # once for a run of calls does (ActorPolicy.bound)
        bind = getattr(policy, "bound", None)
        policy = bind() if bind is not None else policy
        if rows is not None and twin.few_rows(mask) is not None:
            device = twin.device

            def act(observation):
                return torch.as_tensor(policy(observation), device=device).long()

            twin.run_subframes(rows, act, validated=validated)
            twin.last_rra_actions = None  # the rows' actions alone: not the batch's
            return
        for _ in range(twin.subframes_per_interval):
            observation = twin.rra_observation()
            if rows is None:
                actions = policy(observation)
                if self._torch:
                    actions = torch.as_tensor(actions, device=twin.device).long()
            else:
                chosen = policy(observation.index_select(0, rows))
                chosen = torch.as_tensor(chosen, device=twin.device).long()
                actions = chosen.new_zeros(observation.shape[:-1]).index_copy_(0, rows, chosen)
            twin.step_subframe(actions, validated=validated, mask=mask)
        twin.last_rra_actions = actions  # the last subframe's, for the renderer's powers

    def _policy_rows(self, mask: torch.Tensor | None, policy) -> torch.Tensor | None:
        """The masked scenarios' indices when ``policy`` may be asked for them alone, else
        None (no mask, every scenario masked, NumPy twin, or a policy that is not rowwise)."""
        if mask is None or not self._torch or not getattr(policy, "rowwise", False):
            return None
        rows = torch.as_tensor(mask, device=self.twin.device).nonzero().flatten()
        return None if rows.numel() == mask.numel() else rows

    def step_subframe(self, actions, validated: bool = True):
        """One subframe with RRA ``actions`` [B, L]: the twin's outcome
        (:class:`~vdtn_marl.sim.link.SubframeOutcome`). The actions stay on the twin as
        ``last_rra_actions`` (what :func:`~vdtn_marl.envs.render.render_twin` draws)."""
        outcome = self.twin.step_subframe(actions, validated=validated)
        self.twin.last_rra_actions = actions
        return outcome

    def subframe_reward(self, outcome):
        """The reward function's (RRA reward [B, L], V2I throughput [B] in Mbps) of a
        subframe's ``outcome``."""
        reward_fn, bandwidth_hz, subframe_s = self.reward_fn, self._bandwidth_hz, self._subframe_s
        if getattr(reward_fn, "uses_aoi", False):
            age_ms = self.twin.cam_age_ms()
            return reward_fn.per_subframe(outcome, bandwidth_hz, subframe_s, cam_age_ms=age_ms)
        return reward_fn.per_subframe(outcome, bandwidth_hz, subframe_s)

    # ------------------------------------------------------------------ observe and act
    def observe(self, mask: torch.Tensor | None = None, cams_lost: bool = False) -> torch.Tensor:
        """The followers' observations [B, F, 8]: perfect, or impaired and completed
        (docs/model.md §4.7); ``cams_lost``: as if this interval's CAMs had been lost (what the
        followers know at the next decision time, before its CAM arrives)."""
        if self.perfect:
            return self.twin.vehicle_observation(perfect=True)
        obs = self.twin.vehicle_observation(perfect=False, cams_lost=cams_lost)
        if self.completion is None:
            return obs
        if mask is None:  # a completer of the Completion protocol takes mask=; others need not
            return self.completion.complete(obs, self.twin.interval)
        return self.completion.complete(obs, self.twin.interval, mask)

    def decide(self, cams_lost: bool = False) -> torch.Tensor:
        """The control module's commands [B, F] on this interval's observation."""
        return self.control(self.observe(cams_lost=cams_lost))

    # ------------------------------------------------------------------ close
    def finish(self, commands: torch.Tensor | None = None) -> IntervalRecord:
        """Integrate the interval with ``commands`` (default: the control module's) and nothing
        more: no IVoI, no RRA reward (a burn-in, a warm-up)."""
        if commands is None:
            commands = self.decide(False)
        return self.twin.finish_interval(commands, self.perfect)

    def close(self, commands: torch.Tensor | None = None) -> IntervalOutcome:
        """Integrate the interval with ``commands`` [B, F] (default: the control module's),
        then ξ and the RRA reward at the interval's end. Does not start the next interval
        (:meth:`advance`)."""
        twin = self.twin
        decide = self.decide if commands is None and self.control is not None else None
        record = close_interval(twin, self.ivoi_estimator, decide, self.perfect, commands)
        xi = rra_reward = None
        if self.ivoi_estimator is not None:
            xi = self.ivoi_estimator(twin, record)
        if self.reward_fn is not None:
            lost = record.cam_delay_subframes > twin.subframes_per_interval
            rra_reward = self.reward_fn.at_interval_end(xi, lost)
        terminated = record.collided.any(-1)
        truncated = record.truncated & ~terminated
        return IntervalOutcome(record, xi, rra_reward, terminated, truncated)

    def advance(self, going: torch.Tensor | None = None, radio: bool = True) -> None:
        """Start the next interval of the ``going`` scenarios (all by default), with its radio
        when the engine drives it (:attr:`drives_radio`) and ``radio`` is True (False: the
        caller runs it, e.g. at the top of its own loop)."""
        twin = self.twin
        run = radio and self.drives_radio
        if going is None or bool(going.all()):
            twin.begin_interval()
            if run:
                self.run_radio()
        elif bool(going.any()):
            twin.begin_interval(going)
            if run:
                self.run_radio(going)
