"""End caps of the Eq. 8 wall (issue 22): always a triangulated disc spanning the end section.

Truths independent of the code under test: the shoelace area of the section polygon (a cap that
covers the polygon exactly once has that area), Euler's formula V - E + F = 1 for a disc, and
hand-made triangulations with a known defect.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from vcs.surface import _cap, cap_topology, check_closed, wall_mesh
from vcs.vessel import VesselModel
from vcs.wall import WallModel

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from model_phantoms import narrowed_model


def shoelace(b2: np.ndarray) -> float:
    """Signed area of a closed 2-D polygon (its vertices in order)."""
    x, y = b2[:, 0], b2[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def plane_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    return a, np.cross(normal, a)


def concave_vertices(b2: np.ndarray) -> int:
    """Vertices of a 2-D polygon where it turns against its orientation (reflex corners)."""
    d = np.diff(np.vstack([b2[-1:], b2, b2[:1]]), axis=0)
    turn = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
    return int((turn * np.sign(shoelace(b2)) < 0).sum())


def cap_in_3d(b2: np.ndarray, center: np.ndarray, normal: np.ndarray):
    """Cap a 2-D polygon placed in the plane (center, normal); return ring, new vertices, faces."""
    e1, e2 = plane_frame(normal)
    ring = center + b2[:, :1] * e1 + b2[:, 1:] * e2
    verts, faces = _cap(ring, center, normal, (0, len(ring)))
    return ring, verts, faces


def covered_area(points: np.ndarray, faces: np.ndarray, normal: np.ndarray) -> tuple[float, float]:
    """Sum of the unsigned triangle areas and the sum of their areas signed along ``normal``."""
    t = points[faces]
    cr = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    return 0.5 * float(np.linalg.norm(cr, axis=1).sum()), 0.5 * float((cr @ normal).sum())


def check_disc(b2: np.ndarray, center=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0)) -> None:
    center, normal = np.asarray(center, float), np.asarray(normal, float) / np.linalg.norm(normal)
    ring, verts, faces = cap_in_3d(b2, center, normal)
    n = len(ring)
    topo = cap_topology(faces, np.column_stack([np.arange(n), (np.arange(n) + 1) % n]))
    assert topo["disc"], topo
    pts = np.vstack([ring, verts])
    assert np.abs((pts - center) @ normal).max() < 1e-9 * np.abs(b2).max()  # flat, in the section's plane
    unsigned, signed = covered_area(pts, faces, normal)
    true = abs(shoelace(b2))
    # covered exactly once: no overlap (unsigned = |signed|) and no gap (= the polygon's area)
    assert unsigned == pytest.approx(true, rel=1e-9) and abs(signed) == pytest.approx(true, rel=1e-9)


def test_cap_topology_finds_the_defects_of_hand_made_caps():
    """A square split into two triangles is a disc; the defects of issue 22 (an edge in three
    triangles, a boundary edge left open, a triangle missing) are each found."""
    ring = np.array([[0, 1], [1, 2], [2, 3], [3, 0]])
    good = np.array([[0, 1, 2], [0, 2, 3]])
    t = cap_topology(good, ring)
    assert t["disc"] and t["euler_characteristic"] == 1
    fan = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    assert cap_topology(fan, ring)["disc"]
    three = np.vstack([good, [[0, 2, 4]]])  # edge (0, 2) in three triangles, two new edges used once
    t = cap_topology(three, ring)
    assert not t["disc"] and t["overused_interior_edges"] == 1 and t["open_interior_edges"] == 2
    assert cap_topology(good[:1], ring)["ring_edges_missing"] == 2
    doubled = np.vstack([good, good[:1]])  # a triangle listed twice: ring edges overused
    assert not cap_topology(doubled, ring)["disc"]
    holed = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 5], [3, 0, 5], [4, 2, 5], [0, 4, 5]])  # a fan, Euler 1
    assert cap_topology(holed, ring)["disc"]
    assert not cap_topology(holed[:-1], ring)["disc"]  # a triangle out: an interior hole


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(8, 96),
    lobes=st.integers(1, 9),
    amp=st.floats(0.0, 0.45),
    noise=st.floats(0.0, 0.04),
    seed=st.integers(0, 2**31 - 1),
    normal=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0.1, 1)),
)
def test_star_shaped_non_convex_sections_get_a_disc(n, lobes, amp, noise, seed, normal):
    """Property: a section r(theta) = r0 (1 + a cos(k theta + phi) + noise), the shape of an
    aortic root's sinus lobes or of a bumpy scan, in any plane, is capped by a disc that covers
    its polygon exactly once."""
    rng = np.random.default_rng(seed)
    th = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = 10.0 * (1 + amp * np.cos(lobes * th + rng.uniform(0, 2 * np.pi)) + noise * rng.uniform(-1, 1, n))
    check_disc(np.column_stack([r * np.cos(th), r * np.sin(th)]), rng.normal(0, 50, 3), np.array(normal))


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    n=st.integers(6, 60),
    opening=st.floats(0.2, 2.5),  # an arc of more than pi: no point sees the whole section
    width=st.floats(0.15, 0.7),
    wiggle=st.floats(0.0, 0.2),
    seed=st.integers(0, 2**31 - 1),
)
def test_non_star_shaped_sections_get_a_disc(n, opening, width, wiggle, seed):
    """Property: a C-shaped section (an annular sector of 2 pi - opening radians, radii 10 and
    10 (1 - width), its radii wiggled by less than a quarter of the gap, so the polygon stays
    simple) is not star-shaped from any point; it is capped by a disc that covers it once."""
    rng = np.random.default_rng(seed)
    a = np.linspace(opening / 2, 2 * np.pi - opening / 2, n)
    gap = 10.0 * width
    r_out = 10.0 + 0.25 * wiggle * gap * rng.uniform(-1, 1, n)
    r_in = 10.0 - gap + 0.25 * wiggle * gap * rng.uniform(-1, 1, n)
    outer = np.column_stack([r_out * np.cos(a), r_out * np.sin(a)])
    inner = np.column_stack([r_in * np.cos(a), r_in * np.sin(a)])[::-1]
    b2 = np.vstack([outer, inner])
    assert concave_vertices(b2) >= 1  # the inner arc turns against the outer one
    check_disc(b2)


def lobed_end_model(seed: int) -> VesselModel:
    """A straight vessel (radius 10 mm) whose outlet section (tau = 1) has random wall
    coefficients in [9.4, 11.3] mm, the rho_w range of the issue's real outlet."""
    base = narrowed_model(r_in=10.0, r_mid=10.0, r_out=10.0, K=19, R=15, L=9)
    b = base.wall.coefficients.copy()
    b[-2:] = np.random.default_rng(seed).uniform(9.4, 11.3, b.shape[1])
    return VesselModel(base.vcs, WallModel(19, 15, b))


