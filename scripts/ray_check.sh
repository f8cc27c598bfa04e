#!/usr/bin/env bash
# The Ray check: builds the environment of the `ray` extra (constraints-ray.txt: the pins of
# constraints.txt plus ray[default] and what it adds) apart from the main one, installs the
# Hydra plugin hydra-ray-launcher without its AWS-only dependencies, checks that none of
# constraints.txt's pins moved, and runs a two-job `vdtn-marl -m jocc experiment=smoke` sweep on
# a local Ray instance there (tests/test_cli.py::test_ray_sweep_two_jobs_real).
#
#   bash scripts/ray_check.sh          the check
#   bash scripts/ray_check.sh setup    only build the environment (.ci/run builds it while the
#                                 main suite runs)
#
# .ci/run runs it after the main suite. Environment variables:
#   RAY_VENV         where to build the environment (default: .venv-ray in the repository)
#   PYTHON           interpreter used to create it (default: python3)
#   TORCH_INDEX_URL  index to take torch from (as in scripts/dev.sh)
set -euo pipefail

ROOT="$(cd -P "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

VENV="${RAY_VENV:-$ROOT/.venv-ray}"
PY="$VENV/bin/python"
CONSTRAINTS=constraints-ray.txt

say() { printf '[ray_check] %s\n' "$*" >&2; }
die() { printf '[ray_check] error: %s\n' "$*" >&2; exit 1; }

case "${1:-}" in
  "" | setup) ;;
  *) die "unknown argument '$1' (usage: bash scripts/ray_check.sh [setup])" ;;
esac

# shellcheck source=scripts/extra_venv.sh
source scripts/extra_venv.sh

SECONDS=0
# hydra-ray-launcher 1.2.2 requires boto3 and cloudpickle<3, which only its AWS launcher
# imports; resolved with its dependencies it would downgrade cloudpickle (docs/cli.md, Ray).
extra_venv_setup "$VENV" "$CONSTRAINTS" test,ray hydra-ray-launcher
say "setup: ${SECONDS}s ($("$PY" -c 'import importlib.metadata as m
print(", ".join(f"{p} {m.version(p)}" for p in ("ray", "hydra-ray-launcher", "torch")))'))"
[[ "${1:-}" == setup ]] && exit 0

# The tested set of the main environment stays as it is beside Ray.
"$PY" - constraints.txt <<'EOF' || die "the Ray environment moved pins of constraints.txt"
import importlib.metadata as metadata
import re
import sys

moved = []
for line in open(sys.argv[1]):
    pin = re.match(r"^([A-Za-z0-9_.-]+)==([^\s;#]+)", line)
    if pin:
        name, want = pin.groups()
        have = metadata.version(name).split("+")[0]
        if have != want:
            moved.append(f"{name} {have} (constraints.txt: {want})")
if moved:
    print("[ray_check] moved: " + "; ".join(moved), file=sys.stderr)
    sys.exit(1)
EOF

# `pip check` reports the two requirements of the plugin's AWS launcher that the --no-deps
# step leaves unmet (docs/cli.md, Ray, quotes these lines) and nothing else.
EXPECTED_PIP_CHECK=(
  "hydra-ray-launcher 1.2.2 requires boto3, which is not installed."
  "hydra-ray-launcher 1.2.2 has requirement cloudpickle<3, but you have cloudpickle 3.1.2."
)
pip_report="$("$PY" -m pip check 2>&1 || true)"
unexpected="$(grep -vxF -f <(printf '%s\n' "${EXPECTED_PIP_CHECK[@]}") <<<"$pip_report" | grep -vx -e '' -e 'No broken requirements found.' || true)"
[[ -z "$unexpected" ]] || die "pip check reports more than the plugin's AWS requirements: $unexpected"

# The plugin imports (the test below would be skipped if it did not).
"$PY" -c 'import hydra_plugins.hydra_ray_launcher.ray_launcher' || die "the Ray plugin does not import"

start=$SECONDS
say "a two-job sweep on a local Ray instance"
"$PY" -m pytest -q -p no:cacheprovider tests/test_cli.py::test_ray_sweep_two_jobs_real
say "tests: $((SECONDS - start))s"
say "done in ${SECONDS}s"
