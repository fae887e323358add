"""One patient's quality-control sheet: a single PNG that shows whether its fit and its CFD can be
trusted, before the patient goes into an atlas (issue 26, item 2).

Nine panels on three rows, each drawn from the patient's own files (:func:`write_qc_sheet`):

1. the input mesh (grey) with the fitted wall of Eq. 8 (blue rings and lines at constant tau and
   theta), the centerline c(tau) (red) and the two end planes (orange discs), in the model's own
   sagittal view (:class:`vcs.atlas.plots3d.ViewFrame`);
2. the fit residual r(p) (Eq. 11: signed distance of each mesh vertex from the fitted wall, mm) on
   the input mesh, vertices the fit did not use grey;
3. the same residual over the (tau, theta) plane (the paper's Fig. 4), for reading values;
4. a slice of the CFD mesh through the centerline's best-fit plane, cell edges drawn;
5. a close-up of that slice at the wall, half-way along the vessel: the near-wall (layer) cells;
6. the solver's residual history (``residuals.csv``) and the convergence verdict (a pulsatile run
   with its outlets' last cycle: each outlet's pressure and flow over it instead);
7. |U| on that slice (m/s; the time average when the run was averaged);
8. the wall shear stress magnitude on the CFD wall (Pa; time-averaged likewise);
9. for a transient or pulsatile run the figure its verdict was made on (``transient.png``: the
   running mean of the pressure difference, the averaging window and the error bar;
   ``pulsatile.png``: the cycles), else a table of the patient's key numbers.

The title line names the patient and its verdict; a patient that failed at any stage gets the
stage and reason in red, and every panel whose input does not exist says why in place of the
picture. A panel that cannot be drawn (an unreadable file, a VTK error) says so in its place and
the reason goes to the log: a QC sheet never fails a patient's run.
"""

from __future__ import annotations

import json
import logging
import textwrap
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from vcs.atlas.plots3d import ViewFrame
    from vcs.vessel import VesselModel

log = logging.getLogger(__name__)

#: Pixel size (width, height) of one 3-D panel's render; the sheet's figure size (inches) and dpi.
PANEL_PX = (520, 430)
SHEET_INCHES = (16.0, 14.0)
SHEET_DPI = 90
#: Millimetres per unit of a mesh's stated units.
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}
FAILED_COLOUR = "#b2182b"


class PanelUnavailable(Exception):
    """A panel's input does not exist (the patient failed earlier, or the run made no such file)."""


@dataclass
class PatientFiles:
    """Where one patient's results are (any of them may be missing: a failed patient)."""

    patient: str
    mesh: Path | None = None
    fit_dir: Path | None = None
    case_dir: Path | None = None
    status: Path | None = None
    fields_summary: Path | None = None

    def json(self, path: Path | None) -> dict[str, Any] | None:
        """The JSON object in ``path`` (None when missing or unreadable)."""
        if path is None or not path.is_file():
            return None
        try:
            with open(path) as fh:
                obj = json.load(fh)
        except (OSError, ValueError):
            return None
        return obj if isinstance(obj, dict) else None


@dataclass
class SheetData:
    """What the panels draw, read once (``None``: not there)."""

    files: PatientFiles
    report: dict[str, Any] | None = None
    status: dict[str, Any] | None = None
    verdict: tuple[bool, str] = (False, "")
    model: VesselModel | None = None
    frame: ViewFrame | None = None
    case: tuple[Any, dict[str, Any], float] | None = None
    drawn: dict[str, str] = field(default_factory=dict)
    #: meshes more than one panel draws (the input surface, the mid-plane slice), made once
    meshes: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------
# Reading
# ---------------------------------------------------------------------------------------------
def patient_verdict(
    report: dict[str, Any] | None, status: dict[str, Any] | None, fields: dict[str, Any] | None
) -> tuple[bool, str]:
    """(usable, one line): whether the patient goes into an atlas, and why not (the stage and
    reason, as the atlas itself says it: :mod:`vcs.atlas.cohort`)."""
    from vcs.atlas.cohort import fields_exclusion, fit_failure, status_exclusion, status_stage

    why = fit_failure(report)
    if why is not None:
        return False, f"failed at {(report or {}).get('stage', 'fit')}: {why}"
    if status is None:
        return False, "no status.json: the CFD has not run"
    why = status_exclusion(status)
    if why is not None:
        return False, f"failed at {status_stage(status)}: {why}"
    why = fields_exclusion(fields) if fields is not None else None
    if why is not None:
        return False, f"failed at sampling: {why}"
    how = status.get("criterion_used") or "converged"
    return True, f"converged ({how}), {_num(status.get('cells'), ',.0f')} cells"


