"""Fits on every real mesh of ../shared/data/vessels with default parameters (issues 2 and 3)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from vcs.io import read_surface
from vcs.vessel import fit_vessel

pytestmark = pytest.mark.realdata
ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"

CASES = {
    "simvascular_open": ("simvascular_aorta_segment_open.vtp", {}),
    "simvascular_capped": ("simvascular_aorta_segment_capped.vtp", {}),
    "vmtk_closed": ("vmtk_aorta_segment_closed.stl", {"inlet": "219.0,290.0,25.0", "outlet": "221.3,146.5,21.7"}),
    "vmtk_bifurcation": ("vmtk_aorta_bifurcation_open.stl", {"inlet": "221,177.8,21.3", "outlet": "210.2,102.9,30.8"}),
    "aortacfd": (
        "aortacfd_patient1/wall_aorta.stl",
        {"inlet_cap": "aortacfd_patient1/inlet.stl", "outlet_cap": "aortacfd_patient1/outlet4.stl"},
    ),
    # closed surfaces with flat unlabelled caps: points ~6-10 mm inside the root and descending caps
    "vmr0154": (
        "sphinxsys_vmr0154_aorta_capped.stl",
        {"units": "cm", "inlet": "-0.911,4.689,3.648", "outlet": "-1.593,-0.865,0.994"},
    ),
    "tah_coarse": (
        "sphinxsys_tah_aorta_capped_coarse.stl",
        {"units": "mm", "inlet": "-23.0,-202.2,-1177.9", "outlet": "6.6,-123.6,-1246.3"},
    ),
}
BRANCH_FREE = ("simvascular_open", "simvascular_capped", "vmtk_closed", "tah_coarse")


@pytest.fixture(scope="module")
def fits(shared_data):
    out = {}
    for name, (mesh, opts) in CASES.items():
        opts = {k: (str(shared_data / v) if k.endswith("cap") else v) for k, v in opts.items()}
        out[name] = fit_vessel(shared_data / mesh, **opts)
    return out


def _section_centre(surf, p, n, r):
    """Independent section centre: mean of the wall's cut by the plane (p, n) within 2 r of p
    (pyvista's slice, not the project's code)."""
    import pyvista as pv

    faces = np.hstack([np.full((len(surf.faces), 1), 3), surf.faces]).ravel()
    cut = pv.PolyData(surf.vertices, faces).slice(normal=n, origin=p)
    pts = np.asarray(cut.points)
    pts = pts[np.linalg.norm(pts - p, axis=1) < 2 * r]
    return pts.mean(axis=0)


@pytest.mark.parametrize("name", list(CASES))
def test_centerline_inside_lumen_and_at_end_centres(fits, shared_data, name):
    model, report, wall_fit = fits[name]
    surf = read_surface(shared_data / CASES[name][0])
    wall = surf.vertices[np.unique(surf.faces)]
    # slab of wall vertices around each section: at least 3 mm, and 1.5 long edges (90th percentile)
    # on coarse or anisotropic meshes (sphinxsys_vmr0154: p90 edge 4.3 mm, a 3 mm slab misses whole
    # octants of a ring there although the centerline is 9.5 mm from the wall)
    tri = surf.vertices[surf.faces]
    edge = float(np.percentile(np.linalg.norm(tri[:, 0] - tri[:, 1], axis=1), 90))
    half = max(3.0, 1.5 * edge)
    # sections whose slab stays inside the section (a wide slab must not reach past an end plane)
    length = float(np.linalg.norm(np.diff(model.vcs.curve(np.linspace(0, 1, 1001)), axis=0), axis=1).sum())
    ends = max(0.03, 2.0 * half / length)
    for tau in np.linspace(ends, 1.0 - ends, 48):
        c = model.vcs.curve(tau)
        t, v1, v2 = (a[0] for a in model.vcs.frame(np.array([tau])))
        d = wall - c
        slab = np.abs(d @ t) < half
        ang = np.arctan2(d[slab] @ v2, d[slab] @ v1)
        octants = np.unique(((ang + np.pi) / (np.pi / 4)).astype(int) % 8)
        assert len(octants) == 8, f"tau={tau:.2f}: wall does not surround the centerline"
        assert np.linalg.norm(d[slab], axis=1).min() > 1.0
    # the ends: c(0), c(1) within 1 mm of the end centres computed independently with pyvista
    for tau, centre in zip((0.0, 1.0), _end_centres(shared_data, name, model)):
        if centre is not None:
            d = np.linalg.norm(model.vcs.curve(tau) - centre)
            assert d < 1.0, f"end tau={tau}: {d:.2f} mm from the end centre"


def _end_centres(data, name, model):
    """End centres by pyvista: open-loop / cap / cap-file point means; None for explicit points."""
    import pyvista as pv

    mesh_file, opts = CASES[name]
    s = model.scale_to_mm
    if "inlet_cap" in opts:
        return [np.asarray(pv.read(data / opts[k]).points).mean(axis=0) * s for k in ("inlet_cap", "outlet_cap")]
    if "inlet" in opts and name in ("vmtk_closed", "vmr0154", "tah_coarse"):
        return [None, None]
    mesh = pv.read(data / mesh_file)
    if "ModelFaceID" in mesh.cell_data and len(np.unique(mesh.cell_data["ModelFaceID"])) >= 3:
        ids = np.asarray(mesh.cell_data["ModelFaceID"])
        centres = [np.asarray(mesh.extract_cells(np.where(ids == k)[0]).points).mean(axis=0) * s for k in (2, 3)]
    else:
        edges = mesh.extract_feature_edges(
            boundary_edges=True, feature_edges=False, manifold_edges=False, non_manifold_edges=False
        )
        centres = [np.asarray(b.points).mean(axis=0) * s for b in edges.split_bodies() if b.n_points]
    pick = lambda p: min(centres, key=lambda c: np.linalg.norm(c - p))  # noqa: E731
    return [pick(model.vcs.curve(0.0)), pick(model.vcs.curve(1.0))]


def test_simvascular_residuals_beat_reference(fits):
    r = fits["simvascular_open"][1]
    assert (r["L"], r["K"], r["R"]) == (9, 19, 15)
    assert r["residual_mean_mm"] <= 0.056
    assert r["residual_p75_mm"] <= 0.076
    assert r["residual_max_mm"] <= 0.28


def test_aortacfd_branches_left_out(fits):
    model, r, wf = fits["aortacfd"]
    assert r["points_not_used"]["branch"] > 500
    assert r["residual_mean_mm"] < 0.1
    json.dumps(r)  # the report is JSON-serialisable
    # the emitted wall, rendered for a human look (test artefact)
    from vcs.plots import render_wall
    from vcs.surface import wall_mesh

    art = ARTIFACTS / "aortacfd_wall.png"
    render_wall(wall_mesh(model), art, reference=(wf.points, None))
    assert art.stat().st_size > 10_000


def test_aortacfd_wall_has_no_bump_at_branches(fits):
    model, r, wf = fits["aortacfd"]
    br = wf.reason == 4
    tau_b, th_b = wf.tau[br], wf.theta[br]
    ring = model.wall(tau_b[:, None], np.linspace(0, 2 * np.pi, 64)[None, :])
    # where the branches were cut out, the wall stays within 15 % of its ring's median radius
    # (no stump, no bump; measured: at most 1.08)
    assert np.all(model.wall(tau_b, th_b) <= 1.15 * np.median(ring, axis=1))


@pytest.mark.parametrize("name", list(CASES))
def test_default_fit_quality(fits, name):
    """Issue 10 on every shared mesh with default settings (--L auto): the centerline inside the
    lumen, tau the arc length within 2 % (|c'| constant within 2 %: AortaCFD was 0.023 when the
    candidate L were fitted to the noisy section centres), residual mean <= 0.2 mm, >= 95 % of
    the vessel's wall points used (branch-free: 98 % of all between the end planes), quality ok."""
    model, r, wf = fits[name]
    assert r["L_source"] == "auto" and r["L"] >= 9
    assert r["centerline_inside_lumen"] and r["centerline_min_wall_distance_ratio"] > 0.5
    assert r["arc_length_speed_deviation"] <= 0.02 and r["L_auto"]["criteria_met"]
    assert r["residual_mean_mm"] <= 0.2
    assert r["fraction_points_used_of_vessel"] >= 0.95
    if name in BRANCH_FREE:
        assert r["fraction_points_used"] >= 0.98, r["points_not_used"]
        assert r["points_not_used"]["branch"] == 0
    assert r["quality"] == "ok", r["quality_reasons"]
    json.dumps(r)


def test_vmtk_points_on_the_caps_give_full_end_sections(fits):
    """The vmtk segment's points lie on its rounded caps (~4 mm beyond the last full sections):
    the end planes are those sections, not cuts across the caps (which gave rho_w 32 % of the
    lumen radius at tau = 0 and quality poor)."""
    model, r, wf = fits["vmtk_closed"]
    assert r["ends_method"] == "closed_ends"
    assert r["model_radius_min_ratio"] > 0.8 and r["quality"] == "ok"
    # the end sections are as wide as the lumen next to them (rho_w at tau = 0 vs tau = 0.05)
    theta = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    for t0, t1 in ((0.0, 0.05), (1.0, 0.95)):
        r0, r1 = (np.median(model.wall(np.full(64, t), theta)) for t in (t0, t1))
        assert r0 > 0.85 * r1, (t0, r0, r1)


def test_real_branches_still_removed(fits):
    """The three supra-aortic branches of AortaCFD and the four stubs of the VMR aorta are cut out."""
    assert fits["aortacfd"][1]["points_not_used"]["branch"] > 5000
    assert fits["vmr0154"][1]["points_not_used"]["branch"] > 1500
    assert fits["aortacfd"][1]["quality"] == "ok"
