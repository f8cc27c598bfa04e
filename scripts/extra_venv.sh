# Sourced by scripts/benchmarl_check.sh, scripts/ray_check.sh and scripts/extras_check.sh:
# builds the environment of an optional extra apart from the main .venv, with its own
# constraints file, as the README's installation does for the main one (torch first, on its
# own, then the package pinned).
#
#   extra_venv_setup VENV CONSTRAINTS EXTRAS [NO_DEPS_PACKAGE ...]
#
# installs torch (the CONSTRAINTS pin), then `-e ".[EXTRAS]"` pinned by CONSTRAINTS, then each
# NO_DEPS_PACKAGE with --no-deps (its version from CONSTRAINTS). Skipped when VENV was built from
# the same pyproject.toml and CONSTRAINTS. Needs `say` and `die` from the caller.
# Environment variables: PYTHON (interpreter that creates VENV, default python3),
# TORCH_INDEX_URL (index to take torch from, as in scripts/dev.sh).

extra_venv_setup() {
  local venv="$1" constraints="$2" extras="$3"
  shift 3
  local py="$venv/bin/python" stamp="$venv/.vdtn-marl-extra.sha256"
  [[ -f "$constraints" ]] || die "$constraints is missing"
  if [[ ! -x "$py" ]]; then
    local base="${PYTHON:-python3}"
    command -v "$base" >/dev/null 2>&1 || die "$base not found; set PYTHON"
    say "creating $venv with $("$base" -V 2>&1)"
    "$base" -m venv "$venv"
  fi
  local want
  want="$(printf '%s\n' "$extras" "$@" | cat - pyproject.toml "$constraints" | "$py" -c \
    'import hashlib, sys; print(hashlib.sha256(sys.version.encode() + sys.stdin.buffer.read()).hexdigest())')"
  if [[ -f "$stamp" && "$(cat "$stamp")" == "$want" ]]; then
    return 0
  fi
  rm -f "$stamp"
  local torch_pin
  torch_pin="$(grep -E '^torch==' "$constraints" | head -n 1)"
  [[ -n "$torch_pin" ]] || die "$constraints has no torch==VERSION line"
  local torch_args=()
  [[ -n "${TORCH_INDEX_URL:-}" ]] && torch_args=(--index-url "$TORCH_INDEX_URL")
  export PIP_DISABLE_PIP_VERSION_CHECK=1
  "$py" -m pip install --quiet --upgrade pip
  # torch first, alone, so that nothing later can pull a CUDA build (see README, Installation)
  say "installing $torch_pin"
  "$py" -m pip install --quiet ${torch_args[@]+"${torch_args[@]}"} "$torch_pin"
  say "installing vdtn-marl with the extras [$extras], pinned by $constraints"
  "$py" -m pip install --quiet -c "$constraints" -e ".[$extras]"
  if [[ $# -gt 0 ]]; then
    say "installing $* without their dependencies, pinned by $constraints"
    "$py" -m pip install --quiet --no-deps -c "$constraints" "$@"
  fi
  printf '%s\n' "$want" >"$stamp"
}
