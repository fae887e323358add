"""vcs.cfd: templates (both flavours) and real OpenFOAM runs (marker ``openfoam``)."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from model_phantoms import narrowed_model  # tests/ (on sys.path by conftest): vessels with exact sections

from vcs.cfd import DEFAULTS, detect_openfoam, render_case, run_case, sample_case
from vcs.cfd.case import CASE_JSON, jet_region, render_files
from vcs.cfd.foamfiles import (
    function_series,
    parse_layer_summary,
    read_internal_field,
    read_patch_field,
    window_mean,
)
from vcs.cfd.openfoam import deep_merge
from vcs.cfd.run import STAGE_FILES, transient_plan
from vcs.cfd.status import _wall_faces, _wall_values
from vcs.cfd.verification import local_error_stats, poiseuille_wall_shear_stress
from vcs.errors import VCSInputError
from vcs.phantoms.analytic import write_closed_tube_stl
from vcs.surface import wall_mesh, write_multisolid_stl

R = 0.01  # tube radius [m]
L = 0.12  # tube length [m]
AXIS = np.array([0.03, 0.02, 1.0]) / np.linalg.norm([0.03, 0.02, 1.0])  # ~2 deg tilt: see write_closed_tube_stl
Q_POIS = 2.0e-5  # m3/s -> U_mean 0.064 m/s, Re = 378 (parabolic inlet: developed from the start)
HAVE_FOAM = shutil.which("simpleFoam") is not None and detect_openfoam()[0] == "esi"
needs_foam = pytest.mark.skipif(not HAVE_FOAM, reason="Debian's ESI OpenFOAM (simpleFoam) not installed")

POIS_CFG = {
    "mesh": {"cell_size": 1.25e-3},
    "inlet": {"type": "parabolic", "flow_rate": Q_POIS},
    "solver": {"max_iterations": 800, "startup_iterations": 50, "fallback": "none"},
}


def _straight_model(radius=R, length=L, axis=AXIS):
    """The VesselModel (mm) of a straight tube (tests/vcs/test_resample.py)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vcs"))
    from test_resample import straight_model

    return straight_model(radius_mm=radius * 1e3, length_mm=length * 1e3, axis=axis)


def _tube(tmp: Path, axis=AXIS, length=L) -> Path:
    return write_closed_tube_stl(tmp / "tube.stl", radius=R, length=length, n_theta=96, n_z=60, axis=axis)


# ----------------------------------------------------------------- rendering (no OpenFOAM)


def test_defaults_documented_keys():
    assert DEFAULTS["physics"]["nu"] == pytest.approx(3.37e-6)
    assert DEFAULTS["inlet"]["type"] == "jet"
    assert DEFAULTS["inlet"]["velocity"] * DEFAULTS["inlet"]["valve_area"] == pytest.approx(1.2e-4)
    assert DEFAULTS["solver"]["tolerance"] == pytest.approx(1e-5)


def test_config_schema_covers_every_cfd_default():
    """Each key of vcs.cfd.DEFAULTS can be set in config.yaml (the schema forbids unknown keys) and
    config/config.yaml validates, auto cell size and inflow scaling included."""
    import jsonschema
    import yaml

    repo = Path(__file__).resolve().parents[2]
    schema = yaml.safe_load((repo / "workflow/schemas/config.schema.yaml").read_text())

    def missing(defaults: dict, node: dict, where: str) -> list[str]:
        out = []
        for k, v in defaults.items():
            sub = node.get("properties", {}).get(k)
            if sub is None:
                out.append(f"{where}.{k}")
            elif isinstance(v, dict):
                out += missing(v, sub, f"{where}.{k}")
        return out

    assert missing(DEFAULTS, schema["properties"]["cfd"], "cfd") == []
    config = yaml.safe_load((repo / "config/config.yaml").read_text())
    jsonschema.validate(config, schema)
    assert config["cfd"]["mesh"]["cell_size"] == "auto" and config["cfd"]["inlet"]["scaling"] == "scaled_by_inlet_area"
    bad = deep_merge(config, {"cfd": {"mesh": {"cell_size": "fine"}}})
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_render_org10_is_v10_native_and_parses(tmp_path):
    from PyFoam.RunDictionary.ParsedParameterFile import ParsedParameterFile

    st = render_case(tmp_path / "c10", _tube(tmp_path), {"ranks": 2}, flavour="org10")
    case = tmp_path / "c10"
    assert st["flavour"] == "org10"
    # v10 names, no ESI/legacy ones
    assert (case / "constant/physicalProperties").exists()
    assert (case / "constant/momentumTransport").exists()
    assert not (case / "constant/transportProperties").exists()
    assert not (case / "constant/turbulenceProperties").exists()
    assert (case / "constant/geometry/vessel.stl").exists()
    phys = ParsedParameterFile(str(case / "constant/physicalProperties"))
    assert phys["viscosityModel"] == "constant"
    assert float(phys["nu"]) == pytest.approx(3.37e-6)
    mt = ParsedParameterFile(str(case / "constant/momentumTransport"))
    assert mt["simulationType"] == "laminar"
    shm = ParsedParameterFile(str(case / "system/snappyHexMeshDict"))
    cmc = shm["castellatedMeshControls"]
    assert "insidePoint" in cmc and "locationInMesh" not in cmc
    assert set(shm["geometry"]["vessel"]["regions"]) == {"wall", "inlet", "outlet"}
    assert shm["geometry"]["vessel"]["file"].strip('"') == "vessel.stl"
    dec = ParsedParameterFile(str(case / "system/decomposeParDict"))
    assert dec["decomposer"] == "hierarchical" and int(dec["numberOfSubdomains"]) == 2
    for name in ("fvSchemes", "fvSolution", "blockMeshDict"):
        ParsedParameterFile(str(case / "system" / name))
    for name in ("U", "p"):
        ParsedParameterFile(str(case / "0" / name))
    ctl = (case / "system/controlDict").read_text()
    assert "#includeFunc wallShearStress" in ctl
    assert "#includeFunc residuals(p, U)" in ctl
    assert "#includeFunc patchFlowRate(funcName=flowRate_inlet, patch=inlet)" in ctl
    assert "version     2.0" not in ctl  # v10 headers carry no version entry
    sol = ParsedParameterFile(str(case / "system/fvSolution"))
    assert float(sol["SIMPLE"]["residualControl"]["p"]) == pytest.approx(1e-5)
    u = ParsedParameterFile(str(case / "0/U"))
    assert u["boundaryField"]["outlet"]["type"] == "inletOutlet"
    assert u["boundaryField"]["wall"]["type"] == "noSlip"


def test_render_esi_names(tmp_path):
    from PyFoam.RunDictionary.ParsedParameterFile import ParsedParameterFile

    render_case(tmp_path / "ce", _tube(tmp_path), {}, flavour="esi")
    case = tmp_path / "ce"
    tp = ParsedParameterFile(str(case / "constant/transportProperties"))
    assert tp["transportModel"] == "Newtonian" and float(tp["nu"]) == pytest.approx(3.37e-6)
    assert ParsedParameterFile(str(case / "constant/turbulenceProperties"))["simulationType"] == "laminar"
    assert not (case / "constant/physicalProperties").exists()
    assert (case / "constant/triSurface/vessel.stl").exists()
    shm = ParsedParameterFile(str(case / "system/snappyHexMeshDict"))
    assert "locationInMesh" in shm["castellatedMeshControls"]
    ctl = ParsedParameterFile(str(case / "system/controlDict"))
    assert ctl["functions"]["wallShearStress"]["type"] == "wallShearStress"
    assert ctl["functions"]["flowRate_outlet"]["operation"] == "sum"


def test_render_rejects_bad_stl(tmp_path):
    p = tmp_path / "bad.stl"
    p.write_text("solid wall\nendsolid wall\n")
    with pytest.raises(ValueError):
        render_case(tmp_path / "bad", p, {}, flavour="esi")


# ----------------------------------------------------------------------- real OpenFOAM


def _inlet_flux_vtk(case: Path) -> tuple[float, float, float]:
    """The inlet boundary values written by the case (time 0), read back by VTK (pyvista's
    OpenFOAM reader: its own polygon areas and normals, not vcs.cfd's face geometry).

    Returns (flux into the domain m3/s, area of the faces with inflow m2, peak / area-mean speed)."""
    import pyvista as pv

    (case / "case.foam").touch()
    rd = pv.POpenFOAMReader(str(case / "case.foam"))
    rd.set_active_time_value(rd.time_values[0])
    rd.enable_all_patch_arrays()
    rd.cell_to_point_creation = False
    inl = rd.read()["boundary"]["inlet"]
    inl = inl.compute_normals(cell_normals=True, point_normals=False, split_vertices=False, consistent_normals=False)
    area = inl.compute_cell_sizes(length=False, volume=False)["Area"]
    u = np.asarray(inl.cell_data["U"])
    speed = np.linalg.norm(u, axis=1)
    flux = -float((np.einsum("ij,ij->i", u, inl.cell_data["Normals"]) * area).sum())  # normals point out
    wet = speed > 0
    return flux, float(area[wet].sum()), float(speed.max() / ((speed * area)[wet].sum() / area[wet].sum()))


