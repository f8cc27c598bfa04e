"""Run (or resume) a leaderboard benchmark and write its report: `vdtn-marl bench` as a script.

    python benchmarks/leaderboard.py benchmark=smoke                 # about a minute, CI
    python benchmarks/leaderboard.py benchmark=reduced report_dir=benchmarks/results
    python benchmarks/leaderboard.py benchmark=leaderboard           # hours on a CPU

Arguments are those of `vdtn-marl bench` (Hydra overrides and flags; `--help` lists them). The
grid runs cell by cell in `out_dir/<scenario>/<method>/seed<k>/` (default
`outputs/bench/<name>-v<version>`); rerunning the same command skips every finished cell. To
spread the cells over processes with a Hydra launcher, run shards as a sweep, then once more
without shards to write the report from all of them:

    OMP_NUM_THREADS=1 python benchmarks/leaderboard.py -m benchmark=leaderboard \
        shard=0,1 num_shards=2 hydra/launcher=joblib
    python benchmarks/leaderboard.py benchmark=leaderboard

See docs/leaderboard.md and the package vdtn_marl/leaderboard/.
"""

from __future__ import annotations

import sys

from vdtn_marl.cli import bench_main

if __name__ == "__main__":
    raise SystemExit(bench_main(sys.argv[1:]))
