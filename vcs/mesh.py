"""Triangle-mesh helpers shared by the whole package: per-triangle cross products, areas and normals,
vertex normals, edges and half-edges, boundary loops, connected components, winding repair,
enclosed volume, a ray-parity inside test, chords across the lumen (ray casting), and STL/VTP I/O.

Plain vectorised functions on arrays (``vertices``: (N, 3) float, ``faces``: (M, 3) int, or
``tris``: (M, 3, 3) float triangle corners), in whatever length unit the caller uses.
pyvista is imported only inside the VTP writers, VTK only inside :func:`lumen_chords`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse

from vcs.errors import VCSInputError

__all__ = [
    "boundary_loops",
    "connected_faces",
    "consistent_winding",
    "default_vessel_component",
    "edge_topology",
    "half_edges",
    "lumen_chords",
    "orient_outward",
    "point_triangle_distance",
    "points_inside",
    "polygon_properties",
    "read_stl_solids",
    "self_intersections",
    "signed_volume",
    "triangle_areas",
    "triangle_cross",
    "triangle_normals",
    "vertex_adjacency",
    "vertex_normals",
    "write_points_vtp",
    "write_polyline_vtp",
    "write_stl_ascii",
    "write_stl_binary",
]

# --------------------------------------------------------------------------- per triangle


def triangle_cross(tris: NDArray[np.floating]) -> NDArray[np.floating]:
    """Cross product (b - a) x (c - a) of each triangle (a, b, c): twice the area vector.

    Parameters
    ----------
    tris : (M, 3, 3) float
        Triangle corners.

    Returns
    -------
    (M, 3) float
        Normal direction by the winding, length = twice the triangle area (length units squared).
    """
    return np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])


def triangle_areas(vertices: NDArray[np.floating], faces: NDArray[np.integer]) -> NDArray[np.floating]:
    """Area of each triangle of a mesh.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates (any length unit).
    faces : (M, 3) int
        Triangles.

    Returns
    -------
    (M,) float
        Areas, in length units squared.
    """
    return 0.5 * np.linalg.norm(triangle_cross(vertices[faces]), axis=1)


def triangle_normals(tris: NDArray[np.floating]) -> NDArray[np.floating]:
    """Unit normal of each triangle by its winding; (0, 0, 0) for a degenerate (zero-area) triangle.

    Parameters
    ----------
    tris : (M, 3, 3) float
        Triangle corners.

    Returns
    -------
    (M, 3) float
        Unit normals (dimensionless).
    """
    n = triangle_cross(tris)
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, norm, out=np.zeros_like(n), where=norm > 0)


def vertex_normals(vertices: NDArray[np.floating], faces: NDArray[np.integer]) -> NDArray[np.floating]:
    """Area-weighted unit vertex normals, oriented as the winding gives them.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates.
    faces : (M, 3) int
        Triangles.

    Returns
    -------
    (N, 3) float
        Unit normals (dimensionless); (0, 0, 0) for a vertex used by no face.
    """
    cross = triangle_cross(vertices[faces])
    idx = faces.T.ravel()  # corner 0 of every face, then corner 1, then corner 2 (np.add.at's order)
    n = np.column_stack([np.bincount(idx, np.tile(cross[:, k], 3), minlength=len(vertices)) for k in range(3)])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def point_triangle_distance(
    points: ArrayLike, tris: NDArray[np.floating], chunk: int = 131_072
) -> NDArray[np.floating]:
    """Exact Euclidean distance from each point to the nearest of the triangles (brute force).

    Closest point on a triangle by the Voronoi regions of its vertices, edges and face
    (Ericson, Real-Time Collision Detection, 5.1.5), vectorised over points x triangles in chunks.

    Parameters
    ----------
    points : (P, 3) float
        Query points (length units of ``tris``).
    tris : (M, 3, 3) float
        Triangle corners.
    chunk : int
        Point-triangle pairs per vectorised block (~270 bytes each: 35 MB by default; at least
        one point per block).

    Returns
    -------
    (P,) float
        Distances (length units), inf when there is no triangle.
    """
    pts = np.atleast_2d(np.asarray(points, float))
    out = np.full(len(pts), np.inf)
    if len(tris) == 0:
        return out
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    ab, ac = b - a, c - a
    if len(pts) <= 64 and len(tris) > 4096:
        # a few points on a large mesh: for each, only the triangles whose bounding sphere comes
        # within its nearest corner (an upper bound of the distance; the same numbers per pair)
        centre = tris.mean(axis=1)
        radius = np.linalg.norm(tris - centre[:, None, :], axis=2).max(axis=1)
        corners = tris.reshape(-1, 3)
        for i, p in enumerate(pts):
            bound = float(np.sqrt(np.min(np.einsum("ij,ij->i", corners - p, corners - p))))
            near = np.linalg.norm(centre - p, axis=1) - radius <= bound * (1.0 + 1e-9) + 1e-12
            out[i] = _nearest_distance(p[None, None, :], a[near], b[near], c[near], ab[near], ac[near])[0]
        return out
    step = max(1, chunk // max(len(tris), 1))
    for i in range(0, len(pts), step):
        p = pts[i : i + step, None, :]  # (q, 1, 3)
        out[i : i + step] = _nearest_distance(p, a, b, c, ab, ac)
    return out


def _nearest_distance(
    p: NDArray[np.floating],
    a: NDArray[np.floating],
    b: NDArray[np.floating],
    c: NDArray[np.floating],
    ab: NDArray[np.floating],
    ac: NDArray[np.floating],
) -> NDArray[np.floating]:
    """Distance from each of the points ``p`` (q, 1, 3) to the nearest triangle (a, b, c) (m, 3)
    each, ``ab`` = b - a, ``ac`` = c - a: (q,) (:func:`point_triangle_distance`)."""
    ap, bp, cp = p - a, p - b, p - c
    d1, d2 = np.einsum("qmk,mk->qm", ap, ab), np.einsum("qmk,mk->qm", ap, ac)
    d3, d4 = np.einsum("qmk,mk->qm", bp, ab), np.einsum("qmk,mk->qm", bp, ac)
    d5, d6 = np.einsum("qmk,mk->qm", cp, ab), np.einsum("qmk,mk->qm", cp, ac)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    den = np.where(np.abs(va + vb + vc) > 0, va + vb + vc, 1.0)
    v, w = vb / den, vc / den  # face region by default
    with np.errstate(divide="ignore", invalid="ignore"):
        # edge regions (ab, ac, bc), then vertex regions, in the order that makes them win
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        t = np.where(m, d1 / np.where(d1 - d3 != 0, d1 - d3, 1.0), 0.0)
        v, w = np.where(m, t, v), np.where(m, 0.0, w)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        t = np.where(m, d2 / np.where(d2 - d6 != 0, d2 - d6, 1.0), 0.0)
        v, w = np.where(m, 0.0, v), np.where(m, t, w)
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        t = np.where(m, (d4 - d3) / np.where((d4 - d3) + (d5 - d6) != 0, (d4 - d3) + (d5 - d6), 1.0), 0.0)
        v, w = np.where(m, 1.0 - t, v), np.where(m, t, w)
    m = (d1 <= 0) & (d2 <= 0)
    v, w = np.where(m, 0.0, v), np.where(m, 0.0, w)
    m = (d3 >= 0) & (d4 <= d3)
    v, w = np.where(m, 1.0, v), np.where(m, 0.0, w)
    m = (d6 >= 0) & (d5 <= d6)
    v, w = np.where(m, 0.0, v), np.where(m, 1.0, w)
    closest = a + v[..., None] * ab + w[..., None] * ac
    return np.linalg.norm(p - closest, axis=-1).min(axis=1)


def lumen_chords(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], n_rays: int = 256, seed: int = 0
) -> NDArray[np.floating]:
    """Chords across the lumen: from wall samples along the wall normal to the first wall hit.

    ``n_rays`` triangles are drawn by area (fixed ``seed``: the same mesh gives the same chords);
    from each centroid a ray is cast both ways along the mean normal of its corners (VTK's
    OBB tree). On a tube the ray into the lumen crosses it (chord ~ the diameter, longer where it
    runs along the axis near an end) and the ray out of it mostly meets nothing: the direction with
    more hits is the lumen side, whatever the winding. Half the median chord is a robust lumen
    radius, independent of the units, the ends and the branches.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates (any length unit; the chords are in the same unit).
    faces : (M, 3) int
        Triangles, consistently wound.
    n_rays : int
        Rays cast (fewer when the mesh has fewer triangles).
    seed : int
        Seed of the area-weighted draw of the triangles.

    Returns
    -------
    (K,) float
        Chord lengths of the rays on the lumen side that hit the wall (K <= n_rays; empty when
        none did, e.g. a flat sheet), in the units of ``vertices``.
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkIdList, vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkFiltersGeneral import vtkOBBTree

    v = np.ascontiguousarray(vertices, dtype=float)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    area = triangle_areas(v, f)
    if len(f) == 0 or not area.sum() > 0:
        return np.zeros(0)
    points = vtkPoints()
    points.SetData(numpy_to_vtk(v, deep=True))
    cells = vtkCellArray()
    cells.SetData(
        numpy_to_vtkIdTypeArray(np.arange(0, 3 * len(f) + 1, 3, dtype=np.int64), deep=True),
        numpy_to_vtkIdTypeArray(f.ravel(), deep=True),
    )
    poly = vtkPolyData()
    poly.SetPoints(points)
    poly.SetPolys(cells)
    tree = vtkOBBTree()
    tree.SetDataSet(poly)
    tree.BuildLocator()

    rng = np.random.default_rng(seed)
    picked = np.sort(rng.choice(len(f), size=min(n_rays, len(f)), replace=False, p=area / area.sum()))
    vn = vertex_normals(v, f)
    origin = v[f[picked]].mean(axis=1)
    direction = vn[f[picked]].sum(axis=1)
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-300)
    reach = 2.0 * float(np.ptp(v, axis=0).max())
    eps = 1e-7 * reach
    hits: dict[int, list[float]] = {1: [], -1: []}
    found, ids = vtkPoints(), vtkIdList()
    for p0, d, own in zip(origin, direction, picked):
        for sign in (1, -1):
            tree.IntersectWithLine(p0 + sign * eps * d, p0 + sign * reach * d, found, ids)
            best = np.inf
            for k in range(found.GetNumberOfPoints()):
                dist = float(np.linalg.norm(np.asarray(found.GetPoint(k)) - p0))
                if ids.GetId(k) != own and dist > 10 * eps:
                    best = min(best, dist)
            if np.isfinite(best):
                hits[sign].append(best)
    side = max((1, -1), key=lambda s: (len(hits[s]), -float(np.median(hits[s])) if hits[s] else 0.0))
    return np.asarray(hits[side], dtype=float)