def _sections(case: Path, status: dict):
    """Volume-weighted mean p on cross-sections and area-weighted mean |WSS| on the middle wall."""
    import pyvista as pv

    (case / "case.foam").touch()
    rd = pv.POpenFOAMReader(str(case / "case.foam"))
    rd.set_active_time_value(rd.time_values[-1])
    rd.enable_all_patch_arrays()
    rd.cell_to_point_creation = False
    mb = rd.read()
    vol = mb["internalMesh"]
    cc = vol.cell_centers().points
    s = (cc - 0.0) @ AXIS
    v = vol.compute_cell_sizes(length=False, area=False)["Volume"]
    p = np.asarray(vol.cell_data["p"])
    h = 1.25e-3

    def p_at(x):
        m = np.abs(s - x) < h
        return float((p[m] * v[m]).sum() / v[m].sum())

    s1, s2 = 0.3 * L, 0.75 * L
    dp = p_at(s1) - p_at(s2)
    wall = mb["boundary"]["wall"]
    wc = wall.cell_centers().points @ AXIS
    area = wall.compute_cell_sizes(length=False, volume=False)["Area"]
    wss = np.linalg.norm(np.asarray(wall.cell_data["wallShearStress"]), axis=1)
    m = (wc > s1) & (wc < s2)
    return dp, s2 - s1, float((wss[m] * area[m]).sum() / area[m].sum())


