"""The two end planes of a vessel section: open boundary loops, labelled caps, cap files or points.

Paper Section 2.2.1: the section lies between two end planes whose centres p_A (tau = 0, inlet)
and p_B (tau = 1, outlet) are the end points of the centerline search.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError
from vcs.mesh import boundary_loops, edge_topology, polygon_properties, triangle_areas, triangle_cross

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
        ``"open_loops"``, ``"labelled_caps"``, ``"cap_files"`` or ``"points"``.
    wall_mask : (M,) bool
        Faces of the input that belong to the wall (not to labelled caps).
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
    method: str  # "open_loops" | "labelled_caps" | "cap_files" | "points"
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
    """The end of a cap given as triangles: area centroid, unit normal by the winding, equivalent radius."""
    tri = vertices[faces]
    cross = triangle_cross(tri)
    area2 = np.linalg.norm(cross, axis=1)
    area = 0.5 * area2.sum()
    center = (tri.mean(axis=1) * area2[:, None]).sum(axis=0) / max(area2.sum(), 1e-300)
    n = cross.sum(axis=0)
    normal = n / max(np.linalg.norm(n), 1e-300)
    return End(center, normal, float(np.sqrt(area / np.pi)), source)


def _pick(cands: list[End], point: NDArray[np.floating] | None, exclude: int | None = None) -> int:
    """Index of the candidate end nearest to ``point`` (the largest one when None), ``exclude`` skipped."""
    idx = [i for i in range(len(cands)) if i != exclude]
    if point is None:
        return max(idx, key=lambda i: cast(float, cands[i].radius))  # loop and cap ends have a radius
    return min(idx, key=lambda i: float(np.linalg.norm(cands[i].center - point)))


def _near_any(point: NDArray[np.floating], cands: list[End]) -> bool:
    """True when ``point`` lies within max(2 r, 5 mm) of the centre of one of the candidate ends."""
    # candidates are loop or cap ends, which always have a radius
    return any(np.linalg.norm(c.center - point) <= max(2.0 * cast(float, c.radius), 5.0) for c in cands)


def find_ends(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    cell_data: dict[str, NDArray[Any]] | None = None,
    *,
    inlet: ArrayLike | None = None,
    outlet: ArrayLike | None = None,
    inlet_cap: tuple[NDArray[np.floating], NDArray[np.integer]] | None = None,
    outlet_cap: tuple[NDArray[np.floating], NDArray[np.integer]] | None = None,
    cap_array: str | None = "auto",
) -> Ends:
    """Decide the section's two ends (paper Section 2.2.1) and close the lumen for voxelisation.

    Order of precedence: cap files (``inlet_cap``/``outlet_cap``, each ``(vertices, faces)`` in mm),
    a cell array labelling caps (``cap_array``; ``auto`` tries :data:`CAP_ARRAY_NAMES`), open
    boundary loops, explicit points. With open loops or labelled caps, ``inlet``/``outlet``
    points select the nearest end (needed when there are more than two); by default the larger
    end is the inlet (tau = 0). Points far from any loop are used as explicit end points.

    Parameters
    ----------
    vertices : (N, 3) float, mm
        Surface vertices.
    faces : (M, 3) int
        Surface triangles.
    cell_data : dict of str -> (M,) array, optional
        Cell arrays of the surface (searched for cap labels).
    inlet, outlet : (3,) float, mm, optional
        Points at or near the inlet (tau = 0) and outlet (tau = 1).
    inlet_cap, outlet_cap : ((P, 3) float mm, (Q, 3) int), optional
        Cap surfaces; give both or neither.
    cap_array : str or None
        Name of the cell array labelling the caps; ``"auto"`` tries :data:`CAP_ARRAY_NAMES`,
        None skips labelled caps.

    Returns
    -------
    Ends

    Raises
    ------
    VCSInputError
        When the ends cannot be decided (closed surface without points, more than two openings
        and no points, only one cap file, an unknown ``cap_array``).
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
        warnings.append(
            f"{n_nonmanifold} non-manifold edges (used by more than two triangles); "
            "results near them may be unreliable: repair the mesh"
        )

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
        radii = [cast(float, e.radius) for e in loop_ends]  # loop ends always have a radius
        r_big = max(radii)
        holes = [r < 0.2 * r_big or _wall_on_both_sides(vertices, e) for r, e in zip(radii, loop_ends, strict=True)]
        if any(holes):
            warnings.append(
                f"{sum(holes)} small opening(s) (holes) in the wall closed for the lumen; their rims are wall points"
            )
            loop_ends = [e for e, h in zip(loop_ends, holes) if not h]
    closed_v, cap_f = _fan_caps(vertices, loops)
    closed_f = np.concatenate([faces, cap_f])

    def orient(e: End) -> End:
        """``e`` with its normal turned into the lumen (unchanged without a normal)."""
        if e.normal is None:
            return e
        radius = cast(float, e.radius)  # an end with a normal has a radius
        wall_vertices = vertices[np.unique(faces[wall_mask])]
        return End(e.center, _inward(e.center, e.normal, radius, wall_vertices), e.radius, e.source)

    if inlet_cap is not None or outlet_cap is not None:
        if inlet_cap is None or outlet_cap is None:
            raise VCSInputError("give both --inlet-cap and --outlet-cap (or neither)")
        cap_in = _end_from_faces(*inlet_cap, "inlet cap file")
        cap_out = _end_from_faces(*outlet_cap, "outlet cap file")
        return Ends(
            orient(cap_in), orient(cap_out), "cap_files", wall_mask, closed_v, closed_f, len(loops), notes, warnings
        )

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
        return Ends(
            orient(cands[i_in]),
            orient(cands[i_out]),
            method,
            wall_mask,
            closed_v,
            closed_f,
            len(loops),
            notes,
            warnings,
        )

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
        End(inlet, None, None, "point"),
        End(outlet, None, None, "point"),
        "points",
        wall_mask,
        closed_v,
        closed_f,
        len(loops),
        notes,
        warnings,
    )
