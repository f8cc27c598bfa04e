"""CAM value: what one delivered CAM is worth to the acting system, and what IVoI credits it with.

JOCC's RRA agent of link i is paid κ2·ξ_i at the end of the interval in which it (maybe)
delivered follower i's CAM. This script measures, with common random numbers, how much that
delivery is actually worth and how much of it ξ at that interval credits.

For every checkpoint (a run's ``checkpoints/last.pt``; config from the checkpoint) it runs the
acting system (π̃ or the run's control baseline on impaired observations, the run's CAM
completion, the RRA policy of ``--rra``) on the run's held-out scenarios (``--episodes``, the
run's evaluation seed). At every start interval k of ``--starts``, after the interval's
subframes, it copies the twin twice (``copy.deepcopy``: platoon, channel, random state, RRA
and completion state), picks in every scenario one follower at random among those whose CAM of
interval k arrived in time for the decision, and in the second copy drops that CAM
(:meth:`~vdtn_marl.sim.twin.DigitalTwin.drop_cams`). Both copies then run on for
``--horizon`` intervals with the same channel draws and the same RRA draws (a learned or greedy
RRA policy sees the same observations until the platoons' CAM content diverges). Per dropped
CAM:

- **value**: the platoon's discounted control return (sum over followers, γ per interval from
  interval k; a collision ends a copy's episode, as in the environment) of the copy that kept
  the CAM minus that of the copy that lost it;
- **td credit**: ξ_i at interval k from the ``td`` estimator (π*'s critic) in the first copy
  minus that in the second: the part of the value that the RRA agent of link i is paid for
  at the interval of the delivery;
- **one-step credit**: the ``cam_lost`` baseline of
  :class:`~vdtn_marl.voi.RolloutIVoIEstimator` (one interval, then π*'s critic), computed
  in the first copy alone, as an environment can; it should match the td credit up to what
  the other followers do in that interval.

Reported per checkpoint: the number of CAMs, each mean with its 95% CI over CAMs, the
Pearson correlation between value and td credit, and how persistent delivery is in the acting
run (the fraction of CAMs in time, and that fraction right after a CAM of the same link that
was in time and right after one that was not): a comparison of intervals whose CAM was
delivered with intervals whose CAM was lost compares such runs, not single deliveries. The
value is what an RRA agent would have to learn from; if the credit at the delivery interval is
near zero or negative while the value is positive, the value shows up only in later
intervals' ξ, after the RRA agent's discount has shrunk it.

**Credit reaching the carrying actions** (the ``credit`` entry of each run's ``result``).
Per dropped CAM the script also keeps Δξ_{k+j}, j = 0..H−1 (H = ``--horizon``): ξ of the
same follower i from the ``td`` estimator at interval k+j in the copy that kept the CAM minus
in the copy that lost it (a copy's ξ is 0 after the interval of its collision; Δξ_k is the td
credit), and the subframes t ∈ {0..T−1} of interval k in which link i transmitted the CAM
(it still had bits to send at the subframe's start; the link is silent after delivery). For
each RRA credit setting c of ``--credit`` (γ and GAE λ, each per 1 ms subframe or per control
interval, applied as x^(1/T) per subframe; docs/model.md §5; the named settings of
:data:`CREDIT_PRESETS` are ``legacy`` (both per subframe, ``algo.rra_credit=subframe``),
``paper`` (the default: γ per interval, λ per subframe step), ``paper_long_gae`` (both per
interval), and ``legacy_lambda1``, ``paper_lambda1`` with λ = 1) the weight with which ξ paid
at the last subframe of interval k+j enters the GAE advantage of the action at subframe t of
interval k is w_c(t, j) = (γ_s·λ_s)^((T−1−t) + j·T), γ_s and λ_s per subframe. With λ < 1 it
is the part of the advantage carried by the sampled rewards; the rest comes from the critic's
values, and with an exact critic the expected advantage is that of λ = 1 for any λ. The entry
holds:

- ``full_value``: Σ_j γ^j Δξ_{k+j}, γ = the run's control discount per interval (0.99), mean
  with its 95% Student-t CI over CAMs, and the shares of its mean from j = 0
  (``full_value_share_j0``) and from j ≥ 1 (``full_value_share_later``), ratios of means with
  a percentile bootstrap CI over CAMs (``bootstrap_resamples``, seeded);
- ``delta_xi_mean_by_j``: the mean Δξ_{k+j} per j; ``transmitting_subframes``: how many
  subframes carried a CAM (mean and CI);
- per setting (``settings``): its γ and λ with their scales, γ_s, λ_s, w(0, 0), w(0, 1);
  ``credit``: per CAM the mean over its transmitting subframes t of Σ_j w_c(t, j)·Δξ_{k+j},
  mean with its 95% CI over CAMs; ``credit_from_j0``: the same with j = 0 only;
  ``share_of_full_value``: mean credit / mean full value, with its bootstrap CI over CAMs.

``credit_no_collision`` is the same entry over the ``cams_no_collision`` CAMs after which
neither copy collided within the horizon: a collision (its reward penalty and the end of the
episode) moves ξ by tenths of a reward unit where a CAM otherwise moves it by thousandths, so
a few CAMs can decide the means of ``credit``. With more than one checkpoint the JSON's
``pooled`` entry holds both entries over the CAMs of every run together (``runs``, ``cams``,
``cams_no_collision``). CAMs of the same scenario at different start intervals, and of
different runs, are treated as independent in every CI.
Writes ``--output`` (default ``cam_value.json`` beside this file) atomically, and its PNG
next to it unless ``--no-plot``. The committed ``cam_credit.json`` (README.md beside this file)
came from the checkpoints of ``vdtn-marl jocc experiment=default seed=S
hydra.run.dir=outputs/cam_credit/seedS`` for S = 0, 1, from

    python studies/2026-12-01-cam-credit/cam_value.py outputs/cam_credit/seed{0,1}/checkpoints/last.pt \\
        --episodes 2048 --no-progress --no-plot --output studies/2026-12-01-cam-credit/cam_credit.json
"""