def read_sheet_data(files: PatientFiles) -> SheetData:
    """Read the fit report, status and model of a patient (what is missing stays None)."""
    from vcs.atlas.plots3d import ViewFrame
    from vcs.vessel import VesselModel

    d = SheetData(files)
    fit_dir = files.fit_dir
    d.report = files.json(fit_dir / "fit_report.json") if fit_dir else None
    d.status = files.json(files.status)
    d.verdict = patient_verdict(d.report, d.status, files.json(files.fields_summary))
    model_path = fit_dir / "model.json" if fit_dir else None
    if model_path is not None and model_path.is_file() and not (d.report or {}).get("failed"):
        try:
            d.model = VesselModel.load(model_path)
            d.frame = ViewFrame.from_model(d.model)
        except Exception as e:  # noqa: BLE001 - a failure record, an old format: the panels say so
            log.warning("qc: cannot read the model %s: %s", model_path, e)
    return d


def _case(d: SheetData) -> tuple[Any, dict[str, Any], float]:
    """The CFD case at its last time (time averages when the run averaged), read once."""
    from vcs.cfd.resample import read_case

    if d.case is None:
        case = d.files.case_dir
        if (
            case is None
            or not (case / "system" / "controlDict").is_file()
            or not (case / "constant" / "polyMesh").is_dir()
        ):
            raise PanelUnavailable("no CFD mesh (the case was not meshed)")
        if d.status is not None and d.status.get("failed"):
            raise PanelUnavailable("no CFD solution")
        d.case = read_case(case)
    return d.case


def _need_model(d: SheetData) -> tuple[VesselModel, ViewFrame]:
    if d.model is None or d.frame is None:
        raise PanelUnavailable("no fitted model (the fit failed)")
    return d.model, d.frame


# ---------------------------------------------------------------------------------------------
# 3-D renders (pyvista, off-screen) into image arrays
# ---------------------------------------------------------------------------------------------
def _render(meshes: list[tuple[Any, dict[str, Any]]], camera: Callable[[Any], None]) -> np.ndarray:
    """An RGB image of ``meshes`` (``add_mesh`` keywords) with the camera set by ``camera``."""
    import pyvista as pv

    from vcs.atlas.plots3d import BACKGROUND

    pl = pv.Plotter(off_screen=True, window_size=list(PANEL_PX), lighting="none")
    try:
        pl.set_background(BACKGROUND)  # type: ignore[arg-type]  # a colour name
        pl.add_light(pv.Light(light_type="headlight"))
        for mesh, kw in meshes:
            pl.add_mesh(mesh, show_scalar_bar=False, **kw)
        camera(pl.camera)
        return np.asarray(pl.screenshot(return_img=True))
    finally:
        pl.close()


def _frame_camera(frame: ViewFrame, view: str, points: Any) -> Callable[[Any], None]:
    """The mean-frame camera of ``view`` (as :meth:`ViewFrame.set_camera`: parallel projection),
    framing ``points`` (mm: what the panel shows, e.g. a CFD domain longer than the model by its
    flow extensions) in 95 % of the panel (the sheet's titles and colour bars are matplotlib's)."""
    pts = np.asarray(points, float).reshape(-1, 3)

    def set_camera(cam: Any) -> None:
        d = frame.direction(view)
        right = np.cross(frame.up, d)
        x, y = (pts - frame.centre) @ right, (pts - frame.centre) @ frame.up
        scale = 1.05 * max(np.ptp(y) / 2, np.ptp(x) / (2 * PANEL_PX[0] / PANEL_PX[1]))
        focal = frame.centre + 0.5 * (x.max() + x.min()) * right + 0.5 * (y.max() + y.min()) * frame.up
        size = max(frame.size, float(np.ptp(pts, axis=0).max()))
        cam.focal_point = tuple(focal)
        cam.position = tuple(focal + 4.0 * size * d)
        cam.up = tuple(frame.up)
        cam.parallel_projection = True
        cam.parallel_scale = scale
        cam.clipping_range = (0.1 * size, 10.0 * size)

    return set_camera


