#!/usr/bin/env bash
# Create .venv and install drill-string-gym with its [rl,dev,video,scale,zoo] extras into it.
# Idempotent: the installs are skipped while .venv/.installed-<sha256 of pyproject.toml and the
# extras> exists and the three packages are importable from it. Works from any working
# directory. The scale extra (Ray, Optuna) is for the sweeps, the zoo extra (RL Baselines3 Zoo)
# for agents/zoo; their tests run in the default suite.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

if [[ ! -x .venv/bin/python ]]; then
    echo "setup: creating .venv" >&2
    python3 -m venv .venv
fi

extras="rl,dev,video,scale,zoo"
hash=$(.venv/bin/python -c \
    'import hashlib, sys; print(hashlib.sha256(open("pyproject.toml", "rb").read() + sys.argv[1].encode()).hexdigest())' \
    "${extras}")
stamp=".venv/.installed-${hash}"

installed() {
    # -I: the repository root (cwd) must not stand in for the installed packages.
    [[ -f "${stamp}" && -x .venv/bin/drill-gym ]] && .venv/bin/python -I -c '
import importlib.util, sys
sys.exit(any(importlib.util.find_spec(n) is None for n in ("drill_env", "baselines", "agents")))
' 2>/dev/null
}

if ! installed; then
    echo "setup: installing into .venv (first run, pyproject.toml changed or install incomplete)" >&2
    pip=(.venv/bin/python -m pip -qq --disable-pip-version-check --no-input)
    "${pip[@]}" install --upgrade pip
    # torch first, pinned: this version is a local CPU wheel here; any other torch request
    # would download a multi-GB CUDA build. The [rl] extra's range is then already satisfied.
    "${pip[@]}" install "torch==2.13.0"
    "${pip[@]}" install -e ".[${extras}]"
    rm -f .venv/.installed-*
    touch "${stamp}"
fi
.venv/bin/python -m drill_env.precompile  # compile the envs into numba's cache now, not at first use
