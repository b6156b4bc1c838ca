#!/usr/bin/env bash
# The whole test suite: ruff (lint and format), mypy, then pytest without the slow tests.
# Arguments are passed on to pytest (a later `-m slow` overrides the default `-m "not slow"`).
# pytest runs on every core, at most four (pytest-xdist; `-n 0` after it: one process).
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# 2-core machines: BLAS/OpenMP thread pools fight numba's threads.
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
unset NUMBA_CACHE_DIR

bash scripts/setup.sh rl,dev,video,scale,zoo  # the extras the tests import

echo "== ruff check"
.venv/bin/ruff check .
echo "== ruff format --check"
.venv/bin/ruff format --check .
echo "== mypy"
.venv/bin/mypy
echo "== pytest"
.venv/bin/python -m pytest -m "not slow" -q -n auto --maxprocesses 4 "$@"