def _zoom_camera(focal: np.ndarray, direction: np.ndarray, up: np.ndarray, half_height: float) -> Callable[[Any], None]:
    def set_camera(cam: Any) -> None:
        cam.focal_point = tuple(focal)
        cam.position = tuple(focal + 50.0 * half_height * direction)
        cam.up = tuple(up)
        cam.parallel_projection = True
        cam.parallel_scale = half_height
        cam.clipping_range = (1.0 * half_height, 100.0 * half_height)

    return set_camera


def _colour_bar(ax: Axes, clim: tuple[float, float], cmap: str, label: str, *, pad: float = 0.02) -> None:
    import matplotlib.pyplot as plt
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize

    sm = ScalarMappable(norm=Normalize(*clim), cmap=cmap)
    plt.colorbar(sm, ax=ax, orientation="horizontal", fraction=0.05, pad=pad, label=label)


def _input_surface(d: SheetData) -> Any:
    """The input mesh in mm with the fit residual (``residual``, NaN where not used) at its points
    (read once; each panel gets its own copy)."""
    if "input_surface" not in d.meshes:
        d.meshes["input_surface"] = _read_input_surface(d)
    return d.meshes["input_surface"].copy()


def _read_input_surface(d: SheetData) -> Any:
    """:func:`_input_surface`, read."""
    import pyvista as pv
    from scipy.spatial import cKDTree

    report = d.report or {}
    mesh_path = d.files.mesh
    if mesh_path is None or not mesh_path.is_file():
        raise PanelUnavailable("the input mesh is not there")
    surface = pv.read(str(mesh_path))
    if not isinstance(surface, pv.PolyData):
        surface = surface.extract_surface(algorithm="dataset_surface")
    surface = surface.scale(MM_PER_UNIT.get(str(report.get("units", "mm")), 1.0))
    values = np.full(surface.n_points, np.nan)
    res_path = d.files.fit_dir / "wall_residuals.vtp" if d.files.fit_dir else None
    if res_path is not None and res_path.is_file():
        res = pv.read(str(res_path))
        mm = _mm_per_output_unit(report)
        r = mm * np.asarray(res.point_data["residual"], float)
        if "used" in res.point_data:
            r = np.where(np.asarray(res.point_data["used"]).astype(bool), r, np.nan)
        dist, idx = cKDTree(mm * np.asarray(res.points)).query(np.asarray(surface.points))
        tol = 1e-3 * max(float(report.get("median_radius_mm", 1.0)), 1e-6)
        values = np.where(dist <= tol, r[idx], np.nan)
    surface.point_data["residual"] = values
    return surface


def _mm_per_output_unit(report: dict[str, Any]) -> float:
    """Millimetres per unit of the fit's VTP outputs (``vcs fit`` writes them in the mesh's units)."""
    return MM_PER_UNIT.get(str(report.get("outputs_units") or report.get("units") or "mm"), 1.0)


def _end_discs(d: SheetData) -> list[Any]:
    import pyvista as pv

    discs = []
    for end in ("inlet", "outlet"):
        e = (d.report or {}).get(end) or {}
        if "center_mm" in e and "normal" in e and e.get("radius_mm"):
            r = float(e["radius_mm"])
            discs.append(pv.Disc(center=e["center_mm"], normal=e["normal"], inner=0.0, outer=1.15 * r, c_res=48))
    return discs


def _fitted_wall_lines(model: VesselModel) -> Any:
    """The fitted wall x(tau, theta) (Eq. 8) as rings every 0.05 in tau and 12 lines in theta."""
    import pyvista as pv

    lines = []
    theta = np.linspace(0.0, 2 * np.pi, 73)
    for tau in np.linspace(0.0, 1.0, 21):
        pts = np.asarray(model.surface_points(np.full_like(theta, tau), theta), float)
        lines.append(pv.lines_from_points(pts))
    tau = np.linspace(0.0, 1.0, 201)
    for th in 2 * np.pi * np.arange(12) / 12:
        lines.append(pv.lines_from_points(np.asarray(model.surface_points(tau, np.full_like(tau, th)), float)))
    return pv.merge(lines)


