"""``python -m vdtn_marl.leaderboard ARGS`` = ``vdtn-marl bench ARGS``."""

from vdtn_marl.leaderboard import main

raise SystemExit(main())