@pytest.fixture(scope="module")
def poiseuille_serial(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("pois")
    render_case(tmp / "serial", _tube(tmp), POIS_CFG, flavour="esi")
    return tmp, run_case(tmp / "serial", ranks=1)


@pytest.mark.openfoam
@needs_foam
def test_hagen_poiseuille(poiseuille_serial):
    tmp, st = poiseuille_serial
    assert st["mesh_ok"], st["reason"]
    assert st["cells"] < 60000
    assert st["converged"], st["reason"]
    assert st["iterations"] < 800
    assert st["mass_imbalance"] < 1e-6
    # the inlet flux, from values independent of vcs.cfd's own sum: OpenFOAM's sum(phi) on the
    # inlet, and the written 0/U integrated by VTK; a parabola's peak is twice its mean
    assert -st["flow_rates"]["inlet"] == pytest.approx(Q_POIS, rel=1e-6)
    flux, _, peak_over_mean = _inlet_flux_vtk(tmp / "serial")
    assert flux == pytest.approx(Q_POIS, rel=1e-6)
    assert peak_over_mean == pytest.approx(2.0, rel=0.02)  # the face centre nearest the axis: r > 0
    pf = st["pyfoam_log_analysis"]  # PyFoam's analyzer agrees with the own log parser
    assert pf["last_iteration"] == pytest.approx(st["iterations"])
    assert pf["initial_residuals"]["p"] == pytest.approx(st["final_residuals"]["p"])
    for f in (
        "residuals.csv",
        "residuals.png",
        "status.json",
        "logs/log.snappyHexMesh",
        "logs/log.checkMesh",
        "logs/log.simpleFoam",
    ):
        assert (tmp / "serial" / f).exists(), f
    nu, rho = DEFAULTS["physics"]["nu"], DEFAULTS["physics"]["rho"]
    mu = nu * rho
    dp_k, length, wss_k = _sections(tmp / "serial", st)
    dp_pa, wss_pa = dp_k * rho, wss_k * rho
    dp_hp = 8 * mu * length * Q_POIS / (np.pi * R**4)
    u_mean = Q_POIS / (np.pi * R**2)
    wss_hp = 4 * mu * u_mean / R
    print(f"dp {dp_pa:.5g} Pa vs HP {dp_hp:.5g} Pa; WSS {wss_pa:.5g} Pa vs HP {wss_hp:.5g} Pa")
    assert dp_pa == pytest.approx(dp_hp, rel=0.03)
    assert wss_pa == pytest.approx(wss_hp, rel=0.05)
    assert st["wall_shear_stress_Pa"]["mean"] == pytest.approx(wss_hp, rel=0.10)
    assert wss_hp == pytest.approx(poiseuille_wall_shear_stress(Q_POIS, R, mu))  # one formula, two homes agree

    # local WSS on the resampled (tau, theta) wall map, which the atlas is built from, node by node
    # against 4 mu U_mean / R. Developed region: tau in [0.1, 0.9] (12 mm = 0.6 diameters from
    # each end). Measured with the default 3 prism layers: p95 3.7 %, max 8.9 %; without layers
    # p95 5.6 %, max 15 % (README, "Local WSS accuracy"). The whole map adds the inlet edge
    # (tau < 0.05: up to +18 % with layers, +30 % without).
    f = sample_case(tmp / "serial", _straight_model(), n_tau=64, n_theta=32, n_rho=3)
    wss_map = np.linalg.norm(f["WSS"], axis=-1)
    dev = local_error_stats(wss_map, wss_hp, f["tau"], (0.1, 0.9))
    whole = local_error_stats(wss_map, wss_hp, f["tau"])
    print("local WSS error, developed:", dev, "whole map:", whole)
    assert dev["n"] == 50 * 32 and whole["n"] == 64 * 32
    assert dev["p95_abs"] <= 0.05 and dev["max_abs"] <= 0.12, dev
    assert whole["p95_abs"] <= 0.08 and whole["max_abs"] <= 0.25, whole


@pytest.mark.openfoam
@needs_foam
def test_serial_and_parallel_agree(poiseuille_serial):
    tmp, st1 = poiseuille_serial
    render_case(tmp / "par", tmp / "tube.stl", POIS_CFG, flavour="esi")
    st2 = run_case(tmp / "par", ranks=2)
    assert st2["mesh_ok"] and st2["ranks"] == 2, st2["reason"]
    assert "decomposePar" in st2["timings_s"] and "reconstructPar" in st2["timings_s"]
    assert (tmp / "par" / "processor1").is_dir()
    dp1, dp2 = st1["inlet_minus_outlet_pressure"]["Pa"], st2["inlet_minus_outlet_pressure"]["Pa"]
    assert dp2 == pytest.approx(dp1, rel=0.005)
    assert st2["converged"] == st1["converged"]


@pytest.mark.openfoam
@needs_foam
def test_jet_inlet_flux(tmp_path):
    stl = write_closed_tube_stl(tmp_path / "tube.stl", radius=R, length=0.06, n_theta=96, n_z=30)
    cfg = {
        "mesh": {"cell_size": 1.25e-3, "layers": 0, "jet_refinement": {"enabled": False}},
        "solver": {"max_iterations": 30, "startup_iterations": 10, "fallback": "none"},
    }
    render_case(tmp_path / "jet", stl, cfg, flavour="esi")
    st = run_case(tmp_path / "jet")
    assert st["mesh_ok"], st["reason"]
    inl = st["inlet"]
    assert inl["type"] == "jet"
    # the flux from values independent of vcs.cfd's own sum: OpenFOAM's sum(phi) on the inlet
    # (surfaceFieldValue), and the written 0/U integrated by VTK
    assert -st["flow_rates"]["inlet"] == pytest.approx(1.2e-4, rel=1e-6)
    flux, wet_area, peak_over_mean = _inlet_flux_vtk(tmp_path / "jet")
    assert flux == pytest.approx(1.2e-4, rel=1e-6)
    # a plug (peak = mean) over a disc of ~1 cm2 (the valve area) on a 3.14 cm2 inlet, at ~1.2 m/s
    assert peak_over_mean == pytest.approx(1.0, abs=1e-6)
    assert 0.7e-4 < wet_area < 1.3e-4 and wet_area == pytest.approx(inl["covered_area"], rel=1e-6)
    assert inl["peak_velocity"] == pytest.approx(1.2e-4 / wet_area, rel=1e-6)
    u0 = (tmp_path / "jet" / "0" / "U").read_text()
    assert re.search(r"value\s+nonuniform List<vector>", u0)
    # only 30 iterations, no fallback: reported as not converged, with a reason, no averaging
    assert st["converged"] is False and "did not reach" in st["reason"]
    assert st["criterion_used"] == "none" and "transient" not in st
    assert not (tmp_path / "jet" / "logs" / "log.pimpleFoam.average").exists()
    # the quantity is named for what it is (a pressure recovery after the jet is negative)
    dp = st["inlet_minus_outlet_pressure"]
    assert dp["Pa"] == pytest.approx(dp["kinematic_m2s2"] * 1060.0) and dp["pressure_recovery"] == (dp["Pa"] < 0)
    assert "pressure_drop" not in st
    assert st["mesh"]["layers"] == {"requested": 0} and st["mesh"]["jet_refinement"] is None


# ------------------------------------------------- mesh sized to the vessel, lost patches

QUICK_SOLVE = {"max_iterations": 2, "startup_iterations": 0, "fallback": "none"}


def _model_stl(tmp: Path, model, n_theta: int) -> Path:
    stl = tmp / "wall.stl"
    write_multisolid_stl(wall_mesh(model, n_theta=n_theta), stl, 1e-3)  # Eq. 8 wall, as the workflow writes it
    return stl


@pytest.mark.openfoam
@needs_foam
def test_too_coarse_cell_size_loses_the_outlet_and_says_so(tmp_path):
    """A 2 mm cell against a 1 mm outlet radius: snappyHexMesh drops the outlet and checkMesh still
    says 'Mesh OK'. The patient stops after meshing with the reason in words, never reaches the
    solver, and the atlas excludes it with that reason."""
    from vcs.atlas import status_exclusion, status_stage
    from vcs.cfd.foamfiles import read_boundary

    model = narrowed_model(6.0, 4.0, 1.0, length=30.0)  # inlet r 6 mm, outlet r 1 mm
    stl = _model_stl(tmp_path, model, 32)
    cfd = {
        "mesh": {"cell_size": 2e-3, "layers": 0, "min_patch_faces": 10},
        "inlet": {"type": "parabolic", "flow_rate": 1e-6},
        "solver": QUICK_SOLVE,
    }
    render_case(tmp_path / "c", stl, cfd, flavour="esi", model=model)
    st = run_case(tmp_path / "c")
    boundary = read_boundary(tmp_path / "c" / "constant" / "polyMesh")  # the real mesh
    assert boundary.get("outlet", {}).get("nFaces", 0) == 0 and boundary["inlet"]["nFaces"] >= 10
    assert "Mesh OK." in (tmp_path / "c" / "logs" / "log.checkMesh").read_text()  # checkMesh does not see it
    r_out = 1.0 * np.sqrt(32 / (2 * np.pi) * np.sin(2 * np.pi / 32))  # equivalent radius of the 32-gon cap: 0.994 mm
    assert st["reason"] == (
        f"outlet lost in meshing: 0 faces (minimum 10); cell size 2 mm vs outlet radius {r_out:.3g} mm; "
        "lower cfd.mesh.cell_size"
    )
    assert st["converged"] is False and st["mesh_ok"] is False and st["stage"] == "mesh"
    assert st["mesh"]["patches"]["outlet"]["faces"] == 0 and st["mesh"]["background_faces"] == 0
    assert st["failed_log"].endswith("logs/log.snappyHexMesh")
    assert not any(k.startswith("simpleFoam") for k in st["timings_s"])  # the solver never ran
    assert st["mesh"]["sizing"]["cell_size"]["source"] == "config"
    assert status_exclusion(st) == st["reason"] and status_stage(st) == "mesh"  # atlas.json: stage and reason


@pytest.mark.openfoam
@needs_foam
def test_auto_cell_size_with_a_coarse_background_keeps_the_lumen_cells(tmp_path):
    """cell_size auto on a vessel with known sections; the background box is capped so low that
    it is 4x coarser than the lumen cell, yet every cell of the lumen is at the lumen cell size
    (the whole lumen is refined) and every STL solid became a patch."""
    import pyvista as pv

    model = narrowed_model(12.0, 10.0, 11.0, length=30.0)  # ends d 24 and 22 mm, narrowest 20 mm
    stl = _model_stl(tmp_path, model, 48)
    cfd = {
        "mesh": {"cell_size": "auto", "cells_across_end": 16, "layers": 0, "max_background_cells": 2000},
        "inlet": {"type": "parabolic", "flow_rate": 2e-5},
        "solver": QUICK_SOLVE,
    }
    state = render_case(tmp_path / "c", stl, cfd, flavour="esi", model=model)
    h = state["mesh_sizing"]["cell_size_m"]
    assert h == pytest.approx(1.37e-3)  # 22 mm / 16 = 1.375 mm, rounded down; narrowest 20 / 8 = 2.5 mm
    bg = state["mesh_sizing"]["background"]
    assert bg["level_offset"] == 2 and bg["background_cells"] <= 2000
    st = run_case(tmp_path / "c")
    assert st["mesh_ok"] is True and st["reason"].startswith("SIMPLE did not reach")  # only 2 iterations
    faces = {k: v["faces"] for k, v in st["mesh"]["patches"].items()}
    assert min(faces.values()) >= 20 and st["mesh"]["background_faces"] == 0
    (tmp_path / "c" / "c.foam").touch()
    rd = pv.POpenFOAMReader(str(tmp_path / "c" / "c.foam"))
    rd.set_active_time_value(rd.time_values[0])
    vol = np.asarray(rd.read()["internalMesh"].compute_cell_sizes(length=False, area=False)["Volume"])
    assert (vol > 1.5 * h**3).mean() < 0.02  # not 5.48 mm background cells in the core
    # cell count ~ lumen volume / h^3; radius 12 - 7 t + 6 t^2 mm (through 12, 10, 11), so
    # V = pi L int_0^1 r^2 dt = pi 30 (a^2 + ab + (b^2 + 2ac)/3 + bc/2 + c^2/5) = pi 30 x 110.533 mm3
    v_lumen = np.pi * 30.0 * (144 - 84 + (49 + 144) / 3 - 21 + 36 / 5) * 1e-9
    assert st["cells"] == pytest.approx(v_lumen / h**3, rel=0.1)  # ~4,050 cells


# ------------------------------------------------- the paper's jet: mesh, transient fallback

# a coarse tube with a small, slow jet: Re_jet = 0.3 m/s x 5 mm / 1e-5 m2/s = 150 (steady), ~4k
# cells; SIMPLE is stopped after 20 iterations so that the transient fallback runs
JET_R, JET_L = 0.006, 0.036
JET_AXIS = np.array([0.3, 0.2, 1.0])
JET_CFG = {
    "mesh": {"cell_size": 1.5e-3, "jet_refinement": {"cells_across": 6, "radius": 1.5, "length": 3.0}},
    "inlet": {"type": "jet", "velocity": 0.3, "valve_area": 2.0e-5},
    "physics": {"nu": 1.0e-5},
    "solver": {
        "max_iterations": 20,
        "startup_iterations": 5,
        "fallback": "transient",
        "transient": {"min_flow_throughs": 0.3, "max_flow_throughs": 0.3, "washout_flow_throughs": 0.15},
    },
}


def _on(value: object) -> bool:
    """An OpenFOAM switch as PyFoam parses it (True, 'true', 'yes', 'on')."""
    return value is True or str(value).lower() in ("true", "yes", "on")


def _jet_tube(tmp: Path) -> Path:
    return write_closed_tube_stl(tmp / "jet_tube.stl", radius=JET_R, length=JET_L, n_theta=64, n_z=24, axis=JET_AXIS)


def test_jet_region_resolves_the_jet(tmp_path):
    from vcs.mesh import read_stl_solids

    solids = read_stl_solids(_tube(tmp_path))
    cfd = deep_merge(DEFAULTS, {"mesh": {"cell_size": 2.0e-3}})  # the paper's jet, default refinement
    jr = jet_region(solids, cfd)
    d = 2 * np.sqrt(1e-4 / np.pi)
    assert jr["jet_diameter"] == pytest.approx(d) and jr["cells_across"] >= 10
    assert jr["level"] == 1 and jr["cell_size"] == pytest.approx(1e-3)
    axis = (np.array(jr["point2"]) - np.array(jr["point1"])) / np.linalg.norm(np.subtract(jr["point2"], jr["point1"]))
    assert axis @ AXIS == pytest.approx(1.0, abs=1e-6)  # along the inlet's inward normal
    assert np.linalg.norm(np.subtract(jr["point2"], jr["point1"])) == pytest.approx(5 * d + 1e-3)
    assert jr["radius"] == pytest.approx(d)  # 2 jet radii
    coarse = jet_region(solids, deep_merge(cfd, {"mesh": {"cell_size": 3.0e-3}}))
    assert coarse["level"] == 2 and coarse["cells_across"] >= 10
    assert jet_region(solids, deep_merge(cfd, {"inlet": {"type": "parabolic"}})) is None
    assert jet_region(solids, deep_merge(cfd, {"mesh": {"jet_refinement": {"enabled": False}}})) is None


def test_background_in_the_inlet_frame(tmp_path):
    """background_frame inlet: the blockMesh box is an orthonormal box whose third axis is the
    inlet's inward normal (the tube's tilted axis), the inlet plane 0.75 of a finest inlet cell
    above one of its grid planes; axes (default): the coordinate box."""
    cfd = deep_merge(JET_CFG, {"mesh": {"background_frame": "inlet"}})
    st = render_case(tmp_path / "inlet", _jet_tube(tmp_path), cfd, flavour="esi")
    c = np.array(st["corners"])
    ax = JET_AXIS / np.linalg.norm(JET_AXIS)
    e = [c[1] - c[0], c[3] - c[0], c[4] - c[0]]  # the box's edges from corner 0
    assert abs(e[0] @ e[1]) + abs(e[0] @ e[2]) + abs(e[1] @ e[2]) < 1e-12  # a rectangular box
    assert np.cross(e[0], e[1]) @ e[2] > 0  # right-handed (blockMesh's hex ordering)
    assert e[2] / np.linalg.norm(e[2]) @ ax == pytest.approx(1.0, abs=1e-9)
    hb = st["mesh_sizing"]["background"]["background_cell_size_m"]
    n = st["ncells"]
    assert [np.linalg.norm(v) for v in e] == pytest.approx([k * hb for k in n])
    # the tube's inlet is the plane through the origin normal to its axis (write_closed_tube_stl)
    h_fine = hb / 2 ** max(st["jet_region"]["level"], max(lv for s in st["solids"] for lv in s["level"]))
    depth = (np.zeros(3) - c[0]) @ ax  # from the box's bottom plane to the inlet plane
    assert (depth / h_fine) % 1.0 == pytest.approx(0.75, abs=1e-6)
    bm = (tmp_path / "inlet" / "system" / "blockMeshDict").read_text()
    assert "inlet's frame" in bm and f"({c[6][0]} {c[6][1]} {c[6][2]})" in bm
    axes = render_case(tmp_path / "axes", _jet_tube(tmp_path), JET_CFG, flavour="esi")
    assert axes["background_frame"]["type"] == "axes"
    ca = np.array(axes["corners"])
    assert np.allclose(ca[6] - ca[0], np.subtract(axes["bmax"], axes["bmin"]))


@pytest.mark.openfoam
@needs_foam
def test_inlet_frame_background_gives_a_uniform_inflow_row(tmp_path):
    """Meshed (blockMesh + snappyHexMesh), the tilted tube's first cell row at the inlet (inside
    the rim) is one slab of hexahedra of equal depth with the inlet-frame background; with the
    coordinate axes the oblique inlet plane cuts the grid into cells of every depth, prisms and
    polyhedra among them (the Courant number of such cells set a jet's time step)."""
    import pyvista as pv

    env = {**os.environ, "WM_PROJECT_DIR": os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam")}
    ax = JET_AXIS / np.linalg.norm(JET_AXIS)
    depth, types = {}, {}
    for frame in ("inlet", "axes"):
        case = tmp_path / frame
        st = render_case(case, _jet_tube(tmp_path), deep_merge(JET_CFG, {"mesh": {"background_frame": frame}}))
        for cmd in (["blockMesh"], ["snappyHexMesh", "-overwrite"]):
            r = subprocess.run(cmd, cwd=case, capture_output=True, text=True, env=env)
            assert r.returncode == 0, r.stdout[-2000:]
        h = st["mesh_sizing"]["smallest_cell_m"]  # the jet cylinder's cells, at the inlet
        (case / "c.foam").touch()
        mesh = pv.OpenFOAMReader(str(case / "c.foam")).read()["internalMesh"]
        cc = mesh.cell_centers().points
        d = cc @ ax  # the inlet plane passes through the origin (write_closed_tube_stl)
        rad = np.linalg.norm(cc - np.outer(d, ax), axis=1)
        first = (d < 1.3 * h) & (rad < JET_R - 2 * h)  # the first row inside the rim
        depth[frame] = d[first] / h
        types[frame] = set(np.asarray(mesh.celltypes)[first].tolist())
    assert types["inlet"] == {12} and np.ptp(depth["inlet"]) < 0.05, (types, depth["inlet"])  # VTK_HEXAHEDRON
    assert types["axes"] != {12} and np.ptp(depth["axes"]) > 0.5, (types, depth["axes"])


@pytest.mark.parametrize("flavour", ["esi", "org10"])
def test_render_jet_mesh_and_transient_stages(tmp_path, flavour):
    """Jet cylinder and prism layers in snappyHexMeshDict; the transient stages' dictionaries
    (pimpleFoam, adjustable time step, PIMPLE, fieldAverage of U, p, WSS, |WSS|) parse."""
    from PyFoam.RunDictionary.ParsedParameterFile import ParsedParameterFile

    case = tmp_path / flavour
    state = render_case(case, _tube(tmp_path), {}, flavour=flavour)  # DEFAULTS: the paper's jet
    shm = ParsedParameterFile(str(case / "system/snappyHexMeshDict"))
    cyl = shm["geometry"]["jetRegion"]
    assert cyl["type"] == "searchableCylinder" and float(cyl["radius"]) == pytest.approx(state["jet_region"]["radius"])
    reg = shm["castellatedMeshControls"]["refinementRegions"]["jetRegion"]
    assert reg["mode"] == "inside" and int(reg["levels"][0][1]) == state["jet_region"]["level"]
    assert state["jet_region"]["cells_across"] >= 10  # DEFAULTS: 1 mm cells, level 0 suffices
    assert _on(shm["addLayers"]) and shm["addLayersControls"]["layers"]["wall"]["nSurfaceLayers"] == 3
    assert float(shm["meshQualityControls"]["maxBoundarySkewness"]) == 4
    render_files(
        case,
        state,
        STAGE_FILES,
        transient=True,
        average=True,
        residual_control=False,
        end_time="2010.5",
        write_interval="4.25",
        delta_t="0.0004",
        max_delta_t="0.2125",
    )
    ctl_text = (case / "system/controlDict").read_text()
    ctl = ParsedParameterFile(str(case / "system/controlDict"))
    assert ctl["application"] == "pimpleFoam" and _on(ctl["adjustTimeStep"])
    assert float(ctl["maxCo"]) == 1.0 and ctl["writeControl"] == "adjustableRunTime"
    assert float(ctl["writeInterval"]) == 4.25 and float(ctl["endTime"]) == 2010.5
    sol = ParsedParameterFile(str(case / "system/fvSolution"))
    assert int(sol["PIMPLE"]["nOuterCorrectors"]) == 1 and "SIMPLE" not in sol
    # without the transient's own setting (a pulsatile run): the solver's non-orthogonal correctors
    assert int(sol["PIMPLE"]["nNonOrthogonalCorrectors"]) == DEFAULTS["solver"]["n_non_orthogonal_correctors"]
    assert "pFinal" in sol["solvers"] and float(sol["relaxationFactors"]["equations"]['".*"']) == 1
    sch = ParsedParameterFile(str(case / "system/fvSchemes"))
    assert sch["ddtSchemes"]["default"] == "backward"
    assert "bounded" not in str(sch["divSchemes"]["div(phi,U)"])
    if flavour == "esi":
        fo = ctl["functions"]
        names = list(fo)
        assert names.index("wallShearStress") < names.index("magWallShearStress") < names.index("fieldAverage")
        assert fo["wallShearStress"]["executeControl"] == "timeStep"
        assert fo["magWallShearStress"]["result"] == "magWallShearStress"
        assert _on(fo["fieldAverage"]["restartOnRestart"])
        averaged = [f for f in fo["fieldAverage"]["fields"] if isinstance(f, str)]
        assert averaged == ["U", "p", "wallShearStress", "magWallShearStress"]
        assert fo["cellVolumes"]["type"] == "writeCellVolumes"
    else:  # OpenFOAM-10 etc/caseDicts/postProcessing/fields/{wallShearStress,mag,fieldAverage,writeCellVolumes}
        lines = [ln.strip() for ln in ctl_text.splitlines() if ln.strip().startswith("#includeFunc")]
        i_wss = lines.index("#includeFunc wallShearStress(executeControl=timeStep)")
        i_mag = lines.index("#includeFunc mag(wallShearStress, result=magWallShearStress, executeControl=timeStep)")
        i_avg = lines.index(
            "#includeFunc fieldAverage(U, p, wallShearStress, magWallShearStress, restartOnRestart=yes, "
            "funcName=fieldAverage)"
        )
        assert i_wss < i_mag < i_avg and "#includeFunc writeCellVolumes" in lines
        assert "version     2.0" not in ctl_text
    # the wash-out stage: no averages, WSS only at write time
    render_files(
        case,
        state,
        STAGE_FILES,
        transient=True,
        average=False,
        residual_control=False,
        end_time="2001.7",
        write_interval="1.7",
        delta_t="0.0004",
        max_delta_t="0.2",
    )
    txt = (case / "system/controlDict").read_text()
    assert "fieldAverage" not in txt and "timeStep)" not in txt.replace("writeControl    timeStep", "")


def test_paper_config_is_the_papers_jet(tmp_path):
    """config/paper.yaml over config/config.yaml (as ``--configfile`` merges it) is valid and is the
    paper's set-up (Section 2.4.1): 1.2 m/s over 1 cm2 (Q 1.2e-4 m3/s), nu 3.37e-6 m2/s, steady
    SIMPLE to 1e-5 first, the transient time average otherwise, known to its tolerance within
    2-20 flow-through times."""
    import yaml
    from snakemake.utils import validate

    repo = Path(__file__).resolve().parents[2]
    cfg = deep_merge(
        yaml.safe_load((repo / "config" / "config.yaml").read_text()),
        yaml.safe_load((repo / "config" / "paper.yaml").read_text()),
    )
    validate(cfg, str(repo / "workflow" / "schemas" / "config.schema.yaml"))
    cfd = cfg["cfd"]
    assert cfd["inlet"] == {**cfd["inlet"], "type": "jet", "velocity": 1.2, "valve_area": 1.0e-4, "flow_rate": None}
    assert cfd["physics"]["nu"] == pytest.approx(3.37e-6) and cfd["solver"]["tolerance"] == pytest.approx(1e-5)
    tr = cfd["solver"]["transient"]
    assert cfd["solver"]["fallback"] == "transient" and tr["min_flow_throughs"] >= 2 and tr["max_flow_throughs"] >= 20
    assert cfd["mesh"]["layers"] > 0 and cfd["mesh"]["jet_refinement"]["enabled"]
    cfd.pop("flavour")
    state = render_case(tmp_path / "paper", _tube(tmp_path), cfd, flavour="esi")
    assert state["flow_rate"] == pytest.approx(1.2e-4) and state["jet_region"]["cells_across"] >= 10


def test_paper_atlas_config_keeps_the_jet_at_level_1(tmp_path):
    """config/paper_atlas.yaml over config.yaml + paper.yaml (the README's atlas of jet patients):
    valid, the paper's jet and window unchanged, 2.8 mm lumen cells and the jet cylinder one level
    finer: 1.4 mm, 11.28 / 1.4 = 8.06 cells across the 1 cm2 jet; its sheet: demo aortas 0-3."""
    import csv

    import yaml
    from snakemake.utils import validate

    repo = Path(__file__).resolve().parents[2]
    cfg: dict = {}
    for name in ("config.yaml", "paper.yaml", "paper_atlas.yaml"):
        cfg = deep_merge(cfg, yaml.safe_load((repo / "config" / name).read_text()))
    validate(cfg, str(repo / "workflow" / "schemas" / "config.schema.yaml"))
    cfd = cfg["cfd"]
    assert cfd["inlet"]["velocity"] == 1.2 and cfd["inlet"]["valve_area"] == 1.0e-4
    assert cfd["solver"]["transient"]["max_flow_throughs"] == 20 and cfd["mesh"]["layers"] > 0
    sheet = repo / cfg["patients"]
    rows = list(csv.DictReader((ln for ln in open(sheet) if not ln.startswith("#")), delimiter="\t"))
    assert [(r["id"], r["mesh"]) for r in rows] == [
        (f"demo_aorta_{s}", f"results/demo/aorta_seed{s}.stl") for s in (0, 1, 2, 3)
    ]
    cfd.pop("flavour")
    state = render_case(tmp_path / "atlas", _tube(tmp_path), cfd, flavour="esi")
    d_jet = 2 * np.sqrt(1.0e-4 / np.pi)
    assert state["jet_region"]["level"] == 1 and state["jet_region"]["cell_size"] == pytest.approx(1.4e-3)
    assert state["jet_region"]["cells_across"] == pytest.approx(d_jet / 1.4e-3)


def test_bad_cfd_words_and_removed_fallback(tmp_path):
    stl = _tube(tmp_path)
    with pytest.raises(VCSInputError, match="'average'.*removed.*transient") as e:
        render_case(tmp_path / "a", stl, {"solver": {"fallback": "average"}}, flavour="esi")
    assert "\n" not in str(e.value)
    with pytest.raises(VCSInputError, match="div_scheme must be one of"):
        render_case(tmp_path / "b", stl, {"solver": {"div_scheme": "linear; evil"}}, flavour="esi")
    with pytest.raises(VCSInputError, match="max_co must be a number in"):
        render_case(tmp_path / "c", stl, {"solver": {"transient": {"max_co": 5}}}, flavour="esi")
    with pytest.raises(VCSInputError, match="min_flow_throughs must be a number"):
        render_case(tmp_path / "d", stl, {"solver": {"transient": {"min_flow_throughs": "5"}}}, flavour="esi")
    for bad in (1.5, 0, 11, True, "1"):
        with pytest.raises(VCSInputError, match="outer_correctors must be a whole number in"):
            render_case(tmp_path / "e", stl, {"solver": {"transient": {"outer_correctors": bad}}}, flavour="esi")
    with pytest.raises(VCSInputError, match=r"max_flow_throughs \(2\) must not be below min_flow_throughs \(3\)"):
        tr = {"min_flow_throughs": 3, "max_flow_throughs": 2}
        render_case(tmp_path / "f", stl, {"solver": {"transient": tr}}, flavour="esi")
    with pytest.raises(VCSInputError, match="confidence must be a number in"):
        render_case(tmp_path / "g", stl, {"solver": {"transient": {"confidence": 1.0}}}, flavour="esi")
    # the keys of the half-window test of earlier versions: one line naming what replaced them
    for old in ("flow_throughs", "max_doublings", "stationarity_tolerance", "stationarity_tolerance_U"):
        with pytest.raises(VCSInputError, match=f"transient.{old} was replaced") as e:
            render_case(tmp_path / "h", stl, {"solver": {"transient": {old: 1}}}, flavour="esi")
        assert "\n" not in str(e.value)


def test_transient_plan_from_flow_through_time():
    state = {
        "cfd": deep_merge(DEFAULTS, {"mesh": {"cell_size": 2e-3}}),
        "flow_rate": 1.2e-4,
        "jet_region": {"level": 1},
    }
    plan = transient_plan(state, 2.078e-4, 1000.0, 1.2)
    t_ft = 2.078e-4 / 1.2e-4
    assert plan["flow_through_time_s"] == pytest.approx(t_ft)
    # defaults: wash-out 1, window 2 to 10 flow-through times, each rounded up to 3 digits
    assert plan["min_window_s"] == pytest.approx(3.47) and plan["washout_s"] == pytest.approx(1.74)
    assert plan["max_window_s"] == pytest.approx(17.4)
    assert plan["min_window_flow_throughs"] >= 2 and plan["washout_flow_throughs"] >= 1
    assert plan["max_window_flow_throughs"] >= 10
    assert plan["averaging_start_time"] == pytest.approx(1001.74) and plan["max_end_time"] == pytest.approx(1019.14)
    assert plan["min_end_time"] == pytest.approx(1001.74 + 3.47)
    assert plan["delta_t_initial_s"] == pytest.approx(1.0 * 1e-3 / 1.2)
    assert plan["max_delta_t_s"] == pytest.approx(0.02 * t_ft)


LAYER_LOG = """Extruding 1211 out of 1246 faces (97.19101124%). Removed extrusion at 3 faces.
Added 3300 out of 3738 cells (88.3%).
Extruding 1200 out of 1246 faces (96.3081862%). Removed extrusion at 0 faces.
Added 3333 out of 3738 cells (89.16532905%).

patch faces    layers   overall thickness
                       [m]       [%]
----- -----    ------   ---       ---
wall 1246     2.67     0.000601  87.1{trailing}

Layer mesh : cells:21818  faces:68492  points:26174
""".format(trailing="    ")  # snappyHexMesh pads the table's rows


def test_parse_layer_summary():
    rep = parse_layer_summary(LAYER_LOG)  # ESI v1912's snappyHexMesh (snappyLayerDriver.C)
    assert rep["added"] and rep["patches"]["wall"] == {
        "faces": 1246,
        "mean_layers": 2.67,
        "thickness_m": 0.000601,
        "thickness_percent": 87.1,
    }
    assert rep["extruded_faces"] == 1200 and rep["extruded_fraction"] == pytest.approx(1200 / 1246)
    assert rep["cells_added"] == 3333 and rep["cells_wanted"] == 3738
    assert parse_layer_summary("no layers here") == {"added": False, "patches": {}}


def test_window_mean_and_field_readers(tmp_path):
    d = tmp_path / "postProcessing" / "pressure_inlet"
    (d / "20").mkdir(parents=True)
    (d / "20.5").mkdir()
    # steps of 0.1 then 0.2; a restarted stage re-writes 20.5
    (d / "20" / "surfaceFieldValue.dat").write_text("# Time areaAverage(p)\n20.1 1\n20.2 1\n20.3 1\n20.5 9\n")
    (d / "20.5" / "surfaceFieldValue.dat").write_text("# Time areaAverage(p)\n20.5 3\n20.7 3\n20.9 5\n")
    assert function_series(tmp_path, "pressure_inlet")[:, 1].tolist() == [1, 1, 1, 3, 3, 5]
    # (0.1 + 0.1 + 0.1) x 1 + 0.2 x 3 over 0.5 s
    assert window_mean(tmp_path, "pressure_inlet", 20.0, 20.5) == pytest.approx((0.3 + 0.6) / 0.5)
    assert window_mean(tmp_path, "pressure_inlet", 20.5, 20.9) == pytest.approx(4.0)
    assert window_mean(tmp_path, "pressure_inlet", 21.0, 22.0) is None
    f = tmp_path / "UMean"
    f.write_text(
        "FoamFile\n{\n    format ascii;\n    class volVectorField;\n    object UMean;\n}\n"
        "dimensions [0 1 -1 0 0 0 0];\ninternalField nonuniform List<vector> 3 ((1 0 0) (0 2 0) (0 0 -3e-1));\n"
        "boundaryField\n{\n    inlet\n    {\n        type calculated;\n        value uniform (0 0 1);\n    }\n"
        "    wall\n    {\n        type calculated;\n"
        "        value nonuniform List<vector> 2((1 1 1)(2 2 2));\n    }\n}\n"
    )
    assert read_internal_field(f).tolist() == [[1, 0, 0], [0, 2, 0], [0, 0, -0.3]]
    assert read_patch_field(f, "inlet", 2).tolist() == [[0, 0, 1], [0, 0, 1]]
    assert read_patch_field(f, "wall").tolist() == [[1, 1, 1], [2, 2, 2]]
    assert read_patch_field(f, "outlet") is None


@pytest.fixture(scope="module")
def jet_transient(tmp_path_factory):
    """The coarse jet tube: SIMPLE stopped early, transient fallback over 0.3 flow-through times."""
    tmp = tmp_path_factory.mktemp("jet_transient")
    render_case(tmp / "case", _jet_tube(tmp), JET_CFG, flavour="esi")
    return tmp / "case", run_case(tmp / "case", ranks=1)


@pytest.mark.openfoam
@needs_foam
def test_jet_transient_window_and_stationarity(jet_transient):
    import json

    case, st = jet_transient
    assert st["mesh_ok"], st["reason"]
    assert st["cells"] < 6000
    # SIMPLE did not converge (20 iterations); the time average did, by its own criterion
    assert st["converged"] is True and st["reason"] is None, st["reason"]
    assert st["criterion_used"] == "time_average_stationary" and "stationary" in st["criterion"]
    assert st["iterations"] == 20 and "did not reach" in st["transient"]["steady_not_converged"]
    tr = st["transient"]
    # the window: flow-through time from the lumen volume and the flow rate
    t_ft = st["lumen_volume_m3"] / 6.0e-6
    assert tr["flow_through_time_s"] == pytest.approx(t_ft)
    assert st["lumen_volume_m3"] == pytest.approx(np.pi * JET_R**2 * JET_L, rel=0.03)
    assert tr["window_flow_throughs"] == pytest.approx(0.3, rel=0.01) and tr["window_flow_throughs"] >= 0.3
    assert tr["washout_flow_throughs"] == pytest.approx(0.15, rel=0.01) and tr["washout_flow_throughs"] >= 0.15
    assert tr["end_time"] - tr["averaging_start_time"] == pytest.approx(tr["window_s"])
    assert tr["averaging_start_time"] - tr["start_time"] == pytest.approx(tr["washout_s"])
    assert float(tr["end_time_folder"]) == pytest.approx(tr["end_time"]) == pytest.approx(tr["max_end_time"])
    assert tr["time_steps"]["washout"] > 10 and tr["time_steps"]["average"] > 20
    # pimpleFoam's pressure equation without non-orthogonal correctors (the transient key), SIMPLE's with 1
    from PyFoam.RunDictionary.ParsedParameterFile import ParsedParameterFile

    pimple = ParsedParameterFile(str(case / "system" / "fvSolution"))["PIMPLE"]
    assert int(pimple["nNonOrthogonalCorrectors"]) == 0 and DEFAULTS["solver"]["n_non_orthogonal_correctors"] == 1
    # the time step: the snapped inlet and outlet planes leave slivers whose Courant number is
    # several times that of the cells the flow crosses; pimpleFoam's limit is raised by that factor
    cour = tr["courant"]
    assert cour["end_plane_factor"] > 1.5 and cour["end_plane_cells"] > 0
    assert cour["pimple_max_co"] == pytest.approx(min(cour["end_plane_factor"], 4.0))
    assert cour["outer_correctors"] == 1  # the default: PISO-like, the cells the flow crosses at Co 1
    assert 0.5 * cour["pimple_max_co"] < tr["courant_max"] <= 1.02 * cour["pimple_max_co"]
    # the error bars: every mean known to its tolerance, their statistics recorded
    rel, tols = tr["relative_errors"], tr["tolerances"]
    assert set(rel) == set(tols) == {"inlet_minus_outlet_pressure", "tawss_mean", "U"}
    assert tr["stationary"] is True and all(rel[k] <= tols[k] for k in rel)
    assert st["time_average_errors"]["relative"] == rel and tr["confidence"] == 0.95
    stats = tr["statistics"]
    assert stats["U"]["n_probes"] == 64
    # the record's mean is fieldAverage's (both time-weighted over the same window)
    end = case / tr["end_time_folder"]
    walls = _wall_faces(case, json.loads((case / CASE_JSON).read_text()))
    area = np.concatenate([a for _, a in walls])
    tawss_field = (_wall_values(end, "magWallShearStressMean", walls) * area).sum() / area.sum() * 1060.0
    assert stats["tawss_mean"]["mean_Pa"] == pytest.approx(tawss_field, rel=1e-3)
    # time-averaged results: WSS of the mean vector, TAWSS, OSI, window means of flow and pressure
    assert st["fields"]["time_averaged"] and st["fields"]["U"] == "UMean"
    assert st["wall_shear_stress_Pa"]["field"] == "wallShearStressMean"
    assert st["tawss_Pa"]["mean"] >= st["wall_shear_stress_Pa"]["mean"] * (1 - 1e-9)  # |mean| <= mean |.|
    assert 0 <= st["osi"]["mean"] <= st["osi"]["max"] <= 0.5
    assert st["mass_imbalance"] < 1e-4
    assert "time-weighted" in st["inlet_minus_outlet_pressure"]["definition"] and "pressure_drop" not in st
    assert st["inlet_minus_outlet_pressure"]["Pa"] == pytest.approx(
        stats["inlet_minus_outlet_pressure"]["mean_Pa"], rel=1e-6
    )
    # the mesh: jet refinement and prism layers, with their coverage
    assert st["mesh"]["jet_refinement"]["level"] == 1 and st["mesh"]["jet_refinement"]["cells_across"] >= 6
    lay = st["mesh"]["layers"]
    assert lay["requested"] == 3 and lay["added"] and 0.5 < lay["coverage"] <= 1.0
    assert 0.5 < lay["extruded_fraction"] <= 1.0
    for f in ("UMean", "pMean", "wallShearStressMean", "magWallShearStressMean", "V", "U", "p"):
        assert (end / f).exists(), f
    assert (case / "transient.png").exists() and (case / "logs" / "log.pimpleFoam.average").exists()
    assert json.loads((case / "status.json").read_text())["transient"]["stationary"] is True


@pytest.mark.openfoam
@needs_foam
def test_jet_transient_resampled_from_the_means(jet_transient):
    """fields.npz keeps the names U, p, WSS, taken from the time averages; TAWSS and OSI added."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vcs"))
    from test_resample import straight_model

    from vcs.cfd import sample_case

    case, st = jet_transient
    ax = JET_AXIS / np.linalg.norm(JET_AXIS)
    model = straight_model(radius_mm=JET_R * 1e3, length_mm=JET_L * 1e3, axis=ax)
    f = sample_case(case, model, n_tau=9, n_theta=8, n_rho=4)
    assert str(f["field_source"]) == "time_average"
    assert f["U"].shape == (9, 8, 4, 3) and f["WSS"].shape == (9, 8, 3) and f["p"].shape == (9, 8, 4)
    assert f["OSI"].shape == (9, 8) and (0 <= f["OSI"]).all() and (f["OSI"] <= 0.5).all()
    assert f["TAWSS"].shape == (9, 8) and (f["TAWSS"] > 0).all()
    inst = sample_case(case, model, n_tau=9, n_theta=8, n_rho=4, fields="instantaneous")
    assert str(inst["field_source"]) == "instantaneous" and "OSI" not in inst
    with pytest.raises(VCSInputError, match="fields must be one of"):
        sample_case(case, model, n_tau=9, n_theta=8, n_rho=4, fields="mean")


@pytest.mark.openfoam
@needs_foam
def test_jet_transient_too_short_window_is_not_stationary(tmp_path):
    """A longest window of 1/50 flow-through right after 3 SIMPLE iterations: its means are not
    known to the tolerance (the flow still starts up: fewer than 3 batches of 3 integral time
    scales, a range far wider than 3 %); converged false with the reason naming the error bars and
    what to change (run in parallel: decomposed transient stages, the Courant numbers and probe
    cells read from the processors, reconstructPar of the end)."""
    cfg = deep_merge(
        JET_CFG,
        {
            "solver": {
                "max_iterations": 3,
                "startup_iterations": 1,
                "transient": {"min_flow_throughs": 0.02, "max_flow_throughs": 0.02, "washout_flow_throughs": 0.0},
            }
        },
    )
    render_case(tmp_path / "short", _jet_tube(tmp_path), cfg, flavour="esi")
    st = run_case(tmp_path / "short", ranks=2)
    assert st["mesh_ok"] and (tmp_path / "short" / "processor1").is_dir(), st["reason"]
    assert st["converged"] is False
    assert "time average not known to the tolerance" in st["reason"] and "max_flow_throughs" in st["reason"]
    tr = st["transient"]
    assert tr["stationary"] is False and tr["evaluated"] and st["criterion_used"] == "time_average_stationary"
    assert any(not tr["relative_errors"][k] <= tr["tolerances"][k] for k in tr["tolerances"])
    assert "washout" not in tr["time_steps"] and tr["washout_s"] == 0
    assert tr["statistics"]["U"]["n_probes"] == 64 and tr["courant"]["end_plane_factor"] >= 1
    assert (tmp_path / "short" / tr["end_time_folder"] / "UMean").exists()  # reconstructed
    assert "reconstructPar" in st["timings_s"]


def _averaging_total_time(time_dir: Path) -> float:
    """fieldAverage's accumulated averaging time of UMean, as the function object stored it
    (ESI: uniform/functionObjects/functionObjectProperties, fieldAverage { U { totalTime } })."""
    from PyFoam.RunDictionary.ParsedParameterFile import ParsedParameterFile

    props = ParsedParameterFile(str(time_dir / "uniform" / "functionObjects" / "functionObjectProperties"))
    return float(props["fieldAverage"]["U"]["totalTime"])


@pytest.mark.openfoam
@needs_foam
def test_jet_transient_window_ends_once_its_means_are_known(tmp_path, caplog, monkeypatch):
    """A window of 0.1 to 3 flow-through times on the slow (steady, Re 150) jet, the watch looking
    at every poll: the means settle, so pimpleFoam is stopped (stopAt writeNow) long before the
    longest window; the means written are those of exactly the judged window (fieldAverage's
    accumulated time = end - start of averaging), and the job log says why it stopped."""
    import vcs.cfd.transient as transient

    monkeypatch.setattr(transient, "CHECK_EVERY_S", 0.0)
    caplog.set_level("INFO", logger="vcs.cfd.run")
    cfg = deep_merge(
        JET_CFG,
        {"solver": {"transient": {"min_flow_throughs": 0.1, "max_flow_throughs": 3.0, "washout_flow_throughs": 0.3}}},
    )
    render_case(tmp_path / "ext", _jet_tube(tmp_path), cfg, flavour="esi")
    st = run_case(tmp_path / "ext", ranks=1)
    tr = st["transient"]
    assert tr["evaluated"] and st["converged"] is True, st["reason"]
    assert tr["ended_early_at"] is not None
    assert tr["min_end_time"] - 1e-9 <= tr["end_time"] < tr["averaging_start_time"] + 0.5 * tr["max_window_s"]
    assert tr["window_flow_throughs"] < 1.5
    assert _averaging_total_time(tmp_path / "ext" / tr["end_time_folder"]) == pytest.approx(tr["window_s"], rel=1e-6)
    lines = [r.getMessage() for r in caplog.records if r.name == "vcs.cfd.run"]
    assert any(ln.startswith("steady SIMPLE not converged") and "transient solve" in ln for ln in lines)
    assert any(ln.startswith("averaging window: means known to the tolerance after") for ln in lines), lines
    assert any(ln.startswith("Courant number on the state at") for ln in lines)


@pytest.mark.openfoam
@needs_foam
@pytest.mark.parametrize("fake", ["crash", "silent", "killed"])
def test_transient_fallback_never_raises(tmp_path, monkeypatch, fake):
    """A pimpleFoam that fails, that exits 0 without writing anything, or that is killed from
    outside (the OOM killer's SIGKILL): a reason that says which, no exception."""
    bindir = tmp_path / "bin"
    bindir.mkdir()
    script = bindir / "pimpleFoam"
    body = {
        "crash": 'echo "--> FOAM FATAL ERROR: fake solver"; exit 1',
        "silent": "exit 0",
        "killed": "kill -9 $$",
    }[fake]
    script.write_text(f"#!/bin/sh\n{body}\n")
    script.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bindir}:{os.environ['PATH']}")
    cfg = deep_merge(JET_CFG, {"solver": {"max_iterations": 3, "startup_iterations": 0}})
    render_case(tmp_path / "c", _jet_tube(tmp_path), cfg, flavour="esi")
    st = run_case(tmp_path / "c", ranks=1)
    assert st["converged"] is False and "transient fallback" in st["reason"]
    assert st["criterion_used"] == "none" and st["transient"]["evaluated"] is False
    if fake == "crash":
        assert "pimpleFoam (washout) failed" in st["reason"] and st["failed_log"].endswith("log.pimpleFoam.washout")
    elif fake == "killed":
        assert "pimpleFoam (washout) was killed by signal 9 (SIGKILL) from outside the run" in st["reason"]
    else:
        assert "wrote no time folder" in st["reason"]
    assert st["fields"]["time_averaged"] is False


@pytest.mark.openfoam
@needs_foam
def test_diverged_simple_hands_over_to_the_transient(tmp_path, monkeypatch):
    """SIMPLE's main stage dies of a floating point exception (a simpleFoam that fakes it after
    the real start-up): the transient fallback starts from the start-up's state and its window is
    judged; without the fallback the divergence is the reason."""
    real = shutil.which("simpleFoam")
    bindir = tmp_path / "bin"
    bindir.mkdir()
    script = bindir / "simpleFoam"
    script.write_text(
        "#!/bin/bash\n"
        "if grep -Eq '^endTime +20;' system/controlDict; then\n"  # the main stage (max_iterations 20)
        '  echo "#0  Foam::error::printStack(Foam::Ostream&)"; echo "Floating point exception"; exit 136\n'
        "fi\n"
        f'exec "{real}" "$@"\n'
    )
    script.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bindir}:{os.environ['PATH']}")
    stl = _jet_tube(tmp_path)
    tr_cfg = {"min_flow_throughs": 0.1, "max_flow_throughs": 0.1, "washout_flow_throughs": 0.05}
    cfg = deep_merge(JET_CFG, {"solver": {"transient": tr_cfg}})
    render_case(tmp_path / "c", stl, cfg, flavour="esi")
    st = run_case(tmp_path / "c", ranks=1)
    tr = st["transient"]
    assert "simpleFoam (main) diverged: floating point exception" in tr["steady_not_converged"]
    assert tr["started_from"] == "SIMPLE iteration 5" and tr["start_time"] == 5
    assert tr["evaluated"] and st["criterion_used"] == "time_average_stationary"
    assert st["converged"] is tr["stationary"]
    assert st["reason"] is None if tr["stationary"] else "not known to the tolerance" in st["reason"]
    assert "failed_log" not in st
    render_case(tmp_path / "n", stl, deep_merge(cfg, {"solver": {"fallback": "none"}}), flavour="esi")
    st = run_case(tmp_path / "n", ranks=1)
    assert st["converged"] is False and "transient" not in st
    assert st["reason"].startswith("simpleFoam (main) diverged") and st["failed_log"].endswith("log.simpleFoam")


# ----------------------------------------------------------------- SIMPLE residual plateau


@pytest.mark.openfoam
@needs_foam
def test_residual_plateau_is_steady_and_a_too_strict_check_is_not(tmp_path):
    """SIMPLE stopped by max_iterations above an unreachable residual tolerance (1e-12) on a
    Poiseuille tube whose solution no longer changes: the plateau check runs 60 more iterations,
    finds dp, mean |WSS| and U unchanged (< 1e-4) and calls it converged (criterion_used
    residual_plateau), and the pressure drop is Hagen-Poiseuille's. With a plateau tolerance no
    solution meets (1e-14) the same run is not converged, with the changes and the reason. (A
    limit cycle: test_plateau_pressure_change_sees_a_limit_cycle.)"""
    stl = _tube(tmp_path)
    cfg = deep_merge(
        POIS_CFG,
        {
            "mesh": {"cell_size": 2.0e-3, "layers": 0},
            "solver": {
                "tolerance": 1.0e-12,
                "max_iterations": 400,
                "plateau": {"iterations": 60, "max_residual": 1.0e-3, "tolerance": 1.0e-4, "early_stop": False},
            },
        },
    )
    render_case(tmp_path / "a", stl, cfg, flavour="esi")
    st = run_case(tmp_path / "a", ranks=1)
    pl = st["plateau"]
    assert st["converged"] is True and st["criterion_used"] == "residual_plateau", (st["reason"], pl)
    assert st["reason"] is None and "residual plateau" in st["criterion"]
    assert pl["stationary"] and pl["from_iteration"] == "400" and pl["to_iteration"] == "460"
    assert all(v < 1e-4 for v in pl["changes"].values()), pl
    assert pl["max_residual_in_window"] < 1e-3
    assert st["iterations"] == 460 and st["stage_iterations"]["simpleFoam.plateau"] == 60
    assert "transient" not in st
    mu = DEFAULTS["physics"]["nu"] * DEFAULTS["physics"]["rho"]
    dp_k, length, _ = _sections(tmp_path / "a", st)
    dp_hp = 8 * mu * length * Q_POIS / (np.pi * R**4)
    assert dp_k * DEFAULTS["physics"]["rho"] == pytest.approx(dp_hp, rel=0.06)

    strict = deep_merge(cfg, {"solver": {"plateau": {"tolerance": 1.0e-14}}})
    render_case(tmp_path / "b", stl, strict, flavour="esi")
    st = run_case(tmp_path / "b", ranks=1)
    pl = st["plateau"]
    assert st["converged"] is False and st["criterion_used"] == "none"
    assert pl["stationary"] is False and pl["why"].startswith("still changing:"), pl
    assert st["reason"].startswith("SIMPLE did not reach initial residuals < 1e-12 in 400 iterations")
    assert "; plateau check (60 more iterations): still changing: " in st["reason"]


@pytest.mark.openfoam
@needs_foam
def test_simple_stops_as_soon_as_its_residuals_level_off(tmp_path):
    """Issue 23: SIMPLE ran all of max_iterations before the plateau check even when its residuals
    had levelled off long before. The same Poiseuille tube with an unreachable tolerance (1e-12)
    and max_iterations 3000: the main stage is stopped once p and U fell by less than x1.5 over
    the 60-iteration window (stopAt writeNow), the plateau check runs from there, the patient is
    converged (residual_plateau), with the same pressure drop as a run to iteration 400 without
    the early stop (within the plateau tolerance), in far fewer iterations than 3000."""
    stl = _tube(tmp_path)
    base = deep_merge(
        POIS_CFG,
        {
            "mesh": {"cell_size": 2.0e-3, "layers": 0},
            "solver": {
                "tolerance": 1.0e-12,
                "plateau": {"iterations": 60, "max_residual": 1.0e-3, "tolerance": 1.0e-4},
            },
        },
    )
    full = deep_merge(base, {"solver": {"max_iterations": 400, "plateau": {"early_stop": False}}})
    early = deep_merge(base, {"solver": {"max_iterations": 3000, "plateau": {"early_stop": True}}})
    render_case(tmp_path / "full", stl, full, flavour="esi")
    ref = run_case(tmp_path / "full", ranks=1)
    render_case(tmp_path / "early", stl, early, flavour="esi")
    st = run_case(tmp_path / "early", ranks=1)
    stop = st["plateau_early_stop"]
    assert st["converged"] is True and st["criterion_used"] == "residual_plateau", (st["reason"], st.get("plateau"))
    assert 120 <= stop["iteration"] < 3000 and max(stop["decline_factor"].values()) < 1.5, stop
    written = int(st["plateau"]["from_iteration"])
    if stop["deterministic"]:  # set ahead of the solver (issue 38): exactly there
        assert written == stop["iteration"] == stop["decided_at"] + stop["lead"]
    else:  # the solver was past it when the log was read: stopped where it was
        assert stop["iteration"] <= written < stop["iteration"] + 50
    assert st["iterations"] == written + 60 and "stopped early" in st["criterion"]
    dp = st["inlet_minus_outlet_pressure"]["Pa"]
    assert dp == pytest.approx(ref["inlet_minus_outlet_pressure"]["Pa"], rel=1e-3)
    assert "plateau_early_stop" not in ref


def test_plateau_pressure_change_sees_a_limit_cycle():
    """An odd/even 2-cycle of SIMPLE (period dividing the window): equal ends, but the check
    looks at every iteration of the window."""
    from vcs.cfd.run import plateau_pressure_change

    cycle = np.array([10.0, 11.0] * 50 + [10.0])  # 101 values, iterations t0..t0+100
    assert cycle[0] == cycle[-1]
    assert plateau_pressure_change(cycle, 10.0) == pytest.approx(0.1)
    assert plateau_pressure_change(np.full(101, 10.0), 10.0) == 0.0
    drift = 10.0 + 1e-3 * np.arange(101)
    assert plateau_pressure_change(drift, 10.0) == pytest.approx(0.01)


def test_signal_deaths_are_told_apart(tmp_path):
    """KILL/TERM are deaths from outside (OOM killer, scheduler); SEGV/ABRT the utility's own crash."""
    from vcs.cfd.run import _solver_failure, _utility_failure

    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "log.snappyHexMesh").write_text("Create mesh\n\n# vcsflow: killed by signal 9 (SIGKILL)\n")
    assert _utility_failure(tmp_path, "snappyHexMesh").startswith(
        "snappyHexMesh was killed by signal 9 (SIGKILL) from outside the run (out of memory"
    )
    (logs / "log.simpleFoam").write_text("Time = 3\n\n# vcsflow: killed by signal 11 (SIGSEGV)\n")
    assert _solver_failure(logs / "log.simpleFoam", "main") == (
        "simpleFoam (main) crashed with signal 11 (SIGSEGV) (see logs/log.simpleFoam)"
    )
    # every OpenFOAM banner mentions floating point exceptions: a kill early in the run (a short
    # log, banner included) is a kill, not a divergence; the sigFpe handler's trace is one
    banner = "trapFpe: Floating point exception trapping enabled (FOAM_SIGFPE).\nsigFpe : Enabling floating point\n"
    (logs / "log.simpleFoam").write_text(banner + "Time = 1\n\n# vcsflow: killed by signal 9 (SIGKILL)\n")
    assert "was killed by signal 9 (SIGKILL)" in _solver_failure(logs / "log.simpleFoam", "main")
    (logs / "log.simpleFoam").write_text(banner + "Time = 1\n\n# vcsflow: killed by signal 15 (SIGTERM)\n")
    assert "was killed by signal 15 (SIGTERM)" in _solver_failure(logs / "log.simpleFoam", "main")
    trace = "#0  Foam::error::printStack(Foam::Ostream&)\n#1  Foam::sigFpe::sigHandler(int)\n"
    (logs / "log.simpleFoam").write_text(banner + "Time = 9\n" + trace + "\n# vcsflow: killed by signal 8 (SIGFPE)\n")
    assert _solver_failure(logs / "log.simpleFoam", "main").startswith("simpleFoam (main) diverged: floating point")