from __future__ import annotations

import argparse
import copy
import time
from pathlib import Path
from typing import NamedTuple

import torch
from rich.console import Console
from rich.progress import track
from rich.table import Table

from vdtn_marl.algos.evaluate import bind_to_twin
from vdtn_marl.core.interval import IntervalEngine, close_interval
from vdtn_marl.experiment.api import loaded_checkpoints
from vdtn_marl.experiment.evaluate import EVAL_SEED_OFFSET
from vdtn_marl.experiment.jocc import JointOptimisation
from vdtn_marl.io.files import atomic_write_json
from vdtn_marl.policies import RRA_BASELINES, make_rra_baseline
from vdtn_marl.reporting.benchmarking import (
    checkpoint_run,
    ci_summary,
    provenance,
    table_console,
)
from vdtn_marl.reporting.plots import pyplot_agg, save_figure
from vdtn_marl.sim.twin import DigitalTwin, IntervalRecord

RESULTS = Path(__file__).parent / "cam_value.json"
LEARNED = "learned"
DEFAULT_STARTS = "20,40,60,80,100,120,140,160"


class ActingSystem(IntervalEngine):
    """One copy of the acting system on a twin: control policy, completer and RRA policy,
    stepped one control interval at a time (the interval engine, with the subframes run here
    to see which links transmit)."""

    def __init__(self, twin: DigitalTwin, control, completion, rra):
        super().__init__(
            twin, perfect=False, rra_policy=rra, control=control, completion=completion
        )
        self.rra = rra

    def copy(self, base_control, base_rra) -> ActingSystem:
        """An independent copy in the same state. Policies bound to a twin are bound again to
        the copied twin; the others (and the completer) are copied with their state."""
        twin = copy.deepcopy(self.twin)

        def again(base, current):
            return bind_to_twin(base, twin) if hasattr(base, "bind") else copy.deepcopy(current)

        return ActingSystem(
            twin,
            again(base_control, self.control),
            copy.deepcopy(self.completion),
            again(base_rra, self.rra),
        )

    def run_subframes(self) -> torch.Tensor:
        """Run the interval's T subframes; [T, B, L] bool: link l still had bits of its CAM to
        send at the start of subframe t (it transmitted then; a link is silent after
        delivery)."""
        twin = self.twin
        pending = []
        for _ in range(twin.subframes_per_interval):
            action = torch.as_tensor(self.rra(twin.rra_observation())).long()
            pending.append(torch.as_tensor(self.step_subframe(action, validated=False).was_pending))
        return torch.stack(pending)

    def finish(self, estimator=None) -> IntervalRecord:
        """Decide and integrate the interval, recording what ``estimator`` needs (the command
        a lost CAM would have led to, for the ``cam_lost`` baseline)."""
        return close_interval(self.twin, estimator, self.decide)

    def begin(self) -> None:
        self.advance(radio=False)  # the caller runs the subframes (run_subframes)


