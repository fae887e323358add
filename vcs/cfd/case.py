"""Rendering an OpenFOAM case (paper Section 2.4.1) from the wall STL and the CFD parameters:
background box, a point inside the lumen, patches from the STL solids, the jinja2 templates of
the flavour, and the inlet velocity profile on the meshed inlet faces."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from vcs.cfd.foamfiles import patch_geometry
from vcs.cfd.openfoam import DEFAULTS, FLAVOURS, check_cfd, deep_merge, detect_openfoam, foam_library, template_dir
from vcs.cfd.sizing import (
    background_plan,
    cell_size_value,
    choose_cell_size,
    choose_inflow,
    closed_volume,
    stl_sizes,
    surface_area,
    vessel_sizes,
)
from vcs.cfd.utilities import TIME_PRECISION
from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message
from vcs.mesh import points_inside, read_stl_solids, triangle_cross

if TYPE_CHECKING:
    import jinja2

    from vcs.vessel import VesselModel

#: per-patient values render_case accepts (SI units), e.g. from the patients sheet; ``outlet_bc``
#: (the per-outlet RCR table, :mod:`vcs.cfd.bc_tables`) and ``mesh`` (the patient's surface, which
#: resolves the table's ``end:N`` rows) are paths
PATIENT_KEYS = ("cell_size", "flow_rate", "velocity", "valve_area", "waveform", "outlets", "outlet_bc", "mesh")

STL_NAME = "vessel.stl"
CASE_JSON = "vcsflow_case.json"

# --------------------------------------------------------------------------- rendering


def _jinja_env(flavour: str) -> jinja2.Environment:
    """jinja2 environment of a flavour: its override templates first, then ``common/``."""
    import jinja2

    return jinja2.Environment(
        loader=jinja2.ChoiceLoader(
            [
                jinja2.FileSystemLoader(str(template_dir() / flavour)),
                jinja2.FileSystemLoader(str(template_dir() / "common")),
            ]
        ),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        autoescape=False,
    )


def patch_role(name: str) -> str:
    """Role of an STL solid / patch from its name: inlet*, outlet* or branch* (an outlet), wall* or other.

    Parameters
    ----------
    name : str
        Solid or patch name (case-insensitive prefix match).

    Returns
    -------
    str
        ``"inlet"``, ``"outlet"``, ``"wall"`` or ``"other"``.
    """
    n = name.lower()
    if n.startswith("inlet"):
        return "inlet"
    if n.startswith(("outlet", "branch")):
        return "outlet"
    if n.startswith("wall"):
        return "wall"
    return "other"


def _inside_point(
    solids: dict[str, NDArray[np.floating]], bmin: NDArray[np.floating], h: float, h_finest: float | None = None
) -> list[float]:
    """A point inside the closed STL (for snappyHexMesh), off the faces of every mesh level.

    Tried in order: points on the inlet's normal at 4, 8, 16, 2, 32 lumen cells ``h`` from its
    centroid, then the mean of all corners; each snapped to a fixed fraction inside its cell of
    the finest level ``h_finest`` (default ``h``), whose faces include those of every coarser
    level.
    """
    h_grid = h if h_finest is None else h_finest
    alltris = np.concatenate(list(solids.values()))
    inlets = [k for k in solids if patch_role(k) == "inlet"]
    seeds = []
    if inlets:
        c, n = _inlet_disc(solids)
        for k in (4, 8, 16, 2, 32):
            seeds += [c + k * h * n, c - k * h * n]  # inward first
    seeds.append(alltris.reshape(-1, 3).mean(0))
    frac = np.array([0.371, 0.413, 0.437])
    for p in seeds:
        q = bmin + (np.floor((p - bmin) / h_grid) + frac) * h_grid  # keep it off mesh faces
        if points_inside(q[None], alltris)[0]:
            return [float(x) for x in q]
    raise VCSInputError("could not find a point inside the vessel surface; set mesh.inside_point")


def _inlet_disc(solids: dict[str, NDArray[np.floating]]) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Area centroid (m) and unit inward normal of the STL's inlet solid."""
    t = solids[next(k for k in solids if patch_role(k) == "inlet")]
    s = 0.5 * triangle_cross(t)
    a = np.linalg.norm(s, axis=1)
    c = (t.mean(axis=1) * a[:, None]).sum(0) / a.sum()
    n = -s.sum(0) / max(float(np.linalg.norm(s.sum(0))), 1e-300)  # STL normals point out of the lumen
    return c, n


