"""Synthetic phantoms (vcs.phantoms) against independent truth.

Truth used here never comes from the generator's own geometry code: analytic distances (z-axis,
torus centre circle, the conftest Helix), polygon-prism volumes, a from-scratch edge/loop
analysis, a nearest-point projection onto the centreline by Newton's method, and raw STL bytes.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from vcs.errors import VCSInputError
from vcs.mesh import read_stl_solids, signed_volume
from vcs.phantoms import KINDS, Phantom, make_phantom, sweep_tube, write_closed_tube_stl, write_stl


@pytest.fixture(scope="module")
def phantoms():
    return {k: make_phantom(k) for k in KINDS}


# ---------------------------------------------------------------------------------------------
# independent helpers


def _topology(F):
    """(directed-edge count ok, undirected edge multiplicities, boundary loops as vertex lists)."""
    d = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    d_unique, d_count = np.unique(d, axis=0, return_counts=True)
    und = np.sort(d, axis=1)
    u_unique, u_count = np.unique(und, axis=0, return_counts=True)
    # boundary edges: directed edges whose reverse is absent
    key = lambda e: e[:, 0].astype(np.int64) * (F.max() + 1) + e[:, 1]  # noqa: E731
    bnd = d[~np.isin(key(d[:, ::-1]), key(d))]
    nxt = {int(a): int(b) for a, b in bnd}
    loops, seen = [], set()
    for start in nxt:
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(np.array(loop))
    return bool(np.all(d_count == 1)), u_count, loops, bnd


def _capped(V, F):
    """Close every boundary loop with a fan to its vertex centroid, winding matched to the wall."""
    _, _, loops, bnd = _topology(F)
    nxt = {int(a): int(b) for a, b in bnd}
    V2, caps = [V], []
    n = len(V)
    for loop in loops:
        V2.append(V[loop].mean(axis=0)[None])
        for a in loop:
            caps.append([nxt[int(a)], int(a), n])  # reverse of the wall's boundary edge a -> next
        n += 1
    return np.concatenate(V2), np.concatenate([F, np.array(caps)])


def _signed_volume(V, F):
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _loop_area(P):
    c = P.mean(axis=0)
    return 0.5 * np.linalg.norm(np.cross(P - c, np.roll(P, -1, axis=0) - c).sum(axis=0))


def _project(centerline, X, n=6001, iters=3, newton=True):
    """Nearest point on the curve: global search over dense samples, then Newton steps on
    g(s) = (X - c(s)) . c'(s) = 0 with central differences of the curve itself."""
    u = np.linspace(0.0, 1.0, n)
    _, j = cKDTree(centerline(u)).query(X)
    s = u[j]
    h = 1e-4
    for _ in range(iters if newton else 0):
        sc = np.clip(s, h, 1 - h)  # stencil inside [0, 1]; the curve is smooth there
        cm, c0, cp = centerline(sc - h), centerline(s), centerline(sc + h)
        d1, d2 = (cp - cm) / (2 * h), (cp - 2 * centerline(sc) + cm) / h**2
        d1 = d1 + (s - sc)[:, None] * d2
        r = X - c0
        g, dg = np.sum(r * d1, 1), np.sum(r * d2, 1) - np.sum(d1 * d1, 1)
        s = np.clip(s - g / dg, 0.0, 1.0)
    return s


def _vcs_coords(ph: Phantom, X):
    """(s, phi, distance) of points from the centreline's nearest point and the phantom frame."""
    s = _project(ph.centerline, X)
    d = X - ph.centerline(s)
    _, v1, v2 = ph.frame(s)
    phi = np.mod(np.arctan2(np.sum(d * v2, 1), np.sum(d * v1, 1)), 2 * np.pi)
    return s, phi, np.linalg.norm(d, axis=1)


# ---------------------------------------------------------------------------------------------
# analytic kinds


