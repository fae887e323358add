#!/usr/bin/env bash
# Install everything (scripts/install.sh), then run the demo: 8 synthetic aortas (seeds 0..7)
# -> VCS fits -> Eq. 8 wall STLs -> OpenFOAM (snappyHexMesh + simpleFoam) -> resampled fields
# -> atlas, with the local profile and config/config.yaml, then the Snakemake HTML report.
# Extra arguments go to snakemake, e.g.  bash scripts/demo.sh --configfile config/ci.yaml
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install.sh
export WM_PROJECT_DIR=${WM_PROJECT_DIR:-/usr/share/openfoam}
# one BLAS thread per process: reproducible sums, and no oversubscription next to OpenFOAM ranks
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1} OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
# config/config.yaml is the Snakefile's configfile; a --configfile in "$@" is merged over it
smk=(.venv/bin/snakemake --profile profiles/local "$@")

rc=0
"${smk[@]}" || rc=$?
if [ -f results/atlas/atlas.json ]; then
  "${smk[@]}" --report results/report.html || echo "[demo] snakemake --report failed (see above)" >&2
fi
echo
echo "[demo] per patient:  results/patients/<id>/ (fit/, wall/, case/, status.json, fields.npz, qc.png: the QC sheet)"
echo "[demo] atlas:        $(pwd)/results/atlas/atlas.json (figures: results/atlas/figures/, cohort table: results/atlas/patients.html)"
[ -f results/report.html ] && echo "[demo] report:       $(pwd)/results/report.html"
echo "[demo] provenance:   $(pwd)/results/provenance.json"
if [ -f results/atlas/atlas.json ]; then
  .venv/bin/python - <<'PY'
import json
a = json.load(open("results/atlas/atlas.json"))
print(f"[demo] included {len(a['patients_included'])} patients; excluded {len(a['patients_excluded'])}")
for e in a["patients_excluded"]:
    print(f"[demo]   excluded {e['id']}: {e['reason']}")
PY
fi
exit $rc
