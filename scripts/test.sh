#!/usr/bin/env bash
# Run the whole test suite (installs first if needed). Extra arguments go to pytest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
export WM_PROJECT_DIR=${WM_PROJECT_DIR:-/usr/share/openfoam}
exec .venv/bin/python -m pytest -q -rs "$@"
