"""The self-intersection test of every fit (issue 22, item 4): exact on hand-made crossings, the
same as the all-pairs test on random triangle soups (so the k-d tree broad phase and the plane
rejection drop no crossing), and found on an otherwise good fit, with its (tau, theta)."""

from __future__ import annotations

import numpy as np
import pytest

from vcs.io import Surface
from vcs.mesh import _edges_cross, self_intersections
from vcs.phantoms.sweep import sweep_tube
from vcs.vessel import fit_vessel


def all_pairs(V: np.ndarray, F: np.ndarray) -> list[int]:
    """The definition, by brute force: every pair of triangles sharing fewer than two corners,
    each edge of one against the other."""
    F = np.asarray(F, np.int64)
    a, b = np.triu_indices(len(F), 1)
    shared = (F[a][:, :, None] == F[b][:, None, :]).sum(axis=(1, 2))
    a, b = a[shared < 2], b[shared < 2]
    tri = V[F]
    hit = _edges_cross(F, tri, a, b) | _edges_cross(F, tri, b, a)
    return sorted(set(a[hit].tolist()) | set(b[hit].tolist()))


def test_a_fold_at_a_shared_vertex_is_found():
    """Two triangles sharing vertex 0, the second's opposite edge passing through the first: a
    fold at a vertex (a mesh folded back on itself), found; the same pair bent away is not."""
    V = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [1, 1, -1], [1, 1, 1]], float)
    assert self_intersections(V, np.array([[0, 1, 2], [0, 3, 4]])).tolist() == [0, 1]
    V[3, 2] = 0.5  # both of its other corners above the plane: no crossing
    assert self_intersections(V, np.array([[0, 1, 2], [0, 3, 4]])).tolist() == []


@pytest.mark.parametrize("seed", range(6))
def test_broad_phase_drops_no_crossing(seed):
    """Random soups of 300 triangles of sizes spanning a factor 50 (the k-d trees' size classes),
    some sharing corners: the same crossing triangles as the all-pairs definition."""
    rng = np.random.default_rng(seed)
    n = 300
    centres = rng.uniform(0, 20, (n, 3))
    size = np.exp(rng.uniform(np.log(0.2), np.log(10.0), n))
    V = (centres[:, None, :] + size[:, None, None] * rng.normal(0, 1, (n, 3, 3))).reshape(-1, 3)
    F = np.arange(3 * n).reshape(n, 3)
    F[1::7, 0] = F[0:-1:7, 1][: len(F[1::7])]  # some corners shared
    expected = all_pairs(V, F)
    assert len(expected) > 20
    assert self_intersections(V, F, chunk=1000).tolist() == expected


def folded_tube():
    """A straight tube (r 8 mm, 100 mm, rings 1.5 mm apart) with four vertices of ring 40 (z = 60)
    pushed 3.75 mm along the axis, past the next two rings, and half a step around: a small fold
    of the wall that crosses itself, at theta ~ 0-32 degrees; elsewhere a perfect tube."""
    z = np.linspace(0, 100.0, 67)
    V, F = sweep_tube(np.column_stack([0 * z, 0 * z, z]), 8.0, edge=1.5)
    n_phi = len(V) // len(z)
    k = slice(40 * n_phi, 40 * n_phi + 4)
    V[k, 2] += 3.75
    half = np.pi / n_phi  # and half a step around: the folded chords cross the wall's chords
    x, y = V[k, 0].copy(), V[k, 1].copy()
    V[k, 0], V[k, 1] = np.cos(half) * x - np.sin(half) * y, np.sin(half) * x + np.cos(half) * y
    return V, F, n_phi


def test_a_small_crossing_on_an_otherwise_good_fit_is_reported():
    """Issue 22: the test ran only on poor fits, so this fold (a good fit otherwise) reached
    snappyHexMesh unreported. Now: found, located at the fold (tau ~ 0.6, theta ~ 15 deg), a
    quality reason, and timed."""
    V, F, n_phi = folded_tube()
    assert len(all_pairs(V, F)) > 0
    _, r, _ = fit_vessel(Surface(V, F, {}, "mm", "given", "folded"))
    assert r["self_intersecting_triangles"] == len(all_pairs(V, F))
    patch = r["self_intersections"][0]
    assert abs(patch["tau"] - (60.0 + 1.5) / 100.0) < 0.03
    assert -20 < (patch["theta_deg"] + 180) % 360 - 180 < 50
    assert r["quality"] == "poor" and any("intersects itself" in q for q in r["quality_reasons"])
    assert any("tau = 0.6" in w for w in r["warnings"] if "intersects itself" in w)
    assert r["timings_s"]["self_intersection"] > 0
    assert r["timings_s"]["total"] >= r["timings_s"]["self_intersection"] + r["timings_s"]["wall_fit"]


def test_a_clean_fit_reports_no_crossing():
    z = np.linspace(0, 100.0, 67)
    V, F = sweep_tube(np.column_stack([0 * z, 0 * z, z]), 8.0, edge=1.5)
    _, r, _ = fit_vessel(Surface(V, F, {}, "mm", "given", "tube"))
    assert r["self_intersecting_triangles"] == 0 and r["self_intersections"] == []
    assert r["quality"] == "ok", r["quality_reasons"]
