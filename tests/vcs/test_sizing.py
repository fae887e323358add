"""vcs.cfd.sizing: the cell-size rule, the bounded background box and the inflow, against values
computed by hand on models whose sections are known exactly (tests/model_phantoms.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from vcs.cfd import render_case
from vcs.cfd.openfoam import DEFAULTS, deep_merge
from vcs.cfd.sizing import (
    background_plan,
    choose_cell_size,
    choose_inflow,
    closed_volume,
    section_diameters,
    vessel_sizes,
)
from vcs.errors import VCSInputError
from vcs.surface import wall_mesh, write_multisolid_stl

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from model_phantoms import narrowed_model  # noqa: E402

MM = 1e-3
# rho(tau) through (0, 12), (1/2, 4), (1, 9) mm: rho = 12 - 29 tau + 26 tau^2, smallest at
# tau = 29/52 with rho = 12 - 29^2/104 = 3.91346... mm
D_NARROW_MM = 2 * (12 - 29**2 / 104)
TAU_NARROW = 29 / 52


def mesh_cfg(**over):
    return deep_merge(DEFAULTS["mesh"], over)


def test_section_diameters_are_the_quadratic_radius():
    model = narrowed_model(12.0, 4.0, 9.0)
    tau, d = section_diameters(model, n_tau=11)
    assert d == pytest.approx(2 * (12 - 29 * tau + 26 * tau**2), rel=1e-12)


def test_section_diameter_is_the_equivalent_circle_of_a_non_circular_section():
    """rho = a + b cos(theta): area = pi (a^2 + b^2 / 2), so d = 2 sqrt(a^2 + b^2 / 2) (not 2 a)."""
    from vcs.wall import lsq_wall

    model = narrowed_model(10.0, 10.0, 10.0)
    tt, th = np.meshgrid(np.linspace(0, 1, 41), np.linspace(0, 2 * np.pi, 256, endpoint=False), indexing="ij")
    wall = lsq_wall(tt.ravel(), th.ravel(), (10.0 + 4.0 * np.cos(th)).ravel(), np.ones(tt.size), 7, 15, 0.0)
    model = type(model)(model.vcs, wall)
    _, d = section_diameters(model)
    assert d == pytest.approx(2 * np.sqrt(10.0**2 + 4.0**2 / 2), rel=1e-3)  # 20.785 mm; mean radius gives 20


def test_vessel_sizes_find_ends_and_the_narrowest_section():
    s = vessel_sizes(narrowed_model(12.0, 4.0, 9.0, length=100.0))
    assert s["inlet_diameter_m"] == pytest.approx(24 * MM, rel=1e-12)
    assert s["outlet_diameter_m"] == pytest.approx(18 * MM, rel=1e-12)
    assert s["narrowest_diameter_m"] == pytest.approx(D_NARROW_MM * MM, rel=1e-9)
    assert s["narrowest_tau"] == pytest.approx(TAU_NARROW, abs=1e-5)
    assert s["length_m"] == pytest.approx(0.1, rel=1e-9)


def test_auto_cell_size_follows_the_narrowest_section():
    sizes = vessel_sizes(narrowed_model(12.0, 4.0, 9.0))
    c = choose_cell_size(mesh_cfg(cell_size="auto", cells_across_end=12, cells_across_narrowest=8), sizes, 1e-5)
    # 7.82692 mm / 8 = 0.978365 mm, rounded down to 3 digits; the smaller end alone: 18 / 12 = 1.5 mm
    assert c["cell_size_m"] == pytest.approx(0.978e-3, rel=1e-12)
    assert c["source"] == "auto" and c["governed_by"] == "narrowest section"
    assert c["cells_across_narrowest"] == pytest.approx(D_NARROW_MM / 0.978) and c["cells_across_narrowest"] >= 8
    assert c["cells_across_end"] == pytest.approx(18 / 0.978)
    assert "8 cells across the narrowest section (d = 7.83 mm at tau 0.558)" in c["why"]
    assert c["estimated_lumen_cells"] == round(1e-5 / 0.978e-3**3)


def test_auto_cell_size_follows_the_smaller_end():
    sizes = vessel_sizes(narrowed_model(12.0, 4.0, 9.0))
    c = choose_cell_size(mesh_cfg(cells_across_end=12, cells_across_narrowest=4), sizes, 1e-5)
    assert c["cell_size_m"] == pytest.approx(1.5e-3, rel=1e-12)  # 18 / 12 < 7.83 / 4 = 1.96
    assert c["governed_by"] == "smallest end" and c["cells_across_end"] == pytest.approx(12.0)
    assert "12 cells across the smallest end (d = 18 mm)" in c["why"]


def test_auto_cell_size_is_capped_by_max_cells():
    sizes = vessel_sizes(narrowed_model(12.0, 4.0, 9.0))
    c = choose_cell_size(mesh_cfg(max_cells=1000), sizes, 1e-5)
    # (1e-5 m3 / 1000)^(1/3) = 2.1544 mm, rounded up: 2.16 mm, so at most 1000 cells
    assert c["cell_size_m"] == pytest.approx(2.16e-3, rel=1e-12) and c["governed_by"] == "max_cells"
    assert c["estimated_lumen_cells"] <= 1000 and "raised from 0.978 mm to 2.16 mm" in c["why"]


def test_numeric_and_patient_cell_sizes_are_used_as_given():
    sizes = vessel_sizes(narrowed_model(12.0, 4.0, 9.0))
    c = choose_cell_size(mesh_cfg(cell_size=2e-3), sizes, 1e-5)
    assert c["cell_size_m"] == 2e-3 and c["source"] == "config" and c["cells_across_end"] == pytest.approx(9.0)
    p = choose_cell_size(mesh_cfg(cell_size=2e-3), sizes, 1e-5, override=1.2e-3)
    assert p["cell_size_m"] == 1.2e-3 and p["source"] == "patient" and "cell_size_mm" in p["why"]
    a = choose_cell_size(mesh_cfg(cell_size=2e-3), sizes, 1e-5, override="auto")  # the patient asks for auto
    assert a["cell_size_m"] == pytest.approx(0.978e-3) and a["source"] == "auto" and "cell_size_mm" in a["why"]
    with pytest.raises(VCSInputError, match="positive number"):
        choose_cell_size(mesh_cfg(), sizes, 1e-5, override=-1.0)


def test_background_is_coarsened_within_its_cell_limit():
    lo, hi = np.zeros(3), np.array([0.03, 0.03, 0.3])
    m = mesh_cfg(pad_cells=3, max_background_cells=100_000)
    # 1 mm: 36 x 36 x 306 = 396,576 cells > 100k; 2 mm: 21 x 21 x 156 = 68,796
    b = background_plan(1e-3, lo, hi, m, narrowest=8e-3)
    assert b["level_offset"] == 1 and b["background_cell_size_m"] == pytest.approx(2e-3)
    assert b["ncells"] == [21, 21, 156] and b["background_cells"] == 68_796 and not b["over_limit"]
    assert b["bmin"] == pytest.approx([-6e-3] * 3) and b["bmax"] == pytest.approx([0.036, 0.036, 0.306])
    # a 3 mm narrowest section stops the coarsening at 1.5 mm background cells: stays at 1 mm
    n = background_plan(1e-3, lo, hi, m, narrowest=3e-3)
    assert n["level_offset"] == 0 and n["background_cells"] == 396_576 and n["over_limit"]
    assert "above cfd.mesh.max_background_cells" in n["why"]
    # a small box is never coarsened
    assert background_plan(1e-3, lo, hi / 10, m, narrowest=8e-3)["level_offset"] == 0


def test_closed_volume_of_the_eq8_wall(tmp_path):
    model = narrowed_model(5.0, 5.0, 5.0, length=40.0)
    stl = tmp_path / "tube.stl"
    write_multisolid_stl(wall_mesh(model, n_theta=256), stl, 1e-3)
    from vcs.mesh import read_stl_solids

    # a 256-gon prism: n/2 r^2 sin(2 pi / n) L
    v = 128 * 5.0**2 * np.sin(2 * np.pi / 256) * 40.0 * 1e-9
    assert closed_volume(read_stl_solids(stl)) == pytest.approx(v, rel=1e-9)


# ----------------------------------------------------------------------------- inflow

INLET = deep_merge(DEFAULTS["inlet"], {"type": "parabolic", "flow_rate": 8.3e-5, "reference_inlet_area": 4.909e-4})


def test_fixed_inflow_is_the_config_flow():
    f = choose_inflow(deep_merge(INLET, {"scaling": "fixed"}), 1.5e-4)
    assert f["flow_rate_m3_s"] == 8.3e-5 and f["scale_factor"] == 1.0 and f["source"] == "config"
    assert f["flow_rate_l_min"] == pytest.approx(4.98) and f["mean_inlet_velocity_m_s"] == pytest.approx(
        8.3e-5 / 1.5e-4
    )


def test_inflow_scaled_by_inlet_area_and_capped():
    f = choose_inflow(deep_merge(INLET, {"scaling": "scaled_by_inlet_area"}), 1.5e-4)
    assert f["scale_factor"] == pytest.approx(1.5e-4 / 4.909e-4)  # 0.30556
    assert f["flow_rate_m3_s"] == pytest.approx(8.3e-5 * 0.305561, rel=1e-5)
    assert f["mean_inlet_velocity_m_s"] == pytest.approx(8.3e-5 / 4.909e-4)  # same as the reference's
    big = choose_inflow(deep_merge(INLET, {"scaling": "scaled_by_inlet_area"}), 9e-4)  # a dilated root
    assert big["scale_factor"] == 1.0 and big["flow_rate_m3_s"] == 8.3e-5 and "capped" in big["why"]
    wide = choose_inflow(deep_merge(INLET, {"scaling": "scaled_by_inlet_area", "max_scale": 2.0}), 9e-4)
    assert wide["scale_factor"] == pytest.approx(9e-4 / 4.909e-4)


def test_scaled_jet_keeps_its_velocity_and_scales_its_valve():
    jet = deep_merge(
        DEFAULTS["inlet"], {"type": "jet", "scaling": "scaled_by_inlet_area", "reference_inlet_area": 4e-4}
    )
    f = choose_inflow(jet, 2e-4)  # factor 1/2
    assert f["valve_area_m2"] == pytest.approx(0.5e-4) and f["jet_velocity_m_s"] == pytest.approx(1.2)
    assert f["flow_rate_m3_s"] == pytest.approx(0.6e-4)


def test_patient_inflow_is_applied_as_given():
    scaled = deep_merge(INLET, {"scaling": "scaled_by_inlet_area"})
    f = choose_inflow(scaled, 1.5e-4, patient={"flow_rate": 5e-5})
    assert f["flow_rate_m3_s"] == 5e-5 and f["source"] == "patient" and f["scale_factor"] == 1.0
    g = choose_inflow(scaled, 1.5e-4, patient={"velocity": 1.5, "valve_area": 2e-4})
    assert g["flow_rate_m3_s"] == pytest.approx(3e-4) and g["scaling"] == "patient"


# ------------------------------------------------------------------ the rendered case


def test_render_case_records_sizing_and_inflow(tmp_path):
    """The state (vcsflow_case.json) holds the cell size, why, the background plan, the levels
    raised by the background's offset, the lumen refinement region, and the inflow applied."""
    from PyFoam.RunDictionary.ParsedParameterFile import ParsedParameterFile

    model = narrowed_model(12.0, 4.0, 9.0, length=100.0)
    stl = tmp_path / "wall.stl"
    write_multisolid_stl(wall_mesh(model, n_theta=48), stl, 1e-3)
    cfd = {
        "mesh": {"max_background_cells": 70_000, "inlet_level": [0, 1]},
        "inlet": {"type": "parabolic", "flow_rate": 8.3e-5, "scaling": "scaled_by_inlet_area"},
    }
    st = render_case(tmp_path / "c", stl, cfd, flavour="esi", model=model)
    ms = st["mesh_sizing"]
    assert ms["cell_size_m"] == pytest.approx(0.978e-3) and ms["vessel"]["source"] == "vessel model"
    k = ms["background"]["level_offset"]
    assert k == 1 and ms["background"]["background_cells"] <= 70_000
    assert ms["background"]["background_cell_size_m"] == pytest.approx(0.978e-3 * 2**k)
    assert ms["levels"]["wall"] == [k, k] and ms["levels"]["inlet"] == [k, k + 1] and ms["levels"]["lumen"] == k
    assert ms["smallest_cell_m"] == pytest.approx(0.978e-3 / 2)
    shm = ParsedParameterFile(str(tmp_path / "c/system/snappyHexMeshDict"))
    reg = shm["castellatedMeshControls"]["refinementRegions"]["vessel"]
    assert reg["mode"] == "inside" and int(reg["levels"][0][1]) == k
    surf = shm["castellatedMeshControls"]["refinementSurfaces"]["vessel"]["regions"]
    assert [int(x) for x in surf["inlet"]["level"]] == [k, k + 1]
    a_in = np.pi * 0.012**2 * (48 / (2 * np.pi)) * np.sin(2 * np.pi / 48)  # the 48-gon inlet cap
    assert st["inflow"]["inlet_area_m2"] == pytest.approx(a_in, rel=1e-6)
    assert st["flow_rate"] == pytest.approx(8.3e-5 * a_in / 4.909e-4, rel=1e-6)
    # the patient's own values win and are not scaled
    own = render_case(
        tmp_path / "p", stl, cfd, flavour="esi", model=model, patient={"cell_size": 2e-3, "flow_rate": 4e-5}
    )
    assert own["mesh_sizing"]["cell_size"]["source"] == "patient" and own["mesh_sizing"]["cell_size_m"] == 2e-3
    assert own["flow_rate"] == 4e-5 and own["inflow"]["source"] == "patient"
    with pytest.raises(VCSInputError, match="not both"):
        render_case(
            tmp_path / "x", stl, cfd, flavour="esi", patient={"flow_rate": 4e-5, "velocity": 1, "valve_area": 1e-4}
        )
    with pytest.raises(VCSInputError, match="cell_size must be 'auto' or a number"):
        render_case(tmp_path / "y", stl, {"mesh": {"cell_size": "fine"}}, flavour="esi")


def test_render_case_without_model_sizes_from_the_stl_caps(tmp_path):
    model = narrowed_model(12.0, 4.0, 9.0, length=100.0)
    stl = tmp_path / "wall.stl"
    write_multisolid_stl(wall_mesh(model, n_theta=48), stl, 1e-3)
    st = render_case(tmp_path / "c", stl, {}, flavour="esi")
    v = st["mesh_sizing"]["vessel"]
    assert v["source"].startswith("STL caps")
    r_eq = 9.0 * np.sqrt(48 / (2 * np.pi) * np.sin(2 * np.pi / 48))  # equivalent radius of the 48-gon
    assert v["outlet_diameter_m"] == pytest.approx(2 * r_eq * MM, rel=1e-6)
    assert st["mesh_sizing"]["cell_size_m"] == pytest.approx(np.floor(2 * r_eq / 12 * 100) / 100 * MM)  # 1.49 mm
