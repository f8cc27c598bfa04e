#!/usr/bin/env bash
# The loggers' and the video's check: builds the environment of the extras tensorboard, wandb,
# mlflow and video (constraints-extras.txt: the pins of constraints.txt with importlib_metadata
# below 10 for mlflow, plus the loggers, imageio-ffmpeg and what they add) apart from the main
# one, and runs the tests of the loggers (tests/test_runs.py) and of the videos
# (tests/test_video.py) there. The main suite skips the tests of TensorBoard's, W&B's and
# MLflow's loggers and of the MP4 writer, as constraints.txt has none of these libraries; here
# the check fails if any test is skipped or one of those four did not pass.
#
#   bash scripts/extras_check.sh          the check
#   bash scripts/extras_check.sh setup    only build the environment (.ci/run builds it while the
#                                 main suite runs)
#
# .ci/run runs it after the main suite; docs/cli.md (Loggers) has its timing.
# Environment variables:
#   EXTRAS_VENV      where to build the environment (default: .venv-extras in the repository)
#   PYTHON           interpreter used to create it (default: python3)
#   TORCH_INDEX_URL  index to take torch from (as in scripts/dev.sh)
set -euo pipefail

ROOT="$(cd -P "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

VENV="${EXTRAS_VENV:-$ROOT/.venv-extras}"
PY="$VENV/bin/python"
CONSTRAINTS=constraints-extras.txt

say() { printf '[extras_check] %s\n' "$*" >&2; }
die() { printf '[extras_check] error: %s\n' "$*" >&2; exit 1; }

case "${1:-}" in
  "" | setup) ;;
  *) die "unknown argument '$1' (usage: bash scripts/extras_check.sh [setup])" ;;
esac

# shellcheck source=scripts/extra_venv.sh
source scripts/extra_venv.sh

SECONDS=0
extra_venv_setup "$VENV" "$CONSTRAINTS" test,tensorboard,wandb,mlflow,video
say "setup: ${SECONDS}s ($("$PY" -c 'import importlib.metadata as m
print(", ".join(f"{p} {m.version(p)}" for p in ("tensorboard", "wandb", "mlflow", "imageio-ffmpeg", "torch")))'))"
[[ "${1:-}" == setup ]] && exit 0

# The tests that the main suite skips for want of these libraries; each must pass here.
MUST_PASS=(
  tests/test_runs.py::test_tensorboard_events_hold_the_rows
  tests/test_runs.py::test_wandb_offline_writes_the_run_without_a_network
  tests/test_runs.py::test_mlflow_keeps_the_metric_history_in_the_runs_sqlite_store
  tests/test_video.py::test_an_mp4_holds_every_frame_padded_to_whole_blocks
)

LOG="$(mktemp)"
trap 'rm -f "$LOG"' EXIT
start=$SECONDS
say "tests of the loggers and the videos"
# -rsp: the summary names every skipped and every passed test
"$PY" -m pytest -q -rsp --color=no -p no:cacheprovider tests/test_runs.py tests/test_video.py 2>&1 |
  tee "$LOG" || die "tests failed"
say "tests: $((SECONDS - start))s"
if grep -q '^SKIPPED' "$LOG"; then
  die "skipped in the extras' environment: $(grep '^SKIPPED' "$LOG" | tr '\n' ' ')"
fi
for test in "${MUST_PASS[@]}"; do
  grep -qxF "PASSED $test" "$LOG" || die "$test did not pass"
done
say "the ${#MUST_PASS[@]} tests of the extras ran and passed, none skipped"
say "done in ${SECONDS}s"
