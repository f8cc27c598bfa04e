"""Learning algorithms: MAPPO/IPPO from TorchRL parts, VoI-aware RRA, the JOCC loop, baselines.

Entry points for the CLI and for scripts are in :mod:`vdtn_marl.algos.api`.
"""
