"""The patient's own lumen as a CFD domain (``cfd.geometry: surface``): every end of the surface a patch.

The VCS fit describes one single-branch section (paper Section 2.2); the CFD can instead run on the
whole surface the patient has, side branches included, and the fields are still resampled on the
section's (tau, theta, rho_n) grid. :func:`build_lumen` turns the user's surface into a closed
multi-solid STL for snappyHexMesh:

* the surface is read and repaired as `vcs fit` does (:func:`vcs.io.read_surface`: merged vertices,
  degenerate triangles dropped, winding made consistent; :func:`vcs.vessel.vessel_component`: the
  component holding the section's ends);
* every end of it (:func:`vcs.ends.list_ends`: labelled caps, open boundary loops, flat caps) becomes
  a patch: labelled and flat caps keep their own triangles, an open loop is closed by a triangle fan
  around its centroid (so is a cap given as a file: the file says where the section ends, the fan
  closes the surface watertight); small openings that are holes in the wall (not ends) are closed
  and belong to the wall;
* ``inlet`` is the end at the section's tau = 0 (the fit's inlet centre, ``model.json``),
  ``outlet`` the end at tau = 1, and ``branch_1``, ``branch_2``, ... every other end, by decreasing
  area;
* the closed surface must be watertight, manifold and not cross itself; it is wound outward and
  written in metres.

A rounded or remeshed end of a closed surface (a "closed end" of `vcs ends`) has no plane to put a
patch on: it stays wall (a blind stub) unless it is the section's inlet or outlet; an end plane
inside the vessel (a point given away from any opening) would need the
surface clipped there: both are refused with one line saying what to do (cut the end flat, choose
another end, or run that patient with ``cfd_geometry: model``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from vcs.ends import EndCandidate, list_ends
from vcs.errors import VCSInputError
from vcs.io import UNIT_TO_MM, Surface, read_surface
from vcs.mesh import (
    boundary_loops,
    edge_topology,
    orient_outward,
    polygon_properties,
    self_intersections,
    signed_volume,
    triangle_areas,
)

#: an end of the section is the candidate whose centre lies within this many of its radii (or
#: :data:`MATCH_MIN_MM`) of the fit's end centre
MATCH_RADII = 1.0
MATCH_MIN_MM = 3.0


@dataclass(frozen=True)
class LumenEnd:
    """One end of the lumen and its patch (lengths in mm).

    Attributes
    ----------
    name : str
        ``inlet``, ``outlet`` or ``branch_<k>``.
    role : str
        ``inlet``, ``outlet`` (the section's tau = 1 end) or ``branch``.
    center : (3,) float
        Area centroid of the patch.
    normal : (3,) float
        Unit normal of the patch into the lumen.
    area : float, mm^2
        Area of the patch.
    source : str
        What the end is on the input (``open loop``, ``labelled cap ModelFaceID=2``, ``flat cap``).
    opening_center : (3,) float or None
        Centre of the end on the input surface (as `vcs ends` lists it; the section's end is matched
        to it); ``center`` is the patch's, at the far end of the flow extension. None: ``center``.
    extension : float, mm
        Length of the flow extension along the end's normal at its centre (0: none).
    """

    name: str
    role: str
    center: NDArray[np.floating]
    normal: NDArray[np.floating]
    area: float
    source: str
    opening_center: NDArray[np.floating] | None = None
    extension: float = 0.0

    def to_dict(self, scale: float) -> dict[str, Any]:
        """JSON-ready description; ``scale`` = output units per mm (1e-3: metres)."""
        return {
            "name": self.name,
            "role": self.role,
            "center": [float(x) * scale for x in self.center],
            "normal": [float(x) for x in self.normal],
            "area": float(self.area) * scale**2,
            "equivalent_radius": float(np.sqrt(self.area / np.pi)) * scale,
            "source": self.source,
            "opening_center": [
                float(x) * scale for x in (self.center if self.opening_center is None else self.opening_center)
            ],
            "extension": float(self.extension) * scale,
        }


@dataclass(frozen=True)
class Lumen:
    """The closed lumen: triangles per patch (mm), its ends, and what was repaired.

    Attributes
    ----------
    solids : dict of str -> (T, 3, 3) float, mm
        ``wall``, ``inlet``, ``outlet``, ``branch_<k>``: triangles wound outward.
    ends : list of LumenEnd
        Inlet, outlet, then the branches by decreasing area.
    volume_mm3 : float
        Enclosed volume.
    notes : list of str
        Repairs and decisions (components dropped, holes closed, how each end was found).
    """

    solids: dict[str, NDArray[np.floating]]
    ends: list[LumenEnd]
    volume_mm3: float
    notes: list[str] = field(default_factory=list)


def _fan(vertices: NDArray[np.floating], loop: NDArray[np.integer], centre_index: int) -> NDArray[np.integer]:
    """Triangles closing the boundary loop ``loop`` around vertex ``centre_index``."""
    return np.column_stack([loop, np.roll(loop, -1), np.full(len(loop), centre_index)])


def _match(
    cands: list[tuple[EndCandidate, NDArray[np.integer] | None]], centre: NDArray[np.floating], which: str, units: str
) -> int:
    """Index in ``cands`` of the end at the fit's ``centre`` (mm); one-line error when none is."""
    s = UNIT_TO_MM[units]
    best, best_d = -1, np.inf
    for i, (c, _) in enumerate(cands):
        d = float(np.linalg.norm(c.end.center - centre))
        if d <= max(MATCH_RADII * c.radius, MATCH_MIN_MM) and d < best_d:
            best, best_d = i, d
    if best < 0:
        x = centre / s
        raise VCSInputError(
            f"cfd geometry surface: the section's {which} (fit end centre ({x[0]:.4g}, {x[1]:.4g}, {x[2]:.4g}) "
            f"{units}) is not an opening or a flat cap of the surface, so it cannot be a patch; "
            "cut the surface flat there "
            "(or choose an end that `vcs ends MESH` lists), or run this patient with cfd_geometry model"
        )
    return best


def _not_rounded(rounded: list[EndCandidate], centre: NDArray[np.floating], which: str, surf: Surface) -> None:
    """One-line VCSInputError when the section's ``which`` end (fit centre, mm) is a rounded end."""
    for c in rounded:
        if np.linalg.norm(c.end.center - centre) <= max(MATCH_RADII * c.radius, MATCH_MIN_MM) * 2.0:
            x = c.end.center / surf.scale_to_mm
            raise VCSInputError(
                f"cfd geometry surface: the section's {which} is a rounded (closed) end of the surface at "
                f"({x[0]:.4g}, {x[1]:.4g}, {x[2]:.4g}) {surf.units}, with no flat cap to put the {which} patch on; "
                "cut the end flat (or open it), or run this patient with cfd_geometry model"
            )


def _closed_check(vertices: NDArray[np.floating], faces: NDArray[np.integer], surf: Surface) -> None:
    """Refuse (one line) a closed lumen that is not watertight and manifold or crosses itself."""
    _, counts = edge_topology(faces)
    if (counts != 2).any():
        n_open, n_multi = int((counts == 1).sum()), int((counts > 2).sum())
        raise VCSInputError(
            f"cfd geometry surface: the surface cannot be closed into a lumen ({n_open} open edges after capping "
            f"every end, {n_multi} non-manifold edges); repair the mesh (e.g. fill or remesh it), or run this "
            "patient with cfd_geometry model"
        )
    from vcs.vessel import self_intersection_message

    closed = Surface(vertices, faces, {}, surf.units, surf.units_source, surf.path)
    crossing = self_intersection_message(closed)
    if crossing:
        raise VCSInputError(
            f"cfd geometry surface: {crossing}; snappyHexMesh cannot mesh it: repair the mesh, "
            "or run this patient with cfd_geometry model"
        )


def build_lumen(
    surf: Surface,
    inlet_center_mm: NDArray[np.floating],
    outlet_center_mm: NDArray[np.floating],
    *,
    extend_inlet: float = 0.0,
    extend_outlet: float = 0.0,
    grid: str = "none",
) -> Lumen:
    """Close the surface with every end a patch, named after the section's ends (see the module doc).

    Parameters
    ----------
    surf : Surface
        The patient's surface (mm), e.g. from :func:`read_lumen_surface`.
    inlet_center_mm, outlet_center_mm : (3,) float, mm
        Centres of the section's ends as the fit found them (``meta.inlet_center_mm`` and
        ``meta.outlet_center_mm`` of model.json).
    extend_inlet, extend_outlet : float
        Straight flow extensions in diameters of the end (equivalent diameter 2 sqrt(A / pi)), as
        the model wall's (``wall.extend_inlet``, ``wall.extend_outlet``; every branch end takes
        ``extend_outlet``): the end's planar rim extruded along its outward normal
        (:func:`extension`); the extension is wall, its far face the patch. An extension that
        crosses the surface is halved (:data:`SHORTEN_TRIES` times) before the lumen is refused.
    grid : {"none", "axes", "inlet"}
        The CFD's background grid (``cfd.mesh.background_frame``): an end within
        :data:`ALIGN_MAX_DEG` of one of its planes ends on that plane (:func:`grid_axis`; even with
        no extension asked for, a wedge at least one edge long); ``none``: every far face parallel
        to its end.

    Returns
    -------
    Lumen

    Raises
    ------
    VCSInputError
        When an end of the section is not an opening or cap of the surface, the surface has a
        rounded (closed) end, a non-planar end cannot be cut flat near it, an extension crosses the
        surface even when shortened, an extension length is negative, or the capped surface is not
        watertight, manifold and free of self-intersections.
    """
    for name, x in (("inlet", extend_inlet), ("outlet", extend_outlet)):
        if not np.isfinite(x) or x < 0:
            raise VCSInputError(f"--extend-{name} {x} must be a length >= 0 (in diameters)")
    if grid not in ("none", "axes", "inlet"):
        raise VCSInputError(f"grid {grid!r} must be none, axes or inlet")
    v = np.asarray(surf.vertices, float)
    f = np.asarray(surf.faces)
    listing = list_ends(v, f, surf.cell_data, lumen_radius=surf.lumen_radius_mm)
    notes = list(surf.warnings) + list(listing.notes)
    # each candidate with its patch: a cap's faces, or an open loop to close with a fan
    loop_of: dict[int, NDArray[np.integer]] = {}
    for loop in listing.loops:
        centre = polygon_properties(v[loop])[0]
        for i, cand in enumerate(listing.candidates):
            if cand.kind == "open loop" and np.allclose(cand.end.center, centre, atol=1e-9):
                loop_of[i] = loop
    # a rounded (closed) end has no plane for a patch: it stays wall (a blind stub), unless it is
    # the section's inlet or outlet
    rounded = [c for c in listing.candidates if c.kind == "closed end"]
    for which, centre in (("inlet", inlet_center_mm), ("outlet", outlet_center_mm)):
        _not_rounded(rounded, np.asarray(centre, float), which, surf)
    if rounded:
        notes.append(f"{len(rounded)} rounded (closed) end(s) that are not the section's ends kept as wall")
    cands = [(c, loop_of.get(i)) for i, c in enumerate(listing.candidates) if c.kind != "closed end"]
    i_in = _match(cands, np.asarray(inlet_center_mm, float), "inlet", surf.units)
    i_out = _match(cands, np.asarray(outlet_center_mm, float), "outlet", surf.units)
    if i_in == i_out:
        raise VCSInputError(
            "cfd geometry surface: the section's inlet and outlet are the same end of the surface; refit with two ends"
        )
    roles = {i_in: "inlet", i_out: "outlet"}
    wall = f[listing.wall_mask]
    vv = v.copy()
    # every end planar: its rim (the wall's boundary loop there) and the cap closing it
    geo: dict[int, tuple[NDArray[np.integer], NDArray[np.integer]]] = {}
    rims = [r for _, r in cands if r is not None]
    for i, (cand, rim) in enumerate(cands):
        what = roles.get(i, "branch end at ({:.4g}, {:.4g}, {:.4g}) mm".format(*cand.end.center))
        if rim is None:  # a labelled or flat cap: kept when planar, else opened and cut flat
            cap = f[cand.faces]
            loops = boundary_loops(cap)
            _, _, dev, diam = end_plane(v[np.unique(cap)])
            if dev <= PLANAR_TOL * diam or len(loops) != 1:
                geo[i] = (loops[0] if len(loops) == 1 else np.zeros(0, np.int64), cap)
                continue
            rim = loops[0]
            notes.append(f"{what}: its cap is not planar ({dev:.3g} mm off its plane): opened and cut flat")
        _, _, dev, diam = end_plane(vv[rim])
        if dev > PLANAR_TOL * diam:
            other_rims = [r for r in rims if r is not rim]
            vv, wall, rim = planar_cut(
                vv, wall, rim, np.asarray(cand.end.normal, float), other_loops=other_rims, what=what
            )
            notes.append(f"{what}: open end {dev:.3g} mm off its best-fit plane, cut flat by it")
        geo[i] = (rim, _fan(vv, rim, len(vv)))
        vv = np.concatenate([vv, polygon_properties(vv[rim])[0][None]])
    n = len(vv)
    verts = [vv]
    holes = [lp for lp in listing.loops if not any(lp is loop for loop in loop_of.values())]
    for loop in holes:  # openings in the wall that are not ends: closed, part of the wall
        verts.append(polygon_properties(vv[loop])[0][None])
        wall = np.concatenate([wall, _fan(vv, loop, n)])
        n += 1
    if holes:
        notes.append(f"{len(holes)} small opening(s) in the wall (not ends) closed as wall")
    vv = np.concatenate(verts)
    vv, wall, patch_faces, ext = _extended(vv, wall, geo, cands, i_in, extend_inlet, extend_outlet, grid, notes)
    verts = [vv]
    vertices = np.concatenate(verts)
    sizes = [len(wall)] + [len(pf) for _, pf in patch_faces]
    faces = orient_outward(vertices, np.concatenate([wall] + [pf for _, pf in patch_faces]))
    _closed_check(vertices, faces, surf)
    blocks = np.split(faces, np.cumsum(sizes)[:-1])
    areas: dict[int, float] = {}
    for (k_end, _), b in zip(patch_faces, blocks[1:]):
        areas[k_end] = float(triangle_areas(vertices, b).sum())
    others = sorted((j for j in areas if j not in (i_in, i_out)), key=lambda j: -areas[j])
    names = {i_in: ("inlet", "inlet"), i_out: ("outlet", "outlet")}
    names.update({j: (f"branch_{k}", "branch") for k, j in enumerate(others, start=1)})
    solids = {"wall": vertices[blocks[0]]}
    ends = []
    for (i, _), b in zip(patch_faces, blocks[1:]):
        name, role = names[i]
        solids[name] = vertices[b]
        end = cands[i][0]
        kind = end.kind + (f" {end.label}" if end.label else "")
        t = vertices[b]
        sv = 0.5 * np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        a = np.linalg.norm(sv, axis=1)
        centre = (t.mean(axis=1) * a[:, None]).sum(0) / max(float(a.sum()), 1e-300)
        normal = cast(NDArray[np.floating], -sv.sum(0) / max(float(np.linalg.norm(sv.sum(0))), 1e-300))
        ends.append(LumenEnd(name, role, centre, normal, areas[i], kind, end.end.center, float(ext.get(i, 0.0))))
    order = {"inlet": 0, "outlet": 1}
    ends.sort(key=lambda e: (order.get(e.name, 2), -e.area))
    solids = {"wall": solids["wall"], **{e.name: solids[e.name] for e in ends}}
    notes.append(f"{len(ends)} ends: inlet = {ends[0].source}, outlet = {ends[1].source}, {len(ends) - 2} branch(es)")
    return Lumen(solids, ends, float(signed_volume(vertices, faces)), notes)


def _grid_axes(grid: str, inlet_inward: NDArray[np.floating]) -> NDArray[np.floating] | None:
    """Rows: the axes of the CFD's background grid (``grid`` axes: the coordinate axes; inlet: the
    inlet's frame as :func:`vcs.cfd.case.inlet_frame` builds it from the inlet's inward normal)."""
    if grid == "none":
        return None
    if grid == "axes":
        return np.eye(3)
    n = inlet_inward / np.linalg.norm(inlet_inward)
    e1 = np.cross(n, np.eye(3)[int(np.argmin(np.abs(n)))])
    e1 /= np.linalg.norm(e1)
    return np.array([e1, np.cross(n, e1), n])


def _extended(
    vertices: NDArray[np.floating],
    wall: NDArray[np.integer],
    geo: dict[int, tuple[NDArray[np.integer], NDArray[np.integer]]],
    cands: list[tuple[EndCandidate, NDArray[np.integer] | None]],
    i_in: int,
    extend_inlet: float,
    extend_outlet: float,
    grid: str,
    notes: list[str],
) -> tuple[NDArray[np.floating], NDArray[np.integer], list[tuple[int, NDArray[np.integer]]], dict[int, float]]:
    """The planar ends (``geo``: end -> (rim, cap)) with their flow extensions (:func:`extension`),
    each halved while it crosses the surface; (vertices, wall, [(end, patch faces)], end -> length mm)."""
    planes = {}
    for i, (_, cap) in geo.items():
        _, nrm, _, _ = end_plane(vertices[np.unique(cap)])
        inward = np.asarray(cands[i][0].end.normal, float)
        area = float(triangle_areas(vertices, cap).sum())
        planes[i] = (nrm if float(nrm @ inward) >= 0 else -nrm, 2.0 * float(np.sqrt(area / np.pi)))
    axes = _grid_axes(grid, planes[i_in][0])
    factor = {i: extend_inlet if i == i_in else extend_outlet for i in geo}
    hit: set[int] = set()
    for _ in range(SHORTEN_TRIES + 1):
        new_v, walls, owner = [vertices], [wall], [np.full(len(wall), -1)]
        caps: list[tuple[int, NDArray[np.integer]]] = []
        lengths: dict[int, float] = {}
        for i, (rim, cap) in geo.items():
            out, d = -planes[i][0], planes[i][1]
            axis = grid_axis(out, axes) if axes is not None and len(rim) else None
            if axis is not None and float(axis @ out) > 1.0 - 1e-12:
                axis = None
            if not len(rim) or (factor[i] <= 0 and axis is None):
                caps.append((i, cap))
                continue
            nv, ew, ec, lengths[i] = extension(np.concatenate(new_v), rim, cap, out, factor[i] * d, axis)
            new_v.append(nv)
            walls.append(ew)
            owner.append(np.full(len(ew), i))
            caps.append((i, ec))
        vv, ww = np.concatenate(new_v), np.concatenate(walls)
        if not lengths:
            return vv, ww, caps, lengths
        own = np.concatenate(owner + [np.full(len(c), i if i in lengths else -1) for i, c in caps])
        bad = self_intersections(vv, np.concatenate([ww] + [c for _, c in caps]))
        hit = set(own[bad].tolist()) - {-1}
        if not hit:
            for i, length in lengths.items():
                x = np.asarray(cands[i][0].end.center)
                notes.append(
                    f"end at ({x[0]:.4g}, {x[1]:.4g}, {x[2]:.4g}) mm: flow extension {length:.3g} mm "
                    f"({length / planes[i][1]:.2f} diameters)"
                )
            return vv, ww, caps, lengths
        for i in hit:
            factor[i] /= 2.0
    x = np.asarray(cands[min(hit)][0].end.center)
    raise VCSInputError(
        f"cfd geometry surface: the flow extension of the end at ({x[0]:.4g}, {x[1]:.4g}, {x[2]:.4g}) mm crosses "
        f"the surface even at 1/{2**SHORTEN_TRIES} of its length; set wall.extend_inlet / wall.extend_outlet to 0 "
        "(and cfd.mesh.background_frame so that its far face is not turned), or run this patient with "
        "cfd_geometry model"
    )


def read_lumen_surface(
    mesh: Path | str, units: str, inlet_center_mm: NDArray[np.floating], outlet_center_mm: NDArray[np.floating]
) -> Surface:
    """The patient's surface read and repaired as `vcs fit` reads it (mm): the component holding the
    section's ends (:func:`vcs.vessel.vessel_component` given the fit's end centres)."""
    from vcs.vessel import vessel_component

    surf = read_surface(mesh, units)
    return vessel_component(surf, np.asarray(inlet_center_mm, float), np.asarray(outlet_center_mm, float))


def write_lumen(lumen: Lumen, stl_path: Path | str, json_path: Path | str | None, units: str = "m") -> dict[str, Any]:
    """Write the lumen as a multi-solid ASCII STL (solids wall, inlet, outlet, branch_<k>) in
    ``units`` and, when ``json_path`` is given, its ends as JSON (returned too)."""
    from vcs.mesh import write_stl_ascii

    scale = 1.0 / UNIT_TO_MM[units]
    write_stl_ascii(stl_path, {k: t * scale for k, t in lumen.solids.items()})
    info = {
        "units": units,
        "ends": [e.to_dict(scale) for e in lumen.ends],
        "volume": lumen.volume_mm3 * scale**3,
        "triangles": {k: int(len(t)) for k, t in lumen.solids.items()},
        "notes": lumen.notes,
    }
    if json_path is not None:
        Path(json_path).write_text(json.dumps(info, indent=2) + "\n")
    return info


# --------------------------------------------------------------------------- planar ends, extensions

#: an end is planar when its vertices lie within this fraction of its diameter of its best-fit plane
PLANAR_TOL = 1e-6
#: a non-planar open end is cut by its best-fit plane moved this fraction of its diameter inside the
#: vessel beyond its innermost vertex (so the whole loop is outside the cut)
CUT_MARGIN = 0.02
#: vertices within this fraction of the end's mean edge length from the cutting plane are moved onto it
#: (no sliver triangles along the new rim)
CUT_SNAP = 0.05
#: an end whose outward normal is within this angle (degrees) of an axis of the background grid ends
#: on a plane of that grid: its extension's far face is turned parallel to it (no slivers where the
#: snapped patch would cut the background cells obliquely, :func:`vcs.cfd.transient.courant_plan`)
ALIGN_MAX_DEG = 30.0
#: an extension that crosses the surface is halved this many times before the lumen is refused
SHORTEN_TRIES = 3


def end_plane(points: NDArray[np.floating]) -> tuple[NDArray[np.floating], NDArray[np.floating], float, float]:
    """Best-fit plane of an end's vertices (least squares: the smallest singular vector).

    Parameters
    ----------
    points : (P, 3) float
        The end's vertices (a boundary loop, or a cap's vertices).

    Returns
    -------
    centre : (3,) float
        Mean of the points.
    normal : (3,) float
        Unit normal of the plane (sign arbitrary).
    deviation : float
        Largest distance of a point from the plane.
    diameter : float
        Largest distance between two points (an upper bound of the end's size; P <= a few hundred).
    """
    p = np.asarray(points, float)
    c = p.mean(axis=0)
    n = np.linalg.svd(p - c, full_matrices=False)[2][2]
    diam = float(np.max(np.linalg.norm(p[:, None] - p[None], axis=2)))
    return c, n, float(np.abs((p - c) @ n).max()), diam


def planar_cut(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    loop: NDArray[np.integer],
    inward: NDArray[np.floating],
    *,
    other_loops: list[NDArray[np.integer]] | None = None,
    what: str = "end",
) -> tuple[NDArray[np.floating], NDArray[np.integer], NDArray[np.integer]]:
    """Cut a non-planar open end flat: the surface clipped by the loop's best-fit plane, moved
    :data:`CUT_MARGIN` of its diameter inside the vessel beyond the loop's innermost vertex.

    Only the part of the surface joined to the loop beyond the plane is removed (the plane also
    crosses the vessel elsewhere: a neighbouring branch is not touched); triangles crossing the
    plane are clipped, vertices within :data:`CUT_SNAP` of an edge length of it moved onto it, so
    the new boundary loop lies on the plane (to rounding).

    Parameters
    ----------
    vertices : (N, 3) float
        Vertices (mm); returned with the cut's new vertices appended (none is removed or renumbered).
    faces : (M, 3) int
        The wall's triangles, ``loop`` one of its boundary loops.
    loop : (P,) int
        The end's boundary loop.
    inward : (3,) float
        Unit normal of the end into the vessel.
    other_loops : list of (Q,) int, optional
        The other ends' loops: the cut must not reach them.
    what : str
        The end's name, for messages.

    Returns
    -------
    vertices : (N', 3) float
    faces : (M', 3) int
        The wall cut flat.
    loop : (P',) int
        Its new boundary loop, on the plane.

    Raises
    ------
    VCSInputError
        When the cut would reach far from the end (more than 1.5 of its diameters from its centre)
        or another end, or does not leave one boundary loop on the plane.
    """
    v = np.array(vertices, float)
    f = np.asarray(faces, np.int64)
    c, n, _, diam = end_plane(v[loop])
    n = n if float(n @ inward) >= 0 else -n
    edge = float(np.linalg.norm(v[loop] - v[np.roll(loop, -1)], axis=1).mean())
    p0 = c + (float(((v[loop] - c) @ n).max()) + CUT_MARGIN * diam) * n
    s = (v - p0) @ n
    local = np.linalg.norm(v - c, axis=1) < 1.5 * diam
    snap = local & (np.abs(s) < CUT_SNAP * edge)
    v[snap] -= s[snap, None] * n
    s[snap] = 0.0
    # the faces beyond the plane joined to the loop (through shared edges)
    outside = (s[f] < 0).any(axis=1)
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = np.flatnonzero(outside)
    sub = f[idx]
    fe = np.sort(np.stack([sub[:, [0, 1]], sub[:, [1, 2]], sub[:, [2, 0]]], axis=1).reshape(-1, 2), axis=1)
    key = fe[:, 0] * (len(v) + 1) + fe[:, 1]
    order = np.argsort(key, kind="stable")
    same = np.flatnonzero(key[order][1:] == key[order][:-1])
    a, b = order[same] // 3, order[same + 1] // 3
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(len(idx), len(idx)))
    _, comp = connected_components(graph, directed=False)
    at_loop = np.isin(sub, loop).any(axis=1)
    region = idx[np.isin(comp, np.unique(comp[at_loop]))]
    rv = np.unique(f[region])
    far = np.linalg.norm(v[rv] - c, axis=1).max() if len(rv) else 0.0
    touches = any(np.isin(o, rv).any() for o in (other_loops or []))
    if far > 1.5 * diam or touches:
        raise VCSInputError(
            f"cfd geometry surface: the {what} is not planar and its best-fit plane cuts the surface "
            f"{'at another end' if touches else f'{far:.3g} mm from the end'}; cut that end flat yourself, "
            "or run this patient with cfd_geometry model"
        )
    new_pts: list[NDArray[np.floating]] = []
    on_edge: dict[tuple[int, int], int] = {}

    def cross(i: int, j: int) -> int:
        k = (min(i, j), max(i, j))
        if k not in on_edge:
            t = s[i] / (s[i] - s[j])
            x = v[i] + t * (v[j] - v[i])
            new_pts.append(x - ((x - p0) @ n) * n)
            on_edge[k] = len(v) + len(new_pts) - 1
        return on_edge[k]

    clipped = []
    for tri in f[region].tolist():
        poly = []
        for k in range(3):
            i, j = tri[k], tri[(k + 1) % 3]
            if s[i] >= 0:
                poly.append(i)
            if s[i] * s[j] < 0:
                poly.append(cross(i, j))
        clipped += [[poly[0], poly[m], poly[m + 1]] for m in range(1, len(poly) - 1)]
    keep = np.ones(len(f), bool)
    keep[region] = False
    f_new = np.concatenate([f[keep], np.asarray(clipped, np.int64).reshape(-1, 3)])
    v_new = np.concatenate([v, np.asarray(new_pts, float).reshape(-1, 3)])
    s_new = (v_new - p0) @ n
    rims = [lp for lp in boundary_loops(f_new) if np.abs(s_new[lp]).max() <= 1e-9 * diam]
    if len(rims) != 1:
        raise VCSInputError(
            f"cfd geometry surface: cutting the non-planar {what} flat left {len(rims)} boundary loops on its "
            "plane (one expected); cut that end flat yourself, or run this patient with cfd_geometry model"
        )
    return v_new, f_new, rims[0]


