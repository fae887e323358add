#!/usr/bin/env python3
"""Issue 22, item 5: which stage does each patient end in? Every shared real mesh (the seven
surfaces of ../shared/data/vessels) and the synthetic long/bumpy aortas of the tests
(tests/vcs/test_fit_quality.py: two 400-450 mm aortas in mm and cm, and a 420 mm marching-cubes
aorta with three supra-aortic branches) through the whole workflow with the default
config/config.yaml, then one row per patient: the stage reached (in the atlas, or the stage it
was excluded at and why), its fit quality, the wall check, cells and the CFD verdict.

    .venv/bin/python bench/stage_survey.py [-d DIR] [--cores 2] [--json PATH]

DIR (default: a temporary folder) is the Snakemake working directory; a finished DIR is only
re-read. The sheet is config/real_patients.tsv (AortaCFD patient1 at its 1.0 mm cell size there,
the others auto) plus the two shared meshes it leaves out and the synthetic aortas, whose STL
files are written into DIR/meshes. ``--json PATH`` also writes the table in the docs' format
(docs/data/bench/stage_survey.json).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
sys.path.insert(0, str(REPO / "tests" / "vcs"))
from _table import emit  # noqa: E402
from real_cohort import real_rows, run_workflow, write_rows  # noqa: E402

DATA = REPO.parent / "shared" / "data" / "vessels"
EXTRA = [  # the two shared meshes config/real_patients.tsv leaves out (ends as tests/vcs/test_real_vessels.py)
    {"id": "simvascular_open", "mesh": str(DATA / "simvascular_aorta_segment_open.vtp"), "units": "cm"},
    {
        "id": "vmtk_bifurcation",
        "mesh": str(DATA / "vmtk_aorta_bifurcation_open.stl"),
        "units": "mm",
        "inlet": "221,177.8,21.3",
        "outlet": "210.2,102.9,30.8",
    },
]


def synthetic(meshes: Path) -> list[dict]:
    """The long/bumpy aortas of tests/vcs/test_fit_quality.py as STL files (units detected)."""
    from test_fit_quality import long_aorta, segmented_aorta

    from vcs.mesh import write_stl_binary

    meshes.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed, length, unit in ((3, 450.0, "mm"), (4, 400.0, "cm")):
        V, F, _ = long_aorta(seed, length)
        path = meshes / f"long_aorta_{seed}_{unit}.stl"
        write_stl_binary(path, V / {"mm": 1.0, "cm": 10.0}[unit], F)
        rows.append({"id": f"long_aorta_{seed}", "mesh": str(path), "units": "auto"})
    V, F, _ = segmented_aorta(0, 420.0)
    path = meshes / "segmented_aorta_0_cm.stl"
    write_stl_binary(path, V / 10.0, F)
    rows.append({"id": "segmented_aorta_0", "mesh": str(path), "units": "auto"})
    return rows


def write_sheet(wd: Path) -> list[str]:
    return write_rows(wd / "patients.tsv", real_rows() + EXTRA + synthetic(wd / "meshes"))


#: the table's columns (as printed and in the docs JSON)
COLUMNS = ["patient", "stage reached", "fit quality", "Eq. 8 wall", "cells", "CFD"]


def cells(res: Path, pid: str, atlas: dict) -> list[str]:
    """One row's cells, in the order of :data:`COLUMNS`."""
    p = res / "patients" / pid
    fit = json.loads((p / "fit" / "fit_report.json").read_text())
    if fit.get("failed"):
        return [pid, "fit", fit["reason"][:140], "-", "-", "-"]
    quality = fit["quality"] + ("" if fit["quality"] == "ok" else f" ({'; '.join(fit['quality_reasons'])[:90]})")
    wall = (p / "wall" / "wall.stl").read_bytes()[:200]
    wall_ok = "refused" if wall.lstrip().startswith(b"{") else "closed"
    st = json.loads((p / "status.json").read_text())
    cfd = (st.get("reason") or "")[:80]
    if st.get("converged"):
        cfd = f"converged: {st.get('criterion_used')}, {st.get('iterations')} iterations"
    if pid in atlas.get("patients_included", []):
        stage = "atlas"
    else:
        ex = atlas.get("patients_excluded", {}).get(pid, {})
        stage = f"excluded at {ex.get('stage', '?')}: {ex.get('reason', '')[:100]}"
    return [pid, stage, quality, wall_ok, str(st.get("cells", "-")), cfd]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-d", "--directory", type=Path)
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    args = ap.parse_args()
    if not DATA.is_dir():
        sys.exit(f"{DATA} not found: this benchmark needs ../shared/data beside the repository")
    wd = args.directory or Path(tempfile.mkdtemp(prefix="vcs_stage_survey_"))
    wd.mkdir(parents=True, exist_ok=True)
    ids = write_sheet(wd) if not (wd / "patients.tsv").exists() else None
    if ids is None:
        ids = [r["id"] for r in csv.DictReader(open(wd / "patients.tsv"), delimiter="\t")]
    run_workflow(wd, ["config.yaml"], str(wd / "patients.tsv"), args.cores, "stage survey (default config)")
    res = wd / "results"
    atlas_file = res / "atlas" / "atlas.json"
    atlas = json.loads(atlas_file.read_text()) if atlas_file.exists() else {}

    def row(pid: str) -> list[str]:
        try:
            return cells(res, pid, atlas)
        except FileNotFoundError as exc:
            return [pid, f"not finished ({exc.filename})", "", "", "", ""]

    emit(COLUMNS, (row(pid) for pid in ids), args.json, "one run, default config/config.yaml")


if __name__ == "__main__":
    main()