def signed_volume(vertices: NDArray[np.floating], faces: NDArray[np.integer]) -> float:
    """Signed volume enclosed by a closed triangle mesh (divergence theorem).

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates.
    faces : (M, 3) int
        Triangles of a closed surface.

    Returns
    -------
    float
        Volume in length units cubed; positive when the faces are wound outward.
    """
    tri = vertices[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6.0)


def polygon_properties(points: ArrayLike) -> tuple[NDArray[np.floating], NDArray[np.floating], float]:
    """Area centroid, unit normal (Newell) and area of a closed, roughly planar polygon.

    Parameters
    ----------
    points : (P, 3) float
        Polygon corners in order (e.g. a boundary loop).

    Returns
    -------
    centroid : (3,) float
    normal : (3,) float
        Unit normal, right-handed with the corner order; (0, 0, 1) for a zero-area polygon.
    area : float
        Length units squared.
    """
    p = np.asarray(points, float)
    ref = p.mean(axis=0)
    a, b = p - ref, np.roll(p, -1, axis=0) - ref
    cross = np.cross(a, b)  # fan triangles (ref, p_i, p_i+1), doubled areas
    n = cross.sum(axis=0)
    area = 0.5 * np.linalg.norm(n)
    if area <= 0:
        return ref, np.array([0.0, 0.0, 1.0]), 0.0
    unit = n / np.linalg.norm(n)
    w = cross @ unit
    centroid = ref + (w[:, None] * (a + b) / 3.0).sum(axis=0) / w.sum()
    return centroid, unit, float(area)


