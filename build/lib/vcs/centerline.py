"""Centerline of a vessel section (paper Section 2.2.1).

Voxel discretisation of the lumen, Euclidean distance to the wall (scipy.ndimage), A* from p_A to
p_B with cost 1/distance (heapq), then a least-squares cubic B-spline with L uniform interior
knots re-parametrised by arc length on [0, 1].
"""
from __future__ import annotations

import heapq
import logging
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.interpolate import BSpline

from vcs.errors import VCSInputError

log = logging.getLogger(__name__)

# jitter of the voxel grid origin (in voxels) so that scan-line rays never hit mesh vertices/edges
_JITTER = np.array([0.0, 0.0137, 0.0291])


@dataclass(frozen=True)
class VoxelLumen:
    """Voxelised lumen: ``inside`` (nx, ny, nz) bool, voxel centre of [i, j, k] at
    ``origin + (i, j, k) * h``, and ``distance`` to the wall in mm (0 outside)."""

    inside: np.ndarray
    distance: np.ndarray
    origin: np.ndarray
    h: float

    def centers(self, ijk: np.ndarray) -> np.ndarray:
        return self.origin + np.asarray(ijk, float) * self.h

    def index_of(self, points: np.ndarray) -> np.ndarray:
        return np.rint((np.asarray(points, float) - self.origin) / self.h).astype(np.int64)


def voxelize(vertices: np.ndarray, faces: np.ndarray, h: float, pad: int = 2, *, distance: bool = True) -> VoxelLumen:
    """Inside/outside voxel mask of a closed triangulated surface by scan-line parity along x.

    Each triangle is intersected with the x-parallel rays through the voxel centres of its (y, z)
    footprint; a voxel is inside when an odd number of crossings lies before its centre. Vectorised
    over triangles and rays; the result does not depend on face orientation. ``distance``: also the
    Euclidean distance of inside voxels to the nearest outside voxel (mm).
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
    crossings = np.zeros((shape[0] + 1, shape[1], shape[2]), np.int32)
    np.add.at(crossings, (ii, jj[hit], kk[hit]), 1)
    inside = (np.cumsum(crossings[:-1], axis=0) % 2).astype(bool)
    dist = ndimage.distance_transform_edt(inside, sampling=h) if distance else np.zeros(inside.shape)
    return VoxelLumen(inside, dist, origin, float(h))


_OFFSETS = np.array(
    [(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if (i, j, k) != (0, 0, 0)]
)


def astar_path(lumen: VoxelLumen, start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Minimum-cost voxel path from ``start`` to ``goal`` (index triples), 26-connected.

    A* with heapq; moving between voxels a and b costs |a - b| * (1/d_a + 1/d_b) / 2, with d the
    distance to the wall, so the path keeps to the middle of the lumen (paper Section 2.2.1).
    The heuristic |x - goal| / max(d) never overestimates, so the path is optimal.
    Returns (n, 3) voxel indices from start to goal.
    """
    shape = lumen.inside.shape
    strides = np.array([shape[1] * shape[2], shape[2], 1])
    inside = lumen.inside.ravel()
    inv_d = np.zeros(inside.size)
    inv_d[inside] = 1.0 / lumen.distance.ravel()[inside]
    inv_d_list = inv_d.tolist()
    offs = (_OFFSETS @ strides).tolist()
    steps = (np.linalg.norm(_OFFSETS, axis=1) * lumen.h / 2.0).tolist()
    nbr = list(zip(offs, steps))
    s = int(np.dot(start, strides))
    g_idx = int(np.dot(goal, strides))
    goal_xyz = np.asarray(goal, float) * lumen.h
    hscale = 1.0 / float(lumen.distance.max())
    gx, gy, gz = goal_xyz.tolist()
    h_ = lumen.h
    n1, n2 = shape[1] * shape[2], shape[2]

    def heur(f: int) -> float:
        i, r = divmod(f, n1)
        j, k = divmod(r, n2)
        return ((i * h_ - gx) ** 2 + (j * h_ - gy) ** 2 + (k * h_ - gz) ** 2) ** 0.5 * hscale

    inf = float("inf")
    best = [inf] * inside.size  # flat lists: much faster than dicts in the inner loop
    parent = [-1] * inside.size
    best[s] = 0.0
    heap = [(heur(s), 0.0, s)]
    push, pop = heapq.heappush, heapq.heappop
    while heap:
        _, g, f = pop(heap)
        if f == g_idx:
            break
        if g > best[f]:
            continue  # stale entry
        cf = inv_d_list[f]
        for off, step in nbr:
            q = f + off
            cq = inv_d_list[q]
            if cq == 0.0:
                continue
            ng = g + step * (cf + cq)
            if ng < best[q]:
                best[q] = ng
                parent[q] = f
                push(heap, (ng + heur(q), ng, q))
    else:
        raise VCSInputError(
            "the inlet and outlet are not connected through the lumen; check the ends "
            "(--inlet/--outlet) and that the surface is a single vessel"
        )
    path = [g_idx]
    while parent[path[-1]] != -1:
        path.append(parent[path[-1]])
    path = np.array(path[::-1], dtype=np.int64)
    return np.column_stack(np.unravel_index(path, shape))


