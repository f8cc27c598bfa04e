"""``python -m vdtn_marl.cli ARGS`` = ``vdtn-marl ARGS``."""

from vdtn_marl.cli import main

raise SystemExit(main())