def discounted_platoon_return(
    system: ActingSystem,
    first: IntervalRecord,
    horizon: int,
    gamma: float,
    estimator=None,
    first_xi: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor | None, torch.Tensor]:
    """Σ_h γ^h Σ_i r_i over ``horizon`` intervals from ``first`` (already run), [B] float64;
    a collision ends a scenario's sum after its interval. With ``estimator`` also ξ of every
    follower at each of the ``horizon`` intervals, [horizon, B, F] float64 (``first_xi`` at
    the first, already computed), 0 after the interval of a collision (the episode ended),
    else None. Third: [B] bool, no collision in the ``horizon`` intervals."""
    total = first.reward.double().sum(-1)
    alive = ~first.collided.any(-1)
    xi = None
    if estimator is not None:
        start = first_xi if first_xi is not None else estimator(system.twin, first)
        xi = [start.double()]
    weight = gamma
    for _ in range(1, horizon):
        system.begin()
        system.run_subframes()
        record = system.finish()
        total += weight * alive.double() * record.reward.double().sum(-1)
        if xi is not None:
            xi.append(alive.double()[:, None] * estimator(system.twin, record).double())
        alive &= ~record.collided.any(-1)
        weight *= gamma
    return total, (torch.stack(xi) if xi is not None else None), alive


# ---------------------------------------------------------------------- credit to the carriers
CREDIT_SCALES = ("subframe", "interval")
BOOTSTRAP_RESAMPLES = 10_000


class CreditSetting(NamedTuple):
    """How the RRA trainer discounts: γ per ``gamma_scale`` and GAE λ per ``lmbda_scale``
    (``subframe``: as given, per 1 ms subframe; ``interval``: per control interval, applied
    as γ^(1/T) or λ^(1/T) per subframe)."""

    name: str
    gamma: float
    gamma_scale: str
    lmbda: float
    lmbda_scale: str

    @property
    def description(self) -> str:
        return f"γ {self.gamma:g}/{self.gamma_scale}, λ {self.lmbda:g}/{self.lmbda_scale}"

    def per_subframe(self, subframes_per_interval: int) -> tuple[float, float]:
        root = 1.0 / subframes_per_interval
        gamma = self.gamma**root if self.gamma_scale == "interval" else self.gamma
        lmbda = self.lmbda**root if self.lmbda_scale == "interval" else self.lmbda
        return gamma, lmbda


#: Named settings: the RRA learning problems of ``studies/2026-12-01-rra-positive-control/ivoi_noise.py`` (``legacy``:
#: ``algo.rra_credit=subframe``, the setting before model v1; ``paper``: the default,
#: ``algo.rra_credit=interval`` with λ per subframe step; ``paper_long_gae``: λ per interval
#: too) and their λ = 1 forms (the advantage an exact critic gives, for any λ).
CREDIT_PRESETS = {
    setting.name: setting
    for setting in (
        CreditSetting("legacy", 0.99, "subframe", 0.95, "subframe"),
        CreditSetting("paper", 0.99, "interval", 0.95, "subframe"),
        CreditSetting("paper_long_gae", 0.99, "interval", 0.95, "interval"),
        CreditSetting("legacy_lambda1", 0.99, "subframe", 1.0, "subframe"),
        CreditSetting("paper_lambda1", 0.99, "interval", 1.0, "subframe"),
    )
}
DEFAULT_CREDITS = ",".join(CREDIT_PRESETS)


def parse_credits(text: str) -> list[CreditSetting]:
    """``SETTING,...``: names of :data:`CREDIT_PRESETS`, or ``GAMMA:SCALE:LAMBDA:SCALE``
    (SCALE ``subframe`` or ``interval``) → settings."""
    settings = []
    for part in (p.strip() for p in text.split(",")):
        if part in CREDIT_PRESETS:
            settings.append(CREDIT_PRESETS[part])
            continue
        fields = part.split(":")
        try:
            if len(fields) != 4 or fields[1] not in CREDIT_SCALES or fields[3] not in CREDIT_SCALES:
                raise ValueError
            setting = CreditSetting(part, float(fields[0]), fields[1], float(fields[2]), fields[3])
            if not (0.0 < setting.gamma <= 1.0 and 0.0 <= setting.lmbda <= 1.0):
                raise ValueError
        except ValueError as err:
            raise SystemExit(
                f"--credit {text!r}: {part!r} is neither one of {', '.join(CREDIT_PRESETS)} "
                f"nor GAMMA:SCALE:LAMBDA:SCALE with SCALE one of {', '.join(CREDIT_SCALES)}, "
                "GAMMA in (0, 1] and LAMBDA in [0, 1]"
            ) from err
        settings.append(setting)
    return settings