def panel_fit_overlay(ax: Axes, d: SheetData) -> None:
    """Panel 1: input mesh, fitted wall, centerline, end planes (sagittal view)."""
    from vcs.atlas.plots3d import SURFACE_LOOK, centerline_tube

    model, frame = _need_model(d)
    surface = _input_surface(d)
    meshes: list[tuple[Any, dict[str, Any]]] = [
        (surface, {"color": "#cfcfcf", "opacity": 0.45, **SURFACE_LOOK}),
        (_fitted_wall_lines(model), {"color": "#2166ac", "line_width": 1.0}),
        (centerline_tube(model, 0.006 * frame.size), {"color": "#d62728"}),
    ]
    meshes += [(disc, {"color": "#ff7f0e", "opacity": 0.7}) for disc in _end_discs(d)]
    ax.imshow(_render(meshes, _frame_camera(frame, "sagittal", surface.points)))
    ax.set_title("input mesh (grey), fitted wall (blue),\ncenterline (red), end planes (orange)")


def _residual_limits(values: np.ndarray) -> tuple[float, float]:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        raise PanelUnavailable("no residuals (no mesh vertex was used by the fit)")
    lim = max(float(np.percentile(np.abs(finite), 98)), 1e-6)
    return (-lim, lim) if finite.min() < 0 else (0.0, lim)


def panel_residual_surface(ax: Axes, d: SheetData) -> None:
    """Panel 2: the fit residual (mm) on the input mesh, sagittal view."""
    from vcs.atlas.plots import NAN_COLOUR
    from vcs.atlas.plots3d import SURFACE_LOOK

    _, frame = _need_model(d)
    surface = _input_surface(d)
    clim = _residual_limits(np.asarray(surface.point_data["residual"]))
    cmap = "RdBu_r" if clim[0] < 0 else "viridis"
    look = {"scalars": "residual", "clim": clim, "cmap": cmap, "nan_color": NAN_COLOUR, **SURFACE_LOOK}
    ax.imshow(_render([(surface, look)], _frame_camera(frame, "sagittal", surface.points)))
    rep = d.report or {}
    ax.set_title(
        f"fit residual on the input mesh (Eq. 11)\nmean {rep.get('residual_mean_mm', np.nan):.3g} mm, "
        f"95th pct {rep.get('residual_p95_mm', np.nan):.3g} mm"
    )
    _colour_bar(ax, clim, cmap, "residual (mm; grey: not used)")


def panel_residual_map(ax: Axes, d: SheetData) -> None:
    """Panel 3: the fit residual over (tau, theta) (the paper's Fig. 4)."""
    import pyvista as pv

    res_path = d.files.fit_dir / "wall_residuals.vtp" if d.files.fit_dir else None
    if res_path is None or not res_path.is_file() or (d.report or {}).get("failed"):
        raise PanelUnavailable("no fit residuals (the fit failed)")
    res = pv.read(str(res_path))
    pdata = {k: np.asarray(res.point_data[k]) for k in ("tau", "theta", "residual")}
    pdata["residual"] = _mm_per_output_unit(d.report or {}) * pdata["residual"]
    used = np.asarray(res.point_data["used"]).astype(bool) if "used" in res.point_data else np.ones(res.n_points, bool)
    clim = _residual_limits(np.where(used, pdata["residual"], np.nan))
    cmap = "RdBu_r" if clim[0] < 0 else "viridis"
    # a filled map (triangulation of the used vertices in (tau, theta)), the unused vertices grey
    # dots over it: scattered dots left white stripes between the mesh's rings
    tri = _tau_theta_triangulation(pdata["tau"][used], pdata["theta"][used])
    ax.tripcolor(tri, pdata["residual"][used], cmap=cmap, vmin=clim[0], vmax=clim[1], shading="gouraud")
    ax.scatter(pdata["tau"][~used], pdata["theta"][~used], c="lightgrey", s=1)
    ax.set(xlim=(0, 1), ylim=(0, 2 * np.pi), xlabel="tau", ylabel="theta (rad)", title="fit residual over (tau, theta)")
    ax.set_aspect("auto")
    _colour_bar(ax, clim, cmap, "residual (mm)", pad=0.15)


