"""Hydra config tree; installed as the package ``vdtn_marl.conf`` (see pyproject.toml)."""