def gae_weights(setting: CreditSetting, subframes_per_interval: int, horizon: int) -> torch.Tensor:
    """[T, H] float64: w(t, j) = (γ_s·λ_s)^((T−1−t) + j·T), the weight with which the reward
    paid at the last subframe of interval k+j enters the GAE advantage of the action at
    subframe t of interval k (γ_s, λ_s per subframe)."""
    gamma, lmbda = setting.per_subframe(subframes_per_interval)
    t = torch.arange(subframes_per_interval, dtype=torch.float64)[:, None]
    j = torch.arange(horizon, dtype=torch.float64)[None, :]
    steps = (subframes_per_interval - 1 - t) + j * subframes_per_interval
    return torch.as_tensor(gamma * lmbda, dtype=torch.float64) ** steps


def credit_to_carriers(
    weights: torch.Tensor, transmitting: torch.Tensor, delta_xi: torch.Tensor
) -> torch.Tensor:
    """Per CAM [n]: mean over the subframes t in which its link transmitted it
    (``transmitting`` [n, T] bool) of Σ_j w(t, j)·Δξ_{k+j} (``weights`` [T, H], ``delta_xi``
    [n, H])."""
    per_subframe = delta_xi.double() @ weights.T  # [n, T]
    mask = transmitting.double()
    return (per_subframe * mask).sum(-1) / mask.sum(-1)


def discounted_sum(delta_xi: torch.Tensor, gamma: float) -> torch.Tensor:
    """Σ_j γ^j Δξ_{k+j} per CAM, [n] (``delta_xi`` [n, H])."""
    horizon = delta_xi.shape[-1]
    powers = torch.as_tensor(gamma, dtype=torch.float64) ** torch.arange(
        horizon, dtype=torch.float64
    )
    return delta_xi.double() @ powers


def ratio_of_means(
    numerator: torch.Tensor,
    denominator: torch.Tensor,
    resamples: int = BOOTSTRAP_RESAMPLES,
    seed: int = 0,
    confidence: float = 0.95,
) -> dict[str, float | int]:
    """mean(numerator) / mean(denominator) over paired samples [n], with a percentile
    bootstrap CI that resamples the pairs (seeded)."""
    num, den = numerator.double().reshape(-1), denominator.double().reshape(-1)
    n = num.numel()
    ratio = float(num.mean() / den.mean()) if n else float("nan")
    if n < 2:
        return {"ratio": ratio, "low": float("nan"), "high": float("nan"), "n": n}
    generator = torch.Generator().manual_seed(seed)
    draws = []
    for begin in range(0, resamples, 1000):
        index = torch.randint(n, (min(1000, resamples - begin), n), generator=generator)
        draws.append(num[index].mean(-1) / den[index].mean(-1))
    draws = torch.cat(draws)
    tail = (1.0 - confidence) / 2
    low, high = torch.quantile(draws, torch.tensor([tail, 1.0 - tail], dtype=torch.float64))
    return {"ratio": ratio, "low": float(low), "high": float(high), "n": n}


