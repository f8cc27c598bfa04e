#!/usr/bin/env bash
# Developer entry point for vdtn-marl.
#
#   bash scripts/dev.sh setup          create .venv and install the pinned, tested versions
#   bash scripts/dev.sh run [ARGS]     setup, then vdtn-marl jocc ARGS (the default experiment)
#   bash scripts/dev.sh test [ARGS]    setup, then ruff check . and python -m pytest -q ARGS
#                                      on 2 worker processes (pytest-xdist, a file per worker)
#   bash scripts/dev.sh fast [ARGS]    the same without the tests marked slow (the loop while
#                                      editing: model and unit tests, a few minutes)
#   bash scripts/dev.sh bench [ARGS]   setup, then python benchmarks/throughput.py ARGS
#
# Works from any directory (it changes to the repository root) and needs only Python >= 3.10.
# Environment variables:
#   PYTHON           interpreter used to create .venv (default: python3)
#   TORCH_INDEX_URL  index to take torch from, e.g. https://download.pytorch.org/whl/cpu for a
#                    CPU-only build on Linux (default: pip's configured index)
#   TEST_WORKERS     pytest-xdist worker processes of test and fast (default 2; 0: the tests
#                    run in this process, one after another)
set -euo pipefail

ROOT="$(cd -P "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

VENV="$ROOT/.venv"
VENV_PY="$VENV/bin/python"
STAMP="$VENV/.vdtn-marl-setup.sha256"
export PIP_DISABLE_PIP_VERSION_CHECK=1

say() { printf '[dev.sh] %s\n' "$*" >&2; }
die() { printf '[dev.sh] error: %s\n' "$*" >&2; exit 1; }

usage() {
  cat >&2 <<'EOF'
usage: bash scripts/dev.sh COMMAND [ARGS...]

commands:
  setup    create .venv (if missing) and install torch, then the package with the pins
           in constraints.txt; a no-op when nothing changed since the last setup
  run      setup, then the default JOCC experiment: vdtn-marl jocc [OVERRIDES]
  test     setup, then ruff check . and python -m pytest -q [ARGS], on TEST_WORKERS (2)
           worker processes, each test file in one of them
  fast     setup, then ruff check . and python -m pytest -q -m "not slow" [ARGS]: the model
           and unit tests, without the subprocess, training and leaderboard runs
  bench    setup, then python benchmarks/throughput.py --out outputs/benchmarks/throughput.json
           [ARGS] (pass --out benchmarks/results/throughput.json to update the record)
EOF
}

# Hash of everything that decides what setup installs.
setup_hash() {
  "$VENV_PY" - <<'EOF'
import hashlib
import sys

h = hashlib.sha256(sys.version.encode())
for name in ("pyproject.toml", "constraints.txt"):
    with open(name, "rb") as f:
        h.update(name.encode() + b"\0" + f.read() + b"\0")
print(h.hexdigest())
EOF
}

# True when .venv has vdtn_marl installed from this checkout (find_spec runs no package code).
installed_here() {
  "$VENV_PY" - "$ROOT" <<'EOF' >/dev/null 2>&1
import importlib.util
import os
import sys

spec = importlib.util.find_spec("vdtn_marl")
root = os.path.realpath(sys.argv[1])
ok = spec is not None and spec.origin and os.path.realpath(spec.origin).startswith(root + os.sep)
sys.exit(0 if ok else 1)
EOF
}