def test_plateau_settings_are_checked(tmp_path):
    for bad in (
        {"iterations": -1},
        {"iterations": 5},
        {"iterations": 50.5},
        {"iterations": True},
        {"max_residual": 0},
        {"tolerance": 0.5},
        {"window": 100},
    ):
        cfg = {"solver": {"plateau": bad}}
        with pytest.raises(VCSInputError, match=r"cfd\.solver\.plateau"):
            render_case(tmp_path / "x", _tube(tmp_path), cfg, flavour="esi")


_CAVITY = {
    "system/blockMeshDict": """convertToMeters 0.1;
vertices ((0 0 0) (1 0 0) (1 1 0) (0 1 0) (0 0 0.1) (1 0 0.1) (1 1 0.1) (0 1 0.1));
blocks (hex (0 1 2 3 4 5 6 7) (8 8 1) simpleGrading (1 1 1));
boundary (lid {type wall; faces ((3 7 6 2));}
          walls {type wall; faces ((0 4 7 3) (2 6 5 1) (1 5 4 0));}
          frontAndBack {type empty; faces ((0 3 2 1) (4 5 6 7));});
""",
    "system/fvSchemes": """ddtSchemes {default Euler;} gradSchemes {default Gauss linear;}
divSchemes {default none; div(phi,U) Gauss linear;} laplacianSchemes {default Gauss linear orthogonal;}
interpolationSchemes {default linear;} snGradSchemes {default orthogonal;}
""",
    "system/fvSolution": """solvers {p {solver PCG; preconditioner DIC; tolerance 1e-6; relTol 0.05;}
pFinal {$p; relTol 0;} U {solver smoothSolver; smoother symGaussSeidel; tolerance 1e-5; relTol 0;}}
PISO {nCorrectors 2; nNonOrthogonalCorrectors 0; pRefCell 0; pRefValue 0;}
""",
    "constant/transportProperties": "transportModel Newtonian; nu 0.01;\n",
    "0/U": """dimensions [0 1 -1 0 0 0 0]; internalField uniform (0 0 0);
boundaryField {lid {type fixedValue; value uniform (1 0 0);} walls {type noSlip;} frontAndBack {type empty;}}
""",
    "0/p": """dimensions [0 2 -2 0 0 0 0]; internalField uniform 0;
boundaryField {lid {type zeroGradient;} walls {type zeroGradient;} frontAndBack {type empty;}}
""",
}


