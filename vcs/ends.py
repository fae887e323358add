"""The two end planes of a vessel section: open boundary loops, labelled caps, cap files or points.

Paper Section 2.2.1: the section lies between two end planes whose centres p_A (tau = 0, inlet)
and p_B (tau = 1, outlet) are the end points of the centerline search.

The candidate ends of a surface (:func:`list_ends`, what `vcs ends` prints) are, in this order:
labelled caps (planar discs of a cell array such as ``ModelFaceID``), open boundary loops, flat
unlabelled caps of a closed surface (planar discs bounded by sharp edges) and blunt closed ends
(geodesic extremities of a closed surface whose caps are rounded or remeshed). ``end:N`` selects
candidate N of that list, ``NAME=VALUE`` a labelled cap (:func:`parse_end_option`).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.sparse.csgraph import connected_components, dijkstra

from vcs.errors import VCSInputError
from vcs.io import UNIT_TO_MM
from vcs.mesh import (
    boundary_loops,
    edge_topology,
    half_edges,
    lumen_chords,
    plane_section,
    points_inside,
    polygon_properties,
    triangle_areas,
    triangle_cross,
    triangle_normals,
)

log = logging.getLogger(__name__)

CAP_ARRAY_NAMES = ("ModelFaceID", "CapID", "FaceID", "face_id", "RegionId")


@dataclass(frozen=True)
class End:
    """One end of the section: the centre and normal of its end plane (paper Section 2.2.1).

    Attributes
    ----------
    center : (3,) float, mm
        Area centroid of the opening or cap (p_A or p_B), or the given point.
    normal : (3,) float or None
        Unit normal of the end plane pointing into the lumen; None when unknown (an explicit
        point on a closed surface).
    radius : float or None, mm
        Equivalent radius sqrt(area / pi) of the opening; None for an explicit point.
    source : str
        How the end was found (e.g. ``"open loop (64 edges)"``, ``"ModelFaceID=2"``, ``"point"``).
    """

    center: NDArray[np.floating]
    normal: NDArray[np.floating] | None
    radius: float | None
    source: str


@dataclass(frozen=True)
class Ends:
    """Both ends, how they were found, and the closed surface used to voxelise the lumen.

    Attributes
    ----------
    inlet : End
        The end at tau = 0.
    outlet : End
        The end at tau = 1.
    method : str
        ``"open_loops"``, ``"labelled_caps"``, ``"flat_caps"``, ``"closed_ends"``, ``"cap_files"``
        or ``"points"``; two different kinds joined by ``+`` (e.g. ``"flat_caps+points"``).
    wall_mask : (M,) bool
        Faces of the input that belong to the wall (not to labelled or flat caps).
    closed_vertices : (N', 3) float, mm
        The input vertices plus one centre vertex per closed boundary loop.
    closed_faces : (M', 3) int
        The input faces plus triangle fans closing every boundary loop.
    n_open_loops : int
        Number of boundary loops of the input.
    notes : list of str
        What was decided, for the report.
    warnings : list of str
        Mesh problems found (non-manifold edges, holes).
    """

    inlet: End
    outlet: End
    method: str  # "open_loops" | "labelled_caps" | "flat_caps" | "closed_ends" | "cap_files" | "points" | "a+b"
    wall_mask: NDArray[np.bool_]  # (M,) bool: faces of the input that belong to the wall (not caps)
    closed_vertices: NDArray[np.floating]
    closed_faces: NDArray[np.integer]
    n_open_loops: int
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def _inward(
    center: NDArray[np.floating], normal: NDArray[np.floating], radius: float, vertices: NDArray[np.floating]
) -> NDArray[np.floating]:
    """Orient a plane normal at an end towards the wall vertices near that end (into the lumen)."""
    d = vertices - center
    near = np.linalg.norm(d, axis=1) < 2.0 * radius
    side = d[near] @ normal if near.any() else d @ normal
    return normal if np.sum(side) >= 0 else -normal


def _wall_on_both_sides(vertices: NDArray[np.floating], e: End) -> bool:
    """True when the wall near an opening lies on both sides of its plane: a hole in the wall
    (an open end has the whole vessel on one side). ``e`` is an open-loop end (normal and radius set)."""
    radius = cast(float, e.radius)  # open-loop ends always have a radius and a normal
    d = vertices - e.center
    near = np.linalg.norm(d, axis=1) < 2.5 * radius
    side = d[near] @ e.normal
    tol = 0.05 * radius
    return bool(min(np.mean(side > tol), np.mean(side < -tol)) > 0.1)


def _fan_caps(
    vertices: NDArray[np.floating], loops: list[NDArray[np.integer]]
) -> tuple[NDArray[np.floating], NDArray[np.integer]]:
    """Close every boundary loop with a triangle fan around its centroid."""
    new_v, new_f = [vertices], []
    n = len(vertices)
    for loop in loops:
        c, _, _ = polygon_properties(vertices[loop])
        new_v.append(c[None])
        new_f.append(np.column_stack([loop, np.roll(loop, -1), np.full(len(loop), n)]))
        n += 1
    faces = np.concatenate(new_f) if new_f else np.zeros((0, 3), int)
    return np.concatenate(new_v), faces


def _end_from_faces(vertices: NDArray[np.floating], faces: NDArray[np.integer], source: str) -> End:
    """The end of a cap given as triangles: area centroid, unit normal, equivalent radius.

    The normal is the winding's (the sum of the triangles' area vectors) for an open cap. A cap
    file that is a closed thin disc (both faces and the rim: a segmentation tool's "cap solid")
    has an area vector sum of ~0, whose direction is round-off: then the normal is the principal
    axis of the area-weighted normal tensor sum a n n^T (the disc's axis; the caller turns it into
    the lumen), and the equivalent radius counts one face (half the area)."""
    tri = vertices[faces]
    cross = triangle_cross(tri)
    area2 = np.linalg.norm(cross, axis=1)
    area = 0.5 * area2.sum()
    center = (tri.mean(axis=1) * area2[:, None]).sum(axis=0) / max(area2.sum(), 1e-300)
    n = cross.sum(axis=0)
    if np.linalg.norm(n) >= 0.5 * area2.sum():  # an open cap: the winding gives the normal
        return End(center, n / max(np.linalg.norm(n), 1e-300), float(np.sqrt(area / np.pi)), source)
    unit = cross / np.maximum(area2, 1e-300)[:, None]
    _, axes = np.linalg.eigh((unit * area2[:, None]).T @ unit)
    return End(center, axes[:, -1], float(np.sqrt(0.5 * area / np.pi)), source)


# ------------------------------------------------------------------ candidate ends

KIND_METHOD = {
    "labelled cap": "labelled_caps",
    "open loop": "open_loops",
    "flat cap": "flat_caps",
    "closed end": "closed_ends",
}
"""``Ends.method`` of each candidate kind."""

SHARP_EDGE_DEG = 60.0
"""Dihedral angle (degrees) above which an edge bounds a flat cap."""

_PLANARITY = 0.99  # largest eigenvalue / trace of the area-weighted normal tensor of a flat disc
_FLATNESS = 0.05  # largest distance of a disc's vertices from its plane, in disc radii
_ROUNDNESS = 0.3  # smallest 4 pi area / perimeter^2 of a disc (circle 1, 4:1 ellipse ~0.5)
_MAX_LABELS = 256  # a cell array with more distinct values labels cells, not faces
_MIN_CAP_RADIUS = 0.1  # smallest flat cap of an unlabelled surface, in median lumen radii
_MAX_TIP_CANDIDATES = 500  # geodesic local maxima examined as closed ends


@dataclass(frozen=True)
class EndCandidate:
    """One candidate end of a surface, as `vcs ends` lists it (lengths in mm).

    Attributes
    ----------
    kind : str
        ``"labelled cap"``, ``"open loop"``, ``"flat cap"`` or ``"closed end"``.
    end : End
        What the fit uses: the cap or loop plane; for a closed end a point inside the lumen near
        the end, with ``normal`` and ``radius`` None (its end plane then comes from the lumen
        path, as for a point the user gives).
    radius : float, mm
        Equivalent radius sqrt(area / pi) of a cap or loop; for a closed end the lumen radius
        measured next to it.
    normal : (3,) float or None
        Unit normal into the lumen (for a closed end: from its tip into the lumen).
    label : str or None
        ``NAME=VALUE`` of a labelled cap (its cell array and value).
    faces : (K,) int
        Faces of a labelled or flat cap; empty for loops and closed ends.
    """

    kind: str
    end: End
    radius: float
    normal: NDArray[np.floating] | None
    label: str | None = None
    faces: NDArray[np.integer] = field(default_factory=lambda: np.zeros(0, np.int64))


@dataclass(frozen=True)
class EndList:
    """The candidate ends of a surface (:func:`list_ends`); ``end:N`` is ``candidates[N]``.

    Attributes
    ----------
    candidates : list of EndCandidate
        Labelled caps, open loops, flat caps, closed ends; each kind by decreasing radius.
    cap_array : str or None
        The cell array whose values label the caps, if any.
    loops : list of (P,) int
        Every boundary loop of the surface (ends and holes).
    n_holes : int
        Loops that are holes in the wall, not ends (small, or with wall on both sides).
    wall_mask : (M,) bool
        Faces that are wall: not in a labelled or flat cap.
    lumen_radius : float or None, mm
        Median lumen radius, when it was needed (closed surfaces).
    notes : list of str
        How the candidates were found.
    """

    candidates: list[EndCandidate]
    cap_array: str | None
    loops: list[NDArray[np.integer]]
    n_holes: int
    wall_mask: NDArray[np.bool_]
    lumen_radius: float | None = None
    notes: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class EndSelector:
    """An end chosen from :func:`list_ends` by index (``end:N``) or by label (``NAME=VALUE``).

    Attributes
    ----------
    text : str
        As the user wrote it.
    index : int or None
        N of ``end:N``.
    array, value : str and int, or None
        Cell array name and value of ``NAME=VALUE``.
    """

    text: str
    index: int | None = None
    array: str | None = None
    value: int | None = None

    @property
    def label(self) -> str | None:
        """``NAME=VALUE`` (normalised), or None for an index."""
        return None if self.array is None else f"{self.array}={self.value}"


_END_INDEX = re.compile(r"end\s*:\s*(\d+)", re.IGNORECASE)
_END_LABEL = re.compile(r"([A-Za-z_][A-Za-z0-9_.\-]*)\s*=\s*([-+]?\d+)")


def parse_end_option(text: str | ArrayLike | None, name: str) -> NDArray[np.floating] | EndSelector | None:
    """Parse an ``--inlet``/``--outlet`` value: a point ``x,y,z``, ``end:N`` or ``NAME=VALUE``.

    Blanks anywhere and a leading minus sign are fine (``" -40, 0, 0"``).

    Parameters
    ----------
    text : str, array-like of 3 floats, or None
        The value; a point is in mesh units. None passes through.
    name : str
        Option name for the error message (``inlet`` -> ``--inlet``).

    Returns
    -------
    (3,) float, EndSelector or None
        A point (mesh units, not converted), a selector of a listed end, or None.

    Raises
    ------
    VCSInputError
        When ``text`` is none of the three forms (one line naming the forms).
    """
    if text is None:
        return None
    if not isinstance(text, str):
        p = np.asarray(text, float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise VCSInputError(f"--{name} {text!r} is not a point; give three finite numbers x,y,z (mesh units)")
        return p
    t = text.strip()
    m = _END_INDEX.fullmatch(t)
    if m:
        return EndSelector(text, index=int(m.group(1)))
    m = _END_LABEL.fullmatch(t)
    if m:
        return EndSelector(text, array=m.group(1), value=int(m.group(2)))
    try:
        p = np.array([float(v) for v in t.split(",")])
    except ValueError:
        p = np.zeros(0)
    if p.shape == (3,) and np.all(np.isfinite(p)):
        return p
    hint = f"; for end {t} of `vcs ends` write end:{t}" if t.isdigit() else ""
    raise VCSInputError(
        f"--{name} '{text}' is not a point; write it as x,y,z (mesh units), or choose an end listed by "
        f"`vcs ends MESH` as end:N or NAME=VALUE{hint}"
    )


def _face_pairs(faces: NDArray[np.integer]) -> NDArray[np.integer]:
    """(P, 2) pairs of faces sharing a manifold edge (an edge of exactly two faces)."""
    he, fid = half_edges(faces)
    e = np.sort(he, axis=1)
    key = e[:, 0] * (int(faces.max()) + 1) + e[:, 1]
    order = np.argsort(key, kind="stable")
    key, fid = key[order], fid[order]
    first = np.r_[True, key[1:] != key[:-1]]
    group = np.cumsum(first) - 1
    two = np.bincount(group)[group] == 2
    i = np.nonzero(first & two)[0]
    return np.column_stack([fid[i], fid[i + 1]])


def _disc(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], min_radius: float = 0.0
) -> tuple[NDArray[np.floating], NDArray[np.floating], float] | None:
    """Centre, unit normal (by the winding) and equivalent radius of triangles forming a flat disc.

    A flat disc: normals nearly parallel (:data:`_PLANARITY`, sign-insensitive), vertices within
    :data:`_FLATNESS` radii of the plane, one boundary loop, round enough (:data:`_ROUNDNESS`),
    radius at least ``min_radius``. None otherwise.
    """
    tri = vertices[faces]
    cross = triangle_cross(tri)
    a2 = np.linalg.norm(cross, axis=1)
    if len(faces) == 0 or a2.sum() <= 0:
        return None
    n = cross / np.maximum(a2, 1e-300)[:, None]
    tensor = (n * a2[:, None]).T @ n
    w, vec = np.linalg.eigh(tensor)
    if w[-1] < _PLANARITY * w.sum():
        return None
    normal = vec[:, -1] if cross.sum(axis=0) @ vec[:, -1] >= 0 else -vec[:, -1]
    area = 0.5 * float(a2.sum())
    radius = float(np.sqrt(area / np.pi))
    if radius < min_radius:
        return None
    center = (tri.mean(axis=1) * a2[:, None]).sum(axis=0) / a2.sum()
    if np.abs((vertices[np.unique(faces)] - center) @ normal).max() > _FLATNESS * radius:
        return None
    loops = boundary_loops(faces)
    if len(loops) != 1:
        return None
    ring = vertices[loops[0]]
    perimeter = float(np.linalg.norm(ring - np.roll(ring, -1, axis=0), axis=1).sum())
    if 4 * np.pi * area < _ROUNDNESS * perimeter**2:
        return None
    return center, normal, radius


def _groups(labels: NDArray[np.integer]) -> list[NDArray[np.integer]]:
    """Indices of each distinct value of ``labels``, by increasing value."""
    order = np.argsort(labels, kind="stable")
    cuts = np.nonzero(np.diff(labels[order]))[0] + 1
    return np.split(order, cuts)


def _labelled_caps(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    cell_data: dict[str, NDArray[Any]],
    cap_array: str | None,
) -> tuple[str | None, list[tuple[str, NDArray[np.integer], tuple[NDArray[np.floating], NDArray[np.floating], float]]]]:
    """Caps labelled by a cell array: the values whose faces form a flat disc (at least two).

    ``cap_array="auto"`` tries :data:`CAP_ARRAY_NAMES`, then any other integer-valued cell array
    with 3 to :data:`_MAX_LABELS` distinct values; a cap has at least 3 triangles and the caps
    cover less than half the surface (an array numbering the cells is not a labelling of caps).
    Returns the array name (None when no array labels two caps) and per cap its label
    ``NAME=VALUE``, faces and disc.
    """
    if cap_array is None:
        return None, []
    if cap_array != "auto" and cap_array not in cell_data:
        raise VCSInputError(
            f"cell array '{cap_array}' not found in the mesh (it has: {', '.join(cell_data) or 'none'}); "
            "give an existing array with --cap-array or omit it"
        )
    if cap_array == "auto":
        names = [n for n in CAP_ARRAY_NAMES if n in cell_data]
        names += sorted(n for n in cell_data if n not in CAP_ARRAY_NAMES)
    else:
        names = [cap_array]
    total_area = float(triangle_areas(vertices, faces).sum())
    for name in names:
        values = np.asarray(cell_data[name])
        if values.ndim != 1 or len(values) != len(faces) or not np.issubdtype(values.dtype, np.number):
            continue
        if not np.all(np.isfinite(values)) or not np.array_equal(values, np.round(values)):
            continue
        labels = values.astype(np.int64)
        groups = _groups(labels)
        if not 3 <= len(groups) <= _MAX_LABELS:
            continue
        caps = []
        for idx in groups:
            disc = _disc(vertices, faces[idx]) if len(idx) >= 3 else None
            if disc is not None:
                caps.append((f"{name}={int(labels[idx[0]])}", idx, disc))
        cap_area = sum(np.pi * disc[2] ** 2 for _, _, disc in caps)
        if len(caps) >= 2 and cap_area < 0.5 * total_area:  # mostly wall: not one label per cell
            return name, caps
    return None, []


def _flat_caps(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], min_radius: float
) -> list[tuple[NDArray[np.integer], tuple[NDArray[np.floating], NDArray[np.floating], float]]]:
    """Unlabelled flat caps: regions bounded by sharp edges (> :data:`SHARP_EDGE_DEG`) that are flat discs."""
    pairs = _face_pairs(faces)
    n = triangle_normals(vertices[faces])
    smooth = pairs[np.einsum("ij,ij->i", n[pairs[:, 0]], n[pairs[:, 1]]) > np.cos(np.radians(SHARP_EDGE_DEG))]
    m = len(faces)
    graph = sparse.coo_matrix((np.ones(len(smooth)), (smooth[:, 0], smooth[:, 1])), shape=(m, m))
    n_regions, region = connected_components(graph, directed=False)
    if n_regions < 2:
        return []
    caps = []
    for idx in _groups(region):
        if len(idx) >= 3:
            disc = _disc(vertices, faces[idx], min_radius)
            if disc is not None:
                caps.append((idx, disc))
    return caps


def _closed_ends(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    lumen_radius: float,
    taken: list[tuple[NDArray[np.floating], float]],
    closed: bool = True,
) -> list[tuple[NDArray[np.floating], NDArray[np.floating], float]]:
    """Blunt ends of a closed surface: geodesic extremities, each with a point on the lumen axis next to it.

    The tips are the vertex farthest (along the surface) from an arbitrary vertex, and the local
    maxima of the geodesic distance from that tip that are maxima within 1.5 lumen radii. Near
    each tip, the wall within 2 lumen radii (sampled, :func:`_surface_samples`) gives the lumen's
    axis direction (tip -> centroid) and a slab across it a point on the axis, moved to the last
    full cross-section before the end (:func:`_full_section`), and the local radius. Tips within 2 radii (+ half a lumen
    radius) of a ``taken`` end (centre, radius) are the same end and skipped, and so is a point
    within one lumen radius of an earlier one (two tips of one blob, e.g. a sphere). On a
    ``closed`` surface a point outside the lumen is replaced by the first estimate, or dropped.
    Returns (point on the axis, unit direction into the lumen, radius) per closed end, mm.
    """
    he, _ = half_edges(faces)
    length = np.linalg.norm(vertices[he[:, 0]] - vertices[he[:, 1]], axis=1)
    nv = len(vertices)
    graph = sparse.coo_matrix((length, (he[:, 0], he[:, 1])), shape=(nv, nv)).tocsr()
    graph = graph.maximum(graph.T)
    d0 = dijkstra(graph, indices=int(faces[0, 0]))
    first = int(np.argmax(np.where(np.isfinite(d0), d0, -1.0)))
    d = dijkstra(graph, indices=first)
    d = np.where(np.isfinite(d), d, -1.0)
    ring_max = np.full(nv, -np.inf)
    np.maximum.at(ring_max, he[:, 0], d[he[:, 1]])
    cand = np.nonzero((d >= ring_max) & (d > 0))[0]
    cand = cand[np.argsort(-d[cand], kind="stable")][:_MAX_TIP_CANDIDATES]
    rho = 1.5 * lumen_radius
    tips = [first]
    for c in cand.tolist():
        if any(np.linalg.norm(vertices[c] - vertices[t]) < rho for t in tips):
            continue
        ball = np.isfinite(dijkstra(graph, indices=c, limit=rho))
        if d[ball].max() <= d[c]:
            tips.append(c)
    tri = vertices[faces]
    out: list[tuple[NDArray[np.floating], NDArray[np.floating], float]] = []
    for t in tips:
        tip = vertices[t]
        if any(np.linalg.norm(tip - c) <= 2.0 * r + 0.5 * lumen_radius for c, r in taken):
            continue
        near_v = np.isfinite(dijkstra(graph, indices=t, limit=3.0 * lumen_radius))
        x, w = _surface_samples(vertices, faces[near_v[faces].any(axis=1)], 0.2 * lumen_radius)
        keep = np.linalg.norm(x - tip, axis=1) < 3.0 * lumen_radius
        x, w = x[keep], w[keep]
        ball = np.linalg.norm(x - tip, axis=1) < 2.0 * lumen_radius
        if ball.sum() < 6:
            continue
        c = (x[ball] * w[ball, None]).sum(axis=0) / w[ball].sum()
        axis = c - tip
        if np.linalg.norm(axis) < 1e-9 * lumen_radius:
            continue
        axis /= np.linalg.norm(axis)
        slab = ball & (np.abs((x - c) @ axis) < 0.5 * lumen_radius)
        if slab.sum() < 6:
            continue
        start = (x[slab] * w[slab, None]).sum(axis=0) / w[slab].sum()
        point, axis, radius = _full_section(x, w, start, axis, lumen_radius)
        if closed:  # the point must lie in the lumen (ray parity on the closed surface)
            inside = points_inside(np.stack([point, start]), tri)
            if not inside.any():
                continue
            point = point if inside[0] else start
        if any(np.linalg.norm(point - q) < lumen_radius for q, _, _ in out):
            continue  # two tips of one blob (a sphere, a short stump): not two ends of a tube
        out.append((point, axis, radius))
    return out


def _surface_samples(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], spacing: float
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Points on the triangles at most ~``spacing`` apart (barycentric grids), each with its share of
    the triangle's area: long thin triangles (a cylinder wall in one band) are sampled along their
    length, not only at their centroid. Returns (P, 3) points (mm) and (P,) areas (mm^2)."""
    tri = vertices[faces]
    area = triangle_areas(vertices, faces)
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    n_sub = np.clip(np.ceil(edge / spacing), 1, 40).astype(int)
    pts, wts = [tri.mean(axis=1)[n_sub == 1]], [area[n_sub == 1]]
    for n in np.unique(n_sub[n_sub > 1]):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        ok = i + j <= n
        b1, b2 = i[ok] / n, j[ok] / n
        b0 = 1.0 - b1 - b2
        tb = tri[n_sub == n]
        pts.append(
            (
                b0[None, :, None] * tb[:, None, 0]
                + b1[None, :, None] * tb[:, None, 1]
                + b2[None, :, None] * tb[:, None, 2]
            ).reshape(-1, 3)
        )
        wts.append(np.repeat(area[n_sub == n] / len(b0), len(b0)))
    return np.concatenate(pts), np.concatenate(wts)


def _full_section(
    x: NDArray[np.floating],
    w: NDArray[np.floating],
    point: NDArray[np.floating],
    axis: NDArray[np.floating],
    lumen_radius: float,
) -> tuple[NDArray[np.floating], NDArray[np.floating], float]:
    """The last full cross-section before a closed end: a point on the axis there, the axis, the radius.

    ``point`` is a section centre about a lumen radius in from the end and ``axis`` points into
    the lumen. The axis is refined through the centre of the section one radius deeper; then,
    going from ``point`` towards the end in steps of 0.1 lumen radii, the wall's median distance
    from the axis stays above 85 % of the radius at ``point`` until the cap (flat, staircase or
    rounded) begins (or a tenth of a slab's area comes near the axis), at most one radius: the
    returned point is one step before the last such step. ``x``/``w`` are wall samples near the
    end and their areas (mm, mm^2, :func:`_surface_samples`).
    """
    r = lumen_radius
    deeper = (np.abs((x - point - r * axis) @ axis) < 0.5 * r) & (
        np.linalg.norm(x - point - r * axis, axis=1) < 2.0 * r
    )
    if deeper.sum() >= 6:
        q = (x[deeper] * w[deeper, None]).sum(axis=0) / w[deeper].sum()
        if (q - point) @ axis > 0.3 * r:
            axis = (q - point) / np.linalg.norm(q - point)
    rel = x - point
    s = rel @ axis
    rho = np.linalg.norm(rel - np.outer(s, axis), axis=1)
    a = w
    ok = rho < 2.0 * r

    def section(depth: float, full: float | None) -> float | None:
        """Median wall distance from the axis in a slab at ``depth``; None when the slab has too
        few triangles or reaches the cap (a tenth of its area within 0.7 ``full`` of the axis)."""
        band = ok & (np.abs(s - depth) < 0.15 * r)
        if band.sum() < 4:
            return None
        if full is not None and a[band & (rho < 0.7 * full)].sum() > 0.1 * a[band].sum():
            return None
        return float(np.median(rho[band]))

    full = section(0.0, None)
    if full is None:
        return point, axis, r
    depth = 0.0
    while depth > -r:  # at most one lumen radius towards the end
        here = section(depth - 0.1 * r, full)
        if here is None or here < 0.85 * full:
            break
        depth -= 0.1 * r
    return point + (depth + 0.1 * r if depth < 0 else 0.0) * axis, axis, full


def _sorted(cands: list[EndCandidate]) -> list[EndCandidate]:
    """``cands`` by decreasing radius (ties by centre coordinates): a stable listing order."""
    return sorted(cands, key=lambda c: (-round(c.radius, 9), *np.round(c.end.center, 9).tolist()))


def list_ends(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    cell_data: dict[str, NDArray[Any]] | None = None,
    *,
    cap_array: str | None = "auto",
    lumen_radius: float | None = None,
) -> EndList:
    """The candidate ends of a surface, in the order `vcs ends` lists them and ``end:N`` counts.

    1. labelled caps: the values of a cell array (``cap_array``; ``auto``: :data:`CAP_ARRAY_NAMES`,
       then any integer cell array with few values) whose faces form flat discs;
    2. open boundary loops (loops that are holes in the wall, small or with wall on both sides,
       are not ends);
    3. on a closed surface (no labelled caps, fewer than two open ends): flat caps, regions bounded
       by sharp edges (dihedral angle > :data:`SHARP_EDGE_DEG`) that are flat discs of radius at
       least 0.1 median lumen radii;
    4. and closed ends: geodesic extremities not at a cap or loop (blunt or remeshed caps).

    Each kind is listed by decreasing radius; normals point into the lumen.

    Parameters
    ----------
    vertices : (N, 3) float, mm
        Surface vertices.
    faces : (M, 3) int
        Surface triangles (consistently wound).
    cell_data : dict of str -> (M,) array, optional
        Cell arrays of the surface (searched for cap labels).
    cap_array : str or None
        Cell array labelling the caps; ``"auto"`` searches, None skips labelled caps.
    lumen_radius : float, mm, optional
        Median lumen radius (:func:`vcs.io.measure_units`); measured here when a closed surface
        needs it and it is not given.

    Returns
    -------
    EndList

    Raises
    ------
    VCSInputError
        A named ``cap_array`` that the mesh does not have.
    """
    cell_data = cell_data or {}
    notes: list[str] = []
    wall_mask = np.ones(len(faces), bool)
    array, labelled = _labelled_caps(vertices, faces, cell_data, cap_array)
    caps: list[EndCandidate] = []
    for label, idx, (c, n, r) in labelled:
        wall_mask[idx] = False
        caps.append(EndCandidate("labelled cap", End(c, n, r, label), r, n, label, idx))
    if array:
        notes.append(f"caps labelled by cell array '{array}': {len(caps)} flat labelled caps")

    loops = boundary_loops(faces)
    loop_ends = []
    for loop in loops:
        c, n, a = polygon_properties(vertices[loop])
        r = float(np.sqrt(a / np.pi))
        loop_ends.append(EndCandidate("open loop", End(c, n, r, f"open loop ({len(loop)} edges)"), r, n))
    n_holes = 0
    if len(loop_ends) >= 3:  # small openings are holes in the wall, not ends
        r_big = max(e.radius for e in loop_ends)
        holes = [e.radius < 0.2 * r_big or _wall_on_both_sides(vertices, e.end) for e in loop_ends]
        n_holes = sum(holes)
        loop_ends = [e for e, h in zip(loop_ends, holes) if not h]

    flat: list[EndCandidate] = []
    closed: list[EndCandidate] = []
    if not caps and len(loop_ends) < 2:
        if lumen_radius is None:
            chords = lumen_chords(vertices, faces)
            lumen_radius = 0.5 * float(np.median(chords)) if len(chords) >= 8 else None
        if lumen_radius:
            for idx, (c, n, r) in _flat_caps(vertices, faces, _MIN_CAP_RADIUS * lumen_radius):
                wall_mask[idx] = False
                flat.append(EndCandidate("flat cap", End(c, n, r, f"flat cap ({len(idx)} triangles)"), r, n, None, idx))
            taken = [(e.end.center, e.radius) for e in (*flat, *loop_ends)]
            for p, axis, r in _closed_ends(vertices, faces, lumen_radius, taken, closed=not loops):
                closed.append(EndCandidate("closed end", End(p, None, None, "closed end"), r, axis))
            notes.append(f"closed surface: {len(flat)} flat caps, {len(closed)} closed ends")

    wall_vertices = vertices[np.unique(faces[wall_mask])] if wall_mask.any() else vertices
    oriented = []
    for e in (*caps, *loop_ends, *flat):
        n_in = _inward(e.end.center, cast(NDArray[np.floating], e.normal), e.radius, wall_vertices)
        oriented.append(
            EndCandidate(e.kind, End(e.end.center, n_in, e.radius, e.end.source), e.radius, n_in, e.label, e.faces)
        )
    by_kind = {k: _sorted([e for e in (*oriented, *closed) if e.kind == k]) for k in KIND_METHOD}
    candidates = [e for k in KIND_METHOD for e in by_kind[k]]
    return EndList(candidates, array, loops, n_holes, wall_mask, lumen_radius, notes)


def describe_candidates(ends: EndList, units: str = "mm", limit: int | None = None) -> str:
    """One line listing the candidate ends: ``end:N kind [label] at (x, y, z) r=R`` in ``units``.

    Parameters
    ----------
    ends : EndList
        From :func:`list_ends` (mm).
    units : {"mm", "cm", "m"}
        Units of the coordinates and radii printed (the mesh's, as the user gives points).
    limit : int, optional
        List at most this many (then ``...``).

    Returns
    -------
    str
        ``"end:0 flat cap at (-0.99, 4.55, 2.86) r=1.38; end:1 ... (cm)"``.
    """
    s = UNIT_TO_MM[units]
    dec = {"mm": 1, "cm": 2, "m": 4}[units]
    items = []
    for i, c in enumerate(ends.candidates[:limit]):
        x = c.end.center / s
        label = f" {c.label}" if c.label else ""
        items.append(
            f"end:{i} {c.kind}{label} at ({x[0]:.{dec}f}, {x[1]:.{dec}f}, {x[2]:.{dec}f}) r={c.radius / s:.{dec}f}"
        )
    if limit is not None and len(ends.candidates) > limit:
        items.append("...")
    return "; ".join(items) + f" ({units})"


def _select(ends: EndList, sel: EndSelector, name: str, units: str) -> int:
    """Index in ``ends.candidates`` of the end ``sel`` names (one-line error when there is none)."""
    n = len(ends.candidates)
    if sel.index is not None:
        if sel.index < n:
            return sel.index
        listed = describe_candidates(ends, units) if n else "none found"
        raise VCSInputError(
            f"--{name} {sel.text}: the surface has {n} candidate end(s), end:0 to end:{n - 1} ({listed}); "
            "see `vcs ends MESH`"
            if n
            else f"--{name} {sel.text}: the surface has no candidate ends; give points x,y,z"
        )
    for i, c in enumerate(ends.candidates):
        if c.label == sel.label:
            return i
    labels = [c.label for c in ends.candidates if c.label]
    raise VCSInputError(
        f"--{name} {sel.text}: no cap labelled {sel.label}"
        + (
            f" (labelled caps: {', '.join(cast(list[str], labels))})"
            if labels
            else " (the surface has no labelled caps)"
        )
        + "; see `vcs ends MESH`"
    )


def _snap(
    point: NDArray[np.floating], ends: EndList, vertices: NDArray[np.floating], faces: NDArray[np.integer]
) -> int | None:
    """Index of the end ``point`` stands for, else None.

    A cap or loop whose centre is within max(2 r, 5 mm) of ``point``; or a closed end (a rounded
    or remeshed cap) within that distance when the plane through ``point`` across the end's axis
    does not cut a full section of the vessel: the cut's radius is below 85 % of the end's (the
    criterion of :func:`_full_section`), i.e. ``point`` lies on the cap. Its end plane would cut
    across the cap, a small ring, not a section of the vessel (the vmtk segment's caps: rho_w
    32 % of the lumen radius at tau = 0); the closed end's last full section is taken instead. A
    point where the cut is full is the user's own end plane.
    """
    best, best_d = None, np.inf
    for i, c in enumerate(ends.candidates):
        d = float(np.linalg.norm(c.end.center - point))
        if d > max(2.0 * c.radius, 5.0) or d >= best_d:
            continue
        if c.end.normal is None:  # a closed end: only when the point is on its cap
            _, r_cut = plane_section(vertices, faces, point, cast(NDArray[np.floating], c.normal), 2.0 * c.radius)
            if r_cut is not None and r_cut >= 0.85 * c.radius:
                continue
        best, best_d = i, d
    return best


def _group(kind: str) -> str:
    """The group an end's kind is automatic within: caps, loops, or the ends of a closed surface."""
    return "closed" if kind in ("flat cap", "closed end") else kind


def find_ends(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    cell_data: dict[str, NDArray[Any]] | None = None,
    *,
    inlet: ArrayLike | EndSelector | None = None,
    outlet: ArrayLike | EndSelector | None = None,
    inlet_cap: tuple[NDArray[np.floating], NDArray[np.integer]] | None = None,
    outlet_cap: tuple[NDArray[np.floating], NDArray[np.integer]] | None = None,
    cap_array: str | None = "auto",
    lumen_radius: float | None = None,
    units: str = "mm",
) -> Ends:
    """Decide the section's two ends (paper Section 2.2.1) and close the lumen for voxelisation.

    Cap files (``inlet_cap``/``outlet_cap``, each ``(vertices, faces)`` in mm) come first.
    Otherwise the candidate ends are listed (:func:`list_ends`) and:

    * ``inlet``/``outlet`` given as :class:`EndSelector` (``end:N``, ``NAME=VALUE``) take that end;
    * given as points, each takes the cap or loop within max(2 r, 5 mm) of it, or the closed end
      within that distance when it lies on that end's cap (:func:`_snap`), or else is used as an
      explicit point (its end plane then follows the lumen path);
    * only one given: the other is the other end of its kind when there are exactly two;
    * none given: exactly two labelled caps, else exactly two open loops, else exactly two ends of
      a closed surface (flat caps and closed ends) are the ends, the larger one the inlet
      (tau = 0); more than two is an error that lists them with the options to choose.

    Parameters
    ----------
    vertices : (N, 3) float, mm
        Surface vertices.
    faces : (M, 3) int
        Surface triangles.
    cell_data : dict of str -> (M,) array, optional
        Cell arrays of the surface (searched for cap labels).
    inlet, outlet : (3,) float mm, EndSelector, or None
        The inlet (tau = 0) and outlet (tau = 1): a point at or near the end, or a listed end.
    inlet_cap, outlet_cap : ((P, 3) float mm, (Q, 3) int), optional
        Cap surfaces; give both or neither.
    cap_array : str or None
        Name of the cell array labelling the caps; ``"auto"`` searches (:func:`list_ends`), None
        skips labelled caps. A ``NAME=VALUE`` selector searches array NAME.
    lumen_radius : float, mm, optional
        Median lumen radius, if already measured (closed surfaces need it).
    units : {"mm", "cm", "m"}
        Units of the mesh file, for the coordinates printed in error messages.

    Returns
    -------
    Ends

    Raises
    ------
    VCSInputError
        When the ends cannot be decided (closed surface without candidate ends, more than two
        candidates and no choice, a selector naming no end, both options naming the same end,
        only one cap file, an unknown ``cap_array``).
    """
    cell_data = cell_data or {}
    warnings: list[str] = []
    edges, counts = edge_topology(faces)
    n_nonmanifold = int((counts > 2).sum())
    if n_nonmanifold:
        warnings.append(
            f"{n_nonmanifold} non-manifold edges (used by more than two triangles); "
            "results near them may be unreliable: repair the mesh"
        )

    if inlet_cap is not None or outlet_cap is not None:
        if inlet_cap is None or outlet_cap is None:
            raise VCSInputError("give both --inlet-cap and --outlet-cap (or neither)")
        loops = boundary_loops(faces)
        closed_v, cap_f = _fan_caps(vertices, loops)
        cap_in = _end_from_faces(*inlet_cap, "inlet cap file")
        cap_out = _end_from_faces(*outlet_cap, "outlet cap file")

        def orient(e: End) -> End:
            """``e`` with its normal turned into the lumen."""
            n = _inward(e.center, cast(NDArray[np.floating], e.normal), cast(float, e.radius), vertices)
            return End(e.center, n, e.radius, e.source)

        return Ends(
            orient(cap_in),
            orient(cap_out),
            "cap_files",
            np.ones(len(faces), bool),
            closed_v,
            np.concatenate([faces, cap_f]),
            len(loops),
            [],
            warnings,
        )

    labels_wanted = [s.array for s in (inlet, outlet) if isinstance(s, EndSelector) and s.array]
    if labels_wanted and cap_array == "auto" and labels_wanted[0] in cell_data:
        cap_array = labels_wanted[0]
    listing = list_ends(vertices, faces, cell_data, cap_array=cap_array, lumen_radius=lumen_radius)
    cands = listing.candidates
    notes = list(listing.notes)
    if listing.n_holes:
        warnings.append(
            f"{listing.n_holes} small opening(s) (holes) in the wall closed for the lumen; their rims are wall points"
        )
    closed_v, cap_f = _fan_caps(vertices, listing.loops)
    closed_f = np.concatenate([faces, cap_f])

    chosen: dict[str, int | NDArray[np.floating]] = {}
    for name, spec in (("inlet", inlet), ("outlet", outlet)):
        if isinstance(spec, EndSelector):
            chosen[name] = _select(listing, spec, name, units)
        elif spec is not None:
            p = np.asarray(spec, float)
            i = _snap(p, listing, vertices, faces)
            chosen[name] = p if i is None else i
    listed = describe_candidates(listing, units, limit=40)

    if len(chosen) == 1:
        (name, got), (other,) = next(iter(chosen.items())), [n for n in ("inlet", "outlet") if n not in chosen]
        if not isinstance(got, int):
            raise VCSInputError(f"--{name} is a point but --{other} is missing; give both ends")
        same = [i for i, c in enumerate(cands) if _group(c.kind) == _group(cands[got].kind)]
        if len(same) != 2:
            raise VCSInputError(
                f"--{name} chose {'end:' + str(got)} but the surface has {len(cands)} ends ({listed}); "
                f"give --{other} too (end:N, NAME=VALUE or x,y,z)"
            )
        chosen[other] = same[1] if same[0] == got else same[0]
    elif not chosen:
        for group in ("labelled cap", "open loop", "closed"):
            members = [i for i, c in enumerate(cands) if _group(c.kind) == group]
            if len(members) < 2:
                continue
            if len(members) > 2:
                raise VCSInputError(
                    f"the surface has {len(cands)} ends: {listed}; choose two with --inlet end:I --outlet end:J "
                    "(or points --inlet x,y,z --outlet x,y,z; `vcs ends MESH` lists them)"
                )
            big = max(members, key=lambda i: cands[i].radius)  # the larger end is the inlet
            chosen = {"inlet": big, "outlet": members[1] if members[0] == big else members[0]}
            break
        else:
            if not listing.loops:
                found = f"only one end was found on it ({listed})" if cands else "no ends were found on it"
                raise VCSInputError(
                    f"the surface is closed and {found}; give both with --inlet x,y,z --outlet x,y,z "
                    "(a point in or near each end plane)"
                )
            raise VCSInputError(
                f"the surface has {len(cands)} end(s) ({listed}) and no labelled caps; give both ends with "
                "--inlet x,y,z --outlet x,y,z (or end:N)"
            )
    if isinstance(chosen["inlet"], int) and isinstance(chosen["outlet"], int) and chosen["inlet"] == chosen["outlet"]:
        raise VCSInputError(
            f"--inlet and --outlet both choose end:{chosen['inlet']}; choose two different ends ({listed})"
        )

    picked: list[End] = []
    methods: list[str] = []
    for name in ("inlet", "outlet"):
        got = chosen[name]
        if isinstance(got, int):
            picked.append(cands[got].end)
            methods.append(KIND_METHOD[cands[got].kind])
        else:
            picked.append(End(got, None, None, "point"))
            methods.append("points")
    method = methods[0] if methods[0] == methods[1] else "+".join(dict.fromkeys(methods))
    notes.append(f"{len(cands)} candidate ends; inlet = {picked[0].source}, outlet = {picked[1].source} ({method})")
    return Ends(
        picked[0], picked[1], method, listing.wall_mask, closed_v, closed_f, len(listing.loops), notes, warnings
    )
