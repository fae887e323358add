"""Bad-input corpus for `vcs fit` (issue 7): each kind of bad input gives either a one-line error
(exit code 2, no traceback, no model written) or a result whose fit_report.json carries an
explicit warning. The README table lists the same cases."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from vcs.phantoms import make_phantom, sweep_tube


def fit(mesh, out, *args):
    return subprocess.run(
        [sys.executable, "-m", "vcs.cli", "fit", str(mesh), "-o", str(out), *map(str, args)],
        capture_output=True,
        text=True,
    )


def tube(length=100.0, r=8.0, edge=1.5):
    z = np.linspace(0, length, int(length / edge) + 1)
    return sweep_tube(np.column_stack([0 * z, 0 * z, z]), r, edge=edge)


def save(V, F, path):
    trimesh.Trimesh(V, F, process=False).export(path)
    return path


def assert_one_line_error(r, out, *words):
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr
    assert not (out / "model.json").exists()


def assert_warning(r, out, word):
    assert r.returncode == 0, r.stderr
    rep = json.loads((out / "fit_report.json").read_text())
    assert any(word in w for w in rep["warnings"]), rep["warnings"]
    return rep


def test_metres_declared_as_mm(tmp_path):
    V, F = tube()
    path = save(V * 1e-3, F, tmp_path / "m.stl")
    assert_one_line_error(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "--units m")


def test_degenerate_triangles_are_dropped_with_warning(tmp_path):
    V, F = tube()
    F = np.vstack([F, [[F[0, 0], F[0, 0], F[0, 1]]], [[F[5, 0], F[5, 1], F[5, 1]]]])
    path = save(V, F, tmp_path / "d.ply")
    assert_warning(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "degenerate")


def test_disconnected_components(tmp_path):
    V, F = tube()
    V2 = V * 0.2 + [100, 0, 0]
    path = save(np.vstack([V, V2]), np.vstack([F, F + len(V)]), tmp_path / "c.ply")
    rep = assert_warning(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "disconnected")
    assert abs(rep["centerline_length_mm"] - 100.0) < 2


def test_non_manifold_edges(tmp_path):
    V, F = tube()
    fin = np.array([[0, 0, 50.0], [3, 0, 50.0], [0, 3, 52.0]])
    a = len(V)
    # a fin inside the lumen glued to a wall edge (that edge now has three triangles)
    e0, e1 = F[len(F) // 2, 0], F[len(F) // 2, 1]
    path = save(np.vstack([V, fin]), np.vstack([F, [[e0, e1, a]]]), tmp_path / "n.ply")
    assert_warning(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "non-manifold")


def test_hole_in_the_wall(tmp_path):
    V, F = tube()
    c = F.mean(axis=1) if False else V[F].mean(axis=1)
    keep = ~((np.abs(c[:, 2] - 50) < 2.0) & (c[:, 0] > 6))
    path = save(V, F[keep], tmp_path / "h.ply")
    assert_warning(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "holes")


def collar_tube(edge=1.0, n_phi=64):
    """A 100 mm tube (radius 8) with a collar that overhangs both ways (not star-convex).

    The profile (z, r) of its rings: the tube wall z 0 -> 46 at r = 8, a stem up to the circle of
    centre (z, r) = (50, 20) and radius 8, 300 degrees of that circle around its far side
    (theta from -120 to -420 degrees), a stem down at z = 54, the tube wall to z = 100. On the
    circle's undersides (sin theta < 0: theta in (-180, -120] and (-420, -360)) the outward normal
    points towards the axis: the ray from the centerline meets the wall before those vertices.

    Returns
    -------
    V, F, n_under_rings, n_stem_rings
        The mesh (mm), the rings on the undersides and the rings of the two stems.
    """

    def seg(a, b):
        n = max(2, int(np.ceil(np.hypot(*np.subtract(b, a)) / edge)) + 1)
        return np.linspace(a, b, n)[:-1]

    th = np.radians(np.linspace(-120.0, -420.0, int(np.ceil(8.0 * np.radians(300.0) / edge)) + 1))
    arc = np.column_stack([50.0 + 8.0 * np.cos(th), 20.0 + 8.0 * np.sin(th)])
    stem_up, stem_down = seg((46, 8), arc[0]), seg(arc[-1], (54, 8))
    prof = np.vstack([seg((0, 8), (46, 8)), stem_up, arc[:-1], stem_down, seg((54, 8), (100, 8)), [(100, 8)]])
    phi = np.linspace(0, 2 * np.pi, n_phi, endpoint=False)
    V = np.stack(
        [prof[:, 1:2] * np.cos(phi), prof[:, 1:2] * np.sin(phi), np.repeat(prof[:, :1], n_phi, 1)], -1
    ).reshape(-1, 3)
    idx = np.arange(len(prof) * n_phi).reshape(len(prof), n_phi)
    a, b = idx[:-1], idx[1:]
    a2, b2 = np.roll(a, -1, 1), np.roll(b, -1, 1)
    F = np.concatenate([np.stack([a, b, b2], -1).reshape(-1, 3), np.stack([a, b2, a2], -1).reshape(-1, 3)])
    n_under = int((np.sin(th[:-1]) < -1e-9).sum())
    return V, F, n_under, len(stem_up) + len(stem_down) - 1


def test_overhanging_collar_reports_non_star_convex_fraction(tmp_path):
    """Issue 14: the former test's radius bump (rho a function of (tau, theta)) is star-convex by
    construction and passed only through `or branch > 0`. The collar's undersides are not: their
    vertices must be counted as not star-convex (not as a branch), with the warning."""
    V, F, n_under, n_stem = collar_tube()
    path = save(V, F, tmp_path / "a.ply")
    rep = assert_warning(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "not star-convex")
    n_phi = 64
    # every underside vertex, and at most the stem rings besides (their faces' normals are axial)
    assert n_under * n_phi <= rep["points_not_used"]["not_first_crossing"] <= (n_under + n_stem) * n_phi
    assert rep["not_star_convex_fraction"] == pytest.approx(rep["points_not_used"]["not_first_crossing"] / len(V))


def test_bend_radius_close_to_lumen_radius(tmp_path):
    """A half torus of bend radius 12 mm and lumen radius 10 mm: the inner wall (rho = 10 < 1/kappa
    = 12) is inside Omega. The fit succeeds, the centerline is the 12 mm arc (length 12 pi) and
    no wall point is left out (issue 14: the test used to accept exit 2 as well)."""
    ang = np.linspace(0, np.pi, 200)
    R = 12.0
    pts = np.column_stack([R * np.cos(ang), R * np.sin(ang), 0 * ang])
    V, F = sweep_tube(pts, 10.0, edge=1.0)
    path = save(V, F, tmp_path / "b.ply")
    r = fit(path, tmp_path / "o", "--units", "mm")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "o" / "fit_report.json").read_text())
    assert rep["centerline_length_mm"] == pytest.approx(np.pi * R, rel=2e-3)
    assert rep["n_points_used"] == rep["n_wall_points"] and rep["quality"] == "ok", rep["quality_reasons"]
    from vcs.vessel import VesselModel

    c = VesselModel.load(tmp_path / "o" / "model.json").vcs.curve(np.linspace(0, 1, 101))
    assert np.abs(np.hypot(c[:, 0], c[:, 1]) - R).max() < 0.1 and np.abs(c[:, 2]).max() < 0.1


def test_very_coarse_mesh(tmp_path):
    path = tmp_path / "coarse.stl"
    trimesh.creation.cylinder(radius=10, height=100, sections=12).export(path)
    r = fit(path, tmp_path / "o", "--units", "mm", "--inlet", "0,0,49", "--outlet", "0,0,-49")
    assert_one_line_error(r, tmp_path / "o", "coarse")


def test_ends_at_the_same_place(tmp_path):
    path = save(*tube(), tmp_path / "t.ply")
    r = fit(path, tmp_path / "o", "--units", "mm", "--inlet", "0,0,50", "--outlet", "0,0,50")
    assert_one_line_error(r, tmp_path / "o", "--inlet and --outlet are less than 1 mm apart")


def test_phantom_is_fine(tmp_path):
    ph = make_phantom("tube", resolution=2.0)
    path = save(ph.vertices, ph.faces, tmp_path / "ok.ply")
    r = fit(path, tmp_path / "o", "--units", "mm")
    assert r.returncode == 0 and json.loads((tmp_path / "o" / "fit_report.json").read_text())["warnings"] == []


@pytest.mark.parametrize("bad", ["1,2", "a,b,c", "nan,0,0"])
def test_malformed_point(tmp_path, bad):
    path = save(*tube(), tmp_path / "t.ply")
    assert_one_line_error(
        fit(path, tmp_path / "o", "--units", "mm", "--inlet", bad, "--outlet", "0,0,90"), tmp_path / "o", "--inlet"
    )


# ------------------------------------------------------------------ issue 14: true messages


def report_of(out):
    return json.loads((out / "fit_report.json").read_text())


def test_unmerged_duplicate_vertices_are_merged(tmp_path):
    """A triangle soup (each triangle with its own three vertices) used to read as '1 open end'."""
    V, F = tube()
    soup = V[F].reshape(-1, 3)
    path = save(soup, np.arange(len(soup)).reshape(-1, 3), tmp_path / "soup.ply")
    rep = assert_warning(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "duplicate vertices merged")
    assert rep["n_vertices"] == len(V)  # the tube's own vertices, each once
    assert rep["centerline_length_mm"] == pytest.approx(100.0, abs=0.5)


def test_repeated_triangles_are_removed(tmp_path):
    """Every triangle listed twice used to read as 'the surface is closed'."""
    V, F = tube()
    path = save(V, np.vstack([F, F[:, ::-1]]), tmp_path / "dup.ply")
    rep = assert_warning(fit(path, tmp_path / "o", "--units", "mm"), tmp_path / "o", "repeated triangles removed")
    assert f"{len(F)} repeated triangles removed" in " ".join(rep["warnings"])
    assert rep["n_triangles"] == len(F)
    assert rep["centerline_length_mm"] == pytest.approx(100.0, abs=0.5)


def test_5mm_vessel_is_fitted(tmp_path):
    """A 5 mm long tube of radius 10 used to give 'the inlet and outlet are at the same place'
    (a lumen path of fewer than 4 voxels); a section no longer than its diameter gets the straight
    centerline between its end centres."""
    ph = make_phantom("tube", resolution=1.0, length_mm=5.0, radius_mm=10.0)
    path = save(ph.vertices, ph.faces, tmp_path / "t5.ply")
    r = fit(path, tmp_path / "o", "--units", "mm")
    assert r.returncode == 0, r.stderr
    rep = report_of(tmp_path / "o")
    assert rep["centerline_length_mm"] == pytest.approx(5.0, abs=0.01) and rep["short_section"]
    assert rep["quality"] == "ok", rep["quality_reasons"]
    assert rep["residual_mean_mm"] < 0.01  # a circle of radius 10 (the wall model is exact)


def test_15mm_vessel_is_told_to_lower_K(tmp_path):
    """A 15 mm tube of radius 10 (288 vertices) used to be told to 'remesh finer': its wall knots
    (K = 19) would be 0.75 mm apart. The message says the section is short and gives a K that
    works: the fit with that K succeeds."""
    ph = make_phantom("tube", resolution=2.0, length_mm=15.0, radius_mm=10.0)
    path = save(ph.vertices, ph.faces, tmp_path / "t15.ply")
    r = fit(path, tmp_path / "o", "--units", "mm")
    assert_one_line_error(r, tmp_path / "o", "too short for K=19", "give --K 1")
    assert "remesh" not in r.stderr
    r = fit(path, tmp_path / "o", "--units", "mm", "--K", "1")
    assert r.returncode == 0, r.stderr
    assert report_of(tmp_path / "o")["residual_mean_mm"] < 0.01


def test_larger_closed_noise_component_is_dropped(tmp_path):
    """Noise with more area than the vessel (a closed sphere of radius 30 beside a 100 mm tube)
    used to be kept ('the surface is closed'): the component with two open ends is the vessel,
    also for --units auto (read as mm from the tube's radius 8, not the sphere's 30)."""
    V, F = tube()
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=30.0)
    sphere.apply_translation([100, 0, 50])
    path = save(np.vstack([V, sphere.vertices]), np.vstack([F, sphere.faces + len(V)]), tmp_path / "n.ply")
    rep = assert_warning(fit(path, tmp_path / "o"), tmp_path / "o", "disconnected surface components")
    w = next(w for w in rep["warnings"] if "disconnected" in w)
    assert "two open ends, not the largest" in w and f"dropped {len(sphere.faces)} triangles" in w
    assert rep["units"] == "mm" and rep["n_triangles"] == len(F)
    assert rep["centerline_length_mm"] == pytest.approx(100.0, abs=0.5)


def test_end_points_choose_the_component(tmp_path):
    """Two open tubes: the larger is kept by default, the one at --inlet/--outlet when given."""
    V, F = tube()
    big = V * 1.5 + [100, 0, 0]
    path = save(np.vstack([V, big]), np.vstack([F, F + len(V)]), tmp_path / "two.ply")
    r = fit(path, tmp_path / "o", "--units", "mm")
    assert r.returncode == 0 and report_of(tmp_path / "o")["centerline_length_mm"] == pytest.approx(150, abs=1)
    r = fit(path, tmp_path / "p", "--units", "mm", "--inlet", "0,0,0", "--outlet", "0,0,100")
    rep = assert_warning(r, tmp_path / "p", "kept the one nearest --inlet/--outlet")
    assert rep["centerline_length_mm"] == pytest.approx(100.0, abs=0.5)


def test_self_intersecting_tube_is_reported(tmp_path):
    """A 1.25-turn coil of pitch 10 mm and tube radius 8 crosses itself (turns 10 mm apart, tube
    16 mm wide). It used to get only an 'outside Omega' warning; now the report names the
    self-intersection (warning and quality reason), and "the centerline leaves the lumen", which
    was a log line on stderr only, is a warning of fit_report.json too: every warning on stderr
    is one of the report's."""
    s = np.linspace(0, 1, 400)
    a = 2 * np.pi * 1.25
    V, F = sweep_tube(np.column_stack([25 * np.cos(a * s), 25 * np.sin(a * s), 12.5 * s]), 8.0, edge=1.5)
    path = save(V, F, tmp_path / "coil.ply")
    r = fit(path, tmp_path / "o", "--units", "mm")
    rep = assert_warning(r, tmp_path / "o", "the surface intersects itself")
    assert rep["quality"] == "poor" and rep["self_intersecting_triangles"] > 0
    assert any("intersects itself" in q for q in rep["quality_reasons"])
    assert any("centerline leaves the lumen" in w for w in rep["warnings"])
    # issue 22: the crossing is named as the cause, not a lack of knots
    leaves = [q for q in rep["quality_reasons"] if q.startswith("the centerline leaves the lumen")]
    assert leaves and "where the surface intersects itself" in leaves[0] and "more knots" not in leaves[0].split("(")[0]
    stderr = r.stderr.strip().splitlines()
    assert stderr == [f"warning: {w}" for w in rep["warnings"]], stderr