@needs_foam
def test_restart_finds_a_time_folder_written_with_more_digits(tmp_path):
    """A time folder OpenFOAM wrote with more digits than the controlDict's timePrecision (it raises
    the precision on its own: '366.0959205891', AortaCFD patient1's wash-out stopped by writeNow) is
    looked for under a 10-digit name by a solver started from the latest time and not found; the
    stages render timePrecision from the folders (vcs.cfd.utilities.time_precision). Real icoFoam on
    a 8x8 lid-driven cavity."""
    from vcs.cfd.openfoam import foam_env
    from vcs.cfd.utilities import time_precision

    name = "366.0959205891"  # 13 significant digits
    for rel, body in _CAVITY.items():
        cls = "volVectorField" if rel == "0/U" else "volScalarField" if rel == "0/p" else "dictionary"
        head = f"FoamFile {{version 2.0; format ascii; class {cls}; object {Path(rel).name};}}\n"
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(head + body)

    def control(precision: int) -> None:
        (tmp_path / "system" / "controlDict").write_text(
            "FoamFile {version 2.0; format ascii; class dictionary; object controlDict;}\n"
            "application icoFoam; startFrom latestTime; startTime 0; stopAt endTime; "
            f"endTime {float(name) + 0.01!r}; deltaT 0.005; writeControl timeStep; writeInterval 100; "
            f"writeFormat ascii; timeFormat general; timePrecision {precision};\n"
        )

    def run(precision: int) -> subprocess.CompletedProcess:
        control(precision)
        return subprocess.run(["icoFoam"], cwd=tmp_path, env=env, capture_output=True, text=True)

    env = foam_env()
    control(10)
    assert subprocess.run(["blockMesh"], cwd=tmp_path, env=env, capture_output=True).returncode == 0
    (tmp_path / "0").rename(tmp_path / name)
    (tmp_path / name / "uniform").mkdir()
    (tmp_path / name / "uniform" / "time").write_text(  # as pimpleFoam writes it: the value's every digit
        "FoamFile {version 2.0; format ascii; class dictionary; object time;}\n"
        f'value 366.095920589135972; name "{name}"; index 10; deltaT 0.005; deltaT0 0.005;\n'
    )
    assert time_precision(tmp_path) == 13

    failed = run(10)
    assert failed.returncode != 0 and "cannot find file" in failed.stdout + failed.stderr
    ok = run(time_precision(tmp_path))
    assert ok.returncode == 0, ok.stdout[-2000:]
    assert "Time = 366.1009205891" in ok.stdout  # the first step from the 13-digit folder
