#!/usr/bin/env python3
"""The README's inlet-frame figures: the largest Courant number of a jet's potential-flow start on
each patient's mesh with the background grid along the coordinate axes and in the inlet's frame
(``cfd.mesh.background_frame``), i.e. what sets pimpleFoam's Courant-limited time step.

    .venv/bin/python bench/inlet_frame.py -d DIR [--dt 1e-3]

DIR is a workflow directory with at least the openfoam_case step done (e.g. the one of
bench/jet_atlas.py): each results/patients/<id>/case_setup is re-rendered with its own merged
cfd settings in both frames, meshed (blockMesh, snappyHexMesh), given its inlet profile, solved
for potential flow (potentialFoam -writephi) and the Courant number at ``--dt`` is computed
(postProcess -func CourantNo). Prints per patient and frame: cells, the largest and the 5th
largest Courant number, and the time step that would give Courant number 1.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import tempfile
from datetime import date
from pathlib import Path

import numpy as np

POTENTIAL = """
    Phi
    {
        solver          GAMG;
        smoother        GaussSeidel;
        tolerance       1e-08;
        relTol          0.01;
    }
"""


def courant(setup: Path, frame: str, out: Path, dt: float) -> tuple[int, float, float]:
    import pyvista as pv

    from vcs.cfd.case import render_case, render_files
    from vcs.cfd.run import inlet_profile

    st = json.loads((setup / "vcsflow_case.json").read_text())
    cfd = st["cfd"]
    cfd["mesh"]["background_frame"] = frame
    state = render_case(out, st["stl_source"], cfd, model=setup.parent / "fit" / "model.json")
    env = {**os.environ, "WM_PROJECT_DIR": os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam")}
    for cmd in (["blockMesh"], ["snappyHexMesh", "-overwrite"]):
        subprocess.run(cmd, cwd=out, env=env, check=True, capture_output=True)
    prof = inlet_profile(out, state)
    render_files(out, state, ["0/U"], inlet_values=prof["values"].tolist())
    fvs = out / "system" / "fvSolution"
    text = fvs.read_text().replace("solvers\n{", "solvers\n{" + POTENTIAL, 1)
    fvs.write_text(text + "\npotentialFlow\n{\n    nNonOrthogonalCorrectors 2;\n}\n")
    cd = out / "system" / "controlDict"
    cd.write_text("\n".join(f"deltaT {dt};" if ln.startswith("deltaT") else ln for ln in cd.read_text().splitlines()))
    for cmd in (["potentialFoam", "-writephi"], ["postProcess", "-func", "CourantNo", "-time", "0"]):
        subprocess.run(cmd, cwd=out, env=env, check=True, capture_output=True)
    (out / "c.foam").touch()
    rd = pv.OpenFOAMReader(str(out / "c.foam"))
    rd.set_active_time_value(0.0)
    m = rd.read()["internalMesh"]
    co = np.sort(np.asarray(m.cell_data["Co"]))[::-1]
    return m.n_cells, float(co[0]), float(co[4])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-d", "--workdir", type=Path, required=True, help="workflow directory (results/patients/*)")
    ap.add_argument("--dt", type=float, default=1e-3, help="time step of the Courant numbers [s] (default 1e-3)")
    a = ap.parse_args(argv)
    setups = sorted((a.workdir / "results" / "patients").glob("*/case_setup"))
    print(f"inlet frame, {date.today()}, {platform.node()} ({os.cpu_count()} cores), dt {a.dt:g} s")
    print("| patient | frame | cells | largest Courant number | 5th largest | dt for Courant number 1, ms |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for setup in setups:
            for frame in ("axes", "inlet"):
                n, c0, c4 = courant(setup, frame, Path(tmp) / f"{setup.parent.name}_{frame}", a.dt)
                print(f"| {setup.parent.name} | {frame} | {n:,} | {c0:.2f} | {c4:.2f} | {1e3 * a.dt / c0:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