# --------------------------------------------------------------------------- connectivity


def half_edges(faces: NDArray[np.integer]) -> tuple[NDArray[np.integer], NDArray[np.integer]]:
    """Directed half-edges of a triangle list.

    Parameters
    ----------
    faces : (M, 3) int
        Triangles.

    Returns
    -------
    he : (3M, 2) int
        (from, to) vertex pairs: all edges 0->1, then all 1->2, then all 2->0.
    face : (3M,) int
        The face each half-edge belongs to.
    """
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return he, np.tile(np.arange(len(faces)), 3)


def edge_topology(faces: NDArray[np.integer]) -> tuple[NDArray[np.integer], NDArray[np.integer]]:
    """Unique undirected edges of a triangle list and how many faces use each.

    Parameters
    ----------
    faces : (M, 3) int
        Triangles.

    Returns
    -------
    edges : (E, 2) int
        Vertex pairs, sorted per row, rows in lexicographic order.
    counts : (E,) int
        Faces using each edge (1: boundary, 2: manifold interior, > 2: non-manifold).
    """
    e = half_edges(faces)[0].astype(np.int64)
    e.sort(axis=1)
    n = int(e.max()) + 1 if len(e) else 1
    keys, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)  # 1-D keys: same order, faster
    return np.column_stack([keys // n, keys % n]).astype(faces.dtype, copy=False), counts


def boundary_loops(faces: NDArray[np.integer]) -> list[NDArray[np.integer]]:
    """Closed loops of boundary edges (edges used by one face), as ordered vertex index arrays.

    Parameters
    ----------
    faces : (M, 3) int
        Triangles.

    Returns
    -------
    list of (P,) int
        One array of vertex indices per loop, in walking order (loops of fewer than 3 vertices
        left out); empty for a closed surface.
    """
    edges, counts = edge_topology(faces)
    bnd = edges[counts == 1]
    if len(bnd) == 0:
        return []
    nbrs: dict[int, list[int]] = {}
    for a, b in bnd.tolist():
        nbrs.setdefault(a, []).append(b)
        nbrs.setdefault(b, []).append(a)
    unvisited = set(nbrs)
    loops = []
    while unvisited:
        start = min(unvisited)
        loop = [start]
        unvisited.discard(start)
        prev, cur = None, start
        while True:
            nxt = [n for n in nbrs[cur] if n != prev and n in unvisited]
            if not nxt:
                break
            prev, cur = cur, nxt[0]
            loop.append(cur)
            unvisited.discard(cur)
        if len(loop) >= 3:
            loops.append(np.array(loop))
    return loops


def vertex_adjacency(faces: NDArray[np.integer], n_vertices: int) -> sparse.csr_matrix:
    """Symmetric boolean vertex adjacency of the mesh edges.

    Parameters
    ----------
    faces : (M, 3) int
        Triangles.
    n_vertices : int
        N, the number of vertices.

    Returns
    -------
    scipy.sparse.csr_matrix, (N, N) bool
        True where two vertices share an edge.
    """
    e = half_edges(faces)[0]
    A = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    return ((A + A.T) > 0).tocsr()


def connected_faces(faces: NDArray[np.integer], n_vertices: int) -> NDArray[np.integer]:
    """Connected-component label of each face (faces sharing a vertex are connected).

    Parameters
    ----------
    faces : (M, 3) int
        Triangles.
    n_vertices : int
        N, the number of vertices.

    Returns
    -------
    (M,) int
        Component label of each face (labels 0, 1, ...).
    """
    from scipy.sparse.csgraph import connected_components

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = sparse.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n_vertices, n_vertices))
    _, labels = connected_components(graph, directed=False)
    return labels[faces[:, 0]]