def test_tube_matches_cylinder(phantoms):
    ph = phantoms["tube"]
    V = ph.vertices
    np.testing.assert_allclose(np.hypot(V[:, 0], V[:, 1]), 10.0, rtol=1e-12)
    assert V[:, 2].min() == 0.0 and V[:, 2].max() == pytest.approx(100.0, abs=1e-12)
    np.testing.assert_allclose(ph.inlet_center, [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(ph.outlet_center, [0, 0, 100], atol=1e-12)
    # closed by two fans it is a prism over a regular n-gon inscribed in r = 10
    _, _, loops, _ = _topology(ph.faces)
    n = len(loops[0])
    vol = _signed_volume(*_capped(V, ph.faces))
    assert vol == pytest.approx(0.5 * n * 100 * np.sin(2 * np.pi / n) * 100.0, rel=1e-9)


def test_torus_distance_to_centre_circle(phantoms):
    ph = phantoms["torus"]
    V = ph.vertices
    d = np.hypot(np.hypot(V[:, 0], V[:, 1]) - 40.0, V[:, 2])
    np.testing.assert_allclose(d, 8.0, rtol=1e-6)
    s = np.linspace(0, 1, 11)
    np.testing.assert_allclose(
        ph.centerline(s), np.stack([40 * np.cos(np.pi * s), 40 * np.sin(np.pi * s), 0 * s], -1), atol=1e-12
    )
    assert V[:, 1].min() > -1e-9  # 180 deg arc: every section lies in a half-plane through the z-axis
    # Pappus: polygonal section area x centroid path; chords in s shrink it by O(dtheta^2)
    _, _, loops, _ = _topology(ph.faces)
    n = len(loops[0])
    vol = _signed_volume(*_capped(V, ph.faces))
    assert vol == pytest.approx(0.5 * n * 64 * np.sin(2 * np.pi / n) * 40 * np.pi, rel=2e-3)


def test_helix_matches_conftest_helix(phantoms, helix):
    ph = phantoms["helix"]
    s = np.linspace(0, 1, 101)
    np.testing.assert_allclose(ph.centerline(s), helix.c(s), atol=1e-10)
    t, v1, v2 = ph.frame(s)
    np.testing.assert_allclose(t, helix.tangent(s), atol=1e-12)
    np.testing.assert_allclose(v1, helix.rmf(s, 0.0), atol=1e-12)  # exact rotation-minimising frame
    np.testing.assert_allclose(v2, np.cross(t, v1), atol=1e-12)
    # distance of every vertex to the exact helix (projection onto helix.c, not the phantom)
    sv = _project(helix.c, ph.vertices)
    np.testing.assert_allclose(np.linalg.norm(ph.vertices - helix.c(sv), axis=1), helix.r, rtol=1e-6)
    assert ph.params["curvature_radius_mm"] > 2 * ph.params["tube_radius_mm"]


@pytest.mark.parametrize("kind", KINDS)
def test_centerline_is_arc_length_parametrised(phantoms, kind):
    ph = phantoms[kind]
    c = ph.centerline(np.linspace(0, 1, 20001))
    seg = np.linalg.norm(np.diff(c, axis=0), axis=1)
    assert np.ptp(seg) / seg.mean() < 1e-5
    assert seg.sum() == pytest.approx(ph.params["length_mm"], rel=1e-6)
    t, v1, v2 = ph.frame(np.linspace(0, 1, 201))
    for a, b in ((t, v1), (t, v2), (v1, v2)):
        np.testing.assert_allclose(np.sum(a * b, axis=1), 0, atol=1e-9)
    np.testing.assert_allclose(np.sum(np.cross(v1, v2) * t, axis=1), 1, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# every kind: mesh validity


@pytest.mark.parametrize("kind", KINDS)
def test_open_manifold_with_two_loops(phantoms, kind):
    ph = phantoms[kind]
    V, F = ph.vertices, ph.faces
    assert V.dtype == float and V.shape[1] == 3 and F.shape[1] == 3 and np.issubdtype(F.dtype, np.integer)
    consistent, u_count, loops, _ = _topology(F)
    assert consistent  # every directed edge once: consistent winding
    assert u_count.max() == 2 and (u_count == 1).sum() == sum(len(lp) for lp in loops)
    assert len(loops) == 2
    assert len(np.unique(F)) == len(V)
    assert len(V) - len(u_count) + len(F) == 0  # Euler characteristic of an annulus
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    assert area.min() > 1e-3
    # the loops are the ends, centred at inlet/outlet; the inlet is never the smaller one
    cen = [V[lp].mean(axis=0) for lp in loops]
    i_in = int(np.argmin([np.linalg.norm(c - ph.inlet_center) for c in cen]))
    np.testing.assert_allclose(cen[i_in], ph.inlet_center, atol=1e-9)
    np.testing.assert_allclose(cen[1 - i_in], ph.outlet_center, atol=1e-9)
    a_in, a_out = _loop_area(V[loops[i_in]]), _loop_area(V[loops[1 - i_in]])
    if kind == "aorta":
        assert a_in > 1.05 * a_out
    else:
        assert a_in == pytest.approx(a_out, rel=1e-9)


@pytest.mark.parametrize("kind", KINDS)
def test_normals_point_out_of_the_lumen(phantoms, kind):
    ph = phantoms[kind]
    Vc, Fc = _capped(ph.vertices, ph.faces)
    vol = _signed_volume(Vc, Fc)
    assert vol > 0
    m = trimesh.Trimesh(Vc, Fc, process=False)
    assert m.is_watertight and m.is_winding_consistent
    assert m.volume == pytest.approx(vol, rel=1e-9)
    # locally too: each wall normal points away from the centreline (every 3rd face)
    tri = ph.vertices[ph.faces[::3]]
    cen = tri.mean(axis=1)
    s = _project(ph.centerline, cen, n=10001, newton=False)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.sum(n * (cen - ph.centerline(s)), axis=1) > 0)


@pytest.mark.parametrize("kind", KINDS)
def test_wall_is_the_prescribed_radius_about_the_nearest_centreline_point(phantoms, kind):
    """Every vertex's NEAREST centreline point (global search) gives back rho = radius(s, phi):
    the wall is star-shaped about the centreline and the tube does not fold onto itself."""
    ph = phantoms[kind]
    s, phi, d = _vcs_coords(ph, ph.vertices)
    np.testing.assert_allclose(d, ph.radius(s, phi), rtol=1e-6)
    if kind != "aorta":
        np.testing.assert_allclose(d, ph.radius(s, phi).mean(), rtol=1e-6)


def test_triangle_quality(phantoms):
    def ratio(ph):
        tri = ph.vertices[ph.faces]
        e = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2)
        return e.max(1) / e.min(1), e

    for kind in ("tube", "torus", "helix"):
        r, e = ratio(phantoms[kind])
        assert r.max() < 1.8, kind
        assert 0.8 < np.median(e.min(1)) < 1.05, kind  # quad sides ~ resolution = 1 mm
    r, e = ratio(phantoms["aorta"])
    assert np.percentile(r, 95) < 2.5
    assert 0.7 < np.median(e.min(1)) < 1.6 and np.median(e.max(1)) < 2.4


def test_resolution_scales_edges():
    coarse, fine = make_phantom("tube", resolution=2.0), make_phantom("tube", resolution=0.5)
    assert len(fine.faces) / len(coarse.faces) == pytest.approx(16, rel=0.1)
    a1, a2 = make_phantom("aorta", seed=1, resolution=1.0), make_phantom("aorta", seed=1, resolution=2.0)
    assert len(a1.faces) / len(a2.faces) == pytest.approx(4, rel=0.1)
    assert a1.params["ascending_diameter_mm"] == a2.params["ascending_diameter_mm"]


# ---------------------------------------------------------------------------------------------
# aorta


def test_aorta_reproducible_and_seeded():
    a, b, c = make_phantom("aorta", seed=3), make_phantom("aorta", seed=3), make_phantom("aorta", seed=4)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    assert a.params == b.params
    differ = [k for k in a.params if k != "seed" and a.params[k] != c.params[k]]
    assert "ascending_diameter_mm" in differ and len(differ) > 20


def test_aorta_cohort_is_anatomically_bounded():
    ps = []
    for seed in range(6):
        ph = make_phantom("aorta", seed=seed, resolution=2.0)
        p = ph.params
        ps.append(p)
        assert 25 <= p["ascending_diameter_mm"] <= 60
        _, _, d = _vcs_coords(ph, ph.vertices)
        assert d.min() >= 12.5 - 1e-6 and d.max() <= 30 + 1e-6  # diameters 25-60 mm
        s = np.linspace(0, 1, 3001)
        c = ph.centerline(s)
        L = np.linalg.norm(np.diff(c, axis=0), axis=1).sum()
        assert 250 <= L <= 350
        # curvature from second differences of the centreline, radius from the wall itself
        k = np.linalg.norm(np.gradient(np.gradient(c, s * L, axis=0), s * L, axis=0), axis=1)[2:-2]
        phi = np.linspace(0, 2 * np.pi, 90, endpoint=False)
        rmax = ph.radius(s[2:-2, None], phi[None, :]).max(axis=1)
        assert np.max(rmax * k) < 0.8
        # root at the origin rising along +z, descending end runs downwards
        np.testing.assert_allclose(ph.inlet_center, 0, atol=1e-12)
        t, _, _ = ph.frame(np.array([0.0, 1.0]))
        assert t[0, 2] > 0.9 and t[1, 2] < -0.9
        assert p["arch_height_mm"] > 20 and p["arch_width_mm"] > 40
    assert len({round(p["ascending_diameter_mm"], 6) for p in ps}) == len(ps)
    assert {p["aneurysm"] for p in ps} == {True, False}
    assert len({round(p["arch_width_mm"], 3) for p in ps}) == len(ps)


def test_aorta_triangle_budget_at_default_resolution():
    for seed in (4, 5, 9):  # the three widest aortas among seeds 0-11
        assert len(make_phantom("aorta", seed=seed).faces) < 60000


def test_aorta_sinuses_of_valsalva(phantoms):
    ph = phantoms["aorta"]
    p = ph.params
    phi = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    r0 = ph.radius(np.zeros_like(phi), phi)
    assert np.ptp(r0) < 1e-9  # circular annulus at tau = 0
    taus = np.linspace(0, 0.2, 401)
    bulge = np.ptp(ph.radius(taus[:, None], phi[None, :]), axis=1)
    t_peak = taus[np.argmax(bulge)]
    assert 0.03 <= t_peak <= 0.12
    assert bulge[taus > 0.14].max() < 1e-9 + bulge.max() * 0.2 * p["aneurysm"]
    # measured on the mesh: vertices whose nearest centreline point is at the crest
    s, ang, d = _vcs_coords(ph, ph.vertices)
    sel = np.abs(s - t_peak) < 0.004
    coef = [abs(np.sum(d[sel] * np.exp(-1j * m * ang[sel]))) for m in range(1, 7)]
    assert int(np.argmax(coef)) + 1 == 3  # three lobes 120 deg apart
    r = ph.radius(np.full_like(phi, t_peak), phi)
    peaks = phi[(r > np.roll(r, 1)) & (r > np.roll(r, -1))]
    assert len(peaks) == 3
    np.testing.assert_allclose(np.diff(np.sort(peaks)), 2 * np.pi / 3, atol=0.02)


def test_aorta_overrides_and_errors():
    ph = make_phantom("aorta", seed=2, resolution=3.0, ascending_diameter_mm=50.0, aneurysm=True)
    assert ph.params["ascending_diameter_mm"] == 50.0 and ph.params["aneurysm"] is True
    assert ph.params["aneurysm_max_diameter_mm"] > 50.0
    no = make_phantom("aorta", seed=2, resolution=3.0, aneurysm=False)
    assert no.params["aneurysm_max_diameter_mm"] == 0.0
    with pytest.raises(VCSInputError, match="unknown aorta phantom parameter"):
        make_phantom("aorta", diameter=3)
    with pytest.raises(VCSInputError, match="unknown phantom kind"):
        make_phantom("carotid")
    with pytest.raises(VCSInputError, match="resolution"):
        make_phantom("tube", resolution=0)
    with pytest.raises(VCSInputError, match="radius of curvature"):
        make_phantom("helix", tube_radius_mm=20)
    assert make_phantom("torus", arc_angle_deg=90.0, tube_radius_mm=5.0).params["length_mm"] == pytest.approx(
        20 * np.pi
    )


@pytest.mark.parametrize("kind", KINDS)
def test_params_are_plain_json(phantoms, kind):
    p = phantoms[kind].params
    assert json.loads(json.dumps(p)) == p
    assert all(type(v) in (int, float, bool, str) for v in p.values())
    assert p["kind"] == kind and p["n_triangles"] == len(phantoms[kind].faces)


# ---------------------------------------------------------------------------------------------
# sweep_tube and STL


def test_sweep_tube_generic():
    a = np.linspace(0, np.pi / 2, 200)
    pts = np.stack([30 * np.cos(a), 30 * np.sin(a), 0 * a], -1)
    V, F = sweep_tube(pts, lambda s, phi: 4.0 + 2.0 * s + 0 * phi, edge=0.5)
    assert _topology(F)[0] and len(_topology(F)[2]) == 2
    assert _signed_volume(*_capped(V, F)) > 0
    n_phi = len(V) // len(pts)
    d = np.hypot(np.hypot(V[:, 0], V[:, 1]) - 30, V[:, 2]).reshape(len(pts), n_phi)
    np.testing.assert_allclose(d[0], 4.0, rtol=1e-6)
    np.testing.assert_allclose(d[-1], 6.0, rtol=1e-6)
    assert n_phi == int(np.ceil(2 * np.pi * 6.0 / 0.5))
    # left-handed explicit frames are re-oriented; constant radius, straight line
    z = np.linspace(0, 10, 11)
    line = np.stack([0 * z, 0 * z, z], -1)
    ex, ey = np.tile([1.0, 0, 0], (11, 1)), np.tile([0, 1.0, 0], (11, 1))
    V2, F2 = sweep_tube(line, 2.0, n_phi=16, frames=(ey, ex))
    assert _signed_volume(*_capped(V2, F2)) > 0
    with pytest.raises(VCSInputError):
        sweep_tube(line[:1], 2.0)


@pytest.mark.parametrize("kind", ["tube", "aorta"])
def test_write_stl_round_trip(phantoms, kind, tmp_path):
    ph = phantoms[kind]
    path = tmp_path / f"{kind}.stl"
    write_stl(ph, path)
    raw = path.read_bytes()
    assert len(raw) == 84 + 50 * len(ph.faces)
    assert int(np.frombuffer(raw[80:84], "<u4")[0]) == len(ph.faces)
    rec = np.frombuffer(raw[84:], np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
    soup = trimesh.load(path, process=False)
    np.testing.assert_array_equal(soup.vertices.reshape(-1, 3, 3), ph.vertices[ph.faces].astype(np.float32))
    merged = trimesh.load(path)
    assert len(merged.vertices) == len(ph.vertices) and len(merged.faces) == len(ph.faces)
    key = lambda a: a[np.lexsort(a.T[::-1])]  # noqa: E731
    np.testing.assert_array_equal(key(np.asarray(merged.vertices)), key(ph.vertices.astype(np.float32).astype(float)))
    assert merged.is_winding_consistent and len(merged.split(only_watertight=False)) == 1
    tri = ph.vertices[ph.faces]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.min(np.sum(rec["n"] * n, axis=1)) > 0.9999


@pytest.mark.parametrize("axis", [(0.0, 0.0, 1.0), (0.03, 0.02, 1.0), (1.0, 0.5, -0.2)])
def test_closed_tube_stl_is_closed_outward_and_exact(tmp_path, axis):
    """OpenFOAM's Hagen-Poiseuille tube (metres): solids, closure, orientation, volume, inlet area."""
    r, L, n = 0.01, 0.2, 96
    o = np.array([0.05, -0.02, 0.1])
    a = np.asarray(axis) / np.linalg.norm(axis)
    path = write_closed_tube_stl(tmp_path / "tube.stl", radius=r, length=L, n_theta=n, n_z=40, origin=o, axis=axis)
    solids = read_stl_solids(path)
    assert list(solids) == ["wall", "inlet", "outlet"]
    assert [len(solids[k]) for k in solids] == [2 * 40 * n, n, n]
    # merge the solids and their duplicate vertices: every edge is used twice, once each way
    V, inv = np.unique(np.concatenate(list(solids.values())).reshape(-1, 3), axis=0, return_inverse=True)
    F = inv.reshape(-1, 3)
    assert len(V) == 41 * n + 2
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    _, count = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    assert np.all(count == 2)
    assert len(np.unique(directed, axis=0)) == len(directed)  # consistent winding
    vol = signed_volume(V, F)
    assert vol > 0 and abs(vol / (np.pi * r**2 * L) - 1) < 0.01
    polygon = 0.5 * n * r**2 * np.sin(2 * np.pi / n)
    assert abs(vol / (polygon * L) - 1) < 1e-6

    def area_vector(tri):
        return 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])

    inlet, outlet, wall = (area_vector(solids[k]) for k in ("inlet", "outlet", "wall"))
    assert abs(np.linalg.norm(inlet, axis=1).sum() / polygon - 1) < 1e-3
    np.testing.assert_allclose(inlet.sum(0), -polygon * a, atol=1e-6 * polygon)  # faces -axis
    np.testing.assert_allclose(outlet.sum(0), polygon * a, atol=1e-6 * polygon)  # faces +axis
    # caps at the ends, wall at the radius with radially outward normals
    np.testing.assert_allclose(solids["inlet"].reshape(-1, 3) @ a, o @ a, atol=1e-9)
    np.testing.assert_allclose(solids["outlet"].reshape(-1, 3) @ a, o @ a + L, atol=1e-9)
    c = solids["wall"].mean(axis=1)
    radial = (c - o) - np.outer((c - o) @ a, a)
    assert np.all(np.sum(wall * radial, axis=1) > 0)
    w = solids["wall"].reshape(-1, 3) - o
    np.testing.assert_allclose(np.linalg.norm(w - np.outer(w @ a, a), axis=1), r, rtol=1e-8)


def test_closed_tube_stl_rejects_bad_arguments(tmp_path):
    for kw in ({"radius": 0.0}, {"length": -1.0}, {"n_theta": 2}, {"n_z": 0}, {"axis": (0.0, 0.0, 0.0)}):
        with pytest.raises(VCSInputError):
            write_closed_tube_stl(tmp_path / "bad.stl", **kw)