def _tau_theta_triangulation(tau: np.ndarray, theta: np.ndarray) -> Any:
    """Delaunay triangulation of points in the (tau, theta) plane without the triangles that
    bridge a gap (a branch's hole, the theta seam): edges longer than 5x the median are dropped."""
    from matplotlib.tri import Triangulation

    tri = Triangulation(tau, theta / (2 * np.pi))  # both axes on [0, 1]
    x, y = tau[tri.triangles], (theta / (2 * np.pi))[tri.triangles]
    edge = np.max(np.hypot(x - np.roll(x, 1, axis=1), y - np.roll(y, 1, axis=1)), axis=1)
    tri.set_mask(edge > 5.0 * np.median(edge))
    return Triangulation(tau, theta, triangles=tri.get_masked_triangles())


def _mid_slice(d: SheetData) -> tuple[Any, np.ndarray, np.ndarray]:
    """The CFD mesh cut by the centerline's best-fit plane, in mm, with |U| (cell data ``U_mag``)
    and its boundary edges' points (cut once; each panel gets its own copy of the slice)."""
    if "mid_slice" not in d.meshes:
        d.meshes["mid_slice"] = _cut_mid_slice(d)
    cut, rim, normal = d.meshes["mid_slice"]
    return cut.copy(), rim, normal


def _cut_mid_slice(d: SheetData) -> tuple[Any, np.ndarray, np.ndarray]:
    """:func:`_mid_slice`, cut."""
    _, frame = _need_model(d)
    internal, _, _ = _case(d)
    cut = internal.slice(normal=frame.normal, origin=frame.centre / 1000.0, generate_triangles=False)
    if cut.n_cells == 0:
        raise PanelUnavailable("the centerline's plane does not cut the CFD mesh")
    if "U" in cut.cell_data:  # before scaling: the transform filter scales the active vectors too
        cut.cell_data["U_mag"] = np.linalg.norm(np.asarray(cut.cell_data["U"], float), axis=1)
    cut = cut.scale(1000.0)
    edges = cut.extract_feature_edges(
        boundary_edges=True, feature_edges=False, manifold_edges=False, non_manifold_edges=False
    )
    return cut, np.asarray(edges.points), frame.normal


def panel_mesh_slice(ax: Axes, d: SheetData) -> None:
    """Panel 4: the CFD mesh on the mid plane, cell edges drawn."""
    _, frame = _need_model(d)
    cut, _, _ = _mid_slice(d)
    look = {"color": "#f2f2f2", "show_edges": True, "edge_color": "#303030", "line_width": 0.4}
    ax.imshow(_render([(cut, look)], _frame_camera(frame, "sagittal", cut.points)))
    cells = (d.status or {}).get("cells")
    ax.set_title(
        f"CFD mesh on the centerline's plane\n{_num(cells, ',.0f')} cells"
        if cells
        else "CFD mesh on the centerline's plane"
    )