def inlet_frame(solids: dict[str, NDArray[np.floating]]) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Origin (the inlet's area centroid, m) and rows (e1, e2, n) of a right-handed orthonormal
    frame whose third axis n is the inlet's inward normal (the model's t(0))."""
    c, n = _inlet_disc(solids)
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return c, np.array([e1, np.cross(n, e1), n])


def align_background_to_inlet(bg: dict[str, Any], h_fine: float, offset: float = 0.75) -> dict[str, Any]:
    """The background box (in the inlet frame, :func:`inlet_frame`) moved along n so that the inlet
    plane (n = 0) lies ``offset`` of a finest-level cell ``h_fine`` above a grid plane.

    Snapped to a plane parallel to the grid, the first cell row at the inlet is then one uniform,
    prism-free slab of hexahedra (0.87 ``h_fine`` thick on the test tube after snappyHexMesh's
    smoothing, every inner cell alike). With an inlet
    plane oblique to the grid, snapping halves some hexes into prisms where the plane crosses a
    grid plane; on demo aorta seed 1 four of them in the jet disc had twice the Courant number
    of any other cell and halved pimpleFoam's time step (README, "The paper's jet").
    """
    hb = float(bg["background_cell_size_m"])
    lo_n, hi_n = float(bg["bmin"][2]), float(bg["bmax"][2])
    r = (0.0 - lo_n) % h_fine
    lo_n -= (offset * h_fine - r) % h_fine
    nz = int(np.ceil((hi_n - lo_n) / hb - 1e-9))
    out = dict(bg)
    out["bmin"] = [bg["bmin"][0], bg["bmin"][1], lo_n]
    out["bmax"] = [bg["bmax"][0], bg["bmax"][1], lo_n + nz * hb]
    out["ncells"] = [bg["ncells"][0], bg["ncells"][1], nz]
    out["background_cells"] = int(np.prod(out["ncells"]))
    return out


def jet_region(
    solids: dict[str, NDArray[np.floating]],
    cfd: dict[str, Any],
    *,
    background: float | None = None,
    min_level: int = 0,
) -> dict[str, Any] | None:
    """The refinement cylinder along the jet (snappyHexMesh ``refinementRegions``, mode inside).

    The cylinder starts half a background cell behind the jet centre (``inlet.centre`` or the
    inlet's area centroid) and runs along the inlet's inward normal for ``length`` jet diameters,
    with a radius of ``radius`` jet radii; its level is the smallest (at least ``min_level``)
    giving at least ``cells_across`` cells across the jet diameter d = 2 sqrt(valve_area / pi).

    Parameters
    ----------
    solids : dict of str -> (T, 3, 3) float
        The STL's triangles by solid (m).
    cfd : dict
        Merged CFD parameters (``mesh.jet_refinement``, ``inlet``; ``mesh.cell_size`` m when
        ``background`` is None).
    background : float or None, m
        Background (blockMesh) cell size; None: ``mesh.cell_size``.
    min_level : int
        Lowest level (the lumen's refinement level: the jet is never coarser than the lumen).

    Returns
    -------
    dict or None
        None unless ``inlet.type`` is jet and the refinement is enabled; else ``point1``,
        ``point2`` (m), ``radius`` (m), ``level``, ``cell_size`` (m, inside the cylinder),
        ``jet_diameter`` (m), ``cells_across`` (jet diameter / cell size), ``length_diameters``.
    """
    jr = cfd["mesh"]["jet_refinement"]
    if cfd["inlet"]["type"] != "jet" or not jr["enabled"]:
        return None
    h = float(cfd["mesh"]["cell_size"] if background is None else background)
    d = 2.0 * np.sqrt(float(cfd["inlet"]["valve_area"]) / np.pi)
    level = max(int(np.ceil(np.log2(max(jr["cells_across"] * h / d, 1.0)) - 1e-9)), int(min_level))
    c, n = _inlet_disc(solids)
    if cfd["inlet"].get("centre"):
        c = np.asarray(cfd["inlet"]["centre"], float)
    p1 = c - 0.5 * h * n
    p2 = c + float(jr["length"]) * d * n
    return {
        "point1": [float(x) for x in p1],
        "point2": [float(x) for x in p2],
        "radius": float(jr["radius"] * d / 2.0),
        "level": int(level),
        "cell_size": h / 2**level,
        "jet_diameter": float(d),
        "cells_across": float(d / (h / 2**level)),
        "length_diameters": float(jr["length"]),
    }


def _context(state: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """Template variables of a case state; ``extra`` overrides them."""
    cfd = state["cfd"]
    sizing = state.get("mesh_sizing")  # absent from states written before the sizing existed
    ctx = {
        "flavour": state["flavour"],
        "flav": FLAVOURS[state["flavour"]],
        "mesh": cfd["mesh"],
        "physics": cfd["physics"],
        "inlet": cfd["inlet"],
        "solver": cfd["solver"],
        "io": cfd["io"],
        "ranks": max(int(cfd["ranks"]), 1),
        "decomposition": {"method": cfd["decomposition"]["method"], "n": state["decomposition_n"]},
        "background_cell_size": sizing["background"]["background_cell_size_m"] if sizing else cfd["mesh"]["cell_size"],
        "surface_level": sizing["levels"]["surface"] if sizing else cfd["mesh"]["surface_level"],
        "lumen_level": sizing["levels"]["lumen"] if sizing else 0,
        "corners": state["corners"],
        "background_frame": state["background_frame"]["type"],
        "ncells": state["ncells"],
        "inside_point": state["inside_point"],
        "stl_name": STL_NAME,
        "solids": state["solids"],
        "patches": state["patches"],
        "end_time": cfd["solver"]["max_iterations"],
        "time_precision": TIME_PRECISION,
        "delta_t": 1,
        "div_scheme": cfd["solver"]["div_scheme"],
        "residual_control": True,
        "transient": False,
        "average": False,
        "monitors": False,
        "cell_volumes": False,
        "max_co": cfd["solver"]["transient"]["max_co"],
        "outer_correctors": 1,
        "pimple_non_orthogonal_correctors": cfd["solver"]["n_non_orthogonal_correctors"],
        "probe_points": None,
        "write_interval": None,
        "max_delta_t": None,
        "jet_region": state.get("jet_region"),
        "inlet_values": None,
        "waveform": state.get("waveform") is not None,  # pulsatile: the mapped inlet (vcs.cfd.pulsatile)
        "pulsatile": cfd.get("pulsatile") or {},
        "continue_average": False,
        "foam_libs": state.get("foam_libs") or [],
    }
    ctx.update(extra)
    return ctx


def render_files(case_dir: Path, state: dict[str, Any], files: list[str], **extra: Any) -> None:
    """Render template files of the state's flavour into a case.

    Parameters
    ----------
    case_dir : Path
        The case folder.
    state : dict
        Case description from :func:`render_case`.
    files : list of str
        Case-relative paths (e.g. ``"system/controlDict"``), also the template names.
    **extra
        Overrides of template variables (e.g. ``end_time`` of a stage, ``inlet_values``).
    """
    env = _jinja_env(state["flavour"])
    ctx = _context(state, **extra)
    for rel in files:
        out = case_dir / rel
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(env.get_template(rel).render(**ctx))


def branch_levels(
    diameters: dict[str, float], hb: float, outlet_level: list[int], cells_across: float
) -> dict[str, dict[str, Any]]:
    """snappyHexMesh surface levels of the branch ends of a surface geometry (``branch_<k>``).

    A side branch is narrower than the section's ends that size the lumen cell; instead of a
    finer lumen everywhere, each branch end (d_k = 2 sqrt(A_k / pi)) is refined to at least
    ``cells_across`` cells across: level L_k = max(outlet level, ceil(log2(hb cells_across / d_k)))
    with hb the background cell (cell at level L: hb / 2^L); no finer than the outlets when they already
    are. The branch's own lumen keeps the
    lumen cell away from its end (the atlas measures the section, not the branches).

    Parameters
    ----------
    diameters : dict of str -> float, m
        Equivalent diameter of each branch end.
    hb : float, m
        Background cell size.
    outlet_level : [int, int]
        (min, max) snappy level of the outlet solids.
    cells_across : float
        ``cfd.mesh.cells_across_branch``.

    Returns
    -------
    dict of str -> dict
        Per branch: ``level`` [min, max], ``cell_size_m`` and ``cells_across`` (as obtained).
    """
    out = {}
    for name, d in diameters.items():
        need = int(np.ceil(np.log2(max(hb * cells_across / d, 1.0)) - 1e-9))
        level = [int(outlet_level[0]), int(outlet_level[1])] if need <= int(outlet_level[1]) else [need, need]
        h = hb / 2 ** level[1]
        out[name] = {"level": level, "cell_size_m": h, "cells_across": d / h}
    return out


def _end_plane(tris: NDArray[np.floating], role: str) -> dict[str, Any]:
    """Area centroid (m) and unit outward normal of an inlet / outlet / branch solid (empty for a wall)."""
    if role not in ("inlet", "outlet"):
        return {}
    s = 0.5 * triangle_cross(tris)
    a = np.linalg.norm(s, axis=1)
    c = (tris.mean(axis=1) * a[:, None]).sum(0) / max(float(a.sum()), 1e-300)
    n = s.sum(0) / max(float(np.linalg.norm(s.sum(0))), 1e-300)
    return {"center_m": [float(x) for x in c], "normal_out": [float(x) for x in n]}


def _patient_values(patient: dict[str, Any] | None) -> dict[str, Any]:
    """The per-patient values of :func:`render_case`, checked (one-line VCSInputError)."""
    out: dict[str, Any] = {}
    for k, v in (patient or {}).items():
        if k not in PATIENT_KEYS:
            raise VCSInputError(f"unknown per-patient CFD value {k!r}; known: {', '.join(PATIENT_KEYS)}")
        if v is None:
            continue
        if k == "cell_size":
            out[k] = cell_size_value(v, "the patient's cell size")
            continue
        if k == "outlets":  # the patient's outlet conditions, over cfd.outlets
            out[k] = _patient_outlets(v)
            continue
        if k == "waveform":  # the patient's own inflow waveform (a CSV path), checked when loaded
            if not isinstance(v, (str, Path)):
                raise VCSInputError(f"the patient's inflow waveform must be the path of a CSV file, not {v!r}")
            out[k] = str(v)
            continue
        if k in ("outlet_bc", "mesh"):  # paths, checked when read (vcs.cfd.bc_tables.outlet_rcrs)
            what = "per-outlet RCR table (CSV or rcrt.dat)" if k == "outlet_bc" else "surface file"
            if not isinstance(v, (str, Path)) or not str(v).strip():
                raise VCSInputError(f"the patient's {k} must be the path of a {what}, not {v!r}")
            out[k] = str(v)
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v <= 0:
            raise VCSInputError(f"the patient's {k} must be a positive number (SI units), not {v!r}")
        out[k] = float(v)
    if ("velocity" in out) != ("valve_area" in out):
        raise VCSInputError("the patient's inlet velocity needs its valve area (and the other way round)")
    if "flow_rate" in out and "velocity" in out:
        raise VCSInputError("give the patient's inflow either as a flow rate or as velocity + valve area, not both")
    if "waveform" in out and ("flow_rate" in out or "velocity" in out):
        raise VCSInputError(
            "the patient's own inflow waveform is applied as given: "
            "leave its flow rate (or velocity + valve area) empty"
        )
    return out


#: the per-patient outlet values (``patient["outlets"]``) and their ranges (as in check_cfd)
_PATIENT_RCR = {
    "resistance": (0.0, 1e13, "Pa s/m3", True),
    "compliance": (0.0, 1e-3, "m3/Pa", True),
    "proximal_fraction": (0.0, 1.0, "R_p / (R_p + R_d)", False),
    "distal_pressure": (-1e6, 1e6, "Pa", False),
}


def _patient_outlets(v: Any) -> dict[str, Any]:
    """The patient's ``outlets`` (``type`` and/or ``rcr`` totals, as ``cfd.outlets``), checked;
    None values are left out (the config's apply)."""
    from vcs.cfd.outlets import OUTLET_TYPES

    if not isinstance(v, dict):
        raise VCSInputError(f"the patient's outlets must be a dict (type, rcr), not {v!r}")
    unknown = set(v) - {"type", "rcr"}
    if unknown:
        raise VCSInputError(f"unknown key(s) in the patient's outlets: {', '.join(sorted(unknown))}; known: type, rcr")
    out: dict[str, Any] = {}
    if v.get("type") is not None:
        if v["type"] not in OUTLET_TYPES:
            known = ", ".join(OUTLET_TYPES)
            raise VCSInputError(f"the patient's outlet type must be one of {known}, not {v['type']!r}")
        out["type"] = v["type"]
    rcr = v.get("rcr") or {}
    if not isinstance(rcr, dict) or set(rcr) - set(_PATIENT_RCR):
        raise VCSInputError(f"the patient's outlets.rcr must be a dict with keys among {', '.join(_PATIENT_RCR)}")
    for key, x in rcr.items():
        if x is None:
            continue
        lo, hi, unit, lo_open = _PATIENT_RCR[key]
        ok = isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x)
        if not ok or not ((x > lo if lo_open else x >= lo) and (x < hi if key == "proximal_fraction" else x <= hi)):
            raise VCSInputError(
                f"the patient's outlets.rcr.{key} must be a number in [{lo:g}, {hi:g}] ({unit}), not {x!r}"
            )
        out.setdefault("rcr", {})[key] = float(x)
    return out


def render_case(
    case_dir: Path | str,
    stl_path: Path | str,
    cfd: dict[str, Any] | None = None,
    *,
    flavour: str | None = None,
    model: VesselModel | Path | str | None = None,
    patient: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write a complete OpenFOAM case for a multi-solid ASCII STL (paper Section 2.4.1).

    ``cfd`` is merged over ``DEFAULTS``. The flavour is ``flavour`` or ``cfd['flavour']`` or the
    detected installation (``"esi"`` when none is found). The lumen cell size is the patient's,
    ``mesh.cell_size``, or (``auto``) computed from the vessel's end diameters and narrowest
    section (:func:`vcs.cfd.sizing.choose_cell_size`; from the model when given, else from the
    STL's caps); the background box is bounded (:func:`vcs.cfd.sizing.background_plan`); the
    inflow is the patient's, or the config's fixed or scaled by the inlet area
    (:func:`vcs.cfd.sizing.choose_inflow`). What was chosen, and why, is in ``mesh_sizing`` and
    ``inflow`` of the returned state (and of ``status.json`` after :func:`vcs.cfd.run_case`).

    Parameters
    ----------
    case_dir : Path or str
        Case folder (created).
    stl_path : Path or str
        Multi-solid ASCII STL in metres with one ``inlet*`` solid, at least one ``outlet*`` solid
        and the ``wall*`` solid(s) (e.g. from :func:`vcs.surface.write_multisolid_stl`).
    cfd : dict or None
        CFD parameters merged over :data:`vcs.cfd.openfoam.DEFAULTS` (SI units: m, m/s, m^3/s,
        m^2/s, kg/m^3).
    flavour : str or None
        ``"esi"`` or ``"org10"``; overrides ``cfd['flavour']``.
    model : VesselModel, path of a model.json, or None
        The vessel model the STL was made from (its end and narrowest sections size the mesh
        when ``mesh.cell_size`` is ``auto``); None: the STL's caps (ends only).
    patient : dict or None
        The patient's own values, taking precedence over ``cfd`` and applied as given (never
        scaled): ``cell_size`` (m or ``"auto"``), ``flow_rate`` (m^3/s), or ``velocity`` (m/s)
        with ``valve_area`` (m^2), ``waveform`` (a CSV or .flow path), ``outlets`` (type, rcr
        totals), ``outlet_bc`` (path of the per-outlet RCR table, :func:`vcs.cfd.bc_tables.outlet_rcrs`)
        with ``mesh`` (the patient's surface, for its ``end:N`` rows); None values are ignored.

    Returns
    -------
    dict
        The case description (also saved as ``vcsflow_case.json``): flavour, merged ``cfd``
        (``inlet.flow_rate`` and ``inlet.valve_area`` as applied), background box
        ``bmin``/``bmax`` (m, in the box's frame ``background_frame``: the coordinate axes or the
        inlet's) with its world ``corners`` and ``ncells``, ``inside_point`` (m), solids and patches with
        their roles and levels, ``flow_rate`` (m^3/s), ``stl_bounds`` (m), ``mesh_sizing``
        (vessel sizes, cell size and why, background plan, levels, smallest cell), ``inflow``
        (:func:`vcs.cfd.sizing.choose_inflow` + inlet Reynolds number), ``files``.

    Raises
    ------
    VCSInputError
        For an unknown flavour or inlet type, an STL without exactly one inlet or without an
        outlet, a bad per-patient value, or when no point inside the surface is found.
    """
    case_dir = Path(case_dir)
    cfd, own = _merged_cfd(cfd, flavour, patient)
    fl = FLAVOURS[cfd["flavour"]]
    solids, roles = _case_solids(stl_path)
    # the background grid's frame: the coordinate axes, or the inlet's (n = the inward normal)
    if cfd["mesh"]["background_frame"] == "inlet":
        origin, axes = inlet_frame(solids)
    else:
        origin, axes = np.zeros(3), np.eye(3)
    local = {k: (t - origin) @ axes.T for k, t in solids.items()}
    plan = _mesh_plan(cfd["mesh"], solids, roles, local, model, own.get("cell_size"))
    inflow, waveform = _applied_inflow(cfd, solids, roles, own)
    table = patient_outlet_table(own, solids, model, cfd, Path(stl_path).with_name("ends.json"))
    outlets = case_outlets(solids, roles, cfd, inflow["flow_rate_m3_s"], waveform, table=table)
    jet = jet_region(solids, cfd, background=plan["hb"], min_level=plan["k"])
    bg, corners, inside, finest = _placement(cfd["mesh"], plan, jet, local, origin, axes)
    world = np.concatenate([t.reshape(-1, 3) for t in solids.values()])
    n = [1, 1, 1]  # the decomposition: every rank along the longest extent
    n[int(np.argmax(np.ptp(world, axis=0)))] = max(int(cfd["ranks"]), 1)
    level, solid_level, hb = plan["level"], plan["solid_level"], plan["hb"]
    state = {
        "flavour": cfd["flavour"],
        "cfd": cfd,
        "stl_source": str(Path(stl_path).resolve()),
        "bmin": bg["bmin"],
        "bmax": bg["bmax"],
        "ncells": bg["ncells"],
        "background_frame": {
            "type": cfd["mesh"]["background_frame"],
            "origin": [float(x) for x in origin],
            "axes": [[float(x) for x in row] for row in axes],
        },
        "corners": corners,
        "inside_point": [float(x) for x in inside],
        "decomposition_n": n,
        "solids": [
            {
                "name": name,
                "role": roles[name],
                "patch_type": "wall" if roles[name] == "wall" else "patch",
                "level": solid_level[name],
                "area_m2": surface_area(t),
                **_end_plane(t, roles[name]),
                "cell_size_m": hb / 2 ** solid_level[name][1],
            }
            for name, t in solids.items()
        ],
        "patches": [
            {"name": k2, "role": roles[k2]} | ({"outlet": outlets[k2]} if k2 in outlets else {}) for k2 in solids
        ]
        + [{"name": "background", "role": "other"}],
        "outlets": list(outlets.values()),
        "flow_rate": inflow["flow_rate_m3_s"],
        "stl_bounds": [[float(x) for x in world.min(0)], [float(x) for x in world.max(0)]],
        "jet_region": jet,
        "mesh_sizing": {
            "vessel": plan["sizes"],
            "lumen_volume_m3": plan["volume"],
            "cell_size_m": plan["h"],
            "cell_size": plan["sizing"],
            "background": bg,
            "levels": {
                "surface": level["other"],
                "lumen": plan["k"],
                **{r: level[r] for r in ("wall", "inlet", "outlet")},
            },
            "branches": plan["branch"],
            "smallest_cell_m": hb / 2**finest,
            "min_patch_faces": int(cfd["mesh"]["min_patch_faces"]),
        },
        "inflow": inflow,
        "waveform": waveform,
        # compiled boundary conditions the solvers load (controlDict libs): the Windkessel outlets
        "foam_libs": [foam_library("vcsWindkessel")]
        if any(o["bc_p"] == "windkessel" for o in outlets.values())
        else [],
    }
    case_dir.mkdir(parents=True, exist_ok=True)
    geo = case_dir / fl["geometry_dir"]
    geo.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(stl_path, geo / STL_NAME)
    render_files(case_dir, state, fl["files"])
    state["files"] = list(fl["files"]) + [f"{fl['geometry_dir']}/{STL_NAME}"]
    (case_dir / CASE_JSON).write_text(json.dumps(state, indent=2))
    return state


def _merged_cfd(
    cfd: dict[str, Any] | None, flavour: str | None, patient: dict[str, Any] | None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """``cfd`` merged over ``DEFAULTS`` with its flavour set and checked, and the patient's own
    values (their outlets merged into the config's): :func:`render_case`'s first step."""
    cfd = deep_merge(DEFAULTS, cfd)
    flavour = flavour or cfd.get("flavour") or detect_openfoam()[0] or "esi"
    if flavour not in FLAVOURS:
        raise VCSInputError(
            f"OpenFOAM flavour {flavour!r} is not supported (supported: {', '.join(sorted(FLAVOURS))}); "
            "install one of those or set cfd.flavour"
        )
    cfd["flavour"] = flavour
    check_cfd(cfd)
    own = _patient_values(patient)
    if "outlets" in own:
        cfd["outlets"] = deep_merge(cfd["outlets"], own["outlets"])
    return cfd, own


def _case_solids(stl_path: Path | str) -> tuple[dict[str, NDArray[np.floating]], dict[str, str]]:
    """The STL's solids and their roles: exactly one inlet, at least one outlet (else VCSInputError)."""
    solids = read_stl_solids(stl_path)
    roles = {k: patch_role(k) for k in solids}
    if sum(r == "inlet" for r in roles.values()) != 1:
        raise VCSInputError(f"the STL needs exactly one inlet solid, found {list(solids)}")
    if not any(r == "outlet" for r in roles.values()):
        raise VCSInputError(f"the STL has no outlet solid: {list(solids)}")
    return solids, roles


def _mesh_plan(
    m: dict[str, Any],
    solids: dict[str, NDArray[np.floating]],
    roles: dict[str, str],
    local: dict[str, NDArray[np.floating]],
    model: Any,
    cell_size: Any,
) -> dict[str, Any]:
    """The cell size from the vessel (its model, else the STL's caps; ``cell_size``: the patient's),
    the bounded background box (in the frame of ``local``) and the refinement levels relative to
    it, per role and per solid (a surface geometry's side branches ``branch_<k>`` by their
    diameters)."""
    pts = np.concatenate([t.reshape(-1, 3) for t in local.values()])
    if model is not None:
        if not hasattr(model, "fitted_wall"):
            from vcs.vessel import VesselModel

            model = VesselModel.load(model)
        sizes = vessel_sizes(model)
    else:
        sizes = stl_sizes(solids, roles)
    sizes["branch_diameters_m"] = {
        k: 2.0 * float(np.sqrt(surface_area(t) / np.pi)) for k, t in solids.items() if k.lower().startswith("branch")
    }
    volume = closed_volume(solids)
    sizing = choose_cell_size(m, sizes, volume, override=cell_size)
    h = sizing["cell_size_m"]
    bg = background_plan(h, pts.min(0), pts.max(0), m, sizes["narrowest_diameter_m"])
    k = bg["level_offset"]
    hb = bg["background_cell_size_m"]
    level = {
        role: [int(m[key][0]) + k, int(m[key][1]) + k]
        for role, key in (
            ("wall", "wall_level"),
            ("inlet", "inlet_level"),
            ("outlet", "outlet_level"),
            ("other", "surface_level"),
        )
    }
    branch = branch_levels(sizes["branch_diameters_m"], hb, level["outlet"], float(m["cells_across_branch"]))
    solid_level = {name: branch[name]["level"] if name in branch else level[roles[name]] for name in solids}
    return {
        "sizes": sizes,
        "volume": volume,
        "sizing": sizing,
        "h": h,
        "bg": bg,
        "k": k,
        "hb": hb,
        "level": level,
        "branch": branch,
        "solid_level": solid_level,
    }


def _applied_inflow(
    cfd: dict[str, Any], solids: dict[str, NDArray[np.floating]], roles: dict[str, str], own: dict[str, Any]
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """The inflow (the patient's, or the config's fixed or scaled by the inlet area, with the
    inlet Reynolds number) and the applied waveform; the applied values are written into
    ``cfd["inlet"]``."""
    inlet_area = sum(surface_area(t) for name, t in solids.items() if roles[name] == "inlet")
    inflow = choose_inflow(
        cfd["inlet"], inlet_area, patient={k: own[k] for k in ("flow_rate", "velocity", "valve_area") if k in own}
    )
    waveform = applied_waveform(cfd["inlet"], inflow, own.get("waveform"), inlet_area)
    d_in = 2.0 * np.sqrt(inlet_area / np.pi)
    inflow["inlet_reynolds"] = inflow["mean_inlet_velocity_m_s"] * d_in / float(cfd["physics"]["nu"])
    cfd["inlet"]["flow_rate"] = inflow["flow_rate_m3_s"]
    cfd["inlet"]["valve_area"] = inflow["valve_area_m2"]
    if inflow["jet_velocity_m_s"] is not None:
        cfd["inlet"]["velocity"] = inflow["jet_velocity_m_s"]
    return inflow, waveform


def _placement(
    m: dict[str, Any],
    plan: dict[str, Any],
    jet: dict[str, Any] | None,
    local: dict[str, NDArray[np.floating]],
    origin: NDArray[np.floating],
    axes: NDArray[np.floating],
) -> tuple[dict[str, Any], list[list[float]], NDArray[np.floating], int]:
    """The background box (aligned with the inlet in the inlet frame), its world corners, the
    point inside the lumen snappyHexMesh keeps (the config's, or found) and the finest level."""
    k, hb, level, bg = plan["k"], plan["hb"], plan["level"], plan["bg"]
    finest = max(
        [k, *level["wall"], *level["inlet"], *level["outlet"], *level["other"]]
        + [lv[1] for lv in plan["solid_level"].values()]
        + ([jet["level"]] if jet else [])
    )
    if m["background_frame"] == "inlet":
        h_inlet = hb / 2 ** max([level["inlet"][1]] + ([jet["level"]] if jet else []))
        bg = align_background_to_inlet(bg, h_inlet)
        bg["why"] += f"; aligned with the inlet (its plane 0.75 of a {h_inlet * 1e3:.4g} mm cell above a grid plane)"
    bmin = np.asarray(bg["bmin"])
    if m.get("inside_point"):
        inside = np.asarray(m["inside_point"], float)
    else:
        inside = origin + np.asarray(_inside_point(local, bmin, plan["h"], hb / 2**finest)) @ axes
    corners = [
        [float(x) for x in origin + np.array([bg[i][0], bg[j][1], bg[k2][2]]) @ axes]
        for i, j, k2 in (
            ("bmin", "bmin", "bmin"),
            ("bmax", "bmin", "bmin"),
            ("bmax", "bmax", "bmin"),
            ("bmin", "bmax", "bmin"),
            ("bmin", "bmin", "bmax"),
            ("bmax", "bmin", "bmax"),
            ("bmax", "bmax", "bmax"),
            ("bmin", "bmax", "bmax"),
        )
    ]
    return bg, corners, inside, finest


def patient_outlet_table(
    own: dict[str, Any],
    solids: dict[str, NDArray[np.floating]],
    model: Any,
    cfd: dict[str, Any],
    ends_json: Path | None = None,
) -> dict[str, dict[str, float]] | None:
    """The patient's per-outlet RCRs by patch name (:func:`vcs.cfd.bc_tables.outlet_rcrs` of the
    sheet's ``outlet_bc``, in the mesh's units from its model), or None; a table makes the outlets
    ``rcr`` (``cfd["outlets"]["type"]`` is set so), any other outlet type given with it is refused.
    A lumen's rows are matched to its openings on the input surface (``ends_json``, beside the
    lumen's STL, when it exists), not to its patches at the ends of the flow extensions."""
    if not own.get("outlet_bc"):
        return None
    from vcs.cfd.bc_tables import lumen_ends, outlet_rcrs

    kind = cfd["outlets"].get("type", "free")
    own_kind = (own.get("outlets") or {}).get("type")
    if own_kind not in (None, "rcr"):
        raise VCSInputError(
            f"the patient's outlet_bc table gives a Windkessel per outlet, but its outlets are {own_kind}: "
            "set its outlets to rcr (or leave them empty)"
        )
    if kind != "rcr":
        cfd["outlets"]["type"] = "rcr"
    units = "m"
    if model is not None:
        if not hasattr(model, "units"):
            from vcs.vessel import VesselModel

            model = VesselModel.load(model)
        units = str(getattr(model, "units", "m"))
    ends = lumen_ends(ends_json) if ends_json is not None and ends_json.is_file() else None
    return outlet_rcrs(own["outlet_bc"], solids, units=units, mesh=own.get("mesh"), ends=ends)


def case_outlets(
    solids: dict[str, NDArray[np.floating]],
    roles: dict[str, str],
    cfd: dict[str, Any],
    flow_rate: float,
    waveform: dict[str, Any] | None,
    *,
    table: dict[str, dict[str, float]] | None = None,
) -> dict[str, dict[str, Any]]:
    """The outlet plan of a case (:func:`vcs.cfd.outlets.outlet_plan` on the STL's outlet solids
    and their areas), by patch name; a pulsatile case's murray branches also get ``flow_table``:
    their share of the applied waveform over ``max_cycles + 1`` cycles
    (:func:`vcs.cfd.outlets.flow_table`), so that the split holds at every instant."""
    from vcs.cfd.outlets import flow_table, outlet_plan

    names = [n for n in solids if roles[n] == "outlet"]
    plan = outlet_plan(
        names,
        [surface_area(solids[n]) for n in names],
        cfd["outlets"],
        flow_rate=flow_rate,
        rho=float(cfd["physics"]["rho"]),
        table=table,
    )
    for o in plan:
        if waveform is not None and o["bc_u"] == "flowRateOutletVelocity":
            cycles = int(cfd["pulsatile"]["max_cycles"]) + 1
            o["flow_table"] = flow_table(
                waveform["time_s"], waveform["flow_m3_s"], waveform["period_s"], float(o["target_fraction"]), cycles
            )
    return {str(o["name"]): o for o in plan}


# --------------------------------------------------------------------------- inflow waveform


def applied_waveform(
    inlet: dict[str, Any], inflow: dict[str, Any], own: str | None, inlet_area: float
) -> dict[str, Any] | None:
    """The inflow waveform a patient gets (None: steady), and ``inflow`` updated to say so.

    The waveform is the patient's own (``inflow_waveform`` of the sheet: applied as given) or
    ``cfd.inlet.waveform`` scaled as the steady flow would be (:func:`vcs.cfd.sizing.choose_inflow`):
    by the inlet-area factor (``scaling: scaled_by_inlet_area``; the waveform's mean takes the place
    of the config's flow rate), or to the patient's own mean flow (sheet ``flow_rate_l_min``, or
    velocity x valve area). ``inflow`` then holds the applied mean flow rate and a ``waveform``
    summary (:meth:`vcs.cfd.waveform.Waveform.summary`, the file's SHA-256, the scale factor and why).

    Returns
    -------
    dict or None
        ``time_s``, ``flow_m3_s`` (as applied), ``period_s``, ``source``, ``sha256``,
        ``scale_factor``, ``why``.
    """
    path = own or inlet.get("waveform")
    if not path:
        return None
    import hashlib

    from vcs.cfd.waveform import load_waveform

    wf = load_waveform(path)
    if own:
        factor, why = 1.0, f"the patient's own waveform {Path(path).name} (patients sheet), as given"
    elif inflow["source"] == "patient":
        if not wf.mean_m3_s > 0:
            raise VCSInputError(
                f"waveform {path} has a mean flow of {wf.mean_m3_s * 6e4:.4g} L/min: it cannot be scaled to the "
                "patient's flow rate; give the patient's own waveform (inflow_waveform) instead"
            )
        factor = inflow["flow_rate_m3_s"] / wf.mean_m3_s
        why = f"{Path(path).name} scaled to the patient's mean flow {inflow['flow_rate_m3_s'] * 6e4:.4g} L/min"
    else:
        factor = float(inflow["scale_factor"])
        why = f"{Path(path).name} (cfd.inlet.waveform)" + (
            f" x {factor:.4g} ({inflow['scaling']}: inlet area / reference_inlet_area, capped at max_scale)"
            if inflow["scaling"] == "scaled_by_inlet_area"
            else ", unscaled"
        )
    applied = wf.scaled(factor)
    q = applied.mean_m3_s
    inflow.update(
        {
            # what was applied: the waveform (the steady inflow's jet velocity does not apply)
            "source": "patient" if own or inflow["source"] == "patient" else "config",
            "scaling": "patient_waveform"
            if own
            else ("patient" if inflow["source"] == "patient" else inflow["scaling"]),
            "scale_factor": factor,
            "jet_velocity_m_s": None,
            "flow_rate_m3_s": q,
            "flow_rate_l_min": q * 6e4,
            "mean_inlet_velocity_m_s": q / inlet_area,
            "why": why + f": mean {q * 6e4:.4g} L/min",
            "waveform": applied.summary()
            | {"scale_factor": factor, "sha256": hashlib.sha256(Path(path).read_bytes()).hexdigest()},
        }
    )
    return {
        "time_s": [float(x) for x in applied.time_s],
        "flow_m3_s": [float(x) for x in applied.flow_m3_s],
        "period_s": applied.period_s,
        "source": str(Path(path).resolve()),
        "sha256": inflow["waveform"]["sha256"],
        "scale_factor": factor,
        "why": why,
    }


# --------------------------------------------------------------------------- inlet profile


def inlet_profile(case_dir: Path, state: dict[str, Any]) -> dict[str, Any]:
    """Face-wise inlet velocities on the meshed inlet patch, scaled so sum(U.Sf) = -Q exactly.

    The profile (``cfd.inlet.type``) is a jet (plug flow through a disc of area ``valve_area``
    about ``centre``), uniform, or parabolic over the equivalent circle of the inlet, directed
    along the inward patch normal.

    Parameters
    ----------
    case_dir : Path
        A meshed case (ASCII ``constant/polyMesh``).
    state : dict
        Case description from :func:`render_case`.

    Returns
    -------
    dict
        ``patch`` (name), ``values`` ((F, 3) float, m/s, one per inlet face), ``n_faces``,
        ``patch_area`` (m^2), ``direction`` (unit inward normal), ``centre`` (m),
        ``flow_rate_target`` and ``flow_rate_discrete`` (m^3/s), ``flux_error_rel``,
        ``covered_area`` (m^2, faces with inflow), ``peak_velocity`` (m/s).

    Raises
    ------
    VCSInputError
        When the jet disc contains no inlet face centre.
    """
    inlet = state["cfd"]["inlet"]
    name = next(p["name"] for p in state["patches"] if p["role"] == "inlet")
    centres, sf = patch_geometry(case_dir, name)
    mag = np.linalg.norm(sf, axis=1)
    ntot = sf.sum(0)
    n_in = -ntot / np.linalg.norm(ntot)  # Sf points out of the domain
    area = float(mag.sum())
    c0 = np.asarray(inlet.get("centre") or (centres * mag[:, None]).sum(0) / area, float)
    d = centres - c0
    d -= np.outer(d @ n_in, n_in)
    r = np.linalg.norm(d, axis=1)
    q = state["flow_rate"]
    kind = inlet["type"]
    if kind == "jet":
        r_jet = np.sqrt(float(inlet["valve_area"]) / np.pi)
        shape = (r <= r_jet).astype(float)
        if shape.sum() == 0:
            raise VCSInputError("jet disc contains no inlet face centre: refine the inlet or enlarge valve_area")
    elif kind == "uniform":
        shape = np.ones_like(r)
    else:  # parabolic over the equivalent-circle radius of the inlet
        r_eq = np.sqrt(area / np.pi)
        shape = np.clip(1.0 - (r / r_eq) ** 2, 0.0, None)
    inflow_per_unit = float((shape * (sf @ (-n_in))).sum())  # sum shape * (n_in . -Sf)
    scale = q / inflow_per_unit
    values = scale * shape[:, None] * n_in[None, :]
    flux = float(-(values * sf).sum())
    covered = float(mag[shape > 0].sum())
    return {
        "patch": name,
        "values": values,
        "n_faces": int(len(mag)),
        "patch_area": area,
        "direction": [float(x) for x in n_in],
        "centre": [float(x) for x in c0],
        "flow_rate_target": q,
        "flow_rate_discrete": flux,
        "flux_error_rel": abs(flux - q) / q,
        "covered_area": covered,
        "peak_velocity": float(np.abs(values @ n_in).max()),
    }