@pytest.mark.parametrize("seed", [13, 21])
def test_regression_concave_outlet_section_gives_a_closed_wall(seed, tmp_path, capsys):
    """Regression (issue 22): a real aorta fitted `ok` whose outlet section has 6 concave vertices
    (rho_w 9.4-11.3 mm) was refused by `vcs wall` as 'the wall model folds over itself' (Euler
    number 1: the old Delaunay cap shared one edge among three triangles). These two outlet
    sections broke the old cap the same way (Euler 1 and 0); now the wall is closed, Euler 2, and
    each cap is a disc covering its section once."""
    from vcs.cli import main

    model = lobed_end_model(seed)
    th = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rw = model.wall(np.ones(64), th)
    assert rw.min() > 9.4 and rw.max() < 11.3
    assert concave_vertices(np.column_stack([rw * np.cos(th), rw * np.sin(th)])) >= 6
    for extend in (0.0, 1.0):
        w = wall_mesh(model, n_theta=64, extend_outlet=extend)
        c = check_closed(w)
        assert c["closed"] and c["euler_number"] == 2 and c["caps_are_discs"], c
        outlet = w.faces[w.solid == 2]
        _, t1, _ = model.vcs.frame(np.array([1.0]))
        unsigned, _ = covered_area(w.vertices, outlet, model.vcs.frame(np.array([1.0]))[0][0])
        assert unsigned == pytest.approx(abs(shoelace(np.column_stack([rw * np.cos(th), rw * np.sin(th)]))), rel=1e-6)
    model.save(tmp_path / "model.json")
    assert main(["wall", str(tmp_path / "model.json"), "-o", str(tmp_path / "w.stl")]) == 0
    assert "closed, volume" in capsys.readouterr().out


def test_a_cap_problem_is_never_called_a_fold(tmp_path, capsys, monkeypatch):
    """A wall whose cap is broken is reported as a cap defect of ours, never as a fold of the
    wall model: check_closed finds the broken cap (one cap triangle removed), and `vcs wall`,
    with a triangulation that loses a triangle, says 'defect of `vcs wall`' in one line."""
    import triangle

    from vcs.cli import main
    from vcs.surface import WallMesh

    model = lobed_end_model(21)
    w = wall_mesh(model, n_theta=32)
    first_outlet = int(np.flatnonzero(w.solid == 2)[0])
    keep = np.arange(len(w.faces)) != first_outlet
    c = check_closed(WallMesh(w.vertices, w.faces[keep], w.solid[keep]))
    assert not c["closed"] and not c["caps"]["outlet"]["disc"] and c["caps"]["inlet"]["disc"]

    real = triangle.triangulate

    def losing_one(*args, **kwargs):
        out = dict(real(*args, **kwargs))
        out["triangles"] = out["triangles"][1:]
        return out

    model.save(tmp_path / "model.json")
    monkeypatch.setattr(triangle, "triangulate", losing_one)
    assert main(["wall", str(tmp_path / "model.json"), "-o", str(tmp_path / "w.stl")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "could not be closed by a flat cap" in err[0] and "defect of `vcs wall`" in err[0], err
    assert "folds" not in err[0] and not (tmp_path / "w.stl").exists()