def grid_axis(outward: NDArray[np.floating], axes: NDArray[np.floating]) -> NDArray[np.floating] | None:
    """The axis of the background grid (rows of ``axes``, signed) nearest to ``outward``, when within
    :data:`ALIGN_MAX_DEG`; None when the end is more oblique than that (its face is left as it is)."""
    cosines = axes @ outward
    k = int(np.argmax(np.abs(cosines)))
    if abs(cosines[k]) < np.cos(np.radians(ALIGN_MAX_DEG)):
        return None
    return np.sign(cosines[k]) * axes[k]


def extension(
    vertices: NDArray[np.floating],
    rim: NDArray[np.integer],
    cap: NDArray[np.integer],
    outward: NDArray[np.floating],
    length: float,
    axis: NDArray[np.floating] | None,
) -> tuple[NDArray[np.floating], NDArray[np.integer], NDArray[np.integer], float]:
    """A straight flow extension of a planar end: its rim extruded along ``outward``, the cap moved to
    the far end.

    The prism's far face is the end's plane moved ``length`` along ``outward``, or, when ``axis``
    is given (the nearest axis of the background grid, :func:`grid_axis`), the plane normal to
    ``axis`` through that point, moved outward as needed so that every rim vertex travels at least
    one edge length (so an extension of length 0 is then a short wedge). Rings are about one rim
    edge apart.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertices (mm).
    rim : (P,) int
        The end's boundary loop on the wall, planar.
    cap : (C, 3) int
        Triangles closing ``rim`` (a fan or the end's own cap), vertices on the end's plane.
    outward : (3,) float
        Unit normal of the end's plane, out of the vessel.
    length : float, mm
        Extension along ``outward`` (>= 0).
    axis : (3,) float or None
        Unit normal of the far face (None: ``outward``).

    Returns
    -------
    new_vertices : (K, 3) float
        To be appended to ``vertices`` (indices from ``len(vertices)``).
    wall : (W, 3) int
        The extension's wall triangles.
    cap : (C, 3) int
        ``cap`` at the far end.
    length : float, mm
        The extension along ``outward`` at the end's centre.
    """
    v = np.asarray(vertices, float)
    edge = float(np.linalg.norm(v[rim] - v[np.roll(rim, -1)], axis=1).mean())
    ids = np.unique(np.concatenate([rim, cap.ravel()]))
    centre = v[rim].mean(axis=0)
    a = outward if axis is None else axis
    q = centre + length * outward
    travel = ((q - v[ids]) @ a) / float(outward @ a)  # along outward, to the far plane
    shift = max(0.0, edge - float(travel.min()))
    travel += shift
    t_rim = travel[np.searchsorted(ids, rim)]
    m = max(1, int(round(float(travel.max()) / edge)))
    n0, p = len(v), len(rim)
    rings = [v[rim] + (k / m) * t_rim[:, None] * outward for k in range(1, m + 1)]
    idx = [rim] + [n0 + k * p + np.arange(p) for k in range(m)]
    quads = []
    for lo, hi in zip(idx[:-1], idx[1:]):
        quads += [np.column_stack([lo, np.roll(lo, -1), hi]), np.column_stack([np.roll(lo, -1), np.roll(hi, -1), hi])]
    inner = np.setdiff1d(ids, rim)  # cap vertices off the rim (a fan's centre, a cap's inner vertices)
    moved = v[inner] + travel[np.searchsorted(ids, inner)][:, None] * outward
    remap = np.full(len(v), -1, np.int64)
    remap[rim] = idx[-1]
    remap[inner] = n0 + m * p + np.arange(len(inner))
    return np.concatenate(rings + [moved]), np.concatenate(quads), remap[cap], length + shift
