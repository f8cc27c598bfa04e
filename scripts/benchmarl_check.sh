#!/usr/bin/env bash
# The BenchMARL check: builds the environment of the `benchmarl` extra (constraints-benchmarl.txt,
# torchrl 0.11 / tensordict 0.11 under BenchMARL 1.5.2) apart from the main one, runs the tests
# of vdtn_marl.integrations.benchmarl there, and trains BenchMARL's MAPPO (on vdtn/control) and
# QMIX (on vdtn/rra) for one iteration each through BenchMARL's own command line.
#
#   bash scripts/benchmarl_check.sh          the check (a few minutes; setup once more)
#   bash scripts/benchmarl_check.sh full     the same, then the whole test suite on that stack
#   bash scripts/benchmarl_check.sh setup    only build the environment (.ci/run builds it
#                                            while the main suite runs)
#
# .ci/run runs the check (not `full`) after the main suite; docs/integrations.md has its timing.
# Run `full` when the integration, the environments' TorchRL face or the pins change.
#
# Environment variables:
#   BENCHMARL_VENV   where to build the environment (default: .venv-benchmarl in the repository)
#   PYTHON           interpreter used to create it (default: python3)
#   TORCH_INDEX_URL  index to take torch from (as in scripts/dev.sh)
set -euo pipefail

ROOT="$(cd -P "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

VENV="${BENCHMARL_VENV:-$ROOT/.venv-benchmarl}"
PY="$VENV/bin/python"
CONSTRAINTS=constraints-benchmarl.txt

say() { printf '[benchmarl_check] %s\n' "$*" >&2; }
die() { printf '[benchmarl_check] error: %s\n' "$*" >&2; exit 1; }

case "${1:-}" in
  "" | full | setup) ;;
  *) die "unknown argument '$1' (usage: bash scripts/benchmarl_check.sh [full|setup])" ;;
esac

# shellcheck source=scripts/extra_venv.sh
source scripts/extra_venv.sh

SECONDS=0
extra_venv_setup "$VENV" "$CONSTRAINTS" test,benchmarl
say "setup: ${SECONDS}s ($("$PY" -c 'import benchmarl, torchrl, tensordict, torch
print("benchmarl", benchmarl.__version__, "torchrl", torchrl.__version__,
      "tensordict", tensordict.__version__, "torch", torch.__version__)'))"
[[ "${1:-}" == setup ]] && exit 0

start=$SECONDS
say "tests of the integration"
"$PY" -m pytest -q -p no:cacheprovider tests/integrations
say "tests: $((SECONDS - start))s"

# One iteration of each algorithm, small batches: plumbing, not learning.
WORK="$(mktemp -d)"
trap 'rm -rf "$WORK"' EXIT
COMMON=(
  experiment.max_n_iters=1 "experiment.loggers=[csv]" experiment.render=false
  experiment.evaluation_episodes=2 experiment.evaluation_interval=200
)
train() {  # algorithm task overrides...
  local start=$SECONDS
  (cd "$WORK" && "$PY" -m vdtn_marl.integrations benchmarl "algorithm=$1" "task=$2" \
    "hydra.run.dir=$WORK/$1" "${COMMON[@]}" "${@:3}" >"$WORK/$1.log" 2>&1) || { tail -n 40 "$WORK/$1.log" >&2; die "$1 on $2 failed"; }
  local frames
  frames="$(find "$WORK/$1" -name counters_total_frames.csv -exec tail -n 1 {} \; | cut -d, -f2)"
  [[ -n "$frames" ]] || die "$1 on $2 wrote no counters_total_frames.csv"
  say "$1 on $2: one iteration, ${frames%.*} frames, $((SECONDS - start))s"
}
train mappo vdtn/control task.max_cycles=20 \
  experiment.on_policy_collected_frames_per_batch=200 experiment.on_policy_n_envs_per_worker=4 \
  experiment.on_policy_n_minibatch_iters=1 experiment.on_policy_minibatch_size=100
train qmix vdtn/rra task.episode_intervals=2 \
  experiment.off_policy_collected_frames_per_batch=200 experiment.off_policy_n_envs_per_worker=4 \
  experiment.off_policy_n_optimizer_steps=2 experiment.off_policy_train_batch_size=32

if [[ "${1:-}" == full ]]; then
  start=$SECONDS
  say "the whole test suite on the BenchMARL stack"
  "$PY" -m pytest -q -p no:cacheprovider
  say "suite: $((SECONDS - start))s"
fi
say "done in ${SECONDS}s"
