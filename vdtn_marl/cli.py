"""Command-line interface: ``vdtn-marl envs`` and ``vdtn-marl rollout [args]``."""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import textwrap
from collections.abc import Sequence

from vdtn_marl import __version__
from vdtn_marl.registry import EnvSpec, list_envs, spec

_COLUMNS = ("id", "agents", "clocks", "description", "data source")
_WRAP = {"agents": 34, "description": 44, "data source": 30}


def _format_clocks(clocks: dict[str, int]) -> str:
    return ", ".join(f"{kind}={period}ms" for kind, period in clocks.items()) or "-"


def _row(env: EnvSpec) -> dict[str, str]:
    return {
        "id": env.id,
        "agents": env.agents or "-",
        "clocks": _format_clocks(env.clocks),
        "description": env.description or "-",
        "data source": env.data_source or "-",
    }


def format_env_table(specs: Sequence[EnvSpec]) -> str:
    """Plain-text table of the given specs; ids are never wrapped."""
    rows = [_row(s) for s in specs]
    cells = [
        {c: (textwrap.wrap(r[c], _WRAP[c]) if c in _WRAP else [r[c]]) or [""] for c in _COLUMNS}
        for r in rows
    ]
    widths = {
        c: max([len(c)] + [len(line) for cell in cells for line in cell[c]]) for c in _COLUMNS
    }

    def line(values: dict[str, str]) -> str:
        return "  ".join(values[c].ljust(widths[c]) for c in _COLUMNS).rstrip()

    out = [line({c: c for c in _COLUMNS}), line({c: "-" * widths[c] for c in _COLUMNS})]
    for cell in cells:
        height = max(len(v) for v in cell.values())
        for i in range(height):
            out.append(line({c: cell[c][i] if i < len(cell[c]) else "" for c in _COLUMNS}))
    return "\n".join(out)


def _cmd_envs(args: argparse.Namespace) -> int:
    specs = [spec(env_id) for env_id in list_envs()]
    if args.json:
        payload = [
            {
                **{k: v for k, v in _row(s).items() if k != "clocks"},
                "clocks": s.clocks,
                "kwargs": s.kwargs,
                "entry_point": s.entry_point
                if isinstance(s.entry_point, str)
                else f"{s.entry_point.__module__}:{s.entry_point.__qualname__}",
            }
            for s in specs
        ]
        print(json.dumps(payload, indent=2, default=repr))
    else:
        print(format_env_table(specs))
    return 0


def _cmd_rollout(rest: list[str]) -> int:
    try:
        rollout = importlib.import_module("vdtn_marl.rollout")
    except ModuleNotFoundError as exc:
        if exc.name != "vdtn_marl.rollout":
            raise
        print("vdtn-marl: the rollout module (vdtn_marl.rollout) is not available", file=sys.stderr)
        return 1
    rc = rollout.main(rest)
    return rc if isinstance(rc, int) else 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="vdtn-marl",
        description="Vehicular Digital Twin Network multi-agent RL benchmark.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    envs = sub.add_parser("envs", help="list the registered environments")
    envs.add_argument("--json", action="store_true", help="print the specs as JSON")
    sub.add_parser(
        "rollout",
        help="run a rollout (all further arguments go to vdtn_marl.rollout)",
        add_help=False,
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args_list = list(sys.argv[1:] if argv is None else argv)
    # `rollout` forwards everything after it untouched (including --help and its own options).
    if args_list and args_list[0] == "rollout":
        return _cmd_rollout(args_list[1:])
    parser = build_parser()
    args = parser.parse_args(args_list)
    if args.command == "envs":
        try:
            return _cmd_envs(args)
        except BrokenPipeError:  # e.g. `vdtn-marl envs | head`
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 0
    parser.print_usage(sys.stderr)
    parser.exit(2, f"{parser.prog}: error: a command is required (envs, rollout)\n")
    return 2  # unreachable


if __name__ == "__main__":
    raise SystemExit(main())
