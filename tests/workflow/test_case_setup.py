"""The workflow's case set-up (openfoam_case) with the default config: the mesh sized from the
patient's model.json, and the sheet's per-patient values (cell size, inflow) in the rendered case.
Runs vcs phantom, fit, wall and the rendering (no OpenFOAM run)."""

from __future__ import annotations

import json

import numpy as np
import pytest

R_MM = 10.0  # `vcs phantom --kind tube` (any seed): straight tube, radius 10 mm, length 100 mm


def _solid_area(stl_text: str, name: str) -> float:
    """Area (m^2) of one solid of an ASCII STL, parsed here (not with the project's reader)."""
    block = stl_text.split(f"solid {name}\n", 1)[1].split(f"endsolid {name}", 1)[0]
    v = np.array([ln.split()[1:4] for ln in block.splitlines() if ln.strip().startswith("vertex")], float)
    t = v.reshape(-1, 3, 3)
    return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())


def test_sheet_values_and_auto_size_reach_the_rendered_case(tmp_path, workdir_factory):
    mesh = "results/demo/tube_seed0.stl"
    wd = workdir_factory(
        tmp_path,
        [
            {"id": "own", "mesh": mesh, "units": "mm", "cell_size_mm": "1.5", "flow_rate_l_min": "2.4"},
            {"id": "jet", "mesh": mesh, "units": "mm", "inlet_velocity_m_s": "1.1", "valve_area_cm2": "0.8"},
            {"id": "default", "mesh": mesh, "units": "mm"},
        ],
    )
    targets = [f"results/patients/{p}/case_setup" for p in ("own", "jet", "default")]
    wd.snakemake("--cores", "2", *targets, timeout=900)
    state = {
        p: json.loads((wd.path / t / "vcsflow_case.json").read_text())
        for p, t in zip(("own", "jet", "default"), targets)
    }

    own = state["own"]
    assert own["mesh_sizing"]["cell_size_m"] == pytest.approx(1.5e-3)
    assert own["mesh_sizing"]["cell_size"]["source"] == "patient"
    assert own["flow_rate"] == pytest.approx(2.4e-3 / 60) and own["inflow"]["source"] == "patient"
    assert own["inflow"]["scale_factor"] == 1.0  # the patient's flow is never scaled

    jet = state["jet"]
    assert jet["flow_rate"] == pytest.approx(1.1 * 0.8e-4) and jet["inflow"]["scaling"] == "patient"

    # the default: auto size, 12 cells across the 20 mm ends (the fit's radius is within 1 % of 10 mm)
    d = state["default"]
    assert d["mesh_sizing"]["cell_size"]["source"] == "auto"
    assert d["mesh_sizing"]["cell_size_m"] == pytest.approx(2 * R_MM / 12 * 1e-3, rel=0.01)
    assert d["mesh_sizing"]["vessel"]["source"] == "vessel model"
    # the config's 5 L/min scaled by inlet area / 4.909 cm2 (capped at 1): the area read from the STL here
    a_in = _solid_area((wd.path / "results/patients/default/wall/wall.stl").read_text(), "inlet")
    assert a_in == pytest.approx(np.pi * (R_MM * 1e-3) ** 2, rel=0.01)
    assert d["inflow"]["scaling"] == "scaled_by_inlet_area"
    assert d["flow_rate"] == pytest.approx(8.3e-5 * a_in / 4.909e-4, rel=1e-6)
    log = (wd.path / "results/logs/openfoam_case/default.log").read_text()
    assert "auto: 12 cells across the smallest end" in log and "L/min (config 4.98 L/min x inlet area" in log
