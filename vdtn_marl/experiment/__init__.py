"""Experiments: composing and validating a job's config (:mod:`.compose`) and the metrics a
run reports (:mod:`.metrics`). The layer above the trainers and below the leaderboard and the
command line."""
