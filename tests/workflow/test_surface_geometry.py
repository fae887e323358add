"""`cfd_geometry: surface` through the workflow with the real OpenFOAM (marker ``openfoam``): the
shared vmtk aorta bifurcation (one inlet, two iliac outlets) meshed as the patient has it, the
section inlet -> one iliac (``outlet``), the other iliac ``branch_1``.

* ``murray``: the branch takes r_b^3 / (r_o^3 + r_b^3) of the inflow (its prescribed flow rate)
  and the main outlet the rest: both within 1 % of the target, mass conserved to 1e-4;
* ``rcr`` (steady: the resistances R_p + R_d of each outlet, the totals split by Murray's law):
  each outlet's mean pressure equals its resistance times its flow (p = R Q) to 2 %, so the two
  iliacs, in parallel, share the flow in inverse proportion to their resistances;
* status.json names the ends (centre, area, role) and fields.npz marks the grid's wall points at
  the other iliac's ostium (no WSS is taken from the branch).

CI-sized: a 1.2 mm lumen cell (auto: 0.74 mm) and 1 L/min (Re ~400: steady SIMPLE settles). Skipped without
../shared/data."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
from conftest import REPO

SHARED = REPO.parent / "shared" / "data" / "vessels"
HAVE_FOAM = shutil.which("simpleFoam") is not None
MESH = SHARED / "vmtk_aorta_bifurcation_open.stl"
# `vcs ends`: end:0 the aortic inlet r 7.69 mm, end:1 and end:2 the iliacs r 4.41 and 4.37 mm
ENDS_MM = {"inlet": (221.03, 177.80, 21.30), "outlet": (235.24, 101.57, 29.16), "branch_1": (210.19, 102.87, 30.82)}
ROW = {"mesh": str(MESH), "units": "mm", "inlet": "end:0", "outlet": "end:1", "cfd_geometry": "surface"}
ROW |= {"cell_size_mm": "1.2", "flow_rate_l_min": "1.0"}
R_TOTAL_MMHG_S_ML = 1.0


@pytest.mark.openfoam
@pytest.mark.skipif(not HAVE_FOAM, reason="OpenFOAM (simpleFoam) not installed; run scripts/install.sh")
@pytest.mark.skipif(not MESH.is_file(), reason=f"real vessel meshes not available ({SHARED} is absent)")
def test_bifurcation_surface_murray_and_resistance_outlets(tmp_path, workdir_factory):
    rows = [
        {"id": "bif_murray", **ROW, "outlets": "murray"},
        {"id": "bif_rcr", **ROW, "outlets": "rcr", "rcr_resistance_mmhg_s_ml": str(R_TOTAL_MMHG_S_ML)},
    ]
    wd = workdir_factory(tmp_path, rows)
    targets = [f"results/patients/{r['id']}/fields.npz" for r in rows]
    wd.snakemake("--cores", "2", *targets, timeout=1500)
    res = tmp_path / "results" / "patients"
    st = {r["id"]: json.loads((res / r["id"] / "status.json").read_text()) for r in rows}
    for pid, s in st.items():
        assert s["converged"] is True, (pid, s["reason"])
        # the lumen as the patient has it: three ends, each a patch, named after the section
        geo = s["geometry"]
        assert geo["type"] == "surface"
        ends = {e["name"]: e for e in geo["ends"]}
        assert {n: e["role"] for n, e in ends.items()} == {"inlet": "inlet", "outlet": "outlet", "branch_1": "branch"}
        # the patches are at the far ends of the flow extensions; each end's opening is where it was
        lumen = json.loads((res / pid / "lumen" / "ends.json").read_text())
        opening = {e["name"]: e["opening_center"] for e in lumen["ends"]}
        for name, c in ENDS_MM.items():
            np.testing.assert_allclose(np.array(opening[name]) * 1e3, c, atol=0.05)
        q_in = s["inflow"]["flow_rate_m3_s"]
        assert q_in == pytest.approx(1.0e-3 / 60, rel=1e-9)
        # steady SIMPLE settles at this Re (~400; at 2 L/min the transient fallback took ~5 min each)
        assert s["criterion_used"] in ("residualControl", "residual_plateau"), s["criterion_used"]
        outs = {o["name"]: o for o in s["outlets"]}
        assert set(outs) == {"outlet", "branch_1"}
        q_sum = sum(o["flow_rate_m3_s"] for o in outs.values())
        assert abs(q_sum - q_in) / q_in < 1e-4, (pid, q_sum, q_in)  # mass conserved
        assert abs(s["outlet_mass_balance"]["relative"]) < 1e-4
        # the other iliac's ostium: marked on the wall grid, no WSS there
        f = np.load(res / pid / "fields.npz")
        ostium = f["ostium"]
        assert 0 < ostium.mean() < 0.2, ostium.mean()
        assert np.isnan(f["WSS"][ostium]).all() and np.isfinite(f["WSS"][~ostium]).all()

    # murray: fraction_k = r_k^3 / sum r^3 over both iliacs (equivalent radii of the patches)
    outs = {o["name"]: o for o in st["bif_murray"]["outlets"]}
    r3 = {n: (outs[n]["area_m2"] / np.pi) ** 1.5 for n in outs}
    for n in outs:
        target = r3[n] / sum(r3.values())
        assert outs[n]["target_fraction"] == pytest.approx(target, rel=1e-9)
        assert outs[n]["fraction"] == pytest.approx(target, rel=0.01), (n, outs[n])

    # resistance outlets: p = (R_p + R_d) Q on each iliac, R_k = R_total / fraction_k (Murray split)
    rho = st["bif_rcr"]["rho"]
    r_total = R_TOTAL_MMHG_S_ML * 133.322387415 / 1e-6
    outs = {o["name"]: o for o in st["bif_rcr"]["outlets"]}
    for n, o in outs.items():
        r_k = r_total / (r3[n] / sum(r3.values()))
        assert o["r_p"] + o["r_d"] == pytest.approx(r_k, rel=1e-6)
        assert o["mean_pressure_pa"] == pytest.approx(r_k * o["flow_rate_m3_s"], rel=0.02), (n, o, rho)


@pytest.mark.skipif(not SHARED.is_dir(), reason=f"real vessel meshes not available ({SHARED} is absent)")
def test_a_surface_that_cannot_be_a_lumen_is_a_patient_failure(tmp_path, workdir_factory):
    """The coarse TAH aorta has rounded (closed) ends: no plane for an inlet patch. With
    cfd_geometry surface the patient stops at the lumen stage with the one line of `vcs lumen`,
    passed on to status.json (the atlas lists it as excluded), without running OpenFOAM."""
    from vcs.atlas.cohort import status_exclusion

    row = {"id": "tah", "mesh": str(SHARED / "sphinxsys_tah_aorta_capped_coarse.stl"), "units": "mm"}
    row |= {"inlet": "-23.0,-202.2,-1177.9", "outlet": "6.6,-123.6,-1246.3", "cfd_geometry": "surface"}
    wd = workdir_factory(tmp_path, [row])
    wd.snakemake("--cores", "1", "results/patients/tah/status.json", timeout=600)
    st = json.loads((tmp_path / "results" / "patients" / "tah" / "status.json").read_text())
    assert st["failed"] is True and st["stage"] == "lumen"
    assert "inlet is a rounded (closed) end" in st["reason"] and "cfd_geometry model" in st["reason"]
    assert "\n" not in st["reason"] and "Traceback" not in st["reason"]
    assert status_exclusion(st) == st["reason"]
    assert not (tmp_path / "results" / "patients" / "tah" / "case" / "constant" / "polyMesh").exists()
