"""Centerline c(tau) of a vessel section (paper Section 2.2.1), one function per step.

1. :func:`voxel_size` and :func:`lumen_voxels`: the lumen as voxels, with the Euclidean distance
   d of each voxel to the wall (:func:`voxelize`, :func:`wall_distance`).
2. :func:`lumen_path`: the lowest-cost voxel path from p_A to p_B with step cost 1/d
   (:func:`lowest_cost_path`), and the end planes of ends given as points
   (:func:`end_plane_from_path`).
3. :func:`fit_spline`: least-squares cubic B-spline with L uniform interior knots (Eq. 1).
4. :func:`reparametrise_by_arc_length`: tau in [0, 1] becomes the normalised arc length.
5. :func:`recentre` (the project's extension, not in the paper): the curve is moved to the
   centres of the wall's cross-sections.

All lengths are in mm. The frame {t, v1, v2} along the curve is in :mod:`vcs.frame`;
:meth:`vcs.model.VesselCoordinateSystem.from_surface` composes the steps.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage, sparse
from scipy.interpolate import BSpline
from scipy.sparse import csgraph
from scipy.spatial import cKDTree

from vcs.coords import CurveIndex, curvature, to_vcs
from vcs.ends import End, Ends
from vcs.errors import VCSInputError
from vcs.frame import ParallelTransportFrame, initial_v1
from vcs.mesh import plane_section, triangle_cross, vertex_normals

log = logging.getLogger(__name__)

# jitter of the voxel grid origin (in voxels) so that scan-line rays never hit mesh vertices/edges
_JITTER = np.array([0.0, 0.0137, 0.0291])

# ------------------------------------------------------------------ 1. lumen voxels, distance d


@dataclass(frozen=True)
class VoxelLumen:
    """Voxelised lumen on a regular grid of spacing ``h``.

    Attributes
    ----------
    inside : (nx, ny, nz) bool
        Voxels of the lumen.
    distance : (nx, ny, nz) float, mm
        Distance d of each lumen voxel to the wall (0 outside the lumen).
    origin : (3,) float, mm
        Centre of voxel [0, 0, 0]; voxel [i, j, k] is centred at ``origin + (i, j, k) * h``.
    h : float, mm
        Voxel edge length.
    """

    inside: NDArray[np.bool_]
    distance: NDArray[np.floating]
    origin: NDArray[np.floating]
    h: float

    def centers(self, ijk: ArrayLike) -> NDArray[np.floating]:
        """Centres (..., 3) in mm of the voxels with integer indices ``ijk`` (..., 3)."""
        return self.origin + np.asarray(ijk, float) * self.h

    def index_of(self, points: ArrayLike) -> NDArray[np.int64]:
        """Indices (..., 3) of the voxels nearest to ``points`` (..., 3) in mm (not bounds-checked)."""
        return np.rint((np.asarray(points, float) - self.origin) / self.h).astype(np.int64)

    def distance_at(self, points: ArrayLike) -> NDArray[np.floating]:
        """Distance d to the wall (N,), mm, at ``points`` (N, 3), mm: trilinear in the voxels, 0 outside the grid."""
        ijk = ((np.asarray(points, float) - self.origin) / self.h).T
        return ndimage.map_coordinates(self.distance, ijk, order=1, mode="constant", cval=0.0)


def voxelize(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], h: float, pad: int = 2, *, distance: bool = True
) -> VoxelLumen:
    """Inside/outside voxel mask of a closed triangulated surface by scan-line parity along x.

    Each triangle is intersected with the x-parallel rays through the voxel centres of its (y, z)
    footprint; a voxel is inside when an odd number of crossings lies before its centre. Vectorised
    over triangles and rays; the result does not depend on face orientation.

    Parameters
    ----------
    vertices : (N, 3) float, mm
    faces : (M, 3) int
        A closed surface (open ends capped).
    h : float, mm
        Voxel edge length.
    pad : int
        Layers of outside voxels around the surface's bounding box (at least 2: the path search
        relies on every lumen voxel having all 26 neighbours in the grid).
    distance : bool
        Also compute the Euclidean distance of inside voxels to the nearest outside voxel (mm);
        otherwise ``distance`` is all zeros.

    Returns
    -------
    VoxelLumen
    """
    lo = vertices.min(axis=0) - (pad + 0.5) * h
    hi = vertices.max(axis=0) + (pad + 0.5) * h
    origin = lo + _JITTER * h
    shape = np.ceil((hi - origin) / h).astype(int) + 1
    tri = (vertices[faces] - origin) / h  # in voxel units; centre of voxel i at i
    y, z = tri[:, :, 1], tri[:, :, 2]
    j0 = np.ceil(y.min(axis=1)).astype(np.int64)
    j1 = np.floor(y.max(axis=1)).astype(np.int64)
    k0 = np.ceil(z.min(axis=1)).astype(np.int64)
    k1 = np.floor(z.max(axis=1)).astype(np.int64)
    nj = np.maximum(j1 - j0 + 1, 0)
    nk = np.maximum(k1 - k0 + 1, 0)
    counts = nj * nk
    t_id = np.repeat(np.arange(len(faces)), counts)
    start = np.cumsum(counts) - counts
    local = np.arange(counts.sum()) - np.repeat(start, counts)
    jj = j0[t_id] + local // np.maximum(nk[t_id], 1)
    kk = k0[t_id] + local % np.maximum(nk[t_id], 1)
    a, b, c = tri[t_id, 0], tri[t_id, 1], tri[t_id, 2]
    # 2-D barycentric coordinates of (jj, kk) in the (y, z) projection
    v0y, v0z = b[:, 1] - a[:, 1], b[:, 2] - a[:, 2]
    v1y, v1z = c[:, 1] - a[:, 1], c[:, 2] - a[:, 2]
    py, pz = jj - a[:, 1], kk - a[:, 2]
    den = v0y * v1z - v1y * v0z
    ok = np.abs(den) > 1e-14
    den = np.where(ok, den, 1.0)
    w1 = (py * v1z - v1y * pz) / den
    w2 = (v0y * pz - py * v0z) / den
    w0 = 1.0 - w1 - w2
    hit = ok & (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
    x = w0 * a[:, 0] + w1 * b[:, 0] + w2 * c[:, 0]
    ii = np.clip(np.ceil(x[hit]).astype(np.int64), 0, shape[0])
    n_cells = int((shape[0] + 1) * shape[1] * shape[2])
    cell = np.ravel_multi_index((ii, jj[hit], kk[hit]), (shape[0] + 1, shape[1], shape[2]))
    crossings = np.bincount(cell, minlength=n_cells).astype(np.int32).reshape(shape[0] + 1, shape[1], shape[2])
    inside = (np.cumsum(crossings[:-1], axis=0) % 2).astype(bool)
    dist = ndimage.distance_transform_edt(inside, sampling=h) if distance else np.zeros(inside.shape)
    return VoxelLumen(inside, dist, origin, float(h))


def voxel_size(ends: Ends, *, voxels_per_radius: float = 6.0, max_voxels: float = 4e6) -> float:
    """Voxel edge length h (mm) for the lumen grid.

    h = r / ``voxels_per_radius`` with r the smaller end radius (for explicit points on a closed
    surface, which have no radius: three times the mean voxel distance to the wall of a coarse
    voxelisation, 80 voxels along the longest side); h is enlarged so that the grid over the
    closed surface has at most ``max_voxels`` voxels.

    Parameters
    ----------
    ends : Ends
        From :func:`vcs.ends.find_ends`; its closed surface is the one voxelised.
    voxels_per_radius : float
        Voxels across the smaller end radius.
    max_voxels : float
        Upper bound on the voxels of the grid's box.

    Returns
    -------
    float, mm
    """
    cv, cf = ends.closed_vertices, ends.closed_faces
    radii = [e.radius for e in (ends.inlet, ends.outlet) if e.radius]
    if radii:
        r_ref = min(radii)
    else:  # explicit points on a closed surface: radius from a coarse voxelisation
        coarse = voxelize(cv, cf, float(np.ptp(cv, axis=0).max()) / 80.0)
        if not coarse.inside.any():
            raise VCSInputError("the surface encloses no volume; give a closed or open-ended tube surface")
        r_ref = 3.0 * float(coarse.distance[coarse.inside].mean())
    h = r_ref / voxels_per_radius
    extent = np.ptp(cv, axis=0) + 5 * h
    n_vox = np.prod(extent / h)
    if n_vox > max_voxels:
        h *= (n_vox / max_voxels) ** (1 / 3)
    return float(h)


def lumen_voxels(vertices: NDArray[np.floating], faces: NDArray[np.integer], ends: Ends, h: float) -> VoxelLumen:
    """The lumen as voxels of size ``h`` with the distance d of each voxel to the wall.

    Paper Section 2.2.1 (the volume discretised into voxels, d the distance to the wall). The
    closed surface of ``ends`` is voxelised (:func:`voxelize`); d is measured to the wall faces
    only, not to the end caps (:func:`wall_distance`).

    Parameters
    ----------
    vertices : (N, 3) float, mm
    faces : (M, 3) int
        The input surface; ``faces[ends.wall_mask]`` is the wall.
    ends : Ends
        From :func:`vcs.ends.find_ends`.
    h : float, mm
        Voxel edge length (:func:`voxel_size`).

    Returns
    -------
    VoxelLumen
    """
    lumen = voxelize(ends.closed_vertices, ends.closed_faces, h, distance=False)
    if not lumen.inside.any():
        raise VCSInputError(
            "the surface encloses no voxel of the lumen; check the units (--units) and that it is a tube"
        )
    return wall_distance(lumen, vertices, faces[ends.wall_mask])


def wall_distance(lumen: VoxelLumen, vertices: NDArray[np.floating], wall_faces: NDArray[np.integer]) -> VoxelLumen:
    """``lumen`` with its distance replaced by the distance to the *wall* only (end caps are not walls).

    With caps counted as walls the path near an end is pushed only by the cap and wanders
    sideways, giving hooks at the ends of the centerline. Distances are to wall samples
    (vertices, edge midpoints, centroids, and a finer barycentric grid on triangles larger than
    half a voxel), rasterised into wall voxels; then one Euclidean distance transform. Lumen
    voxels get at least h/2.

    Parameters
    ----------
    lumen : VoxelLumen
    vertices : (N, 3) float, mm
    wall_faces : (M, 3) int
        Triangles of the wall.

    Returns
    -------
    VoxelLumen
        Same grid; ``distance`` (nx, ny, nz) float, mm, 0 outside the lumen.
    """
    tri = vertices[wall_faces]
    samples = [
        vertices[np.unique(wall_faces)],
        tri.mean(axis=1),
        0.5 * (tri[:, 0] + tri[:, 1]),
        0.5 * (tri[:, 1] + tri[:, 2]),
        0.5 * (tri[:, 2] + tri[:, 0]),
    ]
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    # triangles larger than half a voxel get a barycentric grid of n x n points, n per triangle
    n_sub = np.minimum(np.ceil(edge / (0.5 * lumen.h)), 24).astype(int)
    for n in np.unique(n_sub[n_sub > 1]):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        w1, w2 = i[keep] / n, j[keep] / n
        w0 = 1 - w1 - w2
        tb = tri[n_sub == n]
        samples.append(
            (
                w0[None, :, None] * tb[:, None, 0]
                + w1[None, :, None] * tb[:, None, 1]
                + w2[None, :, None] * tb[:, None, 2]
            ).reshape(-1, 3)
        )
    ijk_w = lumen.index_of(np.concatenate(samples))
    ok = np.all((ijk_w >= 0) & (ijk_w < np.array(lumen.inside.shape)), axis=1)
    wall = np.zeros(lumen.inside.shape, bool)
    wall[tuple(ijk_w[ok].T)] = True
    dist = ndimage.distance_transform_edt(~wall, sampling=lumen.h)
    dist = np.where(lumen.inside, np.maximum(dist, 0.5 * lumen.h), 0.0)
    return VoxelLumen(lumen.inside, dist, lumen.origin, lumen.h)


# ------------------------------------------------------------------ 2. lowest-cost path p_A -> p_B


def lumen_path(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], ends: Ends, lumen: VoxelLumen
) -> tuple[NDArray[np.floating], End, End]:
    """Lowest-cost path through the lumen voxels from the inlet to the outlet.

    Paper Section 2.2.1: the path from p_A to p_B that minimises the sum of 1/d along it
    (:func:`lowest_cost_path`), starting and ending at the lumen voxels next to the end centres
    (:func:`start_voxel`). An end given as a point (no normal) gets its end plane from the path
    (:func:`end_plane_from_path`), which also drops the path's first voxels there.

    Parameters
    ----------
    vertices : (N, 3) float, mm
    faces : (M, 3) int
        The input surface (cut by the end plane of an end given as a point).
    ends : Ends
    lumen : VoxelLumen
        From :func:`lumen_voxels`.

    Returns
    -------
    path : (n, 3) float, mm
        Voxel centres from the inlet to the outlet.
    inlet, outlet : End
        The ends, with end planes for ends given as points.
    """
    inlet, outlet = ends.inlet, ends.outlet
    start = start_voxel(lumen, inlet, "inlet")
    goal = start_voxel(lumen, outlet, "outlet")
    path = lumen.centers(lowest_cost_path(lumen, start, goal))
    if inlet.normal is None:  # explicit points: end planes from the path and the wall
        inlet, path = end_plane_from_path(vertices, faces, lumen, inlet, path)
    if outlet.normal is None:
        outlet, rev = end_plane_from_path(vertices, faces, lumen, outlet, path[::-1])
        path = rev[::-1]
    return path, inlet, outlet


def start_voxel(lumen: VoxelLumen, end: End, name: str) -> NDArray[np.int64]:
    """Lumen voxel where the path search starts or ends: nearest to a point 1.5 voxels into the lumen.

    Parameters
    ----------
    lumen : VoxelLumen
    end : End
        The point is ``end.center`` moved 1.5 h along ``end.normal`` (the centre itself without a normal).
    name : str
        "inlet" or "outlet", for the error message.

    Returns
    -------
    (3,) int
        Voxel index.

    Raises
    ------
    VCSInputError
        When the nearest lumen voxel is more than 3 h + 1 mm away (the end is not at the lumen).
    """
    target = end.center + (1.5 * lumen.h * end.normal if end.normal is not None else 0.0)
    inside = np.argwhere(lumen.inside)
    d = np.linalg.norm(lumen.centers(inside) - target, axis=1)
    i = int(np.argmin(d))
    if d[i] > 3 * lumen.h + 1.0:
        c = end.center
        raise VCSInputError(
            f"the {name} point ({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}) mm (converted from the mesh units) is "
            f"{d[i]:.1f} mm outside the lumen; give a point inside the vessel in or near the {name} end plane"
        )
    return inside[i]


_OFFSETS = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)])


def lowest_cost_path(lumen: VoxelLumen, start: ArrayLike, goal: ArrayLike) -> NDArray[np.int64]:
    """Minimum-cost voxel path from ``start`` to ``goal`` (index triples), 26-connected.

    Paper Section 2.2.1, cost 1/d: moving between neighbouring lumen voxels a and b costs
    w(a, b) = |a - b| h (1/d_a + 1/d_b) / 2 (mm x 1/mm), with d the distance to the wall, so the
    path keeps to the middle of the lumen.

    The lowest cost g_v from ``start`` to every lumen voxel v is computed by Dijkstra's algorithm
    (:func:`scipy.sparse.csgraph.dijkstra`) on the 26-neighbour graph of the lumen voxels; the
    path is traced back from ``goal`` through predecessors u with g_u + w(u, v) == g_v (exact
    floating-point equality: the weights are computed once, in the same operation order).

    Ties: several predecessors can give the same g_v to the last bit (voxels at equal
    distance d; 1 to 5 tied steps on 10 of the 11 paths of scripts/same_results.py). They are
    broken as the earlier A* implementation did, so that paths stay bit-identical: the
    predecessor an A* search with heuristic |x - x_goal| / max(d) would have expanded first,
    i.e. the smallest (g_u + heuristic_u, g_u, flat index u). Without this rule the paths have
    the same cost but differ: scipy's own Dijkstra predecessors on the helix and torus
    phantoms; scikit-image's ``MCP_Geometric`` (which also rounds the step cost differently,
    length x 0.5 x (c_a + c_b)) on those two and on AortaCFD (unit sampling) or the capped
    SimVascular segment (sampling h).

    Parameters
    ----------
    lumen : VoxelLumen
        Every lumen voxel must have its 26 neighbours in the grid (:func:`voxelize` pads by 2).
    start, goal : (3,) int
        Voxel indices of the two ends, both in the lumen.

    Returns
    -------
    (n, 3) int
        Voxel indices from ``start`` to ``goal``.

    Raises
    ------
    VCSInputError
        When no lumen path joins them.
    """
    shape = lumen.inside.shape
    strides = np.array([shape[1] * shape[2], shape[2], 1])
    flat = np.flatnonzero(lumen.inside)  # lumen voxels (C order) = graph nodes 0..n-1
    inv_d = np.zeros(lumen.inside.size)
    inv_d[flat] = 1.0 / lumen.distance.ravel()[flat]
    node = np.full(lumen.inside.size, -1, np.int64)
    node[flat] = np.arange(len(flat))
    offs = _OFFSETS @ strides
    steps = np.linalg.norm(_OFFSETS, axis=1) * lumen.h / 2.0  # |a - b| h / 2, mm
    # edges u -> u + off of every lumen voxel u, row by row (CSR), weight w(u, v)
    cols = np.empty((len(flat), len(offs)), np.int64)
    w = np.empty((len(flat), len(offs)))
    for o, (off, step) in enumerate(zip(offs, steps)):
        cols[:, o] = node[flat + off]
        w[:, o] = step * (inv_d[flat] + inv_d[flat + off])
    ok = cols >= 0
    indptr = np.concatenate([[0], np.cumsum(ok.sum(axis=1))])
    graph = sparse.csr_array((w[ok], cols[ok], indptr), shape=(len(flat), len(flat)))
    del cols, w, ok
    s = int(np.dot(start, strides))
    g_idx = int(np.dot(goal, strides))
    g = np.full(lumen.inside.size, np.inf)
    g[flat] = csgraph.dijkstra(graph, indices=int(node[s]))
    if not np.isfinite(g[g_idx]):
        raise VCSInputError(
            "the inlet and outlet are not connected through the lumen; check the ends "
            "(--inlet/--outlet) and that the surface is a single vessel"
        )

    # A* tie order: heuristic of the former A* search (same expression, in Python floats)
    gx, gy, gz = (np.asarray(goal, float) * lumen.h).tolist()
    hscale = 1.0 / float(lumen.distance.max())
    h_ = lumen.h
    n1, n2 = shape[1] * shape[2], shape[2]

    def a_star_order(f: int) -> tuple[float, float, int]:
        i, r = divmod(f, n1)
        j, k = divmod(r, n2)
        gf = float(g[f])
        return gf + ((i * h_ - gx) ** 2 + (j * h_ - gy) ** 2 + (k * h_ - gz) ** 2) ** 0.5 * hscale, gf, f

    path = [g_idx]
    v = g_idx
    while v != s:
        u = v - offs
        tied = u[g[u] + steps * (inv_d[u] + inv_d[v]) == g[v]]
        if len(tied) == 0:  # cannot happen: g_v is the minimum of these sums
            raise RuntimeError("lumen path trace-back found no predecessor")
        v = int(tied[0]) if len(tied) == 1 else min((int(x) for x in tied), key=a_star_order)
        path.append(v)
    return np.column_stack(np.unravel_index(np.array(path[::-1], dtype=np.int64), shape))


def end_plane_from_path(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], lumen: VoxelLumen, end: End, path: NDArray[np.floating]
) -> tuple[End, NDArray[np.floating]]:
    """End plane of an end given as a point, from the lumen path that starts there.

    The normal is the path's direction between one and three local radii from its start (past
    the first voxels, which head from an off-centre point to the middle); the centre is the
    centroid of the wall's cut by the plane through the point (:func:`plane_section`). Path
    points within one local radius of the start are dropped so the curve starts at the centre
    without a kink.

    Parameters
    ----------
    vertices : (N, 3) float, mm
    faces : (M, 3) int
    lumen : VoxelLumen
    end : End
        The end given as a point (``end.normal`` is None).
    path : (n, 3) float, mm
        Lumen path starting at this end.

    Returns
    -------
    end : End
        Centre, normal (along the path) and radius of the end plane.
    path : (m, 3) float, mm
        The path without its first points (m <= n).
    """
    ijk = np.rint((path - lumen.origin) / lumen.h).astype(int)
    d = lumen.distance[tuple(ijk.T)]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    r_loc = float(np.median(d[s <= max(s[-1] / 4, 2 * lumen.h)]))
    a = path[np.searchsorted(s, min(r_loc, s[-1] / 3))]
    b = path[np.searchsorted(s, min(3 * r_loc, 2 * s[-1] / 3))]
    normal = (b - a) / max(np.linalg.norm(b - a), 1e-300)
    center, radius = plane_section(vertices, faces, end.center, normal, 3.0 * max(r_loc, lumen.h))
    keep = s > r_loc
    path = path[keep] if keep.sum() >= 4 else path
    if center is None:
        log.warning("no wall cross-section found at the %s point; the path start is used", end.source)
        return End(path[0], normal, None, "point (no wall cross-section found: path start used)"), path
    return End(center, normal, radius, "point, centred on the wall cross-section"), path


# ------------------------------------------------------------------ 3-4. spline fit, arc length


def uniform_knots(n_interior: int, k: int = 3) -> NDArray[np.floating]:
    """Clamped knot vector on [0, 1] with ``n_interior`` uniform interior knots.

    Parameters
    ----------
    n_interior : int
        Interior knots (L for the centerline).
    k : int
        Degree.

    Returns
    -------
    (n_interior + 2 k + 2,) float
    """
    inner = np.linspace(0.0, 1.0, n_interior + 2)[1:-1]
    return np.concatenate([np.zeros(k + 1), inner, np.ones(k + 1)])


def _lsq_fixed_ends(
    u: NDArray[np.floating],
    pts: NDArray[np.floating],
    t: NDArray[np.floating],
    p0: NDArray[np.floating],
    p1: NDArray[np.floating],
    smooth: float = 1e-6,
    d0: ArrayLike | None = None,
    d1: ArrayLike | None = None,
    smoothing: float = 0.0,
    bend: NDArray[np.floating] | None = None,
) -> BSpline:
    """Least-squares cubic B-spline through data (u, pts) with c(0) = p0 and c(1) = p1, and, when
    the unit directions ``d0``/``d1`` are given, c'(0) parallel to d0 and c'(1) parallel to d1.

    The control points are c = C0 + G z with free parameters z: all interior points, except that
    with end directions c_1 = p0 + s0 d0 and c_(n-2) = p1 - s1 d1 (s0, s1 free), so the curve
    leaves and meets the end planes perpendicularly. A small second-difference penalty on the
    control points (weight ``smooth`` relative to the data term) keeps knot spans without data
    well-posed.

    ``smoothing`` > 0 (a length relative to the curve's, ell / S) adds the smoothing-spline
    penalty N (ell / S)^6 int |c''' + a c'|^2 dtau (N data; 4 Gauss points per knot span, exact
    for a = 0). The data term is ~ N int |c - p|^2 dtau, so a wiggle of wavelength 2 pi ell keeps
    half its amplitude, shorter ones are damped as (2 pi ell / wavelength)^6, longer ones (the
    bends of a vessel) are kept, and gaps in the data are bridged with the least change of
    curvature. ``bend`` gives a(tau) = S^2 kappa^2 on equally spaced tau (kappa the curvature
    of a reference curve, 1/mm): for a curve at uniform speed S, c''' = S^3 (kappa' n + kappa
    torsion b) - S^2 kappa^2 c', so arcs of that curvature cost nothing (c''' alone pulled a
    12 mm bend of a 10 mm tube 0.14 mm outwards). (Third differences of the control points would
    penalise a straight line at uniform speed next to the clamped ends, whose control points are
    not uniformly spaced: on a torus arc that bent the curve's ends, curvature 17 % off.)
    """
    B = BSpline.design_matrix(u, t, 3)
    n = B.shape[1]
    C0 = np.zeros((n, 3))
    C0[0], C0[-1] = p0, p1
    cols = []  # each free parameter: an (n, 3) pattern of its effect on the control points
    lo, hi = 1, n - 1
    if d0 is not None:
        C0[1] = p0
        g = np.zeros((n, 3))
        g[1] = d0
        cols.append(g)
        lo = 2
    if d1 is not None:
        C0[n - 2] = p1
        g = np.zeros((n, 3))
        g[n - 2] = -np.asarray(d1)
        cols.append(g)
        hi = n - 2
    free = np.zeros((hi - lo, 3, n, 3))
    free[np.arange(hi - lo)[:, None], np.arange(3)[None, :], np.arange(lo, hi)[:, None], np.arange(3)[None, :]] = 1.0
    G = (
        np.concatenate([np.stack(cols, axis=-1), free.reshape(-1, n, 3).transpose(1, 2, 0)], axis=-1)
        if cols
        else (free.reshape(-1, n, 3).transpose(1, 2, 0))
    )  # (n, 3, nz)
    # normal equations through the n x n Gram matrices (B^T B and the penalty's D^T D): the cost
    # does not grow with the number of data points beyond one sparse product
    D = np.diff(np.eye(n), 2, axis=0)
    lam = smooth * len(u)
    M = (B.T @ B).toarray() + lam * (D.T @ D)
    if smoothing > 0:  # int |c''' + a c'|^2 dtau by 4-point Gauss-Legendre per knot span
        edges = np.unique(t)
        gx, gw = np.polynomial.legendre.leggauss(4)
        q = (0.5 * (edges[1:] + edges[:-1])[:, None] + 0.5 * np.diff(edges)[:, None] * gx).ravel()
        qw = (0.5 * np.diff(edges)[:, None] * gw).ravel()
        basis = BSpline(t, np.eye(n), 3)
        A = basis.derivative(3)(q)  # (points, n)
        if bend is not None:  # a = S^2 kappa^2 (tau): arcs of that curvature are not penalised
            a = np.interp(q, np.linspace(0.0, 1.0, len(bend)), bend)
            A = A + a[:, None] * basis.derivative(1)(q)
        M += len(u) * smoothing**6 * (A.T * qw) @ A
    rhs_c = np.asarray(B.T @ pts) - M @ C0  # (n, 3)
    Gk = G.transpose(1, 0, 2)  # (3, n, nz)
    H = np.einsum("knz,kny->zy", Gk, M @ Gk)
    z = np.linalg.solve(H, np.einsum("knz,nk->z", Gk, rhs_c))
    return BSpline(t, C0 + G @ z, 3)


def end_tangents(inlet: End, outlet: End) -> tuple[NDArray[np.floating], NDArray[np.floating]] | None:
    """Unit tangents imposed on the centerline at tau = 0 and 1: the end planes' normals along the flow.

    Parameters
    ----------
    inlet, outlet : End
        Their normals point into the lumen.

    Returns
    -------
    (d0, d1) : two (3,) float, or None when an end plane is unknown.
    """
    if inlet.normal is not None and outlet.normal is not None:  # end planes known: meet them square
        return inlet.normal, -outlet.normal
    return None


def fit_spline(
    points: ArrayLike,
    n_knots: int = 9,
    *,
    end_directions: tuple[ArrayLike, ArrayLike] | None = None,
    smoothing_mm: float = 0.0,
    reference: BSpline | None = None,
) -> BSpline:
    """Least-squares cubic B-spline through ordered points, end points held (paper Section 2.2.1, Eq. 1).

    c(u) = sum_i c_i B_i(u) with ``n_knots`` = L uniform interior knots on [0, 1]; u is the
    normalised chord length of the points (see :func:`reparametrise_by_arc_length` for tau).
    Coincident consecutive points are dropped first.

    Parameters
    ----------
    points : (n, 3) float, mm
        Ordered path from p_A to p_B; the first and last points are kept exactly (c(0), c(1)).
    n_knots : int
        Number of uniform interior knots L; the curve has L + 4 control points.
    end_directions : (d0, d1) of (3,) float, or None
        Unit tangent directions imposed at u = 0 and 1 (:func:`end_tangents`), so that the normal
        planes of the curve at its ends are the end planes themselves.
    smoothing_mm : float, mm
        Smoothing length ell of the penalty (:func:`_lsq_fixed_ends`; 0: none): wiggles of the
        points shorter than 2 pi ell are damped.
    reference : BSpline or None
        A curve along the points (mm) whose curvature kappa(tau) the penalty leaves alone: the
        penalty is then on c''' + S^2 kappa^2 c', zero on arcs of that curvature, instead of on
        c''', which also straightens a circular bend a little (by (kappa ell)^4 or so).

    Returns
    -------
    BSpline
        Degree 3, control points (L + 4, 3) in mm.

    Raises
    ------
    VCSInputError
        When the ends coincide (a path of fewer than 8 points is resampled linearly to 8).
    """
    pts = np.asarray(points, float)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-12])
    pts = pts[keep]
    u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    if u[-1] <= 0:
        raise VCSInputError("the inlet and outlet are at the same place; give two distinct ends")
    smoothing = smoothing_mm / u[-1]
    bend = None
    if reference is not None and smoothing_mm > 0:
        bend = (u[-1] * curvature(reference, np.linspace(0.0, 1.0, 201))) ** 2
    u /= u[-1]
    if len(pts) < 8:  # a section a few voxels long: the polyline itself, sampled densely enough
        u_new = np.linspace(0.0, 1.0, 8)
        pts, u = np.column_stack([np.interp(u_new, u, pts[:, k]) for k in range(3)]), u_new
    d0, d1 = end_directions if end_directions is not None else (None, None)
    return _lsq_fixed_ends(
        u, pts, uniform_knots(n_knots), pts[0], pts[-1], d0=d0, d1=d1, smoothing=smoothing, bend=bend
    )


def reparametrise_by_arc_length(
    curve: BSpline,
    *,
    end_directions: tuple[ArrayLike, ArrayLike] | None = None,
    n_resample: int = 2000,
    passes: int = 3,
    tolerance: float = 0.002,
) -> BSpline:
    """The same curve with tau in [0, 1] proportional to arc length (paper Section 2.2.1).

    The curve is refitted (same knots, same end points, same end directions) to ``n_resample`` + 1
    of its own points equally spaced in arc length, at tau = 0, 1/n_resample, ..., 1, up to
    ``passes`` times, stopping early once :func:`speed_deviation` is below ``tolerance``. How
    constant |c'(tau)| can be is bounded by how well L uniform knots represent the curve at
    uniform speed (a tight bend needs knots); :func:`choose_n_knots` picks L so that it is
    within 2 %.

    Parameters
    ----------
    curve : BSpline
        Clamped cubic (e.g. from :func:`fit_spline`); its end points c(0), c(1) (mm) are kept.
    end_directions : (d0, d1) of (3,) float, or None
        The tangent directions imposed at the ends (as given to :func:`fit_spline`).
    n_resample : int
        Arc-length samples per pass.
    passes : int
        Most refits.
    tolerance : float
        Stop when max| |c'| / mean |c'| - 1 | is below this (dimensionless).

    Returns
    -------
    BSpline
        Degree 3, same knots, control points (L + 4, 3) in mm.
    """
    t = curve.t
    p0, p1 = curve.c[0], curve.c[-1]  # a clamped spline starts and ends at its end control points
    d0, d1 = end_directions if end_directions is not None else (None, None)
    for _ in range(passes):
        dense = np.linspace(0, 1, 8 * n_resample + 1)
        s = arc_length_table(curve, dense)
        tau = np.linspace(0, 1, n_resample + 1)
        u_of_tau = np.interp(tau * s[-1], s, dense)
        curve = _lsq_fixed_ends(tau, curve(u_of_tau), t, p0, p1, smooth=1e-9, d0=d0, d1=d1)
        if speed_deviation(curve) < tolerance:
            break
    return curve


def speed_deviation(curve: BSpline, n: int = 2001) -> float:
    """How far tau is from normalised arc length: max over tau of | |c'(tau)| / mean |c'| - 1 |.

    Paper Section 2.2.1 defines tau as the normalised arc length, i.e. |c'(tau)| = length for
    every tau; this is the relative deviation from it (0 for an exact arc-length parameter),
    reported as ``arc_length_speed_deviation``.

    Parameters
    ----------
    curve : BSpline
        c(tau) on [0, 1], mm.
    n : int
        Equally spaced samples of tau.

    Returns
    -------
    float
        Dimensionless.
    """
    speed = np.linalg.norm(curve.derivative()(np.linspace(0.0, 1.0, n)), axis=1)
    return float(np.max(np.abs(speed / speed.mean() - 1.0)))


def fit_centerline(
    points: ArrayLike,
    n_knots: int = 9,
    *,
    n_resample: int = 2000,
    end_directions: tuple[ArrayLike, ArrayLike] | None = None,
    smoothing_mm: float = 0.0,
    reference: BSpline | None = None,
) -> BSpline:
    """Cubic B-spline centerline with ``n_knots`` uniform interior knots, arc-length parametrised.

    Paper Section 2.2.1 (centerline c(tau), Eq. 1): :func:`fit_spline` then
    :func:`reparametrise_by_arc_length`.

    Parameters
    ----------
    points : (n, 3) float, mm
        Ordered path from p_A to p_B (first and last are kept exactly).
    n_knots : int
        Number of uniform interior knots L; the curve has L + 4 control points.
    n_resample : int
        Arc-length samples of the reparametrisation.
    end_directions : (d0, d1) of (3,) float, or None
        Unit tangent directions imposed at tau = 0 and 1 (the end planes' normals, along the flow).
    smoothing_mm : float, mm
        Smoothing length of the fit (:func:`fit_spline`; 0: plain least squares).
    reference : BSpline or None
        Curve whose curvature the smoothing leaves alone (:func:`fit_spline`).

    Returns
    -------
    BSpline
        c(tau), tau in [0, 1] the normalised arc length; control points (L + 4, 3) in mm.
    """
    curve = fit_spline(points, n_knots, end_directions=end_directions, smoothing_mm=smoothing_mm, reference=reference)
    return reparametrise_by_arc_length(curve, end_directions=end_directions, n_resample=n_resample)


def arc_length_table(curve: BSpline, u: NDArray[np.floating]) -> NDArray[np.floating]:
    """Cumulative arc length of ``curve`` at sorted parameters (Simpson's rule per interval).

    Parameters
    ----------
    curve : BSpline
        Values in mm.
    u : (n,) float
        Sorted parameters.

    Returns
    -------
    (n,) float, mm
        Arc length from ``u[0]``; the first entry is 0.
    """
    d = curve.derivative()
    mid = 0.5 * (u[1:] + u[:-1])
    speed = np.linalg.norm(d(u), axis=-1)  # each node once (both intervals next to it use it)
    seg = (u[1:] - u[:-1]) / 6.0 * (speed[:-1] + 4 * np.linalg.norm(d(mid), axis=-1) + speed[1:])
    return np.concatenate([[0.0], np.cumsum(seg)])


def curve_length(curve: BSpline) -> float:
    """Length (mm) of ``curve`` over [0, 1] (Simpson's rule on 2048 intervals)."""
    return float(arc_length_table(curve, np.linspace(0, 1, 2049))[-1])


# ------------------------------------------------------------------ 4b. the number of knots L


#: Candidate numbers of centerline knots of ``--L auto``, smallest first (about 10 % apart).
L_LADDER = (9, 10, 11, 12, 13, 14, 16, 18, 20, 22, 25, 28, 32, 36, 40, 45, 50, 56, 63, 70)


@dataclass(frozen=True)
class KnotChoice:
    """Result of :func:`choose_n_knots`.

    Attributes
    ----------
    n_knots : int
        The chosen L.
    curve : BSpline
        The centerline with L knots, arc-length parametrised, mm.
    met : bool
        Both criteria hold for ``curve``.
    trials : list of dict
        Per candidate L tried: ``L``, ``speed_deviation``, ``min_wall_distance_ratio`` (the
        smallest d(c_L(tau)) / d(reference) along the curve, dimensionless).
    """

    n_knots: int
    curve: BSpline
    met: bool
    trials: list[dict]


def choose_n_knots(
    reference: BSpline,
    lumen: VoxelLumen,
    *,
    end_directions: tuple[ArrayLike, ArrayLike] | None = None,
    max_speed_deviation: float = 0.02,
    min_distance_ratio: float = 0.5,
    max_knots: int = 70,
) -> KnotChoice:
    """The smallest number of centerline knots L that fits the vessel (``--L auto``).

    Paper Section 2.2.1 fixes L (9 in the paper) for every vessel; a long or tortuous vessel
    needs more. Candidates L of :data:`L_LADDER` (from the paper's 9 up, never fewer) are fitted
    to the ``reference`` curve at equal arc length (:func:`fit_to_curve`: Eq. 1 with tau the
    normalised arc length) until one meets both criteria:

    * tau is the arc length: max| |c'| / mean |c'| - 1 | <= ``max_speed_deviation``
      (:func:`speed_deviation`);
    * the curve stays inside the lumen with a margin: along the curve, the distance to the wall
      d (voxel distance field, trilinear) is at least ``min_distance_ratio`` times d at the
      nearest point of ``reference`` (the re-centred curve: d there is the local lumen radius).

    The candidates are fitted to one smooth curve, not to the scattered section centres: with
    more knots a fit to the centres follows their noise and the gaps between them (at side
    branches), whose wiggles make |c'| vary more, not less (on the AortaCFD aorta the deviation
    went 0.023, 0.034, ..., 0.085 from L = 10 to 16); fitted to a smooth curve it falls as L
    grows. When no candidate up to ``max_knots`` meets both, the smallest L inside the lumen whose
    speed deviation is within 0.005 of the smallest is taken (``met`` false; the fit report says
    so).

    Parameters
    ----------
    reference : BSpline
        The smoothed, re-centred working curve (:func:`section_centres`), mm.
    lumen : VoxelLumen
        Distance field d of the lumen.
    end_directions : (d0, d1) of (3,) float, or None
        Unit tangents imposed at tau = 0 and 1.
    max_speed_deviation : float
        Dimensionless (0.02: |c'| constant within 2 %).
    min_distance_ratio : float
        Dimensionless margin to the wall.
    max_knots : int
        Largest L tried.

    Returns
    -------
    KnotChoice
    """
    ref_pts = reference(np.linspace(0.0, 1.0, 2001))
    ref_d = np.maximum(lumen.distance_at(ref_pts), lumen.h)
    tree = cKDTree(ref_pts)
    tau = interior_samples(ref_d[[0, -1]], curve_length(reference))
    trials: list[dict] = []
    curves: dict[int, BSpline] = {}
    samples = equal_arc_samples(reference, 1000)  # the same data for every L
    for L in [v for v in L_LADDER if v <= max(max_knots, L_LADDER[0])]:
        curve = fit_to_curve(reference, L, end_directions=end_directions, n_samples=1000, samples=samples)
        dev = speed_deviation(curve)
        c = curve(tau)
        ratio = float(np.min(lumen.distance_at(c) / ref_d[tree.query(c)[1]]))
        trials.append({"L": L, "speed_deviation": dev, "min_wall_distance_ratio": ratio})
        curves[L] = curve
        if ratio >= min_distance_ratio and dev <= max_speed_deviation:
            return KnotChoice(L, _full_reparam(curve, end_directions), True, trials)
    # none meets both: inside with the margin, the smallest L within 0.005 of the smallest
    # deviation; else the most central curve
    inside = [t for t in trials if t["min_wall_distance_ratio"] >= min_distance_ratio]
    if inside:
        best_dev = min(t["speed_deviation"] for t in inside)
        pick = next(t for t in inside if t["speed_deviation"] <= best_dev + 0.005)
    else:
        pick = max(trials, key=lambda t: t["min_wall_distance_ratio"])
    return KnotChoice(int(pick["L"]), _full_reparam(curves[pick["L"]], end_directions), False, trials)


def fit_to_curve(
    reference: BSpline,
    n_knots: int,
    *,
    end_directions: tuple[ArrayLike, ArrayLike] | None = None,
    n_samples: int = 2000,
    passes: int = 2,
    samples: tuple[NDArray[np.floating], NDArray[np.floating]] | None = None,
) -> BSpline:
    """A centerline with ``n_knots`` uniform interior knots fitted to a curve at equal arc length (Eq. 1).

    Paper Section 2.2.1: c(tau) = sum_i c_i B_i(tau) with tau the normalised arc length. The
    least-squares fit puts ``reference`` at arc length s_i = i S / n at tau_i = i / n (same end
    points, end directions as given), then :func:`reparametrise_by_arc_length` refits it to its
    own arc-length samples.

    Parameters
    ----------
    reference : BSpline
        The curve to represent (any parametrisation), mm.
    n_knots : int
        L.
    end_directions : (d0, d1) of (3,) float, or None
        Unit tangents imposed at tau = 0 and 1.
    n_samples : int
        Arc-length samples (n above).
    passes : int
        Arc-length refits afterwards.
    samples : (tau, points) or None
        :func:`equal_arc_samples` of ``reference`` with ``n_samples``, if already computed.

    Returns
    -------
    BSpline
        Degree 3, control points (L + 4, 3) in mm.
    """
    tau, pts = equal_arc_samples(reference, n_samples) if samples is None else samples
    d0, d1 = end_directions if end_directions is not None else (None, None)
    curve = _lsq_fixed_ends(tau, pts, uniform_knots(n_knots), pts[0], pts[-1], smooth=1e-9, d0=d0, d1=d1)
    return reparametrise_by_arc_length(curve, end_directions=end_directions, n_resample=n_samples, passes=passes)


def equal_arc_samples(reference: BSpline, n_samples: int) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """``n_samples`` + 1 points of a curve equally spaced in arc length, and tau = i / n_samples.

    Parameters
    ----------
    reference : BSpline
        The curve (any parametrisation), mm.
    n_samples : int

    Returns
    -------
    tau : (n_samples + 1,) float
    points : (n_samples + 1, 3) float, mm
    """
    dense = np.linspace(0.0, 1.0, 8 * n_samples + 1)
    s = arc_length_table(reference, dense)
    tau = np.linspace(0.0, 1.0, n_samples + 1)
    return tau, reference(np.interp(tau * s[-1], s, dense))


def interior_samples(end_radii: ArrayLike, length: float, n: int = 801) -> NDArray[np.floating]:
    """tau samples of a centerline away from its two ends, where a wall-distance margin means something.

    Within one end radius of arc from an end the curve is pinned to the end centre, and the
    wall distance there says more about the end plane than about the fit (on a closed surface
    the cap itself counts as wall); those stretches (at most 10 % of the length each) are left out.

    Parameters
    ----------
    end_radii : (2,) float, mm
        Lumen radius at tau = 0 and tau = 1.
    length : float, mm
        Length of the centerline.
    n : int
        Number of samples.

    Returns
    -------
    (n,) float
        Equally spaced tau.
    """
    r0, r1 = (min(float(r), 0.1 * length) for r in np.asarray(end_radii, float))
    return np.linspace(r0 / length, 1.0 - r1 / length, n)


def _full_reparam(curve: BSpline, dirs: tuple[ArrayLike, ArrayLike] | None) -> BSpline:
    """The final arc-length reparametrisation on the full 2000-sample table (:func:`reparametrise_by_arc_length`)."""
    return reparametrise_by_arc_length(curve, end_directions=dirs, passes=2)


def working_knots(length: float, radius: float, edge: float, *, lo: int = 9, hi: int = 50) -> int:
    """Knots of the working curve that is re-centred before L is chosen (:func:`section_centres`).

    One knot span per lumen radius of arc (a vessel cannot bend tighter than its radius), but
    no finer than 2.5 mesh edges (the recentring windows), within [``lo``, ``hi``].

    Parameters
    ----------
    length : float, mm
        Length of the lumen path.
    radius : float, mm
        Median lumen radius along the path.
    edge : float, mm
        Mean edge length of the wall mesh.
    lo, hi : int
        Bounds.

    Returns
    -------
    int
    """
    span = max(radius, 2.5 * edge, 1e-6)
    return int(np.clip(int(np.ceil(length / span)) - 1, lo, hi))


# ------------------------------------------------------------------ 5. re-centring (beyond the paper)


def recentre(
    curve: BSpline,
    vertices: NDArray[np.floating],
    wall_faces: NDArray[np.integer],
    *,
    iterations: int = 3,
    end_directions: tuple[ArrayLike, ArrayLike] | None = None,
    n_knots: int | None = None,
    smoothing_mm: float = 0.0,
) -> tuple[BSpline, list[float]]:
    """Move the centerline to the centres of the wall's cross-sections (the project's extension).

    Not in the paper: the voxel path cuts bends and carries the voxel staircase (errors of a few
    tenths of a mm). See :func:`section_centres`, which this wraps (it also returns the centres).

    Parameters
    ----------
    curve : BSpline
        Arc-length parametrised centerline (:func:`reparametrise_by_arc_length`), mm.
    vertices : (N, 3) float, mm
    wall_faces : (M, 3) int
        Triangles of the wall.
    iterations : int
        Re-centring steps (0 returns ``curve`` unchanged).
    end_directions : (d0, d1) of (3,) float, or None
        As given to :func:`fit_spline`.
    n_knots : int or None
        L of the refits (default: that of ``curve``).
    smoothing_mm : float, mm
        Smoothing length of the refits (:func:`fit_spline`).

    Returns
    -------
    curve : BSpline
        The re-centred centerline, arc-length parametrised.
    shifts : list of float, mm
        Largest centre shift of each iteration.
    """
    curve, shifts, _ = section_centres(
        curve,
        vertices,
        wall_faces,
        iterations=iterations,
        end_directions=end_directions,
        n_knots=n_knots,
        smoothing_mm=smoothing_mm,
    )
    return curve, shifts


def section_centres(
    curve: BSpline,
    vertices: NDArray[np.floating],
    wall_faces: NDArray[np.integer],
    *,
    iterations: int = 3,
    end_directions: tuple[ArrayLike, ArrayLike] | None = None,
    n_knots: int | None = None,
    smoothing_mm: float = 0.0,
) -> tuple[BSpline, list[float], NDArray[np.floating]]:
    """Centres of the wall's cross-sections along the centerline, and the curve refitted to them.

    The project's extension of paper Section 2.2.1. Each iteration (:func:`recentre_step`) bins
    the wall vertices by tau; the first Fourier harmonic of rho(theta) in a bin is the offset of
    the true centre, and the spline (``n_knots`` uniform interior knots, same end points, same end
    directions) is refitted to the shifted bin centres (:func:`fit_centerline`).

    Parameters
    ----------
    curve : BSpline
        Arc-length parametrised centerline (:func:`reparametrise_by_arc_length`), mm.
    vertices : (N, 3) float, mm
    wall_faces : (M, 3) int
        Triangles of the wall; each vertex votes with a third of its triangles' area.
    iterations : int
        Re-centring steps; 0 returns ``curve`` and its own dense samples.
    end_directions : (d0, d1) of (3,) float, or None
        As given to :func:`fit_spline`.
    n_knots : int or None
        L of the refits (default: that of ``curve``).
    smoothing_mm : float, mm
        Smoothing length of the refits (:func:`fit_spline`): the centres are noisy where side
        branches leave (an ostium pulls a section's centre towards it) and have gaps there.

    Returns
    -------
    curve : BSpline
        The re-centred centerline, arc-length parametrised.
    shifts : list of float, mm
        Largest centre shift of each iteration.
    centres : (n, 3) float, mm
        The ordered points of the last refit: c(0), the section centres, c(1) (the data a
        centerline with another L is fitted to, :func:`choose_n_knots`).

    Notes
    -----
    Robustness (measured on the shared meshes, see README): a tau bin narrower than the spacing
    of the mesh's rings holds a partial ring, whose Fourier fit is biased or rejected (a 100 mm
    tube meshed at 1.5 mm drifted 1.4 mm off its axis at L = 18), so the per-bin sums are pooled
    over a window of at least 2.5 mean wall edges and one knot span; only wall points whose normal is within 45 deg
    of the radial direction vote (ostia, a bifurcation's crotch and obliquely cut sections do
    not), and a window whose 5-term Fourier fit leaves an RMS residual above 10 % of its radius
    (not a tube section: a branch, a stub) does not vote; bins that do not vote move with their
    voting neighbours.
    """
    tri = vertices[wall_faces]
    p0, p1 = curve.c[0], curve.c[-1]
    if n_knots is None:
        n_knots = len(curve.t) - 2 * (curve.k + 1)
    edges = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2) if len(tri) else np.zeros((1, 3))
    edge = float(edges.mean())
    # pooled over >= 2.5 mesh edges (whole rings) and >= one knot span (the curve cannot follow
    # finer detail anyway; wider windows average the noise of bumpy surfaces and ostia out)
    length = curve_length(curve)
    window_mm = max(2.5 * edge, length / (n_knots + 1))
    # long triangles vote along their length, not only at their corners
    spacing = max(2.0 * float(np.median(edges)), length / max(32, 6 * (n_knots + 4)))
    pts, w, normals = wall_samples(vertices, wall_faces, spacing)
    shifts = []
    centres = curve(np.linspace(0.0, 1.0, 257))
    for _ in range(iterations):
        curve, shift, centres = recentre_step(
            curve,
            pts,
            w,
            p0,
            p1,
            n_knots,
            end_directions,
            window_mm=window_mm,
            normals=normals,
            smoothing_mm=smoothing_mm,
        )
        shifts.append(shift)
    return curve, shifts, centres


def wall_samples(
    vertices: NDArray[np.floating], wall_faces: NDArray[np.integer], spacing: float
) -> tuple[NDArray[np.floating], NDArray[np.floating], NDArray[np.floating]]:
    """Area-weighted points of the wall that vote for the section centres (:func:`recentre_step`).

    Each vertex carries a third of the area of its triangles and its (area-weighted) normal,
    except that a triangle with an edge longer than ``spacing`` gives its area to a barycentric
    grid of points at most ~``spacing`` apart, with the triangle's normal: a wall meshed with long
    triangles (a tube in one band of triangles, a coarse or remeshed surface) has no vertices
    along most of its length, and the sections there would have no votes (a 120 mm capsule
    meshed so drifted 17 mm off its axis).

    Parameters
    ----------
    vertices : (N, 3) float, mm
    wall_faces : (M, 3) int
        Triangles of the wall.
    spacing : float, mm
        Largest edge of a triangle voting by its vertices.

    Returns
    -------
    points : (P, 3) float, mm
    weights : (P,) float, mm^2
        Their shares of the wall's area (the sum is the wall's area).
    normals : (P, 3) float
        Unit normals (orientation not significant).
    """
    tri = vertices[wall_faces]
    cross = triangle_cross(tri)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    longest = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1) if len(tri) else np.zeros(0)
    n_sub = np.minimum(np.ceil(longest / max(spacing, 1e-9)), 64).astype(int)
    small = n_sub <= 1
    w_vert = np.bincount(wall_faces[small].ravel(), np.repeat(area[small] / 3.0, 3), minlength=len(vertices))
    used = w_vert > 0
    pts, wts = [vertices[used]], [w_vert[used]]
    nrm = [vertex_normals(vertices, wall_faces)[used]]
    unit = cross / np.maximum(2.0 * area, 1e-300)[:, None]
    for n in np.unique(n_sub[~small]):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        b1, b2 = i[keep] / n, j[keep] / n
        b0 = 1.0 - b1 - b2
        sel = n_sub == n
        tb = tri[sel]
        pts.append(
            (b0[:, None] * tb[:, None, 0] + b1[:, None] * tb[:, None, 1] + b2[:, None] * tb[:, None, 2]).reshape(-1, 3)
        )
        wts.append(np.repeat(area[sel] / len(b0), len(b0)))
        nrm.append(np.repeat(unit[sel], len(b0), axis=0))
    return np.concatenate(pts), np.concatenate(wts), np.concatenate(nrm)


def recentre_step(
    curve: BSpline,
    pts: NDArray[np.floating],
    w: NDArray[np.floating],
    p0: NDArray[np.floating],
    p1: NDArray[np.floating],
    n_knots: int,
    dirs: tuple[ArrayLike, ArrayLike] | None = None,
    n_bins: int | None = None,
    window_mm: float = 0.0,
    normals: NDArray[np.floating] | None = None,
    smoothing_mm: float = 0.0,
) -> tuple[BSpline, float, NDArray[np.floating]]:
    """One re-centring step of :func:`section_centres`.

    Parameters
    ----------
    curve : BSpline
        Current centerline, mm.
    pts : (N, 3) float, mm
        Wall vertices.
    w : (N,) float, mm^2
        Their area weights.
    p0, p1 : (3,) float, mm
        End points kept by the refit.
    n_knots : int
        L of the refit.
    dirs : (d0, d1) of (3,) float, or None
        End tangent directions of the refit.
    n_bins : int or None
        tau bins (default max(32, 6 (L + 4))).
    window_mm : float, mm
        Each bin's centre is fitted to the wall points of the bins within +- ``window_mm`` / 2
        of arc (at least its own bin), so that a bin never sees a partial ring of the mesh.
    normals : (N, 3) float or None
        Unit vertex normals (either orientation); when given, only vertices whose normal is
        within 45 deg of the radial direction vote.
    smoothing_mm : float, mm
        Smoothing length of the refit (:func:`fit_spline`).

    Returns
    -------
    curve : BSpline
        The refitted centerline.
    shift : float, mm
        Largest centre shift applied.
    centres : (n_bins + 2, 3) float, mm
        c(0), the shifted bin centres in tau order, c(1): the data of the refit.
    """
    frame = ParallelTransportFrame(curve, _any_normal(curve.derivative()(0.0)))
    tau, theta, rho, ok = to_vcs(curve, frame, CurveIndex.from_curve(curve, curve_length(curve)), pts)
    n_bins = n_bins or max(32, 6 * (n_knots + 4))
    ok &= (tau > 0) & (tau < 1)
    if normals is not None:
        radial = (pts - curve(tau)) / np.maximum(rho, 1e-300)[:, None]
        ok &= np.abs(np.einsum("ij,ij->i", normals, radial)) > np.cos(np.pi / 4)
    b = np.minimum((tau * n_bins).astype(int), n_bins - 1)
    # robust: points far beyond their bin's median radius (branches, outliers) do not vote
    med = group_median(b[ok], rho[ok], n_bins)
    ok &= (rho < 1.5 * med[b]) & (rho > 0.5 * med[b])
    X = np.column_stack([np.ones_like(theta), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)])
    Xw = X * (w * ok)[:, None]
    # per-bin sums (np.bincount adds in the same order as np.add.at, much faster)
    A = np.empty((n_bins, 5, 5))
    for i in range(5):
        for j in range(5):
            A[:, i, j] = np.bincount(b, Xw[:, i] * X[:, j], minlength=n_bins)
    y: NDArray[np.float64] = np.column_stack([np.bincount(b, Xw[:, i] * rho, minlength=n_bins) for i in range(5)])
    yy: NDArray[np.float64] = np.bincount(b, w * ok * rho**2, minlength=n_bins).astype(float)
    tsum: NDArray[np.float64] = np.bincount(b, w * ok, minlength=n_bins).astype(float)
    tmean = np.bincount(b, w * ok * tau, minlength=n_bins) / np.where(tsum > 0, tsum, 1)
    cnt: NDArray[np.float64] = np.bincount(b, ok.astype(float), minlength=n_bins).astype(float)
    # a bin votes only when its wall points surround the curve (all 8 theta octants present):
    # bins cut by an oblique end plane or a gap would give a biased centre
    octant = np.minimum((theta / (np.pi / 4)).astype(int), 7)
    cover = np.zeros((n_bins, 8))
    cover[b[ok], octant[ok]] = 1.0
    half = int(np.ceil(0.5 * window_mm * n_bins / max(curve_length(curve), 1e-9) - 0.5))
    if half > 0:  # pool the sums of the 2 half + 1 bins around each bin
        A = _window_sum(A, half)
        y = _window_sum(y, half)
        cover = _window_sum(cover, half)
        yy = _window_sum(yy.astype(float), half)
        tw = _window_sum(tmean * tsum, half)
        tsum = _window_sum(tsum.astype(float), half)
        cnt = _window_sum(cnt.astype(float), half)
        tmean = tw / np.where(tsum > 0, tsum, 1)
    good = (cnt >= 12) & (cover > 0).all(axis=1)
    good[good] &= np.linalg.cond(A[good]) < 1e8
    coef = np.zeros((n_bins, 5))
    coef[good] = np.linalg.solve(A[good], y[good][..., None])[..., 0]
    # not a tube section (a branch, a stub, a crotch): the 5-term fit leaves > 10 % RMS residual
    sse = yy - 2 * np.einsum("ij,ij->i", coef, y) + np.einsum("ij,ijk,ik->i", coef, A, coef)
    rms = np.sqrt(np.maximum(sse, 0.0) / np.where(tsum > 0, tsum, 1))
    good &= rms <= 0.1 * np.abs(coef[:, 0])
    tb = np.where(good, tmean, (np.arange(n_bins) + 0.5) / n_bins)
    _, v1, v2 = frame(tb)
    shift = (coef[:, 1:2] * v1 + coef[:, 2:3] * v2) * good[:, None]
    size = np.linalg.norm(shift, axis=1, keepdims=True)
    cap = 0.25 * np.abs(coef[:, :1])  # never move by more than a quarter of the local radius per step
    shift *= np.minimum(1.0, cap / np.maximum(size, 1e-300))
    # the data of the refit are the voting bins' centres only: bins that do not vote (gaps at
    # branches, the ends where points project beyond the end) are bridged by the spline and its
    # smoothness penalty instead of keeping the current curve there, whose wiggles (the voxel
    # path's staircase) would otherwise survive every iteration
    if good.sum() >= max(8, n_knots // 2):
        order = np.argsort(tb[good])
        data = np.vstack([p0, (curve(tb) + shift)[good][order], p1])
    else:  # almost nothing votes: keep the curve
        data = np.vstack([p0, curve((np.arange(n_bins) + 0.5) / n_bins), p1])
    fitted = fit_centerline(data, n_knots, end_directions=dirs, smoothing_mm=smoothing_mm, reference=curve)
    return fitted, float(np.linalg.norm(shift, axis=1).max(initial=0.0)), data


def group_median(groups: NDArray[np.integer], values: NDArray[np.floating], n_groups: int) -> NDArray[np.floating]:
    """Median of ``values`` per group (vectorised: one sort), 0 for empty groups.

    Parameters
    ----------
    groups : (N,) int
        Group index of each value, in [0, n_groups).
    values : (N,) float
    n_groups : int

    Returns
    -------
    (n_groups,) float
        Units of ``values``.
    """
    out = np.zeros(n_groups)
    if len(values) == 0:
        return out
    order = np.lexsort((values, groups))
    g, v = groups[order], values[order]
    counts = np.bincount(g, minlength=n_groups)
    start = np.cumsum(counts) - counts
    has = counts > 0
    lo = start[has] + (counts[has] - 1) // 2
    hi = start[has] + counts[has] // 2
    out[has] = 0.5 * (v[lo] + v[hi])
    return out


def _window_sum(a: NDArray[np.float64], half: int) -> NDArray[np.float64]:
    """Sums of ``a`` over the window of bins [i - half, i + half] along its first axis (clipped at the ends).

    Parameters
    ----------
    a : (n, ...) float
        Per-bin values.
    half : int
        Half-width of the window, in bins.

    Returns
    -------
    (n, ...) float
    """
    c = np.concatenate([np.zeros((1, *a.shape[1:])), np.cumsum(a, axis=0)])
    i = np.arange(len(a))
    return c[np.minimum(i + half + 1, len(a))] - c[np.maximum(i - half, 0)]


def _any_normal(t: NDArray[np.floating]) -> NDArray[np.floating]:
    """A unit vector normal to ``t`` (the least-aligned coordinate axis, projected)."""
    return initial_v1(t, np.zeros(3), np.zeros(3))[0]
