#!/usr/bin/env bash
# Run the whole test suite (installs first if needed): lint (ruff), format check (ruff format),
# type check of the package (mypy), the documentation built with warnings as errors and the
# docstring examples, then pytest. Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
export WM_PROJECT_DIR=${WM_PROJECT_DIR:-/usr/share/openfoam}
# one BLAS thread per process: reproducible sums, and no oversubscription next to OpenFOAM ranks
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
code=(vcs tests bench scripts workflow/scripts setup.py)
# modules whose docstrings hold runnable examples (numpydoc "Examples" sections)
doctest_modules=(vcs/grid.py vcs/model.py vcs/vessel.py vcs/phantoms/factory.py vcs/atlas/pca.py vcs/atlas/cohort.py
  vcs/cfd/markers.py vcs/cfd/verification.py vcs/cfd/utilities.py)
echo "[test] ruff check + ruff format --check"
.venv/bin/ruff check --quiet "${code[@]}"
.venv/bin/ruff format --check --quiet "${code[@]}"
echo "[test] mypy vcs"
.venv/bin/mypy vcs
echo "[test] docs: sphinx-build -W (warnings are errors: broken cross-references and links fail) + docstring examples"
.venv/bin/sphinx-build -E -W --keep-going -q -b html docs docs/_build/html
.venv/bin/python -m pytest -q -p no:cacheprovider --doctest-modules "${doctest_modules[@]}"
exec .venv/bin/python -m pytest -q -rs "$@"
