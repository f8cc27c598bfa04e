"""Run another library's command line with vdtn-marl's integration registered:

    python -m vdtn_marl.integrations benchmarl algorithm=mappo task=vdtn/control
    python -m vdtn_marl.integrations benchmarl -m algorithm=mappo,ippo task=vdtn/rra seed=0,1

``benchmarl`` is BenchMARL's ``benchmarl/run.py`` (its Hydra app, every override of its own
command line) with the ``vdtn`` tasks registered (docs/integrations.md). A missing library is
one line naming the extra to install.
"""

import sys

from vdtn_marl.errors import MissingExtraError

USAGE = "usage: python -m vdtn_marl.integrations benchmarl [BENCHMARL ARGS ...]"


def main(argv: list[str]) -> int:
    if not argv or argv[0] != "benchmarl":
        print(USAGE, file=sys.stderr)
        return 2
    try:
        from vdtn_marl.integrations.benchmarl import run
    except MissingExtraError as exc:
        print(f"python -m vdtn_marl.integrations benchmarl: {exc}", file=sys.stderr)
        return 1
    sys.argv = [f"{sys.argv[0]} benchmarl", *argv[1:]]  # what BenchMARL's Hydra app parses
    run()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
