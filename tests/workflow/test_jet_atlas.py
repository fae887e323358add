"""An atlas of jet patients through the whole workflow with the real OpenFOAM (marker ``openfoam``):
config/config.yaml + config/paper.yaml (the jet, steady SIMPLE first, the transient fallback when it
does not converge) on three demo aortas, shrunk to CI size: CI meshes (config/ci.yaml; its inflow
and fallback replaced), a slow, wide jet in a viscous fluid (0.1 m/s over 2 cm2, nu 2e-5: Re_jet
~ 80, steady, so a window of 0.1 flow-through times is stationary), SIMPLE held below its
(unreachable) tolerance so that every patient goes through pimpleFoam and its time average. The
README's atlas of the paper's jet (bench/jet_atlas.py) is the same chain at the paper's Reynolds
number over 10 flow-through times."""

from __future__ import annotations

import json
import shutil
import sys

import numpy as np
import pytest
import yaml
from conftest import REPO, merge_config, with_ci_config

HAVE_FOAM = shutil.which("pimpleFoam") is not None
SEEDS = (1, 2, 3)
VELOCITY, VALVE_AREA = 0.1, 2.0e-4  # [m/s], [m2]: Q = 2e-5 m3/s
WINDOW, WASHOUT = 0.1, 0.04  # [flow-through times]
JET_CI = {
    "cfd": {
        # a short, coarse jet cylinder (the default 10 cells across would put 1 mm cells in it)
        "mesh": {"jet_refinement": {"cells_across": 5, "length": 2.0, "radius": 1.5}},
        "inlet": {"velocity": VELOCITY, "valve_area": VALVE_AREA},
        "physics": {"nu": 2.0e-5},
        "solver": {
            "tolerance": 1.0e-12,  # never reached: SIMPLE stops at max_iterations, not converged
            "max_iterations": 120,
            "startup_iterations": 20,
            "plateau": {"iterations": 0},  # no steady verdict by plateau: the fallback runs
            "fallback": "transient",  # (config/ci.yaml: none)
            "timeout_s": 900,
            "transient": {
                "min_flow_throughs": WINDOW,
                "max_flow_throughs": 2 * WINDOW,
                "washout_flow_throughs": WASHOUT,
            },
        },
    },
}


@pytest.mark.openfoam
@pytest.mark.skipif(not HAVE_FOAM, reason="OpenFOAM (pimpleFoam) not installed; run scripts/install.sh")
def test_atlas_of_jet_patients_from_time_averages(tmp_path, workdir_factory, repo):
    rows = [{"id": f"demo_aorta_{s}", "mesh": f"results/demo/aorta_seed{s}.stl", "units": "mm"} for s in SEEDS]
    wd = workdir_factory(tmp_path, rows)
    paper = yaml.safe_load((REPO / "config" / "paper.yaml").read_text())
    cfg = merge_config(merge_config(with_ci_config(wd.config()), paper), JET_CI)  # ci.yaml's inflow replaced
    assert cfg["cfd"]["inlet"]["type"] == "jet" and cfg["cfd"]["inlet"]["scaling"] == "fixed"
    assert cfg["cfd"]["solver"]["fallback"] == "transient"
    wd.write_config(cfg)
    r = wd.snakemake("--profile", str(repo / "profiles" / "local"), "--cores", "2", check=False, timeout=1800)
    res = tmp_path / "results"
    statuses = {}
    for s in SEEDS:
        f = res / "patients" / f"demo_aorta_{s}" / "status.json"
        statuses[s] = json.loads(f.read_text()) if f.exists() else None
    report = "\n".join(
        f"seed {s}: " + ("no status.json" if st is None else f"{st.get('converged')} {st.get('reason')}")
        for s, st in statuses.items()
    )
    assert r.returncode == 0, report + "\n" + r.stderr[-3000:]
    q = VELOCITY * VALVE_AREA
    for s, st in statuses.items():
        assert st is not None
        # SIMPLE did not converge; the time average did: its means known to the tolerance
        assert st["converged"] is True and st["criterion_used"] == "time_average_stationary", report
        assert st["iterations"] == 120 and "steady_not_converged" in st["transient"]
        assert st["inflow"]["flow_rate_m3_s"] == pytest.approx(q)
        tr = st["transient"]
        # window and wash-out in flow-through times of this patient: lumen volume / Q
        assert tr["flow_through_time_s"] == pytest.approx(st["lumen_volume_m3"] / q)
        assert 1.0e-4 < st["lumen_volume_m3"] < 5.0e-4  # a demo aorta: 100-500 cm3
        assert WINDOW * 0.99 <= tr["window_flow_throughs"] <= 2 * WINDOW * 1.01
        assert tr["washout_flow_throughs"] == pytest.approx(WASHOUT, rel=0.01)
        assert tr["stationary"] is True and tr["time_steps"]["average"] > 10
        assert st["fields"]["time_averaged"] is True and st["wall_shear_stress_Pa"]["field"] == "wallShearStressMean"
        # resampled from the window means: U, p, WSS under their names, TAWSS and OSI added
        with np.load(res / "patients" / f"demo_aorta_{s}" / "fields.npz") as z:
            assert str(z["field_source"]) == "time_average"
            assert z["TAWSS"].shape == z["WSS"].shape[:2] and np.isfinite(z["TAWSS"]).all()
            assert ((0 <= z["OSI"]) & (z["OSI"] <= 0.5)).all()
            # the mean wall shear magnitude, resampled, near the case's own area mean (same field)
            tawss = float(np.mean(z["TAWSS"]))
        assert tawss == pytest.approx(st["tawss_Pa"]["mean"], rel=0.15)  # measured 3-8 % apart
    atlas = json.loads((res / "atlas" / "atlas.json").read_text())
    assert atlas["patients_included"] == [f"demo_aorta_{s}" for s in SEEDS] and atlas["patients_excluded"] == []
    assert atlas["field_sources"] == {f"demo_aorta_{s}": "time_average" for s in SEEDS}
    # the atlas records each time average's error bars, as its status.json has them
    assert atlas["time_average_errors"] == {f"demo_aorta_{s}": statuses[s]["time_average_errors"] for s in SEEDS}
    assert set(atlas["flow_explained_variance"]) == {"U", "p", "WSS"}
    # the README's table (bench/jet_atlas.py) reads every figure it prints from these results
    sys.path.insert(0, str(REPO / "bench"))
    from jet_atlas import row

    for s in SEEDS:
        line = row(res, f"demo_aorta_{s}")
        assert line.endswith("| time_average_stationary |") and " - " not in line and "nan" not in line, line