def default_vessel_component(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], labels: NDArray[np.integer] | None = None
) -> tuple[int, bool]:
    """The connected component taken for the vessel when no end point says which.

    Among the (at most ten) largest components by area, the largest with at least two open ends
    (boundary loops) - a vessel section is a tube -, else the largest: a closed blob of noise
    larger than the vessel is not taken for it.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates.
    faces : (M, 3) int
        Triangles.
    labels : (M,) int, optional
        Component label of each face (:func:`connected_faces`), computed when not given.

    Returns
    -------
    label : int
        The chosen component's label.
    not_largest : bool
        True when a larger component (without two open ends) was passed over.
    """
    if labels is None:
        labels = connected_faces(faces, len(vertices))
    per = np.bincount(labels, triangle_areas(vertices, faces))
    by_area = [int(c) for c in np.argsort(-per, kind="stable") if per[c] > 0][:10] or [0]
    open_tubes = [c for c in by_area if len(boundary_loops(faces[labels == c])) >= 2]
    pick = open_tubes[0] if open_tubes else by_area[0]
    return pick, pick != by_area[0]


def consistent_winding(vertices: NDArray[np.floating], faces: NDArray[np.integer]) -> tuple[NDArray[np.integer], bool]:
    """Make triangle winding consistent across shared manifold edges.

    Some exporters (e.g. STL from segmentation tools) mix windings; normals, and the star-convexity
    test of the wall fit, need them consistent. Breadth-first over the face-adjacency graph
    (scipy.sparse.csgraph): a face is flipped when it traverses an edge shared with its BFS parent
    in the same direction as the parent does. (Measured 30x faster than trimesh's
    ``repair.fix_winding`` on a 60k-triangle aorta, which walks the graph in Python.)
    The first face of each connected component keeps its winding.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates (unused; kept for a uniform signature).
    faces : (M, 3) int
        Triangles.

    Returns
    -------
    faces : (M, 3) int
        Consistently wound triangles (``faces`` itself when nothing changed).
    changed : bool
        Whether an inconsistency was found (and repaired).
    """
    from scipy.sparse.csgraph import breadth_first_order, connected_components

    m = len(faces)
    he, fid = half_edges(faces)
    key = np.sort(he, axis=1).astype(np.int64)
    n = int(key.max()) + 1 if len(key) else 1
    # 1-D keys (rows in the same lexicographic order as np.unique(axis=0), ~10x faster)
    _, inv, cnt = np.unique(key[:, 0] * n + key[:, 1], return_inverse=True, return_counts=True)
    manifold = cnt[inv] == 2
    order = np.argsort(inv[manifold], kind="stable")
    pair_f = fid[manifold][order].reshape(-1, 2)
    pair_he = he[manifold][order].reshape(-1, 2, 2)
    same_dir = np.all(pair_he[:, 0] == pair_he[:, 1], axis=1)  # inconsistent pair
    if not same_dir.any():
        return faces, False
    # graph weight 1 = consistent, 2 = flip relative to the neighbour
    w = np.where(same_dir, 2, 1)
    G = sparse.coo_matrix(
        (np.concatenate([w, w]), (np.concatenate(pair_f.T), np.concatenate(pair_f[:, ::-1].T))), shape=(m, m)
    ).tocsr()
    n_comp, labels = connected_components(G, directed=False)
    pair_f = pair_f.astype(np.int64)
    pair_key = np.concatenate([pair_f[:, 0] * m + pair_f[:, 1], pair_f[:, 1] * m + pair_f[:, 0]])
    pair_w = np.concatenate([w, w])
    srt = np.argsort(pair_key)
    pair_key, pair_w = pair_key[srt], pair_w[srt]
    # BFS tree of each component; a face flips when the swaps on its path to the root are odd
    up = np.arange(m)  # the BFS parent (roots: themselves)
    flip_mask = np.zeros(m, bool)  # swaps between a face and up[face], then (below) its root
    roots = np.unique(labels, return_index=True)[1]  # the first face of each component
    for root in roots.tolist():
        nodes, pred = breadth_first_order(G, root, directed=False, return_predecessors=True)
        child, parent = nodes[1:].astype(np.int64), pred[nodes[1:]].astype(np.int64)
        up[child] = parent
        flip_mask[child] = pair_w[np.searchsorted(pair_key, child * m + parent)] == 2
    while np.any(up[up] != up):  # pointer jumping: log2(tree depth) vectorised passes
        flip_mask ^= flip_mask[up]
        up = up[up]
    out = faces.copy()
    out[flip_mask] = out[flip_mask][:, ::-1]
    return out, True


