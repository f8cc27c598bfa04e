"""Where a PPO iteration of π̃ under the learned RRA goes, what compiling its two hot functions
gives, and the arithmetic it cannot avoid, against the 30-minute JOCC iteration budget.

    python studies/2026-12-05-pi-tilde-budget/pi_tilde_budget.py  # writes pi_tilde_budget.json
    python studies/2026-12-05-pi-tilde-budget/pi_tilde_budget.py --batch-sizes 64 --repeats 1 \
        --out /tmp/pt.json
    python studies/2026-12-05-pi-tilde-budget/pi_tilde_budget.py \
        --budget-only  # the budget again, from the stored rows

π̃ under the learned RRA is most of a later ``experiment=paper`` JOCC iteration
(``benchmarks/results/stage_throughput.json``): every control interval runs T = 50 subframes, each
one call of the RRA policy and one of the subframe kernel. Per batch size B (scenarios, rollout
25,600 / B intervals, the ``experiment=paper`` loop as ``benchmarks/stage_throughput.py`` builds it,
torch on the run's 1 intra-op thread plus the draw-ahead thread), in one process:

1. **Paired iterations**, ``--repeats`` pairs, eager then compiled: a PPO iteration (collect +
   update) as the run does it, and the same with the subframe kernel
   (``link.link_major_arithmetic``) and the RRA policy's deterministic call
   (``CategoricalMode``) handed to ``torch.compile(dynamic=False)`` (TorchInductor; a C++
   compiler at run time). The compiled functions replace the eager ones for the timing only:
   this is a measurement, not a switch (docs/profile.md, *Not done*). Each iteration also
   counts its radio runs: one per control interval, and one more per interval at which some
   scenarios ended (a partial reset runs its first interval's radio over the whole batch, the
   other scenarios masked out), so a π̃ whose scenarios crash costs more.
2. **The arithmetic floor** of an iteration: the PPO update as measured, plus, for one radio
   run per interval, the RRA network's matrix products and activations alone (three
   ``F.linear`` and two activations, in place as the call applies them, on ``[B, L, D]``,
   nothing else) and the compiled kernel's subframe, each the fastest of 5 timed blocks.
   Everything else (observations, the interval's start and close, the control policy,
   TensorDicts, Python) counts as free. It is a floor for torch on this CPU as long as the
   network's products and activations stay torch's (MKL's GEMM, torch's activation kernels);
   a hand-fused kernel could save the activations' memory passes, not the products.
3. **The budget**: from ``benchmarks/results/stage_throughput.json`` (its chosen sizes, and under
   ``paper`` the ``experiment=paper`` sizes; a later JOCC iteration), the seconds of every
   other stage, hence the seconds per π̃ iteration that would leave a JOCC iteration within
   30 minutes; the speed-up needed over that file's π̃ and
   the speed-up the floor allows over this run's eager iteration (a ratio within one run).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
BENCHMARKS = HERE.parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import stage_throughput  # noqa: E402  (the sibling script: the stage loop it builds)
from stage_throughput import CONTROL_FRAMES  # noqa: E402  (π̃'s samples per iteration)

RESULTS = HERE / "pi_tilde_budget.json"
STAGES = BENCHMARKS / "results" / "stage_throughput.json"
BUDGET_S = 30 * 60.0


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[256, 1024])
    p.add_argument("--repeats", type=int, default=3, help="eager/compiled iteration pairs per B")
    p.add_argument("--calls", type=int, default=200, help="calls per floor timing")
    p.add_argument(
        "--frames",
        type=int,
        default=CONTROL_FRAMES,
        help="samples per PPO iteration (B × rollout intervals); the paper's by default",
    )
    p.add_argument("--stages", type=Path, default=STAGES, help="a stage_throughput.py result")
    p.add_argument("--out", type=Path, default=RESULTS)
    p.add_argument(
        "--budget-only",
        action="store_true",
        help="recompute the budget of the result at --out from --stages; time nothing",
    )
    args = p.parse_args(argv)
    if args.frames < 1:
        p.error(f"--frames {args.frames} must be >= 1")
    bad = [b for b in args.batch_sizes if b < 1 or args.frames % b]
    if bad:
        p.error(f"--batch-sizes {bad} must divide --frames {args.frames}")
    if args.repeats < 1 or args.calls < 1:
        p.error(f"--repeats {args.repeats} and --calls {args.calls} must be >= 1")
    return args


# ---------------------------------------------------------------------- compiled stand-ins
def _mode_arithmetic(x, functions, weights):
    """``CategoricalMode.__call__`` after its scaler, as one function of tensors."""
    import torch.nn.functional as F

    i = 0
    for function in functions:
        if function is None:
            x = F.linear(x, weights[i], weights[i + 1])
            i += 2
        else:
            x = function(x)
    logits = x - x.logsumexp(dim=-1, keepdim=True)
    return F.softmax(logits, dim=-1).argmax(dim=-1)


def _weights(mode, layers=None) -> list:
    """The Linear layers' weights and biases in order (``layers``: ``mode.weights()``)."""
    return [t for layer in (layers or mode.weights()) if layer is not None for t in layer]