def credit_summary(
    delta_xi: torch.Tensor,
    transmitting: torch.Tensor,
    settings: list[CreditSetting],
    gamma_interval: float,
    subframes_per_interval: int,
) -> dict:
    """The ``credit`` entry of a run (see the module doc) from Δξ [n, H] and the transmitting
    subframes [n, T] of the n dropped CAMs."""
    horizon = delta_xi.shape[-1]
    full = discounted_sum(delta_xi, gamma_interval)
    first = delta_xi[:, 0].double()
    rows = []
    for setting in settings:
        weights = gae_weights(setting, subframes_per_interval, horizon)
        credit = credit_to_carriers(weights, transmitting, delta_xi)
        from_first = credit_to_carriers(weights[:, :1], transmitting, delta_xi[:, :1])
        gamma_s, lmbda_s = setting.per_subframe(subframes_per_interval)
        rows.append(
            {
                "name": setting.name,
                "gamma": setting.gamma,
                "gamma_scale": setting.gamma_scale,
                "lmbda": setting.lmbda,
                "lmbda_scale": setting.lmbda_scale,
                "gamma_per_subframe": gamma_s,
                "lmbda_per_subframe": lmbda_s,
                "weight_t0_j0": float(weights[0, 0]),
                "weight_t0_j1": float(weights[0, 1]) if horizon > 1 else float("nan"),
                "credit": ci_summary(credit),
                "credit_from_j0": ci_summary(from_first),
                "share_of_full_value": ratio_of_means(credit, full),
            }
        )
    delta_mean = delta_xi.double().mean(0) if delta_xi.shape[0] else torch.zeros(horizon)
    return {
        "estimator": "td",
        "gamma_interval": gamma_interval,
        "subframes_per_interval": subframes_per_interval,
        "full_value": ci_summary(full),
        "full_value_share_j0": ratio_of_means(first, full),
        "full_value_share_later": ratio_of_means(full - first, full),
        "delta_xi_mean_by_j": [float(x) for x in delta_mean],
        "transmitting_subframes": ci_summary(transmitting.double().sum(-1)),
        "settings": rows,
    }


