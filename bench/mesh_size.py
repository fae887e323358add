#!/usr/bin/env python3
"""Mesh sizes of the default configuration on real vessels, meshing only: AortaCFD patient1,
SPHinXsys VMR 0154 and the coarse TAH aorta (config/real_patients.tsv at the default ``auto`` cell
size, as bench/cfd_cost.py) and a helix phantom, fitted (``vcs fit``), walled and rendered by the
workflow with config/config.yaml (target ``results/patients/<id>/case_setup``), then each rendered
case meshed as ``vcs.cfd.run_case`` meshes it (blockMesh, snappyHexMesh, checkMesh, the patch
check) and no solver.

    .venv/bin/python bench/mesh_size.py [-d DIR] [--cores 2] [--json PATH]

DIR (default: a temporary folder) is the Snakemake working directory; the meshed copies of the
cases are DIR/meshing/<id>. Per vessel: the smaller end's and the narrowest diameter, the cell size
and what set it, the background box's cells (and the levels it was coarsened by, with the box it
would have had without ``cfd.mesh.max_background_cells``), cells, wall / inlet / outlet faces,
snappyHexMesh's wall seconds and the CPU seconds of the meshing utilities (blockMesh,
snappyHexMesh, checkMesh: their resource usage), the inflow. ``--json PATH`` also writes the table in the docs'
format (docs/data/bench/mesh_size_real.json). Needs ../shared/data beside the repository and
OpenFOAM.
"""

from __future__ import annotations

import argparse
import math
import resource
import shutil
import sys
import tempfile
from pathlib import Path

from _table import emit  # bench/ is on sys.path when this runs as a script
from real_cohort import real_rows, run_workflow, write_rows

REPO = Path(__file__).resolve().parents[1]
REAL = ("aortacfd_patient1", "vmr0154", "tah_coarse")  # of config/real_patients.tsv
HELIX = {"id": "helix_phantom", "mesh": "results/demo/helix_seed0.stl", "units": "mm"}
LABELS = {
    "aortacfd_patient1": "AortaCFD patient1 (`inlet.stl` -> `outlet4.stl`)",
    "vmr0154": "SPHinXsys VMR 0154 (cm; inlet/outlet points of `tests/vcs/test_real_vessels.py`)",
    "tah_coarse": "SPHinXsys TAH aorta, coarse (points as above)",
    "helix_phantom": "helix phantom (`vcs phantom --kind helix`, seed 0)",
}
SET_BY = {"narrowest section": "narrowest", "smallest end": "end"}  # vcs.cfd.sizing's governed_by, shorter
#: the table's columns (as printed and in the docs JSON)
COLUMNS = [
    "vessel (fit with `vcs fit`, wall as in the workflow)",
    "smaller end / narrowest d mm",
    "cell mm (set by)",
    "background box cells (k)",
    "cells",
    "wall / inlet / outlet faces",
    "snappyHexMesh s (meshing CPU s)",
    "inflow L/min",
]


def sheet_rows() -> list[dict[str, str]]:
    """The three real vessels at the default cell size, then the helix phantom."""
    rows = [dict(r) for r in real_rows() if r["id"] in REAL]
    for r in rows:
        r["cell_size_mm"] = ""  # the default auto size, not a sheet's own
    return rows + [dict(HELIX)]


def mesh_only(case: Path) -> dict:
    """Mesh a rendered case as :func:`vcs.cfd.run_case` does, without solving; its status (a mesh
    that stopped the case: ``reason``)."""
    from vcs.cfd.meshing import mesh_case
    from vcs.cfd.openfoam import detect_openfoam
    from vcs.cfd.run import _new_status, _read_state, _start
    from vcs.cfd.utilities import Stop

    installed, version = detect_openfoam()
    state = _read_state(case, 1)
    status = _new_status(case, state, version)
    status["state"] = state
    try:
        mesh_case(case, state, status, _start(case, state, status, installed))
    except Stop as stop:
        status["reason"] = stop.reason
    return status


def cells(pid: str, st: dict, meshing_cpu: float | None) -> list[str]:
    """One vessel's row of :data:`COLUMNS` from its meshing status (:func:`mesh_only`, with the
    rendered case's ``state``) and the meshing utilities' CPU seconds."""
    state = st["state"]
    sizing = state["mesh_sizing"]
    vessel, bg, size = sizing["vessel"], sizing["background"], sizing["cell_size"]
    h = sizing["cell_size_m"]
    smaller = min(vessel["inlet_diameter_m"], vessel["outlet_diameter_m"])
    k = int(bg["level_offset"])
    box = f"{bg['background_cells']:,} ({k})"
    if k:  # the box at the lumen cell size, which max_background_cells stopped
        lo, hi = state["stl_bounds"]
        pad = int(state["cfd"]["mesh"]["pad_cells"])
        n = [math.ceil((b - a) / h - 1e-9 + 2 * pad) for a, b in zip(lo, hi)]
        box = f"{bg['background_cells']:,} ({k}; {math.prod(n):,} without the cap)"
    patches = (st.get("mesh") or {}).get("patches") or {}
    faces = " / ".join(f"{(patches.get(p) or {}).get('faces', 0):,}" for p in ("wall", "inlet", "outlet"))
    snappy = st["timings_s"].get("snappyHexMesh")
    return [
        LABELS.get(pid, pid),
        f"{smaller * 1e3:#.3g} / {vessel['narrowest_diameter_m'] * 1e3:#.3g}",
        f"{h * 1e3:.3g} ({SET_BY.get(size['governed_by'], size['governed_by'])})",
        box,
        "-" if st.get("cells") is None else f"{st['cells']:,}",
        faces,
        "-" if snappy is None else f"{snappy:.1f} (" + ("-" if meshing_cpu is None else f"{meshing_cpu:.1f}") + ")",
        f"{state['inflow']['flow_rate_l_min']:.3g}",
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-d", "--workdir", type=Path, help="Snakemake working directory (default: temporary)")
    ap.add_argument("--cores", type=int, default=2, help="cores for Snakemake (default 2)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    if not (REPO.parent / "shared" / "data").is_dir():
        print(f"mesh_size: error: {REPO.parent / 'shared' / 'data'} is absent", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        wd = (a.workdir or Path(tmp)).resolve()
        wd.mkdir(parents=True, exist_ok=True)
        ids = write_rows(wd / "patients.tsv", sheet_rows())
        targets = [f"results/patients/{pid}/case_setup" for pid in ids]
        r = run_workflow(wd, ["config.yaml"], "patients.tsv", a.cores, "mesh sizes, default config", targets=targets)

        def row(pid: str) -> list[str]:
            case = wd / "meshing" / pid
            shutil.rmtree(case, ignore_errors=True)
            shutil.copytree(wd / "results" / "patients" / pid / "case_setup", case)
            before = resource.getrusage(resource.RUSAGE_CHILDREN)  # snappyHexMesh logs no ExecutionTime
            st = mesh_only(case)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            if st.get("reason"):
                print(f"{pid}: {st['reason']}", file=sys.stderr)
            cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
            return cells(pid, st, cpu)

        emit(
            COLUMNS,
            (row(pid) for pid in ids),
            a.json,
            "one run, meshing only, serial, one vessel after the other; default config/config.yaml",
        )
    return 0 if r.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
