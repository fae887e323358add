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
from vcs.mesh import edge_topology, orient_outward, polygon_properties, signed_volume, triangle_areas

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
        Area centroid of the end.
    normal : (3,) float
        Unit normal into the lumen.
    area : float, mm^2
        Area of the patch.
    source : str
        What the end is on the input (``open loop``, ``labelled cap ModelFaceID=2``, ``flat cap``).
    """

    name: str
    role: str
    center: NDArray[np.floating]
    normal: NDArray[np.floating]
    area: float
    source: str

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


def build_lumen(surf: Surface, inlet_center_mm: NDArray[np.floating], outlet_center_mm: NDArray[np.floating]) -> Lumen:
    """Close the surface with every end a patch, named after the section's ends (see the module doc).

    Parameters
    ----------
    surf : Surface
        The patient's surface (mm), e.g. from :func:`read_lumen_surface`.
    inlet_center_mm, outlet_center_mm : (3,) float, mm
        Centres of the section's ends as the fit found them (``meta.inlet_center_mm`` and
        ``meta.outlet_center_mm`` of model.json).

    Returns
    -------
    Lumen

    Raises
    ------
    VCSInputError
        When an end of the section is not an opening or cap of the surface, the surface has a
        rounded (closed) end, or the capped surface is not watertight, manifold and free of
        self-intersections.
    """
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
    verts = [v]
    n = len(v)
    patch_faces: list[tuple[int, NDArray[np.integer]]] = []
    for i, (cand, rim) in enumerate(cands):
        if rim is None:
            patch_faces.append((i, f[cand.faces]))
        else:
            verts.append(polygon_properties(v[rim])[0][None])
            patch_faces.append((i, _fan(v, rim, n)))
            n += 1
    wall = f[listing.wall_mask]
    holes = [lp for lp in listing.loops if not any(lp is loop for loop in loop_of.values())]
    for loop in holes:  # openings in the wall that are not ends: closed, part of the wall
        verts.append(polygon_properties(v[loop])[0][None])
        wall = np.concatenate([wall, _fan(v, loop, n)])
        n += 1
    if holes:
        notes.append(f"{len(holes)} small opening(s) in the wall (not ends) closed as wall")
    vertices = np.concatenate(verts)
    sizes = [len(wall)] + [len(pf) for _, pf in patch_faces]
    faces = orient_outward(vertices, np.concatenate([wall] + [pf for _, pf in patch_faces]))
    _closed_check(vertices, faces, surf)
    blocks = np.split(faces, np.cumsum(sizes)[:-1])
    areas = {i: float(triangle_areas(vertices, b).sum()) for (i, _), b in zip(patch_faces, blocks[1:])}
    others = sorted((i for i in areas if i not in (i_in, i_out)), key=lambda i: -areas[i])
    names = {i_in: ("inlet", "inlet"), i_out: ("outlet", "outlet")}
    names.update({i: (f"branch_{k}", "branch") for k, i in enumerate(others, start=1)})
    solids = {"wall": vertices[blocks[0]]}
    ends = []
    for (i, _), b in zip(patch_faces, blocks[1:]):
        name, role = names[i]
        solids[name] = vertices[b]
        end = cands[i][0]
        kind = end.kind + (f" {end.label}" if end.label else "")
        ends.append(LumenEnd(name, role, end.end.center, cast(NDArray[np.floating], end.end.normal), areas[i], kind))
    order = {"inlet": 0, "outlet": 1}
    ends.sort(key=lambda e: (order.get(e.name, 2), -e.area))
    solids = {"wall": solids["wall"], **{e.name: solids[e.name] for e in ends}}
    notes.append(f"{len(ends)} ends: inlet = {ends[0].source}, outlet = {ends[1].source}, {len(ends) - 2} branch(es)")
    return Lumen(solids, ends, float(signed_volume(vertices, faces)), notes)


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