def _pick_one(in_time: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """One True per row of ``in_time`` [B, L], chosen uniformly among its True entries (rows
    without any stay all False)."""
    scores = torch.rand(in_time.shape, generator=generator).masked_fill(~in_time.cpu(), -1.0)
    chosen = torch.zeros_like(in_time.cpu())
    best = scores.argmax(-1)
    rows = torch.arange(in_time.shape[0])
    chosen[rows, best] = in_time.cpu()[rows, best]
    return chosen.to(in_time.device)


def delivery_persistence(in_time: torch.Tensor, alive: torch.Tensor) -> dict[str, float]:
    """Fraction of CAMs in time overall, after a CAM of the same link in time and after one
    that was not; ``in_time`` [K, B, L] per interval, ``alive`` [K, B] (only pairs of
    consecutive intervals in which the scenario was running count)."""
    counted = alive[:, :, None].expand_as(in_time).double()
    both = (alive[:-1] & alive[1:])[:, :, None].expand_as(in_time[1:]).double()
    before, after = in_time[:-1].double(), in_time[1:].double()
    return {
        "in_time": float((in_time.double() * counted).sum() / counted.sum()),
        "after_in_time": float((before * after * both).sum() / (before * both).sum()),
        "after_miss": float(((1 - before) * after * both).sum() / ((1 - before) * both).sum()),
    }


def _pearson(x: torch.Tensor, y: torch.Tensor) -> float:
    if x.numel() < 3 or float(x.std()) == 0.0 or float(y.std()) == 0.0:
        return float("nan")
    return float(torch.corrcoef(torch.stack([x, y]))[0, 1])


def measure(
    loop: JointOptimisation,
    rra_name: str,
    episodes: int,
    starts: list[int],
    horizon: int,
    show_progress: bool = True,
    credits: list[CreditSetting] | None = None,
    samples: list | None = None,
) -> dict:
    """Per dropped CAM: value, td credit and one-step credit, and Δξ over the horizon with the
    subframes that carried it, summarised per setting of ``credits`` (see the module doc).
    ``samples`` (a list) receives (Δξ [n, H], transmitting [n, T], no collision [n], γ, T)
    for pooling."""
    credits = parse_credits(DEFAULT_CREDITS) if credits is None else credits
    cfg, params = loop.cfg, loop.params
    seed = EVAL_SEED_OFFSET + cfg.seed
    twin = DigitalTwin(
        params, batch_size=episodes, device=loop.device, seed=seed,
        trace_source=loop.eval_traces, radio=True, backend="torch",
    )  # fmt: skip
    twin.reset(seed=seed)
    base_control = loop.control_policy()
    base_rra = (
        loop.rra_policy() if rra_name == LEARNED else make_rra_baseline(rra_name, params, cfg.seed)
    )
    completion = copy.deepcopy(loop.completion)
    completion.reset()
    td = loop.ivoi_estimator("td")
    one_step = loop.ivoi_estimator(
        "rollout", rollout_intervals=1, bootstrap=True, baseline="cam_lost"
    )
    main = ActingSystem(
        twin, bind_to_twin(base_control, twin), completion, bind_to_twin(base_rra, twin)
    )
    generator = torch.Generator().manual_seed(seed)
    alive = torch.ones(episodes, dtype=torch.bool, device=twin.device)
    value, td_credit, one_step_credit, delta_xi, transmitting = [], [], [], [], []
    no_collision = []
    in_time_history, alive_history = [], []
    last = max(starts)
    steps = track(range(last + 1), description="intervals", disable=not show_progress)
    for k in steps:
        if k > 0:
            main.begin()
        pending = main.run_subframes()
        in_time_history.append(twin.switch_subframe(perfect=False) < twin.subframes_per_interval)
        alive_history.append(alive.clone())
        if k in starts:
            kept = main.copy(base_control, base_rra)
            lost = kept.copy(base_control, base_rra)
            in_time = twin.switch_subframe(perfect=False) < twin.subframes_per_interval
            drop = _pick_one(in_time & alive[:, None], generator)
            lost.twin.drop_cams(drop)
            record_kept = kept.finish(one_step)
            record_lost = lost.finish()
            td_kept = td(kept.twin, record_kept)
            td_lost = td(lost.twin, record_lost)
            one_step_kept = one_step(kept.twin, record_kept)
            sampled = drop.any(-1)
            return_kept, xi_kept, alive_kept = discounted_platoon_return(
                kept, record_kept, horizon, loop.gamma, td, td_kept
            )
            return_lost, xi_lost, alive_lost = discounted_platoon_return(
                lost, record_lost, horizon, loop.gamma, td, td_lost
            )
            no_collision.append((alive_kept & alive_lost)[sampled])
            value.append((return_kept - return_lost)[sampled])
            td_credit.append((td_kept - td_lost)[drop].double())
            one_step_credit.append(one_step_kept[drop].double())
            delta_xi.append((xi_kept - xi_lost).permute(1, 2, 0)[drop])  # [n, H]
            carried = pending.to(drop.device).permute(1, 2, 0)[drop]  # [n, T]
            delay = torch.as_tensor(twin.link_state.delay_subframes, device=drop.device)[drop]
            if not torch.equal(carried.sum(-1), delay.to(carried.device).long()):
                raise RuntimeError("transmitting subframes disagree with the CAM delivery delay")
            transmitting.append(carried)
        record = main.finish()
        alive &= ~record.collided.any(-1)
    value_all = torch.cat(value).cpu()
    td_all = torch.cat(td_credit).cpu()
    one_all = torch.cat(one_step_credit).cpu()
    delta_all, transmitting_all = torch.cat(delta_xi).cpu(), torch.cat(transmitting).cpu()
    survived = torch.cat(no_collision).cpu()
    subframes = twin.subframes_per_interval
    if samples is not None:
        samples.append((delta_all, transmitting_all, survived, loop.gamma, subframes))
    return {
        "rra": f"{cfg.rra.name} ({LEARNED})" if rra_name == LEARNED else rra_name,
        "cams": int(value_all.numel()),
        "value": ci_summary(value_all),
        "td_credit": ci_summary(td_all),
        "one_step_credit": ci_summary(one_all),
        "correlation_value_td_credit": _pearson(value_all, td_all),
        "value_sd": float(value_all.std()) if value_all.numel() > 1 else float("nan"),
        "delivery": delivery_persistence(
            torch.stack(in_time_history).cpu(), torch.stack(alive_history).cpu()
        ),
        "credit": credit_summary(delta_all, transmitting_all, credits, loop.gamma, subframes),
        "cams_no_collision": int(survived.sum()),
        "credit_no_collision": credit_summary(
            delta_all[survived], transmitting_all[survived], credits, loop.gamma, subframes
        ),
    }


def pooled_credit(samples: list, credits: list[CreditSetting]) -> dict | None:
    """The ``credit`` and ``credit_no_collision`` entries over the CAMs of every run together
    from ``samples`` (per run: Δξ, transmitting subframes, no collision, γ, T); None for a
    single run, or when the runs differ in discount, subframes per interval or horizon."""
    if len(samples) < 2 or len({(g, t, d.shape[-1]) for d, _, _, g, t in samples}) != 1:
        return None
    *_, gamma, subframes = samples[0]
    delta, transmitting, survived = (torch.cat([s[i] for s in samples]) for i in range(3))
    return {
        "runs": len(samples),
        "cams": int(delta.shape[0]),
        "credit": credit_summary(delta, transmitting, credits, gamma, subframes),
        "cams_no_collision": int(survived.sum()),
        "credit_no_collision": credit_summary(
            delta[survived], transmitting[survived], credits, gamma, subframes
        ),
    }


def _fmt(stat: dict) -> str:
    return f"{stat['mean']:+.4f} [{stat['low']:+.4f}, {stat['high']:+.4f}]"


def print_table(runs: list[dict], console: Console) -> None:
    table = Table(title="What one delivered CAM is worth (platoon return over the horizon)")
    columns = ("run", "RRA", "CAMs", "value", "td credit", "one-step credit", "corr", "sd")
    for column in (*columns, "in time (after in time / miss)"):
        table.add_column(column, justify="left" if column in ("run", "RRA") else "right")
    for run in runs:
        row = run["result"]
        table.add_row(
            f"{run['scenario']} seed {run['seed']} ({run['rra_reward']})",
            row["rra"],
            str(row["cams"]),
            _fmt(row["value"]),
            _fmt(row["td_credit"]),
            _fmt(row["one_step_credit"]),
            f"{row['correlation_value_td_credit']:+.2f}",
            f"{row['value_sd']:.3f}",
            "{in_time:.2f} ({after_in_time:.2f} / {after_miss:.2f})".format(**row["delivery"]),
        )
    console.print(table)


def _fmt_ratio(stat: dict) -> str:
    return f"{stat['ratio']:+.2f} [{stat['low']:+.2f}, {stat['high']:+.2f}]"


def print_credit_table(runs: list[dict], console: Console, pooled: dict | None = None) -> None:
    """Per run and credit setting: what of a CAM's IVoI reaches the actions that carried it
    (and over the CAMs of every run, ``pooled``)."""
    table = Table(
        title="Credit reaching the subframes that carried a dropped CAM (td Δξ over the horizon)"
    )
    columns = (
        "run", "CAMs", "credit setting", "γ_s·λ_s", "w(0,0)", "w(0,1)",
        "credit", "from j = 0", "share of full value",
    )  # fmt: skip
    for column in columns:
        table.add_column(column, justify="left" if column in ("run", "credit setting") else "right")
    blocks = [(f"{r['scenario']} seed {r['seed']} ({r['rra_reward']})", r["result"]) for r in runs]
    if pooled is not None:
        blocks.append((f"all {pooled['runs']} runs", pooled))
    rows = []
    for label, result in blocks:
        rows.append((label, result["cams"], result["credit"]))
        if "credit_no_collision" in result:
            no_collision = (result["cams_no_collision"], result["credit_no_collision"])
            rows.append((f"{label}, no collision", *no_collision))
    for label, cams, credit in rows:
        table.add_row(
            label,
            str(cams),
            f"full value Σ_j {credit['gamma_interval']:g}^j Δξ",
            "",
            "",
            "",
            _fmt(credit["full_value"]),
            "share " + _fmt_ratio(credit["full_value_share_j0"]),
            "j ≥ 1: " + _fmt_ratio(credit["full_value_share_later"]),
        )
        for row in credit["settings"]:
            table.add_row(
                "",
                "",
                f"{row['name']} (γ {row['gamma']:g}/{row['gamma_scale']}, "
                f"λ {row['lmbda']:g}/{row['lmbda_scale']})",
                f"{row['gamma_per_subframe'] * row['lmbda_per_subframe']:.5f}",
                f"{row['weight_t0_j0']:.4f}",
                f"{row['weight_t0_j1']:.4f}",
                _fmt(row["credit"]),
                _fmt(row["credit_from_j0"]),
                _fmt_ratio(row["share_of_full_value"]),
            )
    console.print(table)


def plot_runs(runs: list[dict], path: Path, note: str) -> Path:
    """PNG: per run, the value of a CAM (left) and what the IVoI credits it with at its
    interval (right, td and one-step), each mean with its 95% CI."""
    plt = pyplot_agg()
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 0.45 * len(runs) + 2.2), sharey=True)
    labels = [f"{r['scenario']} seed {r['seed']}" for r in runs]
    y = list(range(len(runs)))

    def forest(ax, key, offset, color, label):
        stats = [r["result"][key] for r in runs]
        means = [s["mean"] for s in stats]
        errors = [
            [s["mean"] - s["low"] for s in stats],
            [s["high"] - s["mean"] for s in stats],
        ]
        ys = [v + offset for v in y]
        ax.errorbar(means, ys, xerr=errors, fmt="o", color=color, capsize=3, label=label)

    forest(left, "value", 0.0, "tab:blue", "value over the horizon")
    forest(right, "td_credit", -0.12, "tab:red", "td credit")
    forest(right, "one_step_credit", 0.12, "tab:orange", "one-step (cam_lost) credit")
    rra = runs[0]["result"]["rra"]
    left.set_title(f"What one delivered CAM is worth ({rra} RRA)")
    right.set_title("What the IVoI credits it with at its interval")
    for ax in (left, right):
        ax.axvline(0.0, color="0.5", linewidth=0.8)
        ax.set_xlabel("control return (reward units)")
        ax.legend(loc="best", fontsize=8)
    left.set_yticks(y, labels)
    left.invert_yaxis()
    return save_figure(fig, path, note)


