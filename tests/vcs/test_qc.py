"""The per-patient QC sheet (vcs.qc, issue 26 item 2) without a CFD case: a fitted phantom whose
mesh is given in metres (the residuals of the fit, in mm, must land on every vertex of the input
mesh), and a patient whose fit failed (the sheet names the stage and reason; every panel says why
it is missing, none is drawn from a failure record). The sheet of a finished CFD case is checked
on the CI cohort (tests/workflow/test_demo.py) and in the report (tests/workflow/report_check.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import vcs_in_process

pv = pytest.importorskip("pyvista")

CFD_PANELS = ("mesh_slice", "mesh_wall", "residual_history", "velocity", "wss")
FIT_PANELS = ("fit_overlay", "residual_surface", "residual_map")


def _can_render() -> str | None:
    try:
        probe = pv.Plotter(off_screen=True, window_size=[32, 32])
        probe.add_mesh(pv.Sphere())
        probe.screenshot(return_img=True)
        probe.close()
    except Exception as exc:  # noqa: BLE001
        return f"no off-screen render window: {exc}"
    return None


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A phantom aorta written in metres and fitted with --units m: (mesh path, fit dir)."""
    why = _can_render()
    if why:
        pytest.skip(why)
    d = tmp_path_factory.mktemp("qc")
    stl = d / "aorta_mm.stl"
    r = vcs_in_process(
        "phantom", "--kind", "aorta", "--seed", "3", "--resolution", "3", "-o", stl, "--params", d / "p.json"
    )
    assert r.returncode == 0, r.stderr
    mesh = pv.read(str(stl)).scale(1e-3)  # the same surface in metres
    mesh.save(str(d / "aorta_m.stl"))
    r = vcs_in_process("fit", d / "aorta_m.stl", "-o", d / "fit", "--units", "m")
    assert r.returncode == 0, r.stderr
    return d / "aorta_m.stl", d / "fit"


