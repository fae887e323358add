"""A pulsatile atlas through the whole workflow with the real OpenFOAM (marker ``openfoam``):
config/pulsatile.yaml (the shipped ascending-aorta waveform) on three CI-sized demo aortas
(config/ci.yaml meshes), two cycles of which one is kept, one patient with its own waveform from
the patients sheet. The truths: the inflow each patient got (the waveform's mean, scaled by the
inlet area, or the patient's own file as given), mass conservation over the kept cycle, the marker
definitions on the VCS grid (RRT, ECAP from TAWSS, OSI), and an atlas with a PCA per marker and
per phase field. config/pulsatile.yaml at production size: bench/bench_cohort.py --configfile
config/pulsatile.yaml, then bench/pulsatile_table.py (the README's table)."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import yaml
from conftest import REPO, ci_workdir, merge_config

from vcs.cfd.foamfiles import function_series
from vcs.cfd.waveform import load_waveform

HAVE_FOAM = shutil.which("pimpleFoam") is not None
SEEDS = (1, 2, 3)
SHIPPED = REPO / "vcs" / "data" / "waveforms" / "ascending_aorta.csv"
PULSATILE_CI = {
    "cfd": {
        "pulsatile": {
            "cycles": 2,
            "discard_cycles": 1,
            "max_cycles": 3,
            "periodicity_tolerance": 0.25,  # coarse meshes, one wash-in cycle: CI checks the chain
            "tawss_tolerance": 0.25,
            "samples_per_cycle": 40,
            "min_steps_per_cycle": 40,
            "max_co": 2.0,
            "outer_correctors": 2,
        },
        "solver": {"timeout_s": 900},
    },
}


def _own_waveform(path, factor: float):
    """The shipped waveform scaled by ``factor`` (a patient's own file)."""
    lines = SHIPPED.read_text().splitlines()
    i = lines.index("time_s,flow_rate_l_min")
    rows = [ln.split(",") for ln in lines[i + 1 :] if ln.strip()]
    body = "\n".join(f"{t},{float(q) * factor:.10g}" for t, q in rows)
    path.write_text(f"# the shipped waveform x {factor}\ntime_s,flow_rate_l_min\n{body}\n")
    return path


@pytest.mark.openfoam
@pytest.mark.skipif(not HAVE_FOAM, reason="OpenFOAM (pimpleFoam) not installed; run scripts/install.sh")
def test_pulsatile_atlas_of_three_patients(tmp_path):
    wd = ci_workdir(tmp_path, SEEDS)
    own = _own_waveform(tmp_path / "own.csv", 0.6)
    rows = [{"id": f"demo_aorta_{s}", "mesh": f"results/demo/aorta_seed{s}.stl", "units": "mm"} for s in SEEDS]
    rows[2]["inflow_waveform"] = str(own)
    wd.write_sheet(rows)
    pulsatile = yaml.safe_load((REPO / "config" / "pulsatile.yaml").read_text())
    pulsatile["cfd"]["inlet"]["waveform"] = str(SHIPPED)
    cfg = merge_config(merge_config(wd.config(), pulsatile), PULSATILE_CI)
    wd.write_config(cfg)
    r = wd.snakemake("--profile", str(REPO / "profiles" / "local"), "--cores", "2", check=False, timeout=2400)
    res = tmp_path / "results"
    statuses = {s: json.loads((res / "patients" / f"demo_aorta_{s}" / "status.json").read_text()) for s in SEEDS}
    report = "\n".join(f"seed {s}: {st.get('converged')} {st.get('reason')}" for s, st in statuses.items())
    assert r.returncode == 0, report + "\n" + r.stderr[-3000:]
    shipped, mine = load_waveform(SHIPPED), load_waveform(own)
    for s, st in statuses.items():
        assert st["converged"] is True and st["criterion_used"] == "periodic_cycles", report
        pu = st["pulsatile"]
        assert pu["period_s"] == pytest.approx(0.8) and pu["kept_cycles"] == [pu["cycles_run"]]
        wf = st["inflow"]["waveform"]
        if s == 3:  # the patient's own waveform, as given
            assert wf["scale_factor"] == 1.0 and "own waveform" in st["inflow"]["why"]
            assert st["inflow"]["flow_rate_m3_s"] == pytest.approx(mine.mean_m3_s, rel=1e-9)
        else:  # the shipped one, scaled by the inlet area as the steady flow is
            area = st["inflow"]["inlet_area_m2"]
            factor = min(area / cfg["cfd"]["inlet"]["reference_inlet_area"], cfg["cfd"]["inlet"]["max_scale"])
            assert wf["scale_factor"] == pytest.approx(factor)
            assert st["inflow"]["flow_rate_m3_s"] == pytest.approx(shipped.mean_m3_s * factor, rel=1e-9)
        # the inflow at every time step is the applied waveform there (the boundary data hold its
        # knots, linear in between); what comes in goes out over the kept cycle
        applied = (mine if s == 3 else shipped).scaled(wf["scale_factor"])
        rec = function_series(res / "patients" / f"demo_aorta_{s}" / "case", "flowRate_inlet")
        assert len(rec) > 100
        np.testing.assert_allclose(-rec[:, 1], applied(rec[:, 0]), atol=1e-6 * applied.peak_m3_s)
        assert st["mass_imbalance"] < 1e-3
        assert 0 <= st["osi"]["min"] and st["osi"]["max"] <= 0.5 and st["tawss_Pa"]["min"] >= 0
        f = np.load(res / "patients" / f"demo_aorta_{s}" / "fields.npz")
        assert str(f["field_source"]) == "pulsatile"
        tawss, osi = f["TAWSS"], f["OSI"]
        ok = np.isfinite(f["RRT"])
        np.testing.assert_allclose(f["ECAP"], osi / tawss, rtol=1e-12)
        np.testing.assert_allclose(f["RRT"][ok], 1 / ((1 - 2 * osi[ok]) * tawss[ok]), rtol=1e-12)
        assert list(f["phase_names"]) == ["peak_systole", "end_systole", "mid_diastole"]
        assert f["phase/peak_systole/U"].shape == f["U"].shape
        # at peak systole the flow is several times the mean flow (the waveform's peak / mean ~ 5.7)
        u_peak = np.abs(f["phase/peak_systole/U_vcs"][..., 0]).mean()
        u_mean = np.abs(f["U_vcs"][..., 0]).mean()
        assert u_peak > 3 * u_mean
    atlas = json.loads((res / "atlas" / "atlas.json").read_text())
    assert atlas["flow_kind"] == "pulsatile"
    assert set(atlas["field_sources"].values()) == {"pulsatile"}
    for name in ("TAWSS", "OSI", "ECAP", "phase/peak_systole/U", "phase/mid_diastole/WSS"):
        assert name in atlas["flow_explained_variance"], sorted(atlas["flow_explained_variance"])
