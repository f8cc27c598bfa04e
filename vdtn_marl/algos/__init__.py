"""Learning algorithms: MAPPO/IPPO from TorchRL parts (:mod:`.ppo`, :mod:`.networks`, their
hyper-parameters in :mod:`.params`) behind the trainer protocol (:mod:`.trainer`), imitation,
the value fit, evaluation and checkpoints. The non-learned baselines are in
:mod:`vdtn_marl.policies`; the JOCC loop that runs them all, and the entry points for the CLI
and for scripts, are in :mod:`vdtn_marl.experiment`.
"""
