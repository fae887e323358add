"""The two end planes of a vessel section: open boundary loops, labelled caps, cap files or points.

Paper Section 2.2.1: the section lies between two end planes whose centres p_A (tau = 0, inlet)
and p_B (tau = 1, outlet) are the end points of the centerline search.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from vcs.errors import VCSInputError
from vcs.mesh import boundary_loops, edge_topology, polygon_properties, triangle_areas, triangle_cross

log = logging.getLogger(__name__)

CAP_ARRAY_NAMES = ("ModelFaceID", "CapID", "FaceID", "face_id", "RegionId")


@dataclass(frozen=True)
class End:
    """One end of the section.

    center : (3,) float, mm.  normal : (3,) unit vector into the lumen, or None when unknown
    (an explicit point on a closed surface).  radius : equivalent radius sqrt(area / pi), or None.
    """

    center: np.ndarray
    normal: np.ndarray | None
    radius: float | None
    source: str


@dataclass(frozen=True)
class Ends:
    """Both ends, how they were found, and the closed surface used to voxelise the lumen."""

    inlet: End
    outlet: End
    method: str  # "open_loops" | "labelled_caps" | "cap_files" | "points"
    wall_mask: np.ndarray  # (M,) bool: faces of the input that belong to the wall (not caps)
    closed_vertices: np.ndarray
    closed_faces: np.ndarray
    n_open_loops: int
    notes: list = field(default_factory=list)
    warnings: list = field(default_factory=list)


def _inward(center: np.ndarray, normal: np.ndarray, radius: float, vertices: np.ndarray) -> np.ndarray:
    """Orient a plane normal at an end towards the wall vertices near that end (into the lumen)."""
    d = vertices - center
    near = np.linalg.norm(d, axis=1) < 2.0 * radius
    side = d[near] @ normal if near.any() else d @ normal
    return normal if np.sum(side) >= 0 else -normal


def _wall_on_both_sides(vertices: np.ndarray, e: End) -> bool:
    """True when the wall near an opening lies on both sides of its plane: a hole in the wall
    (an open end has the whole vessel on one side)."""
    d = vertices - e.center
    near = np.linalg.norm(d, axis=1) < 2.5 * e.radius
    side = d[near] @ e.normal
    tol = 0.05 * e.radius
    return min(np.mean(side > tol), np.mean(side < -tol)) > 0.1


def _fan_caps(vertices: np.ndarray, loops: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
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


def _end_from_faces(vertices, faces, source) -> End:
    tri = vertices[faces]
    cross = triangle_cross(tri)
    area2 = np.linalg.norm(cross, axis=1)
    area = 0.5 * area2.sum()
    center = (tri.mean(axis=1) * area2[:, None]).sum(axis=0) / max(area2.sum(), 1e-300)
    n = cross.sum(axis=0)
    normal = n / max(np.linalg.norm(n), 1e-300)
    return End(center, normal, float(np.sqrt(area / np.pi)), source)


def _pick(cands: list[End], point: np.ndarray | None, exclude: int | None = None) -> int:
    idx = [i for i in range(len(cands)) if i != exclude]
    if point is None:
        return max(idx, key=lambda i: cands[i].radius)
    return min(idx, key=lambda i: np.linalg.norm(cands[i].center - point))


def _near_any(point, cands: list[End]) -> bool:
    return any(np.linalg.norm(c.center - point) <= max(2.0 * c.radius, 5.0) for c in cands)


def find_ends(
    vertices: np.ndarray,
    faces: np.ndarray,
    cell_data: dict | None = None,
    *,
    inlet: np.ndarray | None = None,
    outlet: np.ndarray | None = None,
    inlet_cap: tuple[np.ndarray, np.ndarray] | None = None,
    outlet_cap: tuple[np.ndarray, np.ndarray] | None = None,
    cap_array: str | None = "auto",
) -> Ends:
    """Decide the section's two ends (paper Section 2.2.1) and close the lumen for voxelisation.

    Order of precedence: cap files (``inlet_cap``/``outlet_cap``, each ``(vertices, faces)`` in mm),
    a cell array labelling caps (``cap_array``; ``auto`` tries :data:`CAP_ARRAY_NAMES`), open
    boundary loops, explicit points. With open loops or labelled caps, ``inlet``/``outlet``
    points select the nearest end (needed when there are more than two); by default the larger
    end is the inlet (tau = 0). Points far from any loop are used as explicit end points.
    """
    cell_data = cell_data or {}
    inlet = None if inlet is None else np.asarray(inlet, float)
    outlet = None if outlet is None else np.asarray(outlet, float)
    notes: list[str] = []
    warnings: list[str] = []
    n_faces = len(faces)
    wall_mask = np.ones(n_faces, bool)

    edges, counts = edge_topology(faces)
    n_nonmanifold = int((counts > 2).sum())
    if n_nonmanifold:
        warnings.append(f"{n_nonmanifold} non-manifold edges (used by more than two triangles); "
                        "results near them may be unreliable: repair the mesh")

    # (b) labelled caps in a cell array
    cap_ends: list[End] = []
    if inlet_cap is None and cap_array:
        names = CAP_ARRAY_NAMES if cap_array == "auto" else (cap_array,)
        if cap_array != "auto" and cap_array not in cell_data:
            raise VCSInputError(
                f"cell array '{cap_array}' not found in the mesh (it has: {', '.join(cell_data) or 'none'}); "
                "give an existing array with --cap-array or omit it"
            )
        for name in names:
            if name in cell_data:
                labels = np.asarray(cell_data[name]).astype(np.int64)
                uniq = np.unique(labels)
                if len(uniq) < 3:
                    continue
                areas = triangle_areas(vertices, faces)
                wall_label = max(uniq, key=lambda u: areas[labels == u].sum())
                wall_mask = labels == wall_label
                for u in uniq:
                    if u != wall_label:
                        cap_ends.append(_end_from_faces(vertices, faces[labels == u], f"{name}={int(u)}"))
                notes.append(f"caps labelled by cell array '{name}': wall={int(wall_label)}, {len(cap_ends)} caps")
                break

    loops = boundary_loops(faces)
    loop_ends = []
    for loop in loops:
        c, n, a = polygon_properties(vertices[loop])
        loop_ends.append(End(c, n, float(np.sqrt(a / np.pi)), f"open loop ({len(loop)} edges)"))
    if len(loop_ends) >= 3:  # small openings are holes in the wall, not ends
        r_big = max(e.radius for e in loop_ends)
        holes = [e.radius < 0.2 * r_big or _wall_on_both_sides(vertices, e) for e in loop_ends]
        if any(holes):
            warnings.append(f"{sum(holes)} small opening(s) (holes) in the wall closed for the lumen; "
                            "their rims are wall points")
            loop_ends = [e for e, h in zip(loop_ends, holes) if not h]
    closed_v, cap_f = _fan_caps(vertices, loops)
    closed_f = np.concatenate([faces, cap_f])

    def orient(e: End) -> End:
        if e.normal is None:
            return e
        return End(e.center, _inward(e.center, e.normal, e.radius, vertices[np.unique(faces[wall_mask])]), e.radius, e.source)

    if inlet_cap is not None or outlet_cap is not None:
        if inlet_cap is None or outlet_cap is None:
            raise VCSInputError("give both --inlet-cap and --outlet-cap (or neither)")
        a = _end_from_faces(*inlet_cap, "inlet cap file")
        b = _end_from_faces(*outlet_cap, "outlet cap file")
        return Ends(orient(a), orient(b), "cap_files", wall_mask, closed_v, closed_f, len(loops), notes, warnings)

    for cands, method in ((cap_ends, "labelled_caps"), (loop_ends, "open_loops")):
        if len(cands) < 2:
            continue
        use_in = inlet is not None and _near_any(inlet, cands)
        use_out = outlet is not None and _near_any(outlet, cands)
        if (inlet is not None and not use_in) or (outlet is not None and not use_out):
            break  # explicit points that are not at an opening: use them as points below
        if len(cands) > 2 and not (use_in and use_out):
            desc = "; ".join(
                f"{c.source} at ({c.center[0]:.1f}, {c.center[1]:.1f}, {c.center[2]:.1f}) mm r={c.radius:.1f}"
                for c in cands
            )
            raise VCSInputError(
                f"the surface has {len(cands)} ends ({desc}); choose two with --inlet x,y,z --outlet x,y,z"
            )
        if use_in:
            i_in = _pick(cands, inlet)
            i_out = _pick(cands, outlet, exclude=i_in) if use_out else 1 - i_in
        elif use_out:
            i_out = _pick(cands, outlet)
            i_in = 1 - i_out
        else:  # exactly two ends: the larger is the inlet
            i_in = _pick(cands, None)
            i_out = 1 - i_in
        notes.append(f"{len(cands)} candidate ends; inlet = {cands[i_in].source}, outlet = {cands[i_out].source}")
        return Ends(orient(cands[i_in]), orient(cands[i_out]), method, wall_mask, closed_v, closed_f, len(loops), notes, warnings)

    if inlet is None or outlet is None:
        if len(loops) == 0:
            raise VCSInputError(
                "the surface is closed and has no labelled caps, so its ends are unknown; "
                "give them with --inlet x,y,z --outlet x,y,z (a point in or near each end plane)"
            )
        raise VCSInputError(
            f"the surface has {len(loops)} open end(s) and no labelled caps; "
            "give both ends with --inlet x,y,z --outlet x,y,z"
        )
    notes.append("ends given as explicit points")
    return Ends(
        End(inlet, None, None, "point"), End(outlet, None, None, "point"), "points",
        wall_mask, closed_v, closed_f, len(loops), notes, warnings,
    )
