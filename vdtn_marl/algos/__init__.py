"""Learning algorithms: MAPPO/IPPO from TorchRL parts (:mod:`.ppo`, :mod:`.networks`, their
hyper-parameters in :mod:`.params`), imitation, the value fit, evaluation, checkpoints and the
baselines. The JOCC loop that runs them, and the entry points for the CLI and for scripts, are
in :mod:`vdtn_marl.experiment`.
"""