def test_fit_panels_drawn_and_residuals_on_every_vertex_in_mm(fitted, tmp_path):
    from matplotlib.image import imread

    from vcs.qc import PatientFiles, _input_surface, read_sheet_data, write_qc_sheet

    mesh, fit = fitted
    files = PatientFiles("P", mesh=mesh, fit_dir=fit, status=tmp_path / "missing.json")
    drawn = write_qc_sheet(files, tmp_path / "qc.png")
    assert all(drawn[p] == "drawn" for p in FIT_PANELS), drawn
    assert all(drawn[p].startswith("not available") for p in CFD_PANELS), drawn
    # the input mesh in mm (scaled by its units) carries the fit's residual at every vertex
    surface = _input_surface(read_sheet_data(files))
    res = pv.read(str(fit / "wall_residuals.vtp"))
    report = json.loads((fit / "fit_report.json").read_text())
    assert report["units"] == "m" and report["fraction_points_used"] == 1.0
    np.testing.assert_allclose(surface.points, 1e3 * pv.read(str(mesh)).points, rtol=1e-6)
    r = np.asarray(surface.point_data["residual"])
    assert np.isfinite(r).all()
    assert report["outputs_units"] == "m"  # the VTP is in the mesh's units: mm = 1000 x its values
    np.testing.assert_allclose(np.sort(r), np.sort(1e3 * np.asarray(res.point_data["residual"])), rtol=1e-12)
    assert float(np.mean(np.abs(r))) == pytest.approx(report["residual_mean_mm"], rel=1e-6)
    img = imread(tmp_path / "qc.png")[..., :3]
    assert img.shape[0] > 1000 and img.shape[1] > 1200
    h, w = img.shape[:2]
    top_left = img[int(0.05 * h) : h // 3, : w // 3]  # the overlay panel: a drawn vessel, not blank
    assert (top_left.max(axis=2) - top_left.min(axis=2) > 0.15).mean() > 0.02


def test_a_failed_fit_gets_a_sheet_naming_its_stage_and_reason(tmp_path):
    from vcs.qc import PANELS, PatientFiles, read_sheet_data, write_qc_sheet

    why = _can_render()
    if why:
        pytest.skip(why)
    record = {"failed": True, "stage": "fit", "reason": "vcs fit: error: the mesh has no closed lumen", "patient": "P"}
    fit = tmp_path / "fit"
    fit.mkdir()
    for name in ("model.json", "fit_report.json", "centerline.vtp", "wall_residuals.vtp"):
        (fit / name).write_text(json.dumps(record))
    (tmp_path / "status.json").write_text(json.dumps({**record, "converged": False}))
    (tmp_path / "mesh.stl").write_text("solid broken\nendsolid broken\n")
    files = PatientFiles(
        "P", mesh=tmp_path / "mesh.stl", fit_dir=fit, case_dir=tmp_path / "case", status=tmp_path / "status.json"
    )
    usable, line = read_sheet_data(files).verdict
    assert not usable and line == "failed at fit: vcs fit: error: the mesh has no closed lumen"
    drawn = write_qc_sheet(files, tmp_path / "qc.png")
    assert set(drawn) == {name for name, _ in PANELS}
    missing = {k: v for k, v in drawn.items() if k != "verdict"}
    assert all(v.startswith("not available") for v in missing.values()), drawn
    assert (tmp_path / "qc.png").stat().st_size > 10_000 and not list(tmp_path.glob(".qc*"))


def test_a_patient_whose_mesh_failed_gets_its_fit_panels_and_key_numbers(fitted, tmp_path):
    """The CI cohort's broken patient: a good fit, blockMesh failed (no cells, no residuals): the
    verdict names the stage, the key numbers show '-' for what the CFD did not produce."""
    from vcs.qc import PatientFiles, key_numbers, read_sheet_data, write_qc_sheet

    mesh, fit = fitted
    status = {"converged": False, "reason": "blockMesh failed: cannot read", "failed_log": "logs/log.blockMesh"}
    status.update(cells=None, iterations=None, mass_imbalance=None, criterion_used=None)
    (tmp_path / "status.json").write_text(json.dumps(status))
    files = PatientFiles("P", mesh=mesh, fit_dir=fit, case_dir=tmp_path / "case", status=tmp_path / "status.json")
    d = read_sheet_data(files)
    usable, line = d.verdict
    assert not usable and line.startswith("failed at mesh: ") and "blockMesh failed: cannot read" in line
    lines = key_numbers(d)
    assert "cells             -" in lines and any(line.startswith("fit quality       ok") for line in lines)
    drawn = write_qc_sheet(files, tmp_path / "qc.png")
    assert drawn["verdict"] == "drawn" and all(drawn[p] == "drawn" for p in FIT_PANELS), drawn
    assert not any(v.startswith("could not draw") for v in drawn.values()), drawn


@pytest.mark.parametrize("stationary", [True, False])
def test_the_transient_verdict_figure_shows_every_judged_quantity(tmp_path, monkeypatch, caplog, stationary):
    """transient.png (embedded in the QC sheet of a transient run): one row per quantity the
    verdict judged (dp, area-mean |WSS|, probe |U|), drawn from the run's records."""
    from matplotlib.image import imread

    import vcs.cfd.transient as tr

    t = np.linspace(1.0, 3.0, 400)
    rng = np.random.default_rng(0)
    rec = {
        "t": t,
        "dp": 0.02 + 0.002 * np.sin(9 * t) + 1e-4 * rng.standard_normal(t.size),
        "tawss": 1e-3 * (1 + 0.1 * np.cos(7 * t)),
        "U": 0.3 + 0.01 * rng.standard_normal((t.size, 6)),  # two probe cells, 3 components
    }
    monkeypatch.setattr(tr, "_records", lambda *a, **k: rec)
    state = {"cfd": {"physics": {"rho": 1060.0}}}
    plan = {"start_time": 1.0, "averaging_start_time": 1.5, "flow_through_time_s": 0.5}
    rel = {"inlet_minus_outlet_pressure": 0.01, "tawss_mean": 0.02, "U": 0.05 if stationary else 0.4}
    verdict = {
        "window_s": 1.5,
        "confidence": 0.95,
        "stationary": stationary,
        "relative_errors": rel,
        "tolerances": {"inlet_minus_outlet_pressure": 0.03, "tawss_mean": 0.03, "U": 0.2},
        "statistics": {
            "inlet_minus_outlet_pressure": {"mean_Pa": 21.2, "half_width_Pa": 0.2},
            "tawss_mean": {"mean_Pa": 1.06, "half_width_Pa": 0.02},
            "U": {"relative": rel["U"]},
        },
    }
    with caplog.at_level("WARNING"):
        tr._plot_transient(tmp_path, state, plan, verdict)
    assert not caplog.records, caplog.text
    img = imread(tmp_path / "transient.png")[..., :3]
    assert img.shape[0] > 2.5 * 230  # three rows of ~230 px, not the one-row figure
    ink = (img.max(axis=2) - img.min(axis=2) > 0.2).mean()
    assert ink > 0.01  # curves and bands drawn