def self_intersections(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], *, chunk: int = 65536
) -> NDArray[np.integer]:
    """Triangles that another part of the surface passes through (the surface intersects itself).

    Broad phase (:func:`_near_triangle_pairs`): the pairs of triangles whose bounding spheres
    overlap, from scipy's k-d trees of the triangle centroids, one tree per size class. Narrow
    phase, vectorised over the pairs in chunks (bounded memory): two triangles cross when an edge
    of one passes through the other (Moeller & Trumbore 1997 segment-triangle test, strictly
    inside both: margins of 1e-6 in the barycentric and segment parameters, so touching and
    T-junctions are not crossings and coplanar overlaps are not found). An edge is never tested
    against a triangle that has one of its end points as a corner: neighbours sharing an edge
    never count, and of two triangles sharing one vertex only the edges opposite it are tested
    (a fold at a vertex is found).

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates (any length unit).
    faces : (M, 3) int
        Triangles.
    chunk : int
        Pairs tested at a time (memory ~ 400 bytes per pair).

    Returns
    -------
    (K,) int
        Sorted indices of the triangles that take part in a crossing (both triangles of every
        crossing pair; empty for a surface that does not intersect itself).
    """
    faces64: NDArray[np.int64] = np.asarray(faces, np.int64)
    if len(faces64) < 2:
        return np.zeros(0, np.int64)
    tri = np.asarray(vertices, float)[faces64]
    a, b = _near_triangle_pairs(tri)
    shared = np.zeros(len(a), np.int64)
    for s in range(0, len(a), chunk):
        fa, fb = faces64[a[s : s + chunk]], faces64[b[s : s + chunk]]
        for i in range(3):  # corners in common (nine comparisons, summed one by one: fast)
            for j in range(3):
                shared[s : s + chunk] += fa[:, i] == fb[:, j]
    a, b = a[shared < 2], b[shared < 2]
    # a strict crossing needs each triangle to have corners strictly on both sides of the other's
    # plane (Moeller's 1997 triangle-triangle rejection test): most near pairs of a smooth wall fail it
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
    tol = 1e-9 * float(np.ptp(tri.reshape(-1, 3), axis=0).max() or 1.0)
    found: list[NDArray[np.int64]] = []
    for s in range(0, len(a), chunk):
        pa, pb = a[s : s + chunk], b[s : s + chunk]
        for side in (0, 1):  # b's corners about a's plane, then a's about b's for the pairs left
            p, q = (pa, pb) if side == 0 else (pb, pa)
            d = np.einsum("ijk,ik->ij", tri[q] - tri[p, :1], n[p])
            straddle = (d > tol).any(axis=1) & (d < -tol).any(axis=1)
            pa, pb = pa[straddle], pb[straddle]
        hit = _edges_cross(faces64, tri, pa, pb) | _edges_cross(faces64, tri, pb, pa)
        found += [pa[hit], pb[hit]]
    return np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)


