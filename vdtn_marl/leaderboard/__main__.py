"""``python -m vdtn_marl.leaderboard ARGS`` = ``vdtn-marl bench ARGS`` (an entry script: no
module imports it, so the leaderboard itself never imports the command line)."""

from vdtn_marl.cli import bench_main

raise SystemExit(bench_main())