def panel_mesh_wall(ax: Axes, d: SheetData) -> None:
    """Panel 5: close-up of the mid-plane slice at the wall, where the vessel has its median radius
    (tau in [0.25, 0.75]; a coarctation or an aneurysm is not the place to judge the layers)."""
    model, frame = _need_model(d)
    cut, rim, normal = _mid_slice(d)
    if rim.size == 0:
        raise PanelUnavailable("the slice has no wall edge")
    taus = np.linspace(0.25, 0.75, 51)
    theta = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)
    T, TH = np.meshgrid(taus, theta, indexing="ij")
    radius = np.asarray(model.fitted_wall()(T, TH), float).mean(axis=1)
    tau = float(taus[np.argmin(np.abs(radius - np.median(radius)))])
    c = model.vcs.curve(np.array([tau]))[0]
    t = model.vcs.frame.tangent(np.array([tau]))[0]
    out = np.cross(normal, t)
    out /= np.linalg.norm(out)
    rel = rim - c
    along = rel @ out
    perp = np.linalg.norm(rel - np.outer(along, out), axis=1)  # distance from the ray c + s out
    near = (along > 0) & (perp < 0.1 * float(np.median(radius)) + perp.min())
    if not near.any():
        raise PanelUnavailable(f"no wall edge beside the centerline at tau = {tau:.2f}")
    wall = rim[near][np.argmin(along[near])]  # the first wall the ray meets
    sizing = (((d.status or {}).get("mesh") or {}).get("sizing") or {}).get("cell_size_m")
    half = 4.0 * 1000.0 * float(sizing) if sizing else 0.3 * float(np.median(radius))  # ~8 lumen cells high
    half = min(half, 0.6 * float(np.linalg.norm(wall - c)))
    focal = wall - 0.6 * half * out
    look = {"color": "#f2f2f2", "show_edges": True, "edge_color": "#303030", "line_width": 0.8}
    ax.imshow(_render([(cut, look)], _zoom_camera(focal, normal, out, half)))
    lay = ((d.status or {}).get("mesh") or {}).get("layers") or {}
    layers = (
        f"{lay.get('requested')} layers asked, {lay.get('mean_layers', 0):.2g} made, "
        f"{100 * float(lay.get('coverage', 0)):.0f} % of the wall"
        if lay.get("requested")
        else "no prism layers"
    )
    ax.set_title(f"near-wall cells at tau = {tau:.2f} (wall at the top), {2 * half:.2g} mm high\n{layers}")


def panel_outlet_waveforms(ax: Axes, d: SheetData) -> bool:
    """Panel 6 of a pulsatile run with its outlets' last cycle in status.json: each outlet's
    pressure (mmHg, solid) and flow (mL/s, dashed, right axis) over the last cycle, the legend with
    its systolic/diastolic/mean pressure and realised mean split. False when there is none."""
    outlets = [o for o in (d.status or {}).get("outlets") or [] if o.get("last_cycle")]
    if not outlets:
        return False
    mmhg = 133.322387415  # Pa (vcs.cfd.status.MMHG_PA, not imported: the sheet's imports stay light)
    right = ax.twinx()
    for k, o in enumerate(outlets):
        lc, pm = o["last_cycle"], o.get("pressure_mmhg") or {}
        colour = f"C{k % 10}"
        label = (
            f"{o['name']}: {pm.get('systolic', np.nan):.0f}/{pm.get('diastolic', np.nan):.0f} "
            f"({pm.get('mean', np.nan):.0f}) mmHg, {100 * (o.get('fraction') or np.nan):.0f} %"
        )
        ax.plot(lc["phase"], np.asarray(lc["pressure_pa"]) / mmhg, color=colour, lw=1.2, label=label)
        right.plot(lc["phase"], np.asarray(lc["flow_rate_m3_s"]) * 1e6, color=colour, lw=0.8, ls="--")
    ax.set(xlabel="phase of the last cycle", ylabel="outlet pressure (mmHg), solid")
    right.set_ylabel("outlet flow (mL/s), dashed")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("outlets over the last cycle: sys/dia (mean), mean split")
    ax.set_aspect("auto")
    return True


def panel_residual_history(ax: Axes, d: SheetData) -> None:
    """Panel 6: the solver's initial residuals per iteration (``residuals.csv``); a pulsatile run's
    outlets over its last cycle instead when it has them (:func:`panel_outlet_waveforms`)."""
    import csv

    if panel_outlet_waveforms(ax, d):
        return

    path = d.files.case_dir / "residuals.csv" if d.files.case_dir else None
    if path is None or not path.is_file():
        raise PanelUnavailable("no residual history (the solver did not run)")
    with open(path) as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise PanelUnavailable("the residual history is empty")
    it = np.array([float(r["iteration"]) for r in rows])
    for name in [k for k in rows[0] if k != "iteration" and not k.startswith("cont")]:
        y = np.array([float(r[name]) if r[name] not in ("", "nan") else np.nan for r in rows])
        ax.semilogy(it, y, lw=1, label=name)
    st = d.status or {}
    ax.axhline(1e-5, color="k", lw=0.6, ls="--", label="1e-5")
    ax.set(xlabel="iteration", ylabel="initial residual")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(
        f"residual history: {st.get('criterion_used') or 'not converged'}\n{st.get('iterations', len(rows))} iterations"
    )
    ax.set_aspect("auto")