def test_self_intersections_analytic():
    """Two triangles crossing through each other are found; neighbours sharing an edge or a vertex,
    and a tube that does not cross itself, are not."""
    from vcs.mesh import self_intersections

    V = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0.5, 0.5, -1], [0.5, 0.5, 1], [1.5, 1.5, 0.5]], float)
    assert self_intersections(V, np.array([[0, 1, 2], [3, 4, 5]])).tolist() == [0, 1]
    assert self_intersections(V, np.array([[0, 1, 2], [0, 4, 5]])).tolist() == []  # they share vertex 0
    V, F = tube()
    assert len(self_intersections(V, F)) == 0


# ------------------------------------------------------------------ issue 14: points and model.json


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """A model.json of the 100 mm tube (mm)."""
    d = tmp_path_factory.mktemp("fitted")
    r = fit(save(*tube(), d / "t.ply"), d / "fit", "--units", "mm")
    assert r.returncode == 0, r.stderr
    return d / "fit" / "model.json"


def vcs_run(*args):
    return subprocess.run([sys.executable, "-m", "vcs.cli", *map(str, args)], capture_output=True, text=True)


def one_line(r, *words):
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    for w in words:
        assert w in r.stderr, r.stderr


@pytest.mark.parametrize(
    "name, content, words",
    [
        ("four.csv", "0,0,10,5\n1,0,20,5\n", ["4 columns and no header"]),
        ("empty.csv", "", ["no data rows"]),
        ("header.csv", "x,y,z\n", ["no data rows"]),
        ("empty.npy", np.zeros((0, 3)), ["no data rows"]),
        ("nan.csv", "0,0,10\nnan,0,20\n", ["NaN or infinite", "data row 2"]),
        ("nan.npy", np.array([[0, 0, 10.0], [0, np.inf, 20]]), ["NaN or infinite", "data row 2"]),
    ],
)
def test_bad_points_tables(fitted, tmp_path, name, content, words):
    """Issue 14: a 4-column CSV was read as its first 3 columns, an empty .npy gave a header-only
    CSV (an empty CSV an error), NaN points an internal error (exit 1). All: one line, exit 2,
    no output."""
    path = tmp_path / name
    if isinstance(content, str):
        path.write_text(content)
    else:
        np.save(path, content)
    one_line(vcs_run("coords", fitted, path, "-o", tmp_path / "out.csv"), *words)
    assert not (tmp_path / "out.csv").exists()


