#!/usr/bin/env bash
# Run the whole test suite (installs first if needed): lint (ruff), format check (ruff format),
# type check of the package (mypy), then pytest. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
export WM_PROJECT_DIR=${WM_PROJECT_DIR:-/usr/share/openfoam}
# one BLAS thread per process: reproducible sums, and no oversubscription next to OpenFOAM ranks
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
code=(vcs tests bench scripts workflow/scripts setup.py)
echo "[test] ruff check + ruff format --check"
.venv/bin/ruff check --quiet "${code[@]}"
.venv/bin/ruff format --check --quiet "${code[@]}"
echo "[test] mypy vcs"
.venv/bin/mypy vcs
exec .venv/bin/python -m pytest -q -rs "$@"