def uniform_knots(n_interior: int, k: int = 3) -> np.ndarray:
    """Clamped knot vector on [0, 1] with ``n_interior`` uniform interior knots."""
    inner = np.linspace(0.0, 1.0, n_interior + 2)[1:-1]
    return np.concatenate([np.zeros(k + 1), inner, np.ones(k + 1)])


def _lsq_fixed_ends(u, pts, t, p0, p1, smooth=1e-6, d0=None, d1=None):
    """Least-squares cubic B-spline through data (u, pts) with c(0) = p0 and c(1) = p1, and, when
    the unit directions ``d0``/``d1`` are given, c'(0) parallel to d0 and c'(1) parallel to d1.

    The control points are c = C0 + G z with free parameters z: all interior points, except that
    with end directions c_1 = p0 + s0 d0 and c_(n-2) = p1 - s1 d1 (s0, s1 free), so the curve
    leaves and meets the end planes perpendicularly. A small second-difference penalty on the
    control points (weight ``smooth`` relative to the data term) keeps knot spans without data
    well-posed.
    """
    B = BSpline.design_matrix(u, t, 3).toarray()
    n = B.shape[1]
    C0 = np.zeros((n, 3))
    C0[0], C0[-1] = p0, p1
    cols = []  # each free parameter: an (n, 3) pattern of its effect on the control points
    lo, hi = 1, n - 1
    if d0 is not None:
        C0[1] = p0
        g = np.zeros((n, 3)); g[1] = d0; cols.append(g)
        lo = 2
    if d1 is not None:
        C0[n - 2] = p1
        g = np.zeros((n, 3)); g[n - 2] = -np.asarray(d1); cols.append(g)
        hi = n - 2
    for j in range(lo, hi):
        for k in range(3):
            g = np.zeros((n, 3)); g[j, k] = 1.0; cols.append(g)
    G = np.stack(cols, axis=-1)  # (n, 3, nz)
    D = np.diff(np.eye(n), 2, axis=0)
    A = np.einsum("in,nkz->ikz", B, G).reshape(-1, G.shape[-1])
    r = (pts - B @ C0).reshape(-1)
    P = np.einsum("in,nkz->ikz", D, G).reshape(-1, G.shape[-1])
    q = -(D @ C0).reshape(-1)
    lam = smooth * len(u)
    z = np.linalg.solve(A.T @ A + lam * P.T @ P, A.T @ r + lam * P.T @ q)
    return BSpline(t, C0 + G @ z, 3)


def fit_centerline(points: np.ndarray, n_knots: int = 9, *, n_resample: int = 2000,
                   end_directions: tuple | None = None) -> BSpline:
    """Cubic B-spline centerline with ``n_knots`` uniform interior knots, arc-length parametrised.

    Paper Section 2.2.1 (centerline c(tau), Eq. 1): a least-squares fit to the path points with the
    end points held at p_A and p_B, then refitted on points equally spaced in arc length so that
    tau in [0, 1] is the normalised arc length.

    Parameters
    ----------
    points : (n, 3) float
        Ordered path from p_A to p_B (first and last are kept exactly).
    n_knots : int
        Number of uniform interior knots L; the curve has L + 4 control points.
    end_directions : (d0, d1) or None
        Unit tangent directions imposed at tau = 0 and 1 (the end planes' normals, along the flow),
        so that the normal planes of the curve at its ends are the end planes themselves.
    """
    pts = np.asarray(points, float)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-12])
    pts = pts[keep]
    u = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    if u[-1] <= 0 or len(pts) < 4:
        raise VCSInputError("the inlet and outlet are at the same place; give two distinct ends")
    u /= u[-1]
    t = uniform_knots(n_knots)
    p0, p1 = pts[0], pts[-1]
    d0, d1 = end_directions if end_directions is not None else (None, None)
    curve = _lsq_fixed_ends(u, pts, t, p0, p1, d0=d0, d1=d1)
    for _ in range(2):  # re-parametrise by arc length (two passes make |c'| constant to <0.1%)
        dense = np.linspace(0, 1, 8 * n_resample + 1)
        s = arc_length_table(curve, dense)
        tau = np.linspace(0, 1, n_resample + 1)
        u_of_tau = np.interp(tau * s[-1], s, dense)
        curve = _lsq_fixed_ends(tau, curve(u_of_tau), t, p0, p1, smooth=1e-9, d0=d0, d1=d1)
    return curve


def arc_length_table(curve: BSpline, u: np.ndarray) -> np.ndarray:
    """Cumulative arc length of ``curve`` at the sorted parameters ``u`` (Simpson per interval)."""
    d = curve.derivative()
    mid = 0.5 * (u[1:] + u[:-1])
    sp = lambda x: np.linalg.norm(d(x), axis=-1)  # noqa: E731
    seg = (u[1:] - u[:-1]) / 6.0 * (sp(u[:-1]) + 4 * sp(mid) + sp(u[1:]))
    return np.concatenate([[0.0], np.cumsum(seg)])
