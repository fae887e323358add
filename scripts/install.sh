#!/usr/bin/env bash
# Install everything this project needs on a fresh Debian bookworm machine, as root.
# Idempotent: a second run only checks. Used by scripts/demo.sh and scripts/test.sh.
set -euo pipefail
cd "$(dirname "$0")/.."

need_apt=()
command -v simpleFoam >/dev/null 2>&1 || need_apt+=(openfoam)
command -v slurmctld >/dev/null 2>&1 || need_apt+=(slurm-wlm)
command -v munged >/dev/null 2>&1 || need_apt+=(munge)
# off-screen rendering for pyvista/VTK figures
[ -e /usr/lib/x86_64-linux-gnu/libGL.so.1 ] || [ -e /usr/lib/aarch64-linux-gnu/libGL.so.1 ] || need_apt+=(libgl1)
dpkg -s libxrender1 >/dev/null 2>&1 || need_apt+=(libxrender1)
dpkg -s xvfb >/dev/null 2>&1 || need_apt+=(xvfb)
# headless browser: the workflow test opens the Snakemake report as a person would (screenshot, DOM)
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
# a Python >= 3.11 with venv/ensurepip (Debian splits them into python3-venv)
PY=${PYTHON:-python3}
command -v "$PY" >/dev/null 2>&1 || need_apt+=(python3)
"$PY" -c "import ensurepip, venv" >/dev/null 2>&1 || need_apt+=(python3-venv)
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "[install] apt-get install ${need_apt[*]}"
  apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null
fi

"$PY" -c "import sys; sys.exit(sys.version_info < (3, 11))" || {
  echo "[install] error: $PY is $("$PY" --version 2>&1); Python >= 3.11 is needed (set PYTHON=...)" >&2; exit 2; }
if [ ! -x .venv/bin/python ]; then
  echo "[install] creating .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.installed-$(sha256sum pyproject.toml | cut -c1-16)
if [ ! -f "$stamp" ]; then
  echo "[install] pip install -e .[test,docs] (pinned)"
  .venv/bin/python -m pip install -q --upgrade pip >/dev/null 2>&1 || true
  # the build backend's warnings go to the log; shown in full when the install fails
  if ! .venv/bin/python -m pip install -q -e '.[test,docs]' > .venv/pip-install.log 2>&1; then
    cat .venv/pip-install.log >&2
    echo "[install] error: pip install failed (log above, also in .venv/pip-install.log)" >&2
    exit 1
  fi
  touch "$stamp"
fi
# OpenFOAM's headers and wmake (Debian's source package, in /opt/vcs-openfoam-dev) and the
# project's boundary conditions compiled against the installed OpenFOAM: the Windkessel outlet
# (templates/openfoam/lib/vcsWindkessel -> /opt/vcs-openfoam-dev/lib/libvcsWindkessel.so; rebuilt
# only when its sources change)
# (no Debian openfoam package, e.g. a sourced openfoam.org build: setup says so and the build is
# left to the user, see docs/guide/lumen.md; rcr outlets then say the library is missing)
bash scripts/openfoam_dev.sh setup
if [ -f "${VCS_OPENFOAM_DEV:-/opt/vcs-openfoam-dev}/env.sh" ]; then
  bash scripts/openfoam_dev.sh build templates/openfoam/lib/vcsWindkessel >/dev/null
fi
echo "[install] OK: $(.venv/bin/python --version), OpenFOAM $(dpkg-query -W -f='${Version}' openfoam 2>/dev/null || echo '?')"
