#!/usr/bin/env bash
# Create .venv and install drill-string-gym into it with the extras named in $1 (comma-separated;
# none: the core install, numpy + numba + gymnasium + matplotlib, enough for `drill-gym compare`,
# `map`, `evaluate` of the shipped models and every example).
#   bash scripts/setup.sh                          # core (scripts/compare.sh)
#   bash scripts/setup.sh rl,dev,video,scale,zoo   # what the test suite imports (scripts/test.sh)
# Idempotent, per set of extras: the installs are skipped while
# .venv/.installed-<extras>-<sha256 of pyproject.toml and the extras> exists and the three
# packages are importable from it. Works from any working directory.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

extras="${1:-}"
label="${extras:-core}"

if [[ ! -x .venv/bin/python ]]; then
    echo "setup: creating .venv" >&2
    python3 -m venv .venv
fi

hash=$(.venv/bin/python -c \
    'import hashlib, sys; print(hashlib.sha256(open("pyproject.toml", "rb").read() + sys.argv[1].encode()).hexdigest())' \
    "${extras}")
stamp=".venv/.installed-${label}-${hash}"

installed() {
    # -I: the repository root (cwd) must not stand in for the installed packages.
    [[ -f "${stamp}" && -x .venv/bin/drill-gym ]] && .venv/bin/python -I -c '
import importlib.util, sys
sys.exit(any(importlib.util.find_spec(n) is None for n in ("drill_env", "baselines", "agents")))
' 2>/dev/null
}

if ! installed; then
    echo "setup: installing drill-string-gym${extras:+[${extras}]} into .venv" \
        "(first run, pyproject.toml changed or install incomplete)" >&2
    pip=(.venv/bin/python -m pip -qq --disable-pip-version-check --no-input)
    "${pip[@]}" install --upgrade pip
    if [[ ",${extras}," == *",rl,"* || ",${extras}," == *",zoo,"* ]]; then  # both bring torch
        # torch first, pinned so that pip picks a CPU build: where pip's find-links offer the
        # wheel 2.13.0+cpu it takes that one instead of a multi-GB CUDA build from PyPI. Without
        # such a wheel, install the CPU build first yourself:
        #   .venv/bin/python -m pip install torch --index-url https://download.pytorch.org/whl/cpu
        # The [rl] extra's torch range is then already satisfied.
        "${pip[@]}" install "torch==2.13.0"
    fi
    "${pip[@]}" install -e ".${extras:+[${extras}]}"
    rm -f ".venv/.installed-${label}-"*
    touch "${stamp}"
fi
.venv/bin/python -m drill_env.precompile  # compile the envs into numba's cache now, not at first use
