"""``python -m vdtn_marl.cli ARGS`` = ``vdtn-marl ARGS``."""

from vdtn_marl.cli.app import main

raise SystemExit(main())
