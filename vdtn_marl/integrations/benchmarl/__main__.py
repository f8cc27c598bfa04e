"""BenchMARL's ``benchmarl/run.py`` with the vdtn-marl tasks registered:

    python -m vdtn_marl.integrations.benchmarl algorithm=mappo task=vdtn/control
    python -m vdtn_marl.integrations.benchmarl -m algorithm=mappo,ippo task=vdtn/rra seed=0,1

Every override of BenchMARL's own command line works (``experiment.max_n_iters=...``,
``model=...``, ``hydra/launcher=...``); configs come from BenchMARL's ``conf/`` and, for the
``vdtn`` tasks, from this package (docs/integrations.md).
"""

from vdtn_marl.integrations.benchmarl import run

if __name__ == "__main__":
    run()