cmd_setup() {
  [[ -f constraints.txt ]] || die "constraints.txt is missing in $ROOT"

  if [[ -d "$VENV" ]] && ! "$VENV_PY" -c 'pass' >/dev/null 2>&1; then
    say ".venv exists but its python does not run; recreating it"
    local py="${PYTHON:-python3}"
    "$py" -m venv --clear "$VENV" || die "could not recreate .venv with $py"
  elif [[ ! -x "$VENV_PY" ]]; then
    local py="${PYTHON:-python3}"
    command -v "$py" >/dev/null 2>&1 || die "$py not found; install Python >= 3.10 or set PYTHON"
    "$py" -c 'import sys; sys.exit(sys.version_info < (3, 10))' \
      || die "$py is $("$py" -V 2>&1); vdtn-marl needs Python >= 3.10 (set PYTHON=...)"
    say "creating .venv with $("$py" -V 2>&1)"
    "$py" -m venv "$VENV" || die "python -m venv failed (on Debian/Ubuntu: apt install python3-venv)"
  fi

  local want
  want="$(setup_hash)"
  if [[ -f "$STAMP" && "$(cat "$STAMP")" == "$want" ]] && installed_here; then
    return 0
  fi
  rm -f "$STAMP"

  local torch_pin
  torch_pin="$(grep -E '^torch==' constraints.txt | head -n 1 || true)"
  [[ -n "$torch_pin" ]] || die "constraints.txt has no torch==VERSION line"

  say "upgrading pip"
  "$VENV_PY" -m pip install --quiet --upgrade pip

  # torch first, alone: a resolve that may pick any torch can pull a multi-GB CUDA build.
  local torch_args=()
  if [[ -n "${TORCH_INDEX_URL:-}" ]]; then
    torch_args=(--index-url "$TORCH_INDEX_URL")
  fi
  say "installing $torch_pin (a large download the first time)"
  "$VENV_PY" -m pip install --quiet ${torch_args[@]+"${torch_args[@]}"} "$torch_pin"

  say "installing vdtn-marl (editable) with the test extras, pinned by constraints.txt"
  "$VENV_PY" -m pip install --quiet -c constraints.txt -e ".[test]"

  installed_here || die "vdtn_marl is not importable from $ROOT after installing"
  printf '%s\n' "$want" >"$STAMP"
  say "setup done: $("$VENV_PY" -c 'import torch; print("torch", torch.__version__)')"
}

# pytest-xdist's worker processes: TEST_WORKERS (default 2), a whole file per worker, so a
# module's fixtures (the leaderboard's smoke grid) are built once
xdist_args() {
  local n="${TEST_WORKERS:-2}"
  [[ "$n" =~ ^[0-9]+$ ]] || return 1
  if [[ "$n" == 0 ]]; then printf -- '-p no:xdist'; else printf -- '-n %s --dist loadfile' "$n"; fi
}
bad_workers() { die "TEST_WORKERS=${TEST_WORKERS:-} must be a whole number (0: no worker processes)"; }

if [[ $# -lt 1 ]]; then
  usage
  exit 2
fi
command="$1"
shift

case "$command" in
  setup)
    cmd_setup
    ;;
  run)
    cmd_setup
    exec "$VENV/bin/vdtn-marl" jocc "$@"
    ;;
  test)
    xdist="$(xdist_args)" || bad_workers
    cmd_setup
    say "ruff check ."
    "$VENV_PY" -m ruff check .
    say "pytest ($xdist)"
    # shellcheck disable=SC2086 # xdist holds several words
    exec "$VENV_PY" -m pytest -q $xdist "$@"
    ;;
  fast)
    xdist="$(xdist_args)" || bad_workers
    cmd_setup
    say "ruff check ."
    "$VENV_PY" -m ruff check .
    say "pytest -m 'not slow' ($xdist)"
    # shellcheck disable=SC2086 # xdist holds several words
    exec "$VENV_PY" -m pytest -q -m "not slow" $xdist "$@"
    ;;
  bench)
    cmd_setup
    # Writes under outputs/ so a checkout stays clean; a later --out in ARGS wins.
    exec "$VENV_PY" benchmarks/throughput.py --out outputs/benchmarks/throughput.json "$@"
    ;;
  -h | --help | help)
    usage
    ;;
  *)
    say "unknown command: $command"
    usage
    exit 2
    ;;
esac