def panel_velocity(ax: Axes, d: SheetData) -> None:
    """Panel 7: |U| (m/s) on the mid-plane slice."""
    from vcs.atlas.plots import robust_limits

    _, frame = _need_model(d)
    cut, _, _ = _mid_slice(d)
    if "U_mag" not in cut.cell_data:
        raise PanelUnavailable("no velocity field")
    u = np.asarray(cut.cell_data["U_mag"])
    clim = (0.0, max(robust_limits([u])[1], 1e-9))
    look = {"scalars": "U_mag", "preference": "cell", "clim": clim, "cmap": "viridis"}
    ax.imshow(_render([(cut, look)], _frame_camera(frame, "sagittal", cut.points)))
    avg = "time-averaged " if _averaged(d) else ""
    ax.set_title(f"{avg}|U| on the centerline's plane\nmax {u.max():.3g} m/s")
    _colour_bar(ax, clim, "viridis", "|U| (m/s)")


def _averaged(d: SheetData) -> bool:
    internal, _, _ = _case(d)
    return str(np.asarray(internal.field_data.get("field_source", ["instantaneous"]))[0]) == "time_average"


def panel_wss(ax: Axes, d: SheetData) -> None:
    """Panel 8: |WSS| (Pa) on the CFD wall (kinematic wall shear stress times the density)."""
    from vcs.atlas.plots import robust_limits
    from vcs.atlas.plots3d import SURFACE_LOOK

    _, frame = _need_model(d)
    _, patches, _ = _case(d)
    wall = patches.get("wall")
    if wall is None or "wallShearStress" not in wall.cell_data:
        raise PanelUnavailable("no wall shear stress on the wall patch")
    rho = float((d.status or {}).get("rho") or 1060.0)
    wss = rho * np.linalg.norm(np.asarray(wall.cell_data["wallShearStress"], float), axis=1)
    wall = wall.copy()
    wall.cell_data["WSS_Pa"] = wss  # before scaling: the transform filter scales the active vectors too
    wall = wall.scale(1000.0)
    clim = (0.0, max(robust_limits([wss])[1], 1e-9))
    look = {"scalars": "WSS_Pa", "preference": "cell", "clim": clim, "cmap": "inferno", **SURFACE_LOOK}
    ax.imshow(_render([(wall, look)], _frame_camera(frame, "front", wall.points)))
    avg = "time-averaged " if _averaged(d) else ""
    ax.set_title(f"{avg}|WSS| on the CFD wall\nmedian {np.median(wss):.3g} Pa, max {wss.max():.3g} Pa")
    _colour_bar(ax, clim, "inferno", "|WSS| (Pa)")


def panel_verdict(ax: Axes, d: SheetData) -> None:
    """Panel 9: the transient or pulsatile run's own figure, else the key numbers."""
    import matplotlib.image as mpimg

    case = d.files.case_dir
    for name, title in (
        ("pulsatile.png", "cardiac cycles (pulsatile.png)"),
        ("transient.png", "time average and its window (transient.png)"),
    ):
        if case is not None and (case / name).is_file():
            ax.imshow(mpimg.imread(case / name))
            ax.set_title(title)
            return
    ax.axis("off")
    ax.text(
        0.0, 1.0, "\n".join(key_numbers(d)), va="top", ha="left", family="monospace", fontsize=9, transform=ax.transAxes
    )
    ax.set_title("key numbers")


def _num(value: Any, fmt: str, scale: float = 1.0) -> str:
    """``value`` (times ``scale``) formatted by ``fmt``, or ``-`` when it is missing or not a number."""
    try:
        return format(scale * float(value), fmt)
    except (TypeError, ValueError):
        return "-"


