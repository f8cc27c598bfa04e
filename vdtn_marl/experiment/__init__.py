"""Experiments: composing and validating a job's config (:mod:`.compose`), the JOCC loop that
trains, evaluates and checkpoints a run (:mod:`.jocc`), the entry points of the CLI and of
scripts (:mod:`.api`), the files a run writes besides logs and checkpoints (:mod:`.outputs`)
and the metrics a run reports (:mod:`.metrics`). The layer above the trainers and below the
leaderboard and the command line."""
