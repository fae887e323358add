#!/usr/bin/env python3
"""The end-plane Courant factor of a ``cfd_geometry: surface`` lumen: the largest Courant number
over all cells / the largest away from the end planes (:func:`vcs.cfd.transient.courant_plan`,
``end_plane_factor``), which sets how far below the interior's a pulsatile or transient run's
time step falls. Measured on a steady SIMPLE state (the Courant numbers' ratio does not depend on
the time step) of the shared vmtk aorta bifurcation (inlet -> one iliac, the other a branch).

    .venv/bin/python bench/surface_end_courant.py [--work /tmp/end_courant] [--cell-size-mm 1.2]

Prints, per end, the largest Courant number of its end-plane cells over the interior's, and the
factor; ``--json PATH`` writes them. One OpenFOAM rank; ~2-3 minutes at 1.2 mm (CI-sized: the
cell of tests/workflow/test_surface_geometry.py).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MESH = REPO.parent / "shared" / "data" / "vessels" / "vmtk_aorta_bifurcation_open.stl"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--mesh", type=Path, default=MESH)
    ap.add_argument("--units", default="mm")
    ap.add_argument("--inlet", default="end:0")
    ap.add_argument("--outlet", default="end:1")
    ap.add_argument("--work", type=Path, default=Path("/tmp/end_courant"))
    ap.add_argument("--cell-size-mm", type=float, default=1.2)
    ap.add_argument("--flow-rate-l-min", type=float, default=1.0)
    ap.add_argument("--iterations", type=int, default=400, help="SIMPLE iterations (the state's flux)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument(
        "--lumen-args",
        default="--extend-outlet 1 --grid axes",
        help="options of `vcs lumen` (the workflow's: wall.extend_*, cfd.mesh.background_frame); '' before them",
    )
    a = ap.parse_args()
    if not a.mesh.is_file():
        print(f"{a.mesh} is absent (the shared real vessels): nothing to measure", file=sys.stderr)
        return 2

    from vcs.cfd import render_case, run_case
    from vcs.cfd.foamfiles import patch_geometry
    from vcs.cfd.transient import _cell_fields, courant_plan, end_plane_cells
    from vcs.cfd.utilities import _Runner, _time_dirs
    from vcs.cli.main import main as vcs_main

    t0 = time.perf_counter()
    a.work.mkdir(parents=True, exist_ok=True)
    fit, stl, case = a.work / "fit", a.work / "lumen.stl", a.work / "case"
    vcs_main(["fit", str(a.mesh), "-o", str(fit), "--units", a.units, "--inlet", a.inlet, "--outlet", a.outlet])
    model = fit / "model.json"
    lumen = ["lumen", str(a.mesh), "--model", str(model), "-o", str(stl), "--ends", str(a.work / "ends.json")]
    vcs_main(lumen + a.lumen_args.split())
    cfd = {
        "ranks": 1,
        "mesh": {"cell_size": a.cell_size_mm * 1e-3},
        "inlet": {"flow_rate": a.flow_rate_l_min * 1e-3 / 60},
        "solver": {"max_iterations": a.iterations, "fallback": "none"},
    }
    state = render_case(case, stl, cfd, model=model)
    status = run_case(case, ranks=1)
    run = _Runner(case, {}, None)
    cour = courant_plan(
        case,
        state,
        run,
        1,
        case,
        {"delta_t_initial_s": 1.0},
        limits={"max_co": 1.0, "max_co_end_cells": 1e9, "outer_correctors": 2},
    )
    # per end: its end-plane cells' largest Co over the interior's largest
    t_name = _time_dirs(case)[-1][1]
    co, centres, vols = _cell_fields(case, 1, t_name, ("Co", "C", "V"))
    rows = {}
    for p in state["patches"]:
        if p["role"] not in ("inlet", "outlet"):
            continue
        c, sf = patch_geometry(case, p["name"])
        ar = np.linalg.norm(sf, axis=1)
        n = sf.sum(axis=0)
        ctr = (c * ar[:, None]).sum(axis=0) / ar.sum()
        near = end_plane_cells(
            centres, vols, [(ctr, n / np.linalg.norm(n), float(np.linalg.norm(c - ctr, axis=1).max()))]
        )
        rows[p["name"]] = float(co[near].max() / cour["courant_per_s_interior"]) if near.any() else None
    out = {
        "mesh": str(a.mesh),
        "cells": status.get("cells"),
        "converged": status.get("converged"),
        "end_plane_factor": cour["end_plane_factor"],
        "end_plane_cells": cour["end_plane_cells"],
        "per_end": rows,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    print(json.dumps(out, indent=2))
    if a.json:
        a.json.write_text(json.dumps(out, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