def _near_triangle_pairs(tri: NDArray[np.floating]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Pairs (a < b) of triangles whose bounding spheres (centroid, farthest corner) overlap.

    A single radius search would have to use twice the largest sphere for every triangle (4.6
    million candidate pairs on a 61k-triangle scan whose triangles span a factor 8 in size); so
    the triangles are grouped in size classes a factor sqrt(2) apart (those below an eighth of the
    median size in one), each with a k-d tree (scipy's cKDTree), and each pair of classes is
    searched at the sum of their largest radii, then filtered with the exact sphere test."""
    from scipy.spatial import cKDTree

    c = tri.mean(axis=1)
    r = np.linalg.norm(tri - c[:, None, :], axis=2).max(axis=1)
    r_med = float(np.median(r)) or 1.0
    cls = np.floor(2.0 * np.log2(np.maximum(r, r_med / 8.0) / r_med)).astype(np.int64)
    groups = [np.flatnonzero(cls == k) for k in np.unique(cls)]
    trees = [cKDTree(c[g]) for g in groups]
    r_max = [float(r[g].max()) for g in groups]
    out_a: list[NDArray[np.int64]] = []
    out_b: list[NDArray[np.int64]] = []
    for i, gi in enumerate(groups):
        p = trees[i].query_pairs(2.0 * r_max[i], output_type="ndarray")
        out_a.append(gi[p[:, 0]])
        out_b.append(gi[p[:, 1]])
        for j in range(i + 1, len(groups)):
            m = trees[i].sparse_distance_matrix(trees[j], r_max[i] + r_max[j], output_type="ndarray")
            out_a.append(gi[m["i"]])
            out_b.append(groups[j][m["j"]])
    a, b = np.concatenate(out_a), np.concatenate(out_b)
    near = np.linalg.norm(c[a] - c[b], axis=1) <= r[a] + r[b]
    a, b = a[near], b[near]
    return np.minimum(a, b), np.maximum(a, b)


def _edges_cross(
    faces: NDArray[np.int64], tri: NDArray[np.floating], a: NDArray[np.int64], b: NDArray[np.int64]
) -> NDArray[np.bool_]:
    """For each pair (a[i], b[i]): does an edge of triangle a[i] that has no end point at a corner
    of b[i] pass through b[i]? (Moeller-Trumbore, segment against triangle, strictly inside.)"""
    hit = np.zeros(len(a), bool)
    v0, e1, e2 = tri[b, 0], tri[b, 1] - tri[b, 0], tri[b, 2] - tri[b, 0]
    n1, n2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
    fb = faces[b]
    eps = 1e-6
    for k in range(3):
        i, j = faces[a, k], faces[a, (k + 1) % 3]
        free = ~((fb == i[:, None]) | (fb == j[:, None])).any(axis=1)
        p0 = tri[a, k]
        d = tri[a, (k + 1) % 3] - p0
        q = np.cross(d, e2)
        det = np.einsum("ij,ij->i", e1, q)
        ok = free & (np.abs(det) > 1e-9 * np.maximum(np.linalg.norm(d, axis=1) * n1 * n2, 1e-300))
        inv = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
        sv = p0 - v0
        u = np.einsum("ij,ij->i", sv, q) * inv
        r = np.cross(sv, e1)
        v = np.einsum("ij,ij->i", d, r) * inv
        t = np.einsum("ij,ij->i", e2, r) * inv
        hit |= ok & (u > eps) & (v > eps) & (u + v < 1 - eps) & (t > eps) & (t < 1 - eps)
    return hit


def orient_outward(vertices: NDArray[np.floating], faces: NDArray[np.integer]) -> NDArray[np.integer]:
    """Faces of a closed mesh wound consistently and outward (positive enclosed volume).

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates.
    faces : (M, 3) int
        Triangles of a closed surface.

    Returns
    -------
    (M, 3) int
        Triangles wound outward.
    """
    faces, _ = consistent_winding(vertices, faces)
    if signed_volume(vertices, faces) < 0:
        faces = faces[:, ::-1]
    return faces


def points_inside(
    points: ArrayLike, tris: NDArray[np.floating], direction: tuple[float, float, float] = (0.5773, 0.5774, 0.5775)
) -> NDArray[np.bool_]:
    """Ray-parity point-in-closed-surface test (Moeller-Trumbore, vectorised over triangles).

    Parameters
    ----------
    points : (P, 3) float
    tris : (M, 3, 3) float
        Triangles of a closed surface (any winding).
    direction : 3 floats
        Ray direction; slightly off the axes so that rays do not run along mesh edges.

    Returns
    -------
    (P,) bool
    """
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    v0, v1, v2 = tris[:, 0], tris[:, 1], tris[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    h = np.cross(d, e2)
    a = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(a) > 1e-30
    f = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
    out = []
    for p in np.atleast_2d(points):
        s = p - v0
        u = f * np.einsum("ij,ij->i", s, h)
        q = np.cross(s, e1)
        v = f * (q @ d)
        t = f * np.einsum("ij,ij->i", e2, q)
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        out.append(int(hit.sum()) % 2 == 1)
    return np.asarray(out)


# --------------------------------------------------------------------------- STL

_STL_RECORD = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
_FACET = (
    "facet normal {:.9e} {:.9e} {:.9e}\n outer loop\n  vertex {:.9e} {:.9e} {:.9e}\n"
    "  vertex {:.9e} {:.9e} {:.9e}\n  vertex {:.9e} {:.9e} {:.9e}\n endloop\nendfacet\n"
)


def write_stl_ascii(path: str | Path, solids: dict[str, NDArray[np.floating]]) -> None:
    """ASCII STL with one named solid per entry (snappyHexMesh names its patches after them).

    Parameters
    ----------
    path : Path or str
        Output file.
    solids : dict of str -> (M, 3, 3) float
        Triangles of each solid, in the units the file should have; facet normals follow the
        winding.
    """
    with open(path, "w") as fh:
        for name, tri in solids.items():
            tri = np.asarray(tri, float).reshape(-1, 3, 3)
            n = triangle_cross(tri)
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
            fh.write(f"solid {name}\n")
            block = np.concatenate([n[:, None], tri], axis=1).reshape(-1, 12)
            fh.write("".join(_FACET.format(*row) for row in block.tolist()))
            fh.write(f"endsolid {name}\n")


def write_stl_binary(
    path: str | Path, vertices: NDArray[np.floating], faces: NDArray[np.integer], header: str = ""
) -> None:
    """Write a triangle mesh as binary STL (single solid, float32, facet normals by the winding).

    Parameters
    ----------
    path : Path or str
        Output file.
    vertices : (N, 3) float
        Vertex coordinates, in the units the file should have.
    faces : (M, 3) int
        Triangles.
    header : str
        Text for the 80-byte header (truncated to 80 bytes, padded with spaces).
    """
    tri = np.asarray(vertices, float)[np.asarray(faces)]
    rec = np.zeros(len(tri), dtype=_STL_RECORD)
    rec["n"] = triangle_normals(tri)
    rec["v"] = tri
    with open(Path(path), "wb") as fh:
        fh.write(header.encode()[:80].ljust(80, b" "))
        fh.write(np.array([len(tri)], dtype="<u4").tobytes())
        rec.tofile(fh)


def read_stl_solids(path: str | Path) -> dict[str, NDArray[np.floating]]:
    """Read a multi-solid ASCII STL into its named solids.

    Parameters
    ----------
    path : Path or str
        ASCII STL file.

    Returns
    -------
    dict of str -> (M, 3, 3) float
        Triangle corners of each solid, in the units of the file.

    Raises
    ------
    VCSInputError
        When the file holds no ASCII solid (e.g. a binary STL).
    """
    solids: dict[str, list[list[list[float]]]] = {}
    name = None
    tri: list[list[float]] = []
    with open(path, encoding="ascii", errors="replace") as fh:
        for line in fh:
            tok = line.split()
            if not tok:
                continue
            key = tok[0].lower()
            if key == "solid":
                name = tok[1] if len(tok) > 1 else "solid"
                solids.setdefault(name, [])
            elif key == "vertex":
                tri.append([float(tok[1]), float(tok[2]), float(tok[3])])
                if len(tri) == 3:
                    solids.setdefault(name or "solid", []).append(tri)
                    tri = []
            elif key == "endsolid":
                name = None
    if not solids:
        raise VCSInputError(f"{path}: no ASCII STL solids found (binary STL is not supported)")
    return {k: np.asarray(v, dtype=float).reshape(-1, 3, 3) for k, v in solids.items()}


# --------------------------------------------------------------------------- VTP


def write_polyline_vtp(path: str | Path, points: ArrayLike, point_data: dict[str, ArrayLike] | None = None) -> None:
    """Write one polyline through ``points`` with optional point arrays as VTP.

    Parameters
    ----------
    path : Path or str
        Output ``.vtp`` file.
    points : (P, 3) float
        Polyline vertices in order (any length unit).
    point_data : dict of str -> (P, ...) array, optional
        Point arrays.
    """
    n = len(np.asarray(points))
    segments = np.column_stack([np.arange(n - 1), np.arange(1, n)])  # one line cell per segment
    _write_vtp(path, points, point_data, lines=segments)


def write_points_vtp(path: str | Path, points: ArrayLike, point_data: dict[str, ArrayLike] | None = None) -> None:
    """Write a point cloud with optional point arrays as VTP.

    Parameters
    ----------
    path : Path or str
        Output ``.vtp`` file.
    points : (P, 3) float
        Points (any length unit).
    point_data : dict of str -> (P, ...) array, optional
        Point arrays.
    """
    _write_vtp(path, points, point_data, verts=np.arange(len(np.asarray(points)))[:, None])  # one vertex cell per point


def _write_vtp(
    path: str | Path,
    points: ArrayLike,
    point_data: dict[str, ArrayLike] | None,
    *,
    verts: NDArray[np.integer] | None = None,
    lines: NDArray[np.integer] | None = None,
) -> None:
    """Points, their arrays and vertex or line cells as a binary, zlib-compressed VTP (VTK's XML
    writer, as pyvista's ``save``; VTK directly, without pyvista's ~0.2 s import).

    Parameters
    ----------
    path : Path or str
        Output ``.vtp`` file.
    points : (P, 3) float
    point_data : dict of str -> (P, ...) array, optional
    verts, lines : (C, k) int, optional
        Vertex cells (k = 1) or line cells (k = 2) as point indices.
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk, numpy_to_vtkIdTypeArray
    from vtkmodules.vtkCommonCore import vtkPoints
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    poly = vtkPolyData()
    pts = vtkPoints()
    pts.SetData(numpy_to_vtk(np.ascontiguousarray(points, dtype=float), deep=True))
    poly.SetPoints(pts)
    for cells, setter in ((verts, poly.SetVerts), (lines, poly.SetLines)):
        if cells is not None:
            cells = np.asarray(cells, dtype=np.int64)
            arr = vtkCellArray()
            arr.SetData(
                numpy_to_vtkIdTypeArray(
                    np.arange(0, cells.size + 1, max(cells.shape[1], 1), dtype=np.int64), deep=True
                ),
                numpy_to_vtkIdTypeArray(np.ascontiguousarray(cells.ravel()), deep=True),
            )
            setter(arr)
    for name, values in (point_data or {}).items():
        values = np.asarray(values)
        a = numpy_to_vtk(np.ascontiguousarray(values.astype(np.uint8) if values.dtype == bool else values), deep=True)
        a.SetName(name)
        poly.GetPointData().AddArray(a)
    writer = vtkXMLPolyDataWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(poly)
    writer.SetDataModeToBinary()
    writer.SetCompressorTypeToZLib()
    if writer.Write() != 1:
        raise OSError(f"VTK could not write '{path}'")


def plane_section(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    p: NDArray[np.floating],
    n: NDArray[np.floating],
    r_max: float,
) -> tuple[NDArray[np.floating] | None, float | None]:
    """Centroid and equivalent radius of the wall's cut by the plane (p, n), within r_max of p.

    Parameters
    ----------
    vertices : (N, 3) float, mm
    faces : (M, 3) int
    p : (3,) float, mm
        A point of the plane.
    n : (3,) float
        Unit normal of the plane.
    r_max : float, mm
        Only crossings within this distance of ``p`` count.

    Returns
    -------
    center : (3,) float, mm, or None
        Mean of the edge crossings (None when fewer than 3).
    radius : float, mm, or None
        Median distance of the crossings to ``center``.
    """
    sd = (vertices - p) @ n
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    a, b = sd[e[:, 0]], sd[e[:, 1]]
    cross = (a * b) < 0
    ea, eb = e[cross, 0], e[cross, 1]
    w = (a[cross] / (a[cross] - b[cross]))[:, None]
    on = np.abs(sd) <= 1e-9 * max(float(np.ptp(vertices)), 1.0)  # vertices lying in the plane
    x = np.vstack([vertices[ea] + w * (vertices[eb] - vertices[ea]), vertices[np.unique(faces)[on[np.unique(faces)]]]])
    x = x[np.linalg.norm(x - p, axis=1) < r_max]
    if len(x) < 3:
        return None, None
    c = x.mean(axis=0)
    return c, float(np.median(np.linalg.norm(x - c, axis=1)))