def test_points_csv_with_a_header_may_have_more_columns(fitted, tmp_path):
    (tmp_path / "p.csv").write_text("id,z,y,x\n7,50,0,0\n")
    r = vcs_run("coords", fitted, tmp_path / "p.csv", "-o", tmp_path / "out.csv")
    assert r.returncode == 0, r.stderr
    tau = np.loadtxt(tmp_path / "out.csv", delimiter=",", skiprows=1)[0]
    assert tau == pytest.approx(0.5, abs=1e-3)  # (0, 0, 50) is half way along the 100 mm tube


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda d: d["wall"]["coefficients"][3].__setitem__(4, float("nan")), ["wall coefficients", "NaN"]),
        (lambda d: d["centerline"]["control_points"][2].__setitem__(1, float("inf")), ["control_points", "NaN"]),
        (lambda d: d["wall"]["coefficients"].pop(), ["wall coefficients has shape", "expected (23, 16)"]),
        (lambda d: d["centerline"].__setitem__("v1_0", [0, 0, 0]), ["v1_0", "unit vector"]),
        (lambda d: d["centerline"]["knots"].reverse(), ["knots"]),
        (lambda d: d["wall"].__setitem__("K", "19"), ["wall K"]),
    ],
)
def test_hand_edited_model_json(fitted, tmp_path, edit, words):
    """Issue 14: a NaN wall coefficient gave `vcs wall` an internal error (exit 1). model.json is
    checked on load: one line naming the entry, exit 2, nothing written."""
    d = json.loads(fitted.read_text())
    edit(d)
    bad = tmp_path / "model.json"
    bad.write_text(json.dumps(d))
    one_line(vcs_run("wall", bad, "-o", tmp_path / "w.stl"), "not a valid model.json", *words)
    assert not (tmp_path / "w.stl").exists()
    (tmp_path / "p.csv").write_text("0,0,50\n")
    one_line(vcs_run("coords", bad, tmp_path / "p.csv", "-o", tmp_path / "c.csv"), "not a valid model.json")