class Compiled:
    """Swaps the eager kernel and policy call for compiled copies inside ``with``. The policy
    is compiled for the whole batch of ``batch`` scenarios; its calls on a partial reset's few
    scenarios (a number that changes from call to call) stay eager, as recompiling for each
    would cost more than it saves."""

    def __init__(self, batch: int):
        import torch

        from vdtn_marl.algos import networks
        from vdtn_marl.sim import link

        self.link, self.networks = link, networks
        self.eager_kernel = link.link_major_arithmetic
        # every call of the fast path (CategoricalMode.__call__ and .bound()) goes through _act
        self.eager_call = networks.CategoricalMode._act
        self.kernel = torch.compile(self.eager_kernel, dynamic=False)
        arithmetic = torch.compile(_mode_arithmetic, dynamic=False)

        eager_call = self.eager_call

        def call(mode, observation, layers):
            if observation.shape[0] != batch:
                return eager_call(mode, observation, layers)
            return arithmetic(mode.scaler(observation), mode._functions, _weights(mode, layers))

        self.call = call

    def __enter__(self):
        self.link.link_major_arithmetic = self.kernel
        self.networks.CategoricalMode._act = self.call
        return self

    def __exit__(self, *exc):
        self.link.link_major_arithmetic = self.eager_kernel
        self.networks.CategoricalMode._act = self.eager_call
        return False


class RadioRuns:
    """Counts ``IntervalEngine.run_radio`` calls inside ``with``."""

    def __enter__(self):
        from vdtn_marl.core.interval import IntervalEngine

        self.cls, self.original, self.count = IntervalEngine, IntervalEngine.run_radio, 0
        original = self.original

        def counted(engine, *args, **kwargs):
            self.count += 1
            return original(engine, *args, **kwargs)

        IntervalEngine.run_radio = counted
        return self

    def __exit__(self, *exc):
        self.cls.run_radio = self.original
        return False


# ---------------------------------------------------------------------- one batch size
def _iteration(trainer) -> dict:
    with RadioRuns() as radio:
        row = stage_throughput.timed_iteration(trainer)
    return {**row, "radio_runs": radio.count}


def _per_call_us(fn, calls: int, blocks: int = 5) -> float:
    """Microseconds per call of ``fn``: the fastest of ``blocks`` blocks of ``calls`` calls
    (a floor is the best case; the fastest block leaves out the moments another process
    held the core)."""
    fn()
    best = float("inf")
    for _ in range(blocks):
        began = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - began) / calls)
    return 1e6 * best