def key_numbers(d: SheetData) -> list[str]:
    """Lines of the fit's and the CFD's main numbers (what a reviewer checks first); ``-`` for a
    number a failed stage did not produce."""
    rep, st = d.report or {}, d.status or {}
    lines = []
    if rep and not rep.get("failed"):
        lines += [
            f"fit quality       {rep.get('quality', '-')}",
            f"L, K, R           {rep.get('L', '-')}, {rep.get('K', '-')}, {rep.get('R', '-')}",
            f"centerline        {_num(rep.get('centerline_length_mm'), '.1f')} mm",
            f"median radius     {_num(rep.get('median_radius_mm'), '.2f')} mm",
            f"residual mean     {_num(rep.get('residual_mean_mm'), '.3f')} mm",
            f"residual max      {_num(rep.get('residual_max_mm'), '.3f')} mm",
            f"points used       {_num(rep.get('fraction_points_used'), '.1f', 100.0)} %",
        ]
    if st:
        dp = st.get("inlet_minus_outlet_pressure")
        lines += [
            "",
            f"cells             {_num(st.get('cells'), ',.0f')}",
            f"criterion         {st.get('criterion_used') or '-'}",
            f"iterations        {_num(st.get('iterations'), '.0f')}",
            f"mass imbalance    {_num(st.get('mass_imbalance'), '.2e')}",
            f"p(in) - p(out)    {_num(dp.get('Pa') if isinstance(dp, dict) else None, '.4g')} Pa",
        ]
        for k, v in sorted((st.get("final_residuals") or {}).items()):
            lines.append(f"final residual {k:<3}{_num(v, '.2e')}")
    return lines


PANELS: tuple[tuple[str, Callable[[Axes, SheetData], None]], ...] = (
    ("fit_overlay", panel_fit_overlay),
    ("residual_surface", panel_residual_surface),
    ("residual_map", panel_residual_map),
    ("mesh_slice", panel_mesh_slice),
    ("mesh_wall", panel_mesh_wall),
    ("residual_history", panel_residual_history),
    ("velocity", panel_velocity),
    ("wss", panel_wss),
    ("verdict", panel_verdict),
)


def _say_instead(ax: Axes, text: str, colour: str = "#555555") -> None:
    ax.cla()
    ax.set_axis_off()
    ax.set_facecolor("#f4f4f4")
    ax.text(
        0.5, 0.5, textwrap.fill(text, 40), ha="center", va="center", color=colour, fontsize=10, transform=ax.transAxes
    )


def write_qc_sheet(files: PatientFiles, path: Path | str) -> dict[str, str]:
    """Draw the patient's QC sheet (one PNG of the nine panels in this module's docstring).

    Parameters
    ----------
    files : PatientFiles
        The patient's input mesh, fit directory, case directory, ``status.json`` and
        ``fields.json`` (any may be missing or hold a failure record).
    path : Path or str
        The PNG to write (written whole: a temporary file renamed into place).

    Returns
    -------
    dict of str -> str
        Each panel's name and ``"drawn"``, or why it is not (``"not available: ..."``,
        ``"could not draw: ..."``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = read_sheet_data(files)
    fig, axes = plt.subplots(3, 3, figsize=SHEET_INCHES, dpi=SHEET_DPI)
    for ax, (name, draw) in zip(axes.ravel(), PANELS, strict=True):
        ax.set_axis_off()
        try:
            draw(ax, d)
            d.drawn[name] = "drawn"
        except PanelUnavailable as e:
            d.drawn[name] = f"not available: {e}"
            _say_instead(ax, f"not available: {e}")
        except Exception as e:  # noqa: BLE001 - a QC panel never fails the run; the log has the reason
            log.warning("qc %s: panel %s could not be drawn", files.patient, name, exc_info=True)
            d.drawn[name] = f"could not draw: {type(e).__name__}: {e}"
            _say_instead(ax, f"could not draw: {type(e).__name__}: {e}", FAILED_COLOUR)
        if name in ("residual_map", "residual_history") and d.drawn[name] == "drawn":
            ax.set_axis_on()
    usable, line = d.verdict
    fig.suptitle(
        f"{files.patient}: {'in the atlas' if usable else 'NOT in the atlas'} - {textwrap.shorten(line, 150)}",
        color="black" if usable else FAILED_COLOUR,
        fontsize=14,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.97))
    out = Path(path)
    tmp = out.with_name(f".{out.stem}.tmp.png")
    fig.savefig(tmp, dpi=SHEET_DPI)
    plt.close(fig)
    tmp.replace(out)
    return dict(d.drawn)
