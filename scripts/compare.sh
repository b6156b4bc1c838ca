#!/usr/bin/env bash
# Main job: the controller comparison (metrics table + plots in results/).
# Arguments are passed on to `drill-gym compare`; it runs from the repository root.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

# 2-core machines: BLAS/OpenMP thread pools fight numba's threads.
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1
unset NUMBA_CACHE_DIR

bash scripts/setup.sh  # the core install: the comparison needs no extra
exec .venv/bin/drill-gym compare "$@"