def measure(batch: int, repeats: int, calls: int, frames: int = CONTROL_FRAMES) -> dict:
    import torch
    import torch.nn.functional as F

    from vdtn_marl.algos.networks import CategoricalMode
    from vdtn_marl.sim import link

    st = stage_throughput
    _, loop = st._loop([f"algo.num_envs={batch}", f"algo.rollout_steps={frames // batch}"])
    st._learned_rra(loop)
    trainer = loop.pi_tilde
    trainer.fit_observation_scaling()
    trainer.train_iteration()  # warm-up
    twin = trainer.env.twin
    mode = loop.rra_slot.policy.mode
    if not isinstance(mode, CategoricalMode):
        raise SystemExit("the learned RRA policy has no CategoricalMode fast path")
    row: dict = {
        "batch_size": batch,
        "links": mode.n_agents,
        "subframes": twin.subframes_per_interval,
    }
    compiled = Compiled(batch)
    observation = twin.rra_observation().clone()
    try:
        began = time.perf_counter()
        with compiled:
            with torch.no_grad():
                actions = mode(observation)
            trainer.train_iteration()  # compiles the kernel too; a warm-up of the compiled run
        row["compile_s"] = time.perf_counter() - began
    except Exception as error:  # no C++ compiler, an unsupported platform, ...
        row["compiled"] = False
        row["error"] = f"{type(error).__name__}: {str(error).splitlines()[0][:300]}"
    else:
        row["compiled"] = True
        with torch.no_grad():
            row["policy_actions_bit_identical"] = bool(torch.equal(actions, mode(observation)))
    eager, fast = [], []
    for _ in range(repeats):
        eager.append(_iteration(trainer))
        if row["compiled"]:
            with compiled:
                fast.append(_iteration(trainer))
    row["eager"] = eager
    row["eager_s"] = statistics.median(r["seconds"] for r in eager)
    row["update_s"] = statistics.median(r["update_s"] for r in eager)
    if fast:
        row["compiled_runs"] = fast
        row["compiled_s"] = statistics.median(r["seconds"] for r in fast)
        row["eager_over_compiled"] = statistics.median(
            e["seconds"] / c["seconds"] for e, c in zip(eager, fast, strict=True)
        )
    runs = eager + fast
    row["radio_runs_per_interval"] = sum(r["radio_runs"] for r in runs) / sum(
        r["intervals"] for r in runs
    )

    # the floor: the network's products and activations, the compiled kernel, the update
    x = mode.scaler(observation)
    weights = [w.detach() for w in _weights(mode)]
    hidden = []
    with torch.no_grad():
        h = x
        i = 0
        # each activation as the policy's call applies it (in place on a Linear's output)
        for function, call in zip(mode._functions, mode._calls, strict=True):
            if function is None:
                hidden.append(("linear", h, weights[i], weights[i + 1]))
                h = F.linear(h, weights[i], weights[i + 1])
                i += 2
            else:
                hidden.append(("activation", h.clone(), call))
                h = function(h)

        def linears():
            for step in hidden:
                if step[0] == "linear":
                    F.linear(step[1], step[2], step[3])

        def activations():
            for step in hidden:
                if step[0] == "activation":
                    step[2](step[1])

        row["network_linear_us"] = _per_call_us(linears, calls)
        row["network_activation_us"] = _per_call_us(activations, calls)
        row["network_arithmetic_us"] = row["network_linear_us"] + row["network_activation_us"]
    kernel_us = None
    if row["compiled"]:
        interval = _kernel_interval(batch)
        runs_of = max(1, calls // interval.subframes)
        kernel_us = _per_call_us(lambda: interval.run(compiled.kernel), runs_of) / (
            interval.subframes
        )
        row["kernel_compiled_us"] = kernel_us
        row["kernel_eager_us"] = (
            _per_call_us(lambda: interval.run(link.link_major_arithmetic), runs_of)
            / interval.subframes
        )
    subframes = row["subframes"] * (frames // batch)
    row["floor_s"] = row["update_s"] + subframes * 1e-6 * (
        row["network_arithmetic_us"] + (kernel_us or 0.0)
    )
    row["floor_parts_s"] = {
        "update": row["update_s"],
        "rra_network": subframes * 1e-6 * row["network_arithmetic_us"],
        "kernel_compiled": subframes * 1e-6 * (kernel_us or 0.0),
    }
    row["eager_over_floor"] = row["eager_s"] / row["floor_s"]
    return row


def _kernel_interval(batch: int):
    sys.path.insert(0, str(HERE.parent / "2026-12-04-compile-kernel"))
    import compile_kernel

    return compile_kernel.Interval(batch, seed=0)


# ---------------------------------------------------------------------- the budget
def budget(stages_path: Path, rows: list[dict], frames: int = CONTROL_FRAMES) -> dict:
    """The π̃ seconds per iteration that fit a 30-minute later JOCC iteration, from a
    ``benchmarks/stage_throughput.py`` result, and whether the floor measured here could get there:
    at that result's fastest sizes (``estimate``), and under ``paper`` at the ``experiment=paper``
    sizes (``estimate_paper``), where the file has them. ``rows`` timed at other than the
    paper's ``frames`` per iteration are not set against it."""
    if frames != CONTROL_FRAMES:
        rows = []
    if not stages_path.is_file():
        return {"stages": str(stages_path), "missing": True}
    stages = json.loads(stages_path.read_text())
    out = {
        "stages": stages_path.name,
        "stages_written": stages.get("written"),
        **_fit(stages["estimate"], rows),
    }
    if "estimate_paper" in stages:
        out["paper"] = _fit(stages["estimate_paper"], rows)
    return out


def _fit(est: dict, rows: list[dict]) -> dict:
    """:func:`budget` for one estimate of ``benchmarks/stage_throughput.py`` (its batch sizes)."""
    seconds = est["seconds"]
    iterations = est["budgets"]["control_iterations"]
    later = est["later_iteration_s"]
    pi_tilde = seconds["pi_tilde_learned"]
    others = later - pi_tilde
    allowed = (BUDGET_S - others) / iterations
    control = est["chosen_batches"]["control"]
    measured = pi_tilde / iterations
    out = {
        "chosen_control_batch": control,
        "later_iteration_min": later / 60.0,
        "other_stages_min": others / 60.0,
        "pi_tilde_s_per_iteration": measured,
        "allowed_pi_tilde_s_per_iteration": allowed,
        "needed_speedup": measured / allowed if allowed > 0 else float("inf"),
    }
    row = next((r for r in rows if r["batch_size"] == control), None)
    if row is not None:
        out["floor_speedup_here"] = row["eager_over_floor"]
        out["reachable_at_the_floor"] = bool(row["eager_over_floor"] >= out["needed_speedup"])
    return out


def _print_budget(b: dict) -> None:
    if b.get("missing"):
        return
    for name, fit in (("fastest sizes", b), ("experiment=paper sizes", b.get("paper"))):
        if fit is None:
            continue
        print(
            f"30-min JOCC iteration at the {name} ({b['stages']}, {b['stages_written']}): other "
            f"stages {fit['other_stages_min']:.1f} min, so π̃ needs ≤ "
            f"{fit['allowed_pi_tilde_s_per_iteration']:.2f} s per iteration at B = "
            f"{fit['chosen_control_batch']} ({fit['needed_speedup']:.2f}× its "
            f"{fit['pi_tilde_s_per_iteration']:.2f} s); the floor here allows "
            f"{fit.get('floor_speedup_here', float('nan')):.2f}×"
        )


def rebudget(args) -> int:
    """``--budget-only``: recompute the budget of the result at ``--out`` from its stored rows
    and ``--stages``, without timing anything; the rows and their provenance stay."""
    from vdtn_marl.io.files import atomic_write_json

    if not args.out.is_file():
        raise SystemExit(f"--budget-only: no result at --out {args.out}")
    result = json.loads(args.out.read_text())
    result["budget"] = budget(args.stages, result["rows"], result["frames_per_iteration"])
    result["budget"]["recomputed"] = time.strftime("%Y-%m-%d")
    _print_budget(result["budget"])
    atomic_write_json(args.out, result)
    print(f"wrote {args.out}")
    return 0


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.budget_only:
        return rebudget(args)
    import torch  # noqa: F401

    from vdtn_marl.io.files import atomic_write_json
    from vdtn_marl.reporting.benchmarking import provenance

    load_start = os.getloadavg()
    rows = []
    for batch in args.batch_sizes:
        print(f"B = {batch}: {args.repeats} eager/compiled iteration pairs ...", flush=True)
        rows.append(measure(batch, args.repeats, args.calls, args.frames))
    result = {
        **provenance("pi_tilde_budget"),
        "load_average_start": list(load_start),
        "load_average_end": list(os.getloadavg()),
        "repeats": args.repeats,
        "frames_per_iteration": args.frames,
        "rows": rows,
        "budget": budget(args.stages, rows, args.frames),
    }
    print(
        f"\n{'B':>5} {'eager s':>8} {'compiled s':>10} {'eager/comp':>10} {'radio/int':>9} "
        f"{'floor s':>8} {'eager/floor':>11}"
    )
    for r in rows:
        comp = (
            f"{r['compiled_s']:>10.2f} {r['eager_over_compiled']:>10.2f}"
            if r.get("compiled_s")
            else f"{'failed':>10} {'':>10}"
        )
        print(
            f"{r['batch_size']:>5} {r['eager_s']:>8.2f} {comp} "
            f"{r['radio_runs_per_interval']:>9.2f} {r['floor_s']:>8.2f} "
            f"{r['eager_over_floor']:>11.2f}"
        )
    print()
    _print_budget(result["budget"])
    atomic_write_json(args.out, result)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
