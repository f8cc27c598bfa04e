"""Fixed-seed fingerprints of every environment face, the evaluation and a smoke JOCC run.

A restructuring that must not move results runs this before and after and compares:

    python scripts/fingerprints.py --out /tmp/before.json
    ... change the code ...
    python scripts/fingerprints.py --compare /tmp/before.json

Each fingerprint is a SHA-256 of the arrays a short seeded rollout produces (observations,
rewards, terminations, infos' numbers), so any change of a bit shows. ``--skip-jocc`` leaves
out the smoke JOCC run (about 20 s). Exit status 1 when ``--compare`` finds a difference.
``--without KEY`` (repeatable) leaves every dict entry named KEY out of the hashes: a change
that adds a metric compares the rest with the fingerprints from before it.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import torch

SEED = 7
STEPS_PER_SUBFRAME_ENV = 160  # three intervals and a bit
STEPS_PER_INTERVAL_ENV = 12
#: dict keys left out of every hash (``--without``)
WITHOUT: set[str] = set()


def _drop_keys(value):
    """``value`` without the dict entries named in :data:`WITHOUT`, at any depth."""
    if isinstance(value, dict):
        return {k: _drop_keys(v) for k, v in value.items() if k not in WITHOUT}
    if isinstance(value, list | tuple):
        return type(value)(_drop_keys(v) for v in value)
    return value


def _numbers(value, out: list[np.ndarray]) -> None:
    """Append every number of a nested structure to ``out`` in a fixed order."""
    if isinstance(value, dict):
        for key in sorted((k for k in value if k not in WITHOUT), key=str):
            out.append(np.frombuffer(str(key).encode(), dtype=np.uint8))
            _numbers(value[key], out)
    elif isinstance(value, list | tuple):
        for item in value:
            _numbers(item, out)
    elif isinstance(value, torch.Tensor):
        out.append(value.detach().cpu().numpy().ravel())
    elif isinstance(value, np.ndarray):
        out.append(value.ravel())
    elif isinstance(value, str):
        out.append(np.frombuffer(value.encode(), dtype=np.uint8))
    elif isinstance(value, bool | int | float | np.number | np.bool_):
        out.append(np.asarray([value], dtype=np.float64))


def _hash(values: Iterable) -> str:
    h = hashlib.sha256()
    for value in values:
        arrays: list[np.ndarray] = []
        _numbers(value, arrays)
        for a in arrays:
            if a.dtype.kind in "biuf":
                a = a.astype(np.float64)
            h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def pettingzoo_faces() -> dict[str, str]:
    import vdtn_marl

    out = {}
    for env_id in vdtn_marl.list_envs(api="pettingzoo"):
        env = vdtn_marl.make(env_id, seed=SEED)
        clocks = vdtn_marl.spec(env_id).clocks or {}
        subframe_env = any(period == 1 for period in clocks.values())
        steps = STEPS_PER_SUBFRAME_ENV if subframe_env else STEPS_PER_INTERVAL_ENV
        obs, infos = env.reset(seed=SEED)
        record = [obs, infos]
        for agent in env.possible_agents:
            env.action_space(agent).seed(SEED)
        for _ in range(steps):
            if not env.agents:
                break
            actions = {a: env.action_space(a).sample() for a in env.agents}
            record.append(env.step(actions))
        out[f"pettingzoo/{env_id}"] = _hash(record)
    return out


def torchrl_faces() -> dict[str, str]:
    from vdtn_marl.envs.torchrl import MODES, VDTNTorchRLEnv

    out = {}
    for mode in MODES:
        torch.manual_seed(SEED)
        env = VDTNTorchRLEnv(mode, batch_size=4, seed=SEED)
        steps = STEPS_PER_SUBFRAME_ENV if env.has_rra else STEPS_PER_INTERVAL_ENV
        rollout = env.rollout(steps, break_when_any_done=False)
        out[f"torchrl/{mode}"] = _hash([rollout.to_dict()])
    return out


def evaluation() -> dict[str, str]:
    from vdtn_marl.algos.evaluate import evaluate_system
    from vdtn_marl.policies import make_rra_baseline
    from vdtn_marl.policies.cacc import CACCController
    from vdtn_marl.sim.params import TwinParams

    params = TwinParams.from_overrides(episode_intervals=40)
    cacc = CACCController(params.platoon)
    out = {}
    for rra in ("random", "greedy"):
        result = evaluate_system(
            params,
            cacc,
            make_rra_baseline(rra, params, SEED),
            perfect=False,
            episodes=3,
            intervals=40,
            seed=SEED,
            record_traces=True,
        )
        out[f"evaluate/cacc+{rra}"] = _hash([result.__dict__])
    return out


def smoke_jocc() -> dict[str, str]:
    import subprocess

    with tempfile.TemporaryDirectory() as tmp:
        run = Path(tmp) / "run"
        subprocess.run(
            [sys.executable, "-m", "vdtn_marl.cli", "jocc", "experiment=smoke", f"seed={SEED}",
             "progress=false", f"hydra.run.dir={run}"],
            check=True, capture_output=True,
        )  # fmt: skip
        summary = json.loads((run / "summary.json").read_text())
        rows = (run / "metrics.csv").read_text().splitlines()
    timing = ("seconds", "time", "created", "duration", "run_dir", "path", "version")
    # the echoed config is left out: a new config key is not a moved result
    metrics = {
        k: v for k, v in summary.items() if not any(t in k for t in timing + ("plots", "config"))
    }
    metrics = _drop_keys(metrics)
    header = rows[0].split(",")
    keep = [
        i
        for i, name in enumerate(header)
        if not any(t in name for t in timing) and name not in WITHOUT
    ]
    table = [[row.split(",")[i] for i in keep] for row in rows]
    return {"jocc/smoke": _hash([json.dumps(metrics, sort_keys=True, default=str), table])}


SECTIONS: dict[str, Callable[[], dict[str, str]]] = {
    "pettingzoo": pettingzoo_faces,
    "torchrl": torchrl_faces,
    "evaluate": evaluation,
    "jocc": smoke_jocc,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="write the fingerprints to this JSON file")
    parser.add_argument("--compare", type=Path, help="compare with fingerprints written before")
    parser.add_argument("--skip-jocc", action="store_true", help="leave out the smoke JOCC run")
    parser.add_argument(
        "--without",
        action="append",
        default=[],
        metavar="KEY",
        help="leave the dict entries named KEY out of every hash (repeatable)",
    )
    args = parser.parse_args(argv)
    WITHOUT.update(args.without)
    torch.set_num_threads(1)
    prints: dict[str, str] = {}
    for name, section in SECTIONS.items():
        if name == "jocc" and args.skip_jocc:
            continue
        prints.update(section())
    for key, value in prints.items():
        print(f"{value}  {key}")
    if args.out:
        args.out.write_text(json.dumps(prints, indent=1) + "\n")
    if args.compare:
        before = json.loads(args.compare.read_text())
        changed = [k for k in sorted(set(before) | set(prints)) if before.get(k) != prints.get(k)]
        for key in changed:
            print(f"DIFFERS  {key}: {before.get(key)} -> {prints.get(key)}")
        print(f"{len(prints) - len(changed)} of {len(prints)} fingerprints unchanged")
        return 1 if changed else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
