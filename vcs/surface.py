"""The model's wall as a closed triangle mesh (paper Eq. 8).

x(tau, theta) = c(tau) + rho_w(tau, theta) (v1(tau) cos theta + v2(tau) sin theta) on a regular
tau-theta grid, optional straight flow extensions, flat caps; multi-solid STL for snappyHexMesh.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from vcs.errors import VCSInputError
from vcs.mesh import orient_outward, write_stl_ascii

if TYPE_CHECKING:
    from vcs.vessel import VesselModel

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class WallMesh:
    """Closed, outward-oriented triangle mesh of a model's wall (Eq. 8) with its two flat caps.

    Attributes
    ----------
    vertices : (N, 3) float, mm
    faces : (M, 3) int
        Triangles wound outward.
    solid : (M,) int8
        Solid of each face: index into :attr:`SOLIDS` (0 wall, 1 inlet, 2 outlet).
    """

    vertices: NDArray[np.floating]
    faces: NDArray[np.integer]
    solid: NDArray[np.int8]

    SOLIDS: ClassVar[tuple[str, ...]] = ("wall", "inlet", "outlet")


def _grid_faces(n_rows: int, n_theta: int, offset: int = 0) -> np.ndarray:
    """Two triangles per quad of a (n_rows, n_theta) periodic-in-theta vertex grid."""
    idx = np.arange(n_rows * n_theta).reshape(n_rows, n_theta) + offset
    a, b = idx[:-1], idx[1:]
    a2, b2 = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
    t1 = np.stack([a, a2, b2], -1).reshape(-1, 3)
    t2 = np.stack([a, b2, b], -1).reshape(-1, 3)
    return np.concatenate([t1, t2])


def _cap(
    ring: NDArray[np.floating], center: NDArray[np.floating], normal: NDArray[np.floating], offset: tuple[int, int]
) -> tuple[NDArray[np.floating], NDArray[np.integer]]:
    """Triangulate the flat cap bounded by the closed polygon ``ring`` (n, 3), its vertices in
    order: a constrained quality Delaunay triangulation of the polygon (Shewchuk's Triangle,
    `triangle` on PyPI) with the ring's edges as segments (switch ``p``), no angle below 30
    degrees where the boundary allows it (``q30``), no triangle larger than the equilateral one
    on the ring's mean edge (``a``) and no point added on the ring (``Y``): the cap shares
    exactly the wall's boundary edges. Any simple polygon is closed, convex, star-shaped or not.

    Parameters
    ----------
    ring : (n, 3) float
        The end section's boundary, in order, in one plane.
    center : (3,) float
        A point of that plane (the 2-D frame's origin).
    normal : (3,) float
        Unit normal of the plane.
    offset : tuple of int
        (index of ring[0] in the mesh, index of the first new interior vertex).

    Returns
    -------
    vertices : (P, 3) float
        The new interior vertices.
    faces : (M, 3) int
        The cap's triangles in mesh indices.

    Raises
    ------
    CapError
        When the triangulation is not a disc spanning the ring (:func:`cap_topology`), i.e. the
        ring crosses itself or is degenerate.
    """
    import triangle

    n = len(ring)
    e1 = ring[0] - center
    e1 = e1 - (e1 @ normal) * normal
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    b2 = np.column_stack([(ring - center) @ e1, (ring - center) @ e2])
    spacing = float(np.linalg.norm(np.diff(np.vstack([b2, b2[:1]]), axis=0), axis=1).mean())
    segments = np.column_stack([np.arange(n), (np.arange(n) + 1) % n])
    max_area = np.sqrt(3.0) / 4.0 * spacing**2
    out = triangle.triangulate({"vertices": b2, "segments": segments}, f"pq30a{max_area:.6g}YQ")
    pts2 = np.asarray(out.get("vertices", np.zeros((0, 2))), float)
    tri = np.asarray(out.get("triangles", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    topo = cap_topology(tri, segments)
    if len(pts2) < n or not np.allclose(pts2[:n], b2, rtol=0, atol=1e-9 * max(spacing, 1e-300)):
        topo["disc"] = False  # Triangle moved or merged ring vertices (a ring crossing itself)
    if not topo["disc"]:
        raise CapError(topo)
    lat = pts2[n:]
    verts3 = center + lat[:, :1] * e1 + lat[:, 1:] * e2
    idx = np.where(tri < n, tri + offset[0], tri - n + offset[1])
    return verts3, idx


class CapError(VCSInputError):
    """An end cap that is not a triangulated disc; ``topology`` holds :func:`cap_topology`'s counts."""

    def __init__(self, topology: dict[str, int | bool]) -> None:
        self.topology = topology
        super().__init__(f"the cap is not a disc ({topology})")


def cap_topology(faces: NDArray[np.integer], ring_edges: NDArray[np.integer]) -> dict[str, int | bool]:
    """Is a cap a triangulated disc spanning its boundary ring?

    A disc: every ring edge is used by exactly one of the cap's triangles, every other edge by
    exactly two, and the Euler characteristic V - E + F is 1 (a genus-0 surface with one boundary
    loop; a closed genus-0 surface has 2, and each extra hole or handle lowers it by 1 or 2).

    Parameters
    ----------
    faces : (M, 3) int
        The cap's triangles.
    ring_edges : (n, 2) int
        The edges of the boundary ring the cap must span (vertex pairs, any order).

    Returns
    -------
    dict
        ``ring_edges_missing`` (ring edges in no triangle), ``ring_edges_overused`` (in more
        than one), ``open_interior_edges`` (other edges in one triangle only),
        ``overused_interior_edges`` (in more than two), ``euler_characteristic`` (int) and
        ``disc`` (bool: all the counts 0 and the Euler characteristic 1).
    """
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    ring = np.sort(np.asarray(ring_edges, np.int64).reshape(-1, 2), axis=1)
    m = int(max(faces.max(initial=0), ring.max(initial=0)) + 1)
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    keys, count = np.unique(e[:, 0] * m + e[:, 1], return_counts=True)
    ring_keys = np.unique(ring[:, 0] * m + ring[:, 1])
    on_ring = np.isin(keys, ring_keys)
    chi = len(np.unique(faces)) - len(keys) + len(faces)
    out: dict[str, int | bool] = {
        "ring_edges_missing": int((~np.isin(ring_keys, keys)).sum()),
        "ring_edges_overused": int((count[on_ring] > 1).sum()),
        "open_interior_edges": int((count[~on_ring] == 1).sum()),
        "overused_interior_edges": int((count[~on_ring] > 2).sum()),
        "euler_characteristic": int(chi),
    }
    counts_ok = not any(v for key, v in out.items() if key != "euler_characteristic")
    out["disc"] = bool(chi == 1 and len(faces) > 0 and len(ring_keys) >= 3 and counts_ok)
    return out


def wall_mesh(
    model: VesselModel,
    *,
    n_tau: int | None = None,
    n_theta: int = 64,
    extend_inlet: float = 0.0,
    extend_outlet: float = 0.0,
) -> WallMesh:
    """The model's wall (Eq. 8) on a regular tau-theta grid, closed by flat caps, outward-oriented.

    Parameters
    ----------
    model : VesselModel
        With a wall model; lengths in mm.
    n_tau : int or None
        Number of tau intervals; None gives square quads (axial step = mean arc step
        2 pi mean(rho_w) / n_theta).
    n_theta : int
        Vertices around the circumference (>= 8).
    extend_inlet, extend_outlet : float
        Straight flow extensions, in diameters of the end section (dimensionless), along -t(0)
        and +t(1), keeping the end cross-section shape.

    Returns
    -------
    WallMesh
        Vertices in mm.

    Raises
    ------
    VCSInputError
        When the model has no wall model, for n_theta < 8, n_tau < 1, a negative or non-finite
        extension, or a cap that cannot be triangulated.
    """
    if model.wall is None:
        raise VCSInputError("the model has no wall model; refit it with `vcs fit` (K, R)")
    if n_theta < 8:
        raise VCSInputError(f"--n-theta {n_theta} is too small; use at least 8")
    if n_tau is not None and n_tau < 1:
        raise VCSInputError(f"--n-tau {n_tau} must be at least 1")
    for name, ext in (("inlet", extend_inlet), ("outlet", extend_outlet)):
        if not np.isfinite(ext) or ext < 0:
            raise VCSInputError(f"--extend-{name} {ext} must be a length >= 0 (in diameters)")
    vcs = model.vcs
    theta = np.linspace(0, TWO_PI, n_theta, endpoint=False)
    r_mean = float(model.wall(np.linspace(0, 1, 50)[:, None], theta[None, :]).mean())
    if r_mean <= 0:
        raise VCSInputError("the wall model has a non-positive mean radius; refit the model")
    step = TWO_PI * r_mean / n_theta
    if n_tau is None:
        n_tau = max(4, int(round(vcs.length / step)))
    tau = np.linspace(0, 1, n_tau + 1)
    main = model.surface_points(tau[:, None], theta[None, :])
    ends = []
    for tau_e, ext, sign in ((0.0, extend_inlet, -1.0), (1.0, extend_outlet, 1.0)):
        t, v1, v2 = vcs.frame(np.array([tau_e]))
        rw = model.wall(np.full(n_theta, tau_e), theta)
        if rw.min() <= 0:  # the section would pass through the centerline: a fold, not a cap problem
            raise VCSInputError(
                f"the wall model's radius is {rw.min():.3g} mm at tau = {tau_e:.0f} (it must be positive): the wall "
                "would fold through the centerline; check fit_report.json and refit"
            )
        section = vcs.curve(tau_e) + rw[:, None] * (np.cos(theta)[:, None] * v1 + np.sin(theta)[:, None] * v2)
        length = ext * 2.0 * rw.mean()
        n_ext = int(round(length / step)) if ext > 0 else 0
        s = np.linspace(0, length, n_ext + 1)[1:]
        ends.append((section, t[0] * sign, s))
    (sec0, d0, s0), (sec1, d1, s1) = ends
    ext_in = sec0[None] + s0[::-1, None, None] * d0[None, None]  # farthest first
    ext_out = sec1[None] + s1[:, None, None] * d1[None, None]
    grid = np.concatenate([ext_in, main, ext_out], axis=0)
    n_rows = len(grid)
    verts = grid.reshape(-1, 3)
    faces = _grid_faces(n_rows, n_theta)
    solid = np.zeros(len(faces), np.int8)
    all_v, all_f, all_s = [verts], [faces], [solid]
    n_v = len(verts)
    for k, (row, d) in enumerate(((0, d0), (n_rows - 1, d1))):
        ring = grid[row]
        s_end = s0 if k == 0 else s1
        center = vcs.curve(float(k)) + (s_end[-1] if len(s_end) else 0.0) * d
        try:
            v_cap, f_cap = _cap(ring, center, d, (row * n_theta, n_v))
        except CapError as exc:  # the section of a star-shaped rho_w > 0 is a simple polygon: ours
            name = WallMesh.SOLIDS[k + 1]
            raise VCSInputError(
                f"the {name} end section (tau = {k}) could not be closed by a flat cap: its triangulation "
                f"is not a disc ({', '.join(f'{a} {b}' for a, b in exc.topology.items() if a != 'disc')}); "
                "this is a defect of `vcs wall`, not of the fit: please report it with the model.json"
            ) from None
        all_v.append(v_cap)
        all_f.append(f_cap)
        all_s.append(np.full(len(f_cap), k + 1, np.int8))
        n_v += len(v_cap)
    V = np.concatenate(all_v)
    F = np.concatenate(all_f)
    S = np.concatenate(all_s)
    F = orient_outward(V, F)
    return WallMesh(V, F, S)


def fold_check(model: VesselModel, *, n_tau: int = 401, n_theta: int = 72) -> dict[str, float]:
    """Where the Eq. 8 wall would fold over itself: a radius rho_w <= 0 (the wall passes through
    the centerline), or rho_w (e_rho . K) >= 1 with K the curvature vector of c (the wall reaches
    past the centre of curvature on the inner side of a bend: the Jacobian of Eq. 8 vanishes).

    Parameters
    ----------
    model : VesselModel
        With a wall model; mm.
    n_tau, n_theta : int
        Sampling of (tau, theta) on [0, 1] x [0, 2 pi).

    Returns
    -------
    dict
        ``min_radius_mm`` and its ``tau_at_min_radius``; ``max_fold`` = max of
        rho_w (e_rho . K) (dimensionless; >= 1 folds) and its ``tau_at_max_fold``.
    """
    tau = np.linspace(0.0, 1.0, n_tau)
    theta = np.linspace(0.0, TWO_PI, n_theta, endpoint=False)
    rho = model.fitted_wall()(tau[:, None], theta[None, :])
    curve = model.vcs.curve
    d1, d2 = curve.derivative(1)(tau), curve.derivative(2)(tau)
    speed2 = np.einsum("ij,ij->i", d1, d1)
    t = d1 / np.sqrt(speed2)[:, None]
    K = (d2 - np.einsum("ij,ij->i", d2, t)[:, None] * t) / speed2[:, None]  # curvature vector, 1/mm
    _, v1, v2 = model.vcs.frame(tau)
    k1, k2 = np.einsum("ij,ij->i", v1, K), np.einsum("ij,ij->i", v2, K)
    fold = rho * (np.cos(theta)[None, :] * k1[:, None] + np.sin(theta)[None, :] * k2[:, None])
    i_min = int(np.unravel_index(np.argmin(rho), rho.shape)[0])
    i_fold = int(np.unravel_index(np.argmax(fold), fold.shape)[0])
    return {
        "min_radius_mm": float(rho.min()),
        "tau_at_min_radius": float(tau[i_min]),
        "max_fold": float(fold.max()),
        "tau_at_max_fold": float(tau[i_fold]),
    }


def check_closed(mesh: WallMesh) -> dict[str, Any]:
    """Is the Eq. 8 wall a valid closed volume for snappyHexMesh? (trimesh's mesh checks, and
    :func:`cap_topology` on each end cap)

    Parameters
    ----------
    mesh : WallMesh
        Vertices in mm.

    Returns
    -------
    dict
        ``watertight`` (every edge shared by exactly two faces), ``winding_consistent``,
        ``volume_mm3`` (enclosed volume; positive when the faces point outward),
        ``euler_number`` (2 for a closed surface of genus 0, i.e. a tube with two caps),
        ``min_angle_deg`` (smallest triangle angle), ``caps`` ({"inlet": ..., "outlet": ...}:
        :func:`cap_topology` of each cap against the wall's boundary edges next to it),
        ``caps_are_discs`` and ``closed`` (all of the above hold: watertight, consistent,
        positive volume, Euler number 2, both caps discs).
    """
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    angles = np.degrees(tm.face_angles.min()) if len(tm.faces) else 0.0
    wall = mesh.faces[mesh.solid == 0]
    we = np.sort(np.concatenate([wall[:, [0, 1]], wall[:, [1, 2]], wall[:, [2, 0]]]), axis=1)
    we, n_use = np.unique(we, axis=0, return_counts=True)
    wall_boundary = we[n_use == 1]
    caps = {}
    for k, name in enumerate(WallMesh.SOLIDS[1:], start=1):
        cap = mesh.faces[mesh.solid == k]
        ring = wall_boundary[np.isin(wall_boundary, cap).all(axis=1)]
        caps[name] = cap_topology(cap, ring)
    out: dict[str, Any] = {
        "watertight": bool(tm.is_watertight),
        "winding_consistent": bool(tm.is_winding_consistent),
        "volume_mm3": float(tm.volume),
        "euler_number": int(tm.euler_number),
        "min_angle_deg": float(angles),
        "caps": caps,
        "caps_are_discs": all(bool(c["disc"]) for c in caps.values()),
    }
    out["closed"] = bool(
        out["watertight"]
        and out["winding_consistent"]
        and out["volume_mm3"] > 0
        and out["euler_number"] == 2
        and out["caps_are_discs"]
    )
    return out


def write_multisolid_stl(mesh: WallMesh, path: Path | str, scale: float = 1.0) -> None:
    """Write a wall mesh as ASCII STL with one solid per patch name (snappyHexMesh's patch names).

    Parameters
    ----------
    mesh : WallMesh
        Vertices in mm.
    path : Path or str
        Output file.
    scale : float
        Factor applied to the coordinates, output units per mm (e.g. 1e-3: mm -> m).
    """
    V = mesh.vertices * scale
    write_stl_ascii(path, {name: V[mesh.faces[mesh.solid == k]] for k, name in enumerate(WallMesh.SOLIDS)})