def _parse_starts(text: str, horizon: int, episode_intervals: int) -> list[int]:
    try:
        starts = sorted({int(part) for part in text.split(",") if part.strip()})
    except ValueError as err:
        raise SystemExit(f"--starts {text!r} must be integers separated by commas") from err
    if not starts or starts[0] < 0 or starts[-1] + horizon > episode_intervals:
        raise SystemExit(
            f"--starts {text!r} must lie in [0, {episode_intervals - horizon}] so that the "
            f"--horizon {horizon} intervals after each fit in an episode of "
            f"{episode_intervals} intervals"
        )
    return starts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoints", nargs="+", type=Path, help="JOCC checkpoints (.pt)")
    parser.add_argument(
        "--rra",
        default="random",
        help=f"RRA policy: {LEARNED} or one of {', '.join(RRA_BASELINES)}",
    )
    parser.add_argument("--episodes", type=int, default=32, help="held-out scenarios (>= 2)")
    parser.add_argument(
        "--starts", default=DEFAULT_STARTS, help="intervals at which a CAM is dropped"
    )
    parser.add_argument(
        "--horizon", type=int, default=40, help="intervals over which the value is summed"
    )
    parser.add_argument(
        "--credit",
        default=DEFAULT_CREDITS,
        help=f"RRA credit settings, comma-separated: {', '.join(CREDIT_PRESETS)} or "
        "GAMMA:SCALE:LAMBDA:SCALE (SCALE subframe: per 1 ms subframe; interval: per control "
        "interval, applied as x^(1/T) per subframe)",
    )
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (0: default)")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument(
        "--plot",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="write the PNG next to the JSON",
    )
    parser.add_argument("--output", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    if args.rra not in (LEARNED, *RRA_BASELINES):
        raise SystemExit(f"--rra {args.rra!r} is not one of {LEARNED}, {', '.join(RRA_BASELINES)}")
    if args.episodes < 2:
        raise SystemExit(f"--episodes {args.episodes} must be >= 2")
    if args.horizon < 1:
        raise SystemExit(f"--horizon {args.horizon} must be >= 1")
    credits = parse_credits(args.credit)
    if args.threads:
        torch.set_num_threads(args.threads)
    console = table_console(file_width=200)
    began = time.perf_counter()
    runs, samples = [], []
    for path, loop in loaded_checkpoints(args.checkpoints, "cam_value_", console):
        if args.rra == LEARNED and not loop.cfg.rra.learned:
            raise SystemExit(f"--rra {LEARNED}: {path} learned no RRA policy")
        starts = _parse_starts(args.starts, args.horizon, loop.params.episode_intervals)
        runs.append(
            {
                **checkpoint_run(path, loop.cfg),
                "result": measure(
                    loop,
                    args.rra,
                    args.episodes,
                    starts,
                    args.horizon,
                    args.progress,
                    credits,
                    samples,
                ),
            }
        )
    pooled = pooled_credit(samples, credits)
    print_table(runs, console)
    print_credit_table(runs, console, pooled)
    if args.plot:
        note = (
            f"studies/2026-12-01-cam-credit/cam_value.py --rra {args.rra} --episodes {args.episodes} "
            f"--starts {args.starts} --horizon {args.horizon}; 95% CIs over CAMs"
        )
        plot = plot_runs(runs, args.output.with_suffix(".png"), note)
        console.print(f"wrote {plot}")
    atomic_write_json(
        args.output,
        {
            **provenance("cam_value"),
            "episodes": args.episodes,
            "starts": args.starts,
            "horizon": args.horizon,
            "credit": args.credit,
            "bootstrap_resamples": BOOTSTRAP_RESAMPLES,
            "seconds": time.perf_counter() - began,
            "runs": runs,
            **({"pooled": pooled} if pooled is not None else {}),
        },
    )
    console.print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
