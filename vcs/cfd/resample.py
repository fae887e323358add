"""Resample a finished OpenFOAM case onto the vessel's regular (tau, theta, rho_n) grid.

The measurement grid of a patient (paper Section 2.4.2: every vessel gets the same number of
samples at VCS-corresponding places): tau in [0, 1] (``n_tau`` values, both ends included),
theta = 2 pi j / n_theta, rho_n in [0, 1] (``n_rho`` values, axis and wall included), at

    x(tau, theta, rho_n) = c(tau) + rho_n rho_w(tau, theta) (v1 cos theta + v2 sin theta)   (Eq. 8 scaled)

U and p are interpolated inside the lumen by quadratic moving least squares on the cell centres and
boundary-face centres (:func:`mls_interpolate`; the VTK probe of the reader's cell-to-point data is
available as ``method="probe"`` but flattens a Poiseuille peak by ~3 % at 8 cells per radius); WSS
is interpolated on the ``wall`` patch (barycentric, point data) at the point closest to each wall
grid point (rho_n = 1). Points outside the CFD mesh (a VTK probe decides; the Eq. 8 wall and the
snapped mesh wall differ by a fraction of a cell) are handled explicitly and counted:

* rho_n = 1: U = 0 (no-slip; always, inside or not); p interpolated (MLS includes the wall faces);
* rho_n < 1: U and p from the nearest cell centre (distance reported).

Vector fields are stored twice: Cartesian (``U``, ``WSS``, as in the case) and in the local VCS
frame (``U_vcs``, ``WSS_vcs``: components along t(tau), e_theta = -v1 sin theta + v2 cos theta,
e_rho = v1 cos theta + v2 sin theta), which are invariant to rigid motions and are what the atlas
compares across patients.

Ostia. A case run on the patient's own lumen (``cfd.geometry: surface``) has side branches the
single-branch model wall bridges over: at an ostium the closest CFD wall point of a wall grid
point lies on the ostium's rim or down the branch, and its WSS is not the section's. Such wall
grid points are marked ``ostium`` (:func:`ostium_mask`, criterion :data:`OSTIUM_CRITERION`) and
their wall values (WSS, WSS_vcs, WSS_kinematic, TAWSS, OSI, hence RRT and ECAP, and every phase's
WSS) are NaN, never a number taken from the branch. A wall point is at an ostium when

* its closest CFD wall point is farther than :data:`OSTIUM_GAP` = 0.15 rho_w(tau, theta) (on the
  model wall that distance is a fraction of a cell; on the patient's own surface it is the fit
  residual: at most 0.12 rho_w, 99.5 % below 0.08 rho_w on the branch-free real aortas), or
* the CFD wall's normal there makes more than 60 degrees with the model wall's normal
  (:data:`OSTIUM_NORMAL_COS` = cos 60 deg; at least 0.79 on the branch-free real aortas, about 0
  on a branch's wall: this catches the points near the rim whose closest point is up the
  branch); not on the end rows tau = 0, 1, where the wall patch meets the inlet or outlet.

U (no-slip: 0), p and the interior (rho_n < 1) samples are not masked. A lumen without branches
gets no mask. The mask, the distance (``wall_gap``, in rho_w) and the normals' cosine
(``wall_normal_cos``) are in fields.npz, the count in its summary (:func:`summary`); the atlas
leaves the masked cells out of every wall field's PCA (:mod:`vcs.atlas.cohort`).

A time-averaged case (the transient fallback of :func:`vcs.cfd.run.run_case`) is sampled from
its means (UMean, pMean, wallShearStressMean) under the same names U, p, WSS, plus TAWSS and OSI
on the wall (:func:`read_case`).

The grid itself is :mod:`vcs.grid`; this module reads the case (pyvista's POpenFOAMReader).
"""

from __future__ import annotations

import json
import logging
import time as _time
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from vcs.cfd.foamfiles import oscillatory_shear_index
from vcs.errors import VCSInputError
from vcs.grid import GRID_DEFAULTS, grid_axes, grid_points, grid_to_vtk, local_frame, to_vcs_components
from vcs.mesh import vertex_normals

if TYPE_CHECKING:
    import pyvista as pv

    from vcs.vessel import VesselModel

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------------
# Reading a case
# ---------------------------------------------------------------------------------------------
# The time-averaged fields of vcs.cfd.transient's fallback (fieldAverage) and the names they
# are sampled under, so that fields.npz keeps U, p, WSS whatever the case was.
TIME_AVERAGED = {"U": "UMean", "p": "pMean", "wallShearStress": "wallShearStressMean"}
TAWSS_FIELD = "magWallShearStressMean"  # time average of |WSS| (TAWSS)
FIELD_SOURCES = ("auto", "time_average", "instantaneous")


def read_case(
    case_dir: Path | str, *, time: float | None = None, wall_patch: str = "wall", fields: str = "auto"
) -> tuple[pv.UnstructuredGrid, dict[str, pv.PolyData], float]:
    """Internal mesh and boundary patches of a reconstructed OpenFOAM case at the last (or given) time.

    Read with pyvista's POpenFOAMReader (a ``case.foam`` marker file is created when missing),
    with cell and point (cell-to-point) data, in the case's units (metres). A time-averaged case
    (the transient fallback of :func:`vcs.cfd.run.run_case`) holds ``UMean``, ``pMean`` and
    ``wallShearStressMean`` next to the instantaneous fields: they are then copied under the
    names ``U``, ``p`` and ``wallShearStress``, and the wall also gets ``TAWSS`` (time average of
    |WSS|) and ``OSI`` (oscillatory shear index) when ``magWallShearStressMean`` exists. Which
    fields were used is in ``internal.field_data["field_source"]`` (``"time_average"`` or
    ``"instantaneous"``).

    Parameters
    ----------
    case_dir : Path or str
        Reconstructed OpenFOAM case.
    time : float or None
        Time to read (the nearest written one); None: the last.
    wall_patch : str
        Name of the wall patch, which must exist (it is triangulated).
    fields : {"auto", "time_average", "instantaneous"}
        ``"auto"``: the time averages when UMean, pMean and the wall's wallShearStressMean are
        all there, else the instantaneous fields; the other two force a choice.

    Returns
    -------
    internal : pyvista.UnstructuredGrid
        The internal mesh with ``U`` (m/s) and ``p`` (kinematic, m^2/s^2).
    patches : dict of str -> pyvista.PolyData
        Non-empty boundary patches by name.
    time : float
        The time read.

    Raises
    ------
    VCSInputError
        When ``case_dir`` is not a case, has no time with fields, lacks the wall patch, U or p,
        or the time averages asked for; for an unknown ``fields``.
    """
    import pyvista as pv

    if fields not in FIELD_SOURCES:
        raise VCSInputError(f"fields must be one of {', '.join(FIELD_SOURCES)}, not {fields!r}")
    case = Path(case_dir)
    if not (case / "system" / "controlDict").is_file():
        raise VCSInputError(f"'{case}' is not an OpenFOAM case (no system/controlDict)")
    foam = case / "case.foam"
    if not foam.exists():
        foam.touch()
    reader = pv.POpenFOAMReader(str(foam))
    reader.case_type = "reconstructed"
    times = list(reader.time_values)
    if not times:
        raise VCSInputError(f"'{case}' has no time directory with fields; run the solver (and reconstructPar) first")
    t = times[-1] if time is None else min(times, key=lambda v: abs(v - time))
    reader.set_active_time_value(t)
    reader.cell_to_point_creation = True
    reader.enable_all_patch_arrays()
    mb = reader.read()
    # the reader's MultiBlock: pyvista types its items as any dataset or None
    internal = cast("pv.UnstructuredGrid", mb["internalMesh"])
    boundary = cast("pv.MultiBlock | None", mb["boundary"])
    names = list(boundary.keys()) if boundary is not None else []
    if wall_patch not in names:
        raise VCSInputError(f"case '{case}' has no '{wall_patch}' patch (patches: {names})")
    patches = {}
    for name in names:
        # names is empty when boundary is None, which mypy cannot see
        b = cast("pv.DataSet | None", boundary[name])  # type: ignore[index]
        if b is None or b.n_cells == 0:
            continue
        if not isinstance(b, pv.PolyData):
            b = b.extract_surface(algorithm="dataset_surface")
        patches[name] = b.triangulate() if name == wall_patch else b
    wall = patches.get(wall_patch)
    have_means = (
        all(TIME_AVERAGED[k] in internal.cell_data for k in ("U", "p"))
        and wall is not None
        and TIME_AVERAGED["wallShearStress"] in wall.cell_data
    )
    if fields == "time_average" and not have_means:
        raise VCSInputError(
            f"case '{case}' time {t:g} has no time-averaged fields (UMean, pMean, wallShearStressMean); "
            "it was not run with the transient fallback"
        )
    use_means = have_means and fields != "instantaneous"
    if use_means:
        for ds in [internal, *patches.values()]:
            for base, mean in TIME_AVERAGED.items():
                for data in (ds.cell_data, ds.point_data):
                    if mean in data:
                        data[base] = np.asarray(data[mean])
        if wall is not None and TAWSS_FIELD in wall.cell_data:
            for data in (wall.cell_data, wall.point_data):
                if TAWSS_FIELD in data and "wallShearStress" in data:
                    tawss = np.asarray(data[TAWSS_FIELD], float)
                    data["TAWSS"] = tawss
                    data["OSI"] = oscillatory_shear_index(np.asarray(data["wallShearStress"], float), tawss)
    for name in ("U", "p"):
        if name not in internal.cell_data:
            raise VCSInputError(f"case '{case}' time {t:g} has no field '{name}'")
    internal.field_data["field_source"] = np.array(["time_average" if use_means else "instantaneous"])
    return internal, patches, float(t)


# ---------------------------------------------------------------------------------------------
# Sampling
# ---------------------------------------------------------------------------------------------
def _closest_on_surface(
    surface: pv.PolyData,
    points: NDArray[np.floating],
) -> tuple[NDArray[np.integer], NDArray[Any], NDArray[np.floating], NDArray[np.floating]]:
    """Closest cell and barycentric weights of the closest point on a triangulated surface.

    Returns (cell (P,), its corner point ids (P, 3), barycentric weights (P, 3), distance (P,)).
    """
    import vtk

    loc = vtk.vtkStaticCellLocator()
    loc.SetDataSet(surface)
    loc.BuildLocator()
    cell = np.empty(len(points), np.int64)
    closest = np.empty((len(points), 3))
    dist = np.empty(len(points))
    cp = [0.0, 0.0, 0.0]
    cid, sub, d2 = vtk.reference(0), vtk.reference(0), vtk.reference(0.0)
    for i, p in enumerate(points):
        loc.FindClosestPoint(p, cp, cid, sub, d2)
        cell[i], closest[i], dist[i] = int(cid), cp, np.sqrt(float(d2))
    tri = surface.regular_faces[cell]
    a, b, c = (surface.points[tri[:, k]] for k in range(3))
    v0, v1, v2 = b - a, c - a, closest - a
    d00, d01, d11 = (np.einsum("ij,ij->i", x, y) for x, y in ((v0, v0), (v0, v1), (v1, v1)))
    d20, d21 = np.einsum("ij,ij->i", v2, v0), np.einsum("ij,ij->i", v2, v1)
    den = np.where(np.abs(d00 * d11 - d01**2) > 0, d00 * d11 - d01**2, 1.0)
    w1 = (d11 * d20 - d01 * d21) / den
    w2 = (d00 * d21 - d01 * d20) / den
    w = np.clip(np.column_stack([1 - w1 - w2, w1, w2]), 0, 1)
    w /= w.sum(axis=1, keepdims=True)
    return cell, tri, w, dist


def mls_interpolate(
    points: np.ndarray,
    data_points: np.ndarray,
    values: np.ndarray,
    *,
    k: int = 27,
    quadratic_penalty: float = 1e-3,
    tree: cKDTree | None = None,
) -> np.ndarray:
    """Quadratic moving-least-squares interpolation of scattered values (cell centres, face centres).

    For each point: Gaussian-weighted least-squares fit of a quadratic in x (10 coefficients) to the
    ``k`` nearest data values, evaluated at the point. Exact for quadratic fields (a Poiseuille
    profile), second order otherwise, no cell-to-point averaging (which flattens the profile's peak
    by ~2 % on 8 cells per radius). Results are clipped to the neighbours' range widened by half of
    it on both sides (no overshoot where the data are one-sided). The quadratic coefficients carry a
    small ridge penalty (``quadratic_penalty`` times the mean diagonal of the normal matrix; the
    linear ones 1e-6 of it): where the neighbours do not determine the curvature (one layer of
    flat cells, prism layers) the fit falls back smoothly to a linear one instead of oscillating.

    Parameters
    ----------
    points : (N, 3) float
        Where to interpolate (any length unit, the same as ``data_points``).
    data_points : (M, 3) float
        Where the values are known (cell and face centres).
    values : (M,) or (M, c) float
        Data values (any unit).
    k : int
        Number of nearest data points per fit (>= 10).
    quadratic_penalty : float
        Ridge weight of the quadratic coefficients, relative to the mean diagonal (dimensionless).
    tree : scipy.spatial.cKDTree or None
        A tree of ``data_points`` to reuse; None builds one.

    Returns
    -------
    (N,) or (N, c) float
        Interpolated values, in the unit of ``values``.
    """
    tree = tree or cKDTree(data_points)
    squeeze = values.ndim == 1
    V = values.reshape(len(values), -1)
    out = np.empty((len(points), V.shape[1]))
    penalty = np.diag([1e-9] + [1e-6] * 3 + [quadratic_penalty] * 6)
    for a in range(0, len(points), 20000):  # chunks bound the memory to ~100 MB
        P = points[a : a + 20000]
        d, j = tree.query(P, k=k, workers=-1)
        h = d[:, -1:] + 1e-300
        Y = (data_points[j] - P[:, None, :]) / h[..., None]
        B = np.stack(
            [np.ones(Y.shape[:2]), Y[..., 0], Y[..., 1], Y[..., 2]]
            + [Y[..., p] * Y[..., q] for p in range(3) for q in range(p, 3)],
            axis=-1,
        )
        w = np.exp(-2.0 * (d / h) ** 2)
        BtW = B.transpose(0, 2, 1) * w[:, None, :]
        A = BtW @ B
        A += (np.trace(A, axis1=1, axis2=2) / A.shape[1])[:, None, None] * penalty
        Vn = V[j]
        c = np.linalg.solve(A, BtW @ Vn)[:, 0]
        lo, hi = Vn.min(axis=1), Vn.max(axis=1)
        out[a : a + 20000] = np.clip(c, lo - 0.5 * (hi - lo), hi + 0.5 * (hi - lo))
    return out[:, 0] if squeeze else out


# ---------------------------------------------------------------------------------------------
# The wall: WSS and markers at the wall grid points, ostia masked
# ---------------------------------------------------------------------------------------------
#: A wall grid point is at an ostium when its closest CFD wall point is farther than this many
#: rho_w(tau, theta). Branch-free real aortas fitted with the defaults (vmtk closed segment,
#: SimVascular segment; grids 64 x 32 and 128 x 64): at most 0.12 (99.5 % below 0.08); a
#: snapped OpenFOAM model tube: < 0.03 (4 and 8 cells per radius). Inside an ostium
#: the distance grows to the branch radius (0.3-0.7 rho_w on AortaCFD patient1, VMR 0154, the
#: vmtk bifurcation), so only a band of 0.15 rho_w (under one cell of the default 64 x 32 grid on
#: an aorta, 2 pi / 32 = 0.2 rho_w) along the rim is left to the normal criterion. With both
#: criteria 2.1-2.3 % of the wall grid of those three is marked (64 x 32 and 128 x 64), none of
#: the branch-free two (a config-free default: the thresholds are relative to rho_w and the
#: normal, not to the mesh or the grid).
OSTIUM_GAP = 0.15
#: ... or when |n_cfd . n_model| < this (the CFD wall at the closest point turned by more than
#: 60 degrees from the model wall): on the branch-free real aortas the cosine is at least 0.79
#: (a snapped OpenFOAM model tube: 0.99 away from its ends), on a branch's wall about 0; it marks
#: the points near the rim whose closest point lies up the branch wall (where a curved main wall
#: meets the branch, at the ostium's sides: on a tube with a perpendicular branch the distance
#: alone lets branch values reach points 0.1 rho_w from the rim).
OSTIUM_NORMAL_COS = 0.5
#: The criterion in words (fields.npz ``ostium_criterion``, the summary, the atlas).
OSTIUM_CRITERION = (
    "a wall grid point (rho_n = 1) is at an ostium when its closest CFD wall point is farther than "
    "{gap:g} rho_w(tau, theta), or (0 < tau < 1) the CFD wall's normal there and the model wall's "
    "normal have |cos| < {cos:g}; its wall values (WSS, TAWSS, OSI, RRT, ECAP, phase WSS) are NaN"
)


def model_wall_normals(
    model: VesselModel, tau: NDArray[np.floating], theta: NDArray[np.floating]
) -> NDArray[np.floating]:
    """Unit normals of the Eq. 8 wall x(tau, theta) on a (tau, theta) grid, by central differences.

    Parameters
    ----------
    model : VesselModel
        With a wall model (mm).
    tau : (n_tau,) float
        In [0, 1] (one-sided differences at the ends).
    theta : (n_theta,) float, rad

    Returns
    -------
    (n_tau, n_theta, 3) float
        Unit normals (orientation: dx/dtau x dx/dtheta, outward for a right-handed frame).
    """
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    h = 1e-5
    dt = model.surface_points(np.clip(T + h, 0, 1), TH) - model.surface_points(np.clip(T - h, 0, 1), TH)
    dth = model.surface_points(T, TH + h) - model.surface_points(T, TH - h)
    n = np.cross(dt, dth)
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)


def ostium_mask(
    gap: NDArray[np.floating],
    normal_cos: NDArray[np.floating],
    *,
    max_gap: float = OSTIUM_GAP,
    min_normal_cos: float = OSTIUM_NORMAL_COS,
) -> NDArray[np.bool_]:
    """Wall grid points at an ostium (:data:`OSTIUM_CRITERION`).

    The normal criterion is not applied on the end rows (tau = 0 and 1): there the wall patch
    ends at the inlet or outlet patch, whose snapped rim faces can be turned by more than 60
    degrees (|cos| 0.48 at one point of the outlet rim of a snapped model tube, 8 cells per
    radius, gap 0.002 rho_w); a branch cannot leave through an end plane.

    Parameters
    ----------
    gap : (n_tau, n_theta) float
        Distance from each model wall point to its closest CFD wall point, in rho_w(tau, theta).
    normal_cos : (n_tau, n_theta) float
        |n_cfd . n_model|: the CFD wall's unit normal there (interpolated vertex normals) against
        the model wall's (:func:`model_wall_normals`).
    max_gap : float
        :data:`OSTIUM_GAP` (in rho_w).
    min_normal_cos : float
        :data:`OSTIUM_NORMAL_COS`.

    Returns
    -------
    (n_tau, n_theta) bool
        True at an ostium.
    """
    turned = np.asarray(normal_cos) < min_normal_cos
    turned[[0, -1]] = False
    return (np.asarray(gap) > max_gap) | turned


def _sample_wall(
    wall: pv.PolyData,
    model: VesselModel,
    tau: NDArray[np.floating],
    theta: NDArray[np.floating],
    points: NDArray[np.floating],
    rho_w: NDArray[np.floating],
    frame: NDArray[np.floating],
    *,
    rho_density: float,
    wss_name: str,
    gap: float,
    normal_cos: float,
) -> dict[str, Any]:
    """WSS (and TAWSS, OSI of a time-averaged case) at the wall grid points ``points``
    (n_tau, n_theta, 3, case units) from their closest points on the wall patch, NaN at an ostium
    (:func:`ostium_mask`; ``rho_w`` (n_tau, n_theta) in case units); the mask and its counts."""
    n_tau, n_theta = points.shape[:2]
    cell, tri, w, dist = _closest_on_surface(wall, points.reshape(-1, 3))
    pts, faces = np.asarray(wall.points, float), np.asarray(wall.regular_faces)
    n_cfd = np.einsum("ik,ikj->ij", w, vertex_normals(pts, faces)[tri]).reshape(n_tau, n_theta, 3)
    n_cfd /= np.maximum(np.linalg.norm(n_cfd, axis=-1, keepdims=True), 1e-300)
    cos = np.abs(np.einsum("ijk,ijk->ij", n_cfd, model_wall_normals(model, tau, theta)))
    rel = dist.reshape(n_tau, n_theta) / rho_w
    mask = ostium_mask(rel, cos, max_gap=gap, min_normal_cos=normal_cos)

    def interpolate(name: str) -> NDArray[np.floating] | None:
        if name in wall.point_data:
            v = np.asarray(wall.point_data[name], float)
            v = np.einsum("ik,ik...->i...", w, v[tri])
        elif name in wall.cell_data:
            v = np.asarray(wall.cell_data[name], float)[cell]
        else:
            return None
        v = v.reshape(n_tau, n_theta, *v.shape[1:])
        v[mask] = np.nan
        return v

    wss = interpolate(wss_name)
    if wss is None:
        raise VCSInputError(f"the wall patch has no '{wss_name}' field; run the wallShearStress function object")
    kept = rel[~mask]
    out: dict[str, Any] = {
        "WSS": wss * rho_density,
        "WSS_kinematic": wss,
        "WSS_vcs": to_vcs_components(wss, frame) * rho_density,
        "wall_distance_max": np.float64(dist.max()),
        "wall_distance_mean": np.float64(dist.mean()),
        "ostium": mask,
        "wall_gap": rel,
        "wall_normal_cos": cos,
        "n_ostium": np.int64(mask.sum()),
        "ostium_fraction": np.float64(mask.mean()),
        "ostium_criterion": np.str_(OSTIUM_CRITERION.format(gap=gap, cos=normal_cos)),
        "wall_gap_max_kept": np.float64(kept.max() if kept.size else np.nan),
    }
    # time-averaged cases: TAWSS (Pa) and OSI (dimensionless) on the wall grid, like WSS
    for name, scale in (("TAWSS", rho_density), ("OSI", 1.0)):
        v = interpolate(name)
        if v is not None:
            out[name] = v * scale
    if mask.any():
        log.info(
            "%d of %d wall grid points at an ostium (closest CFD wall point > %g rho_w away: %d; "
            "its normal > %.0f deg from the model wall's: %d): their wall values are NaN",
            mask.sum(),
            mask.size,
            gap,
            (rel > gap).sum(),
            np.degrees(np.arccos(np.clip(normal_cos, 0, 1))),
            (cos[1:-1] < normal_cos).sum(),
        )
    if mask.mean() > 0.2:
        log.warning(
            "%.1f%% of the wall grid points are at an ostium: does the model belong to this case?", 100 * mask.mean()
        )
    return out


def _sample_volume(
    internal: pv.DataSet,
    patches: dict[str, pv.PolyData],
    P: NDArray[np.floating],
    on_wall: NDArray[np.bool_],
    method: str,
) -> tuple[NDArray[np.floating], NDArray[np.floating], dict[str, Any]]:
    """U (N, 3) and p (N,) at the grid points ``P`` (case units) and the counts of the points
    outside the CFD mesh: no-slip (U = 0) on the wall (``on_wall``), nearest cell inside."""
    import pyvista as pv

    probe = pv.PolyData(P).sample(internal, pass_cell_data=False, pass_point_data=False)
    missing = ~np.asarray(probe.point_data["vtkValidPointMask"]).astype(bool)
    centres = np.asarray(internal.cell_centers().points)
    cell_U = np.asarray(internal.cell_data["U"], float)
    cell_p = np.asarray(internal.cell_data["p"], float)
    if method == "probe":
        U = np.asarray(probe.point_data["U"], float).copy()
        p = np.asarray(probe.point_data["p"], float).copy()
    else:
        Xs, VU, Vp = [centres], [cell_U], [cell_p]
        for b in patches.values():
            if "U" in b.cell_data and "p" in b.cell_data:
                Xs.append(np.asarray(b.cell_centers().points))
                VU.append(np.asarray(b.cell_data["U"], float))
                Vp.append(np.asarray(b.cell_data["p"], float))
        X = np.concatenate(Xs)
        vals = mls_interpolate(P, X, np.column_stack([np.concatenate(VU), np.concatenate(Vp)]))
        U, p = vals[:, :3], vals[:, 3]
    # points outside the CFD mesh: no-slip on the wall, nearest cell inside the lumen
    interior_missing = missing & ~on_wall
    d, j = cKDTree(centres).query(P[interior_missing], workers=-1)
    U[interior_missing] = cell_U[j]
    p[interior_missing] = cell_p[j]
    if method == "probe":
        wall_missing = missing & on_wall
        p[wall_missing] = cell_p[cKDTree(centres).query(P[wall_missing], workers=-1)[1]]
    U[on_wall] = 0.0
    counts = {
        "n_outside_mesh": np.int64(missing.sum()),
        "n_wall_noslip": np.int64(on_wall.sum()),
        "n_wall_outside_mesh": np.int64((missing & on_wall).sum()),
        "n_interior_nearest": np.int64(interior_missing.sum()),
        "interior_nearest_max_distance": np.float64(d.max() if d.size else 0.0),
    }
    return U, p, counts


def sample_mesh(
    internal: pv.DataSet,
    patches: dict[str, pv.PolyData],
    model: VesselModel,
    *,
    n_tau: int = GRID_DEFAULTS["n_tau"],
    n_theta: int = GRID_DEFAULTS["n_theta"],
    n_rho: int = GRID_DEFAULTS["n_rho"],
    rho_scale: float = 1e-3,
    rho_density: float = 1060.0,
    method: str = "mls",
    wall_patch: str = "wall",
    wss_name: str = "wallShearStress",
    ostium_gap: float = OSTIUM_GAP,
    ostium_normal_cos: float = OSTIUM_NORMAL_COS,
) -> dict[str, Any]:
    """Sample U, p (internal mesh) and WSS (wall patch) on the model's grid; see the module doc.

    Parameters
    ----------
    internal : pyvista.DataSet
        Internal mesh with cell arrays ``U`` (m/s) and ``p`` (kinematic, m^2/s^2) (and the same as
        point arrays for ``method="probe"``).
    patches : dict of str -> pyvista.PolyData
        Boundary patches with face (cell) values of U and p where known (used as data by
        ``"mls"``); ``patches[wall_patch]`` (triangles) carries ``wallShearStress`` (kinematic,
        m^2/s^2) as point or cell data. Without a wall patch WSS is skipped.
    model : VesselModel
        The vessel (mm) with a wall model.
    n_tau, n_theta, n_rho : int
        Grid node counts, see :func:`vcs.grid.grid_axes`.
    rho_scale : float
        Case length unit per mm (1e-3: the case is in metres).
    rho_density : float, kg/m^3
        Fluid density, to convert the kinematic p and WSS to Pa.
    method : {"mls", "probe"}
        ``"mls"`` (default): quadratic moving least squares on cell and boundary-face centres
        (:func:`mls_interpolate`); ``"probe"``: VTK probe of the cell-to-point data (trilinear in
        the containing cell; flattens peaks by a few % on coarse meshes).
    wall_patch : str
        Name of the wall patch in ``patches``.
    wss_name : str
        Name of the wall-shear-stress array on the wall patch.
    ostium_gap, ostium_normal_cos : float
        Thresholds of :func:`ostium_mask` (defaults :data:`OSTIUM_GAP`, :data:`OSTIUM_NORMAL_COS`;
        ``inf`` and 0 mark nothing).

    Returns
    -------
    dict of str -> array
        The content of fields.npz, see :func:`sample_case` (without ``time``, ``read_time_s``,
        ``n_cells``).

    Raises
    ------
    VCSInputError
        For an unknown method, a model without a wall model, or a wall patch without WSS.
    """
    if method not in ("mls", "probe"):
        raise VCSInputError(f"method must be 'mls' or 'probe', not {method!r}")
    t0 = _time.perf_counter()
    ostium = {"gap": ostium_gap, "normal_cos": ostium_normal_cos}
    tau, theta, rho_n = grid_axes(n_tau, n_theta, n_rho)
    pts_mm, rho_w = grid_points(model, tau, theta, rho_n)
    shape = pts_mm.shape[:3]
    P = pts_mm.reshape(-1, 3) * rho_scale
    on_wall = np.broadcast_to(rho_n == 1.0, shape).ravel()

    U, p, counts = _sample_volume(internal, patches, P, on_wall, method)
    t_probe = _time.perf_counter()

    U = U.reshape(*shape, 3)
    p = p.reshape(shape)
    frame = local_frame(model, tau, theta)
    out = {
        "tau": tau,
        "theta": theta,
        "rho_n": rho_n,
        "rho_w_mm": rho_w,
        "points": P.reshape(*shape, 3),
        "U": U,
        "U_vcs": to_vcs_components(U, frame),
        "p": p * rho_density,
        "p_kinematic": p,
        "n_tau": np.int64(n_tau),
        "n_theta": np.int64(n_theta),
        "n_rho": np.int64(n_rho),
        "rho_scale": np.float64(rho_scale),
        "rho_density": np.float64(rho_density),
        "n_points": np.int64(P.shape[0]),
        **counts,
    }
    wall = patches.get(wall_patch)
    if wall is not None:
        Pw = (
            P.reshape(*shape, 3)[:, :, -1]
            if rho_n[-1] == 1.0
            else model.surface_points(*np.meshgrid(tau, theta, indexing="ij")) * rho_scale
        )
        out.update(
            _sample_wall(
                wall,
                model,
                tau,
                theta,
                Pw,
                rho_w * rho_scale,
                frame,
                rho_density=rho_density,
                wss_name=wss_name,
                **ostium,
            )
        )
    source = internal.field_data["field_source"] if "field_source" in internal.field_data else None
    out["field_source"] = np.str_(source[0] if source is not None and len(source) else "instantaneous")
    out["method"] = np.str_(method)
    out["sample_time_s"] = np.float64(_time.perf_counter() - t0)
    out["interpolation_time_s"] = np.float64(t_probe - t0)
    log.info(
        "sampled %d points: %d outside the CFD mesh (%d on the wall, %d interior -> nearest cell, max %.3g)",
        P.shape[0],
        counts["n_outside_mesh"],
        counts["n_wall_outside_mesh"],
        counts["n_interior_nearest"],
        counts["interior_nearest_max_distance"],
    )
    if counts["n_interior_nearest"] > 0.05 * (~on_wall).sum():
        log.warning(
            "%.1f%% of the interior grid points are outside the CFD mesh: do the model and the case match?",
            100 * counts["n_interior_nearest"] / (~on_wall).sum(),
        )
    return out


def sample_case(
    case_dir: Path | str,
    model: VesselModel,
    *,
    n_tau: int = GRID_DEFAULTS["n_tau"],
    n_theta: int = GRID_DEFAULTS["n_theta"],
    n_rho: int = GRID_DEFAULTS["n_rho"],
    rho_scale: float = 1e-3,
    rho_density: float = 1060.0,
    time: float | None = None,
    method: str = "mls",
    fields: str = "auto",
) -> dict[str, Any]:
    """Sample a finished OpenFOAM case on the patient's (tau, theta, rho_n) grid (Section 2.4.2).

    Parameters
    ----------
    case_dir : Path or str
        Reconstructed case (metres) with U, p, wallShearStress at the last time.
    model : VesselModel
        The vessel (mm) whose Eq. 8 wall the case was built from.
    n_tau, n_theta, n_rho : int
        Grid node counts; the same for every patient of an atlas.
    rho_scale : float
        Case length units per mm (1e-3 for a case in metres).
    rho_density : float, kg/m^3
        Fluid density (kinematic p and WSS -> Pa).
    time : float or None
        Time to read (the nearest written one); None: the last.
    method : {"mls", "probe"}
        Interpolation of U and p, see :func:`sample_mesh`.
    fields : {"auto", "time_average", "instantaneous"}
        Which fields to sample, see :func:`read_case` (``"auto"``: the time averages of a
        transient case, else the instantaneous fields). The names in the result stay U, p, WSS.

    Returns
    -------
    dict of arrays:
        tau (n_tau,), theta (n_theta,), rho_n (n_rho,), rho_w_mm (n_tau, n_theta),
        points (n_tau, n_theta, n_rho, 3) case units,
        U, U_vcs (n_tau, n_theta, n_rho, 3) m/s, p, p_kinematic (n_tau, n_theta, n_rho) Pa, m2/s2,
        WSS, WSS_vcs (n_tau, n_theta, 3) Pa, WSS_kinematic; for a time-averaged case also
        TAWSS (n_tau, n_theta) Pa (time average of |WSS|; WSS is the time-averaged vector) and
        OSI (n_tau, n_theta, dimensionless, 0..0.5); field_source ("time_average" or
        "instantaneous"),
        ostium (n_tau, n_theta) bool (wall grid points at a side branch's ostium, whose wall
        values are NaN; :func:`ostium_mask`), wall_gap (n_tau, n_theta, the distance to the
        closest CFD wall point in rho_w), wall_normal_cos (n_tau, n_theta), ostium_criterion (str),
        counts: n_points, n_outside_mesh, n_wall_noslip, n_wall_outside_mesh, n_interior_nearest,
        interior_nearest_max_distance (case units), wall_distance_max/mean (case units, over all
        wall points), n_ostium, ostium_fraction, wall_gap_max_kept (the largest wall_gap outside
        the ostia: the fit residual where the case is the patient's own surface), time, timings.
    """
    t0 = _time.perf_counter()
    internal, patches, t = read_case(case_dir, time=time, fields=fields)
    t_read = _time.perf_counter()
    out = sample_mesh(
        internal,
        patches,
        model,
        n_tau=n_tau,
        n_theta=n_theta,
        n_rho=n_rho,
        rho_scale=rho_scale,
        rho_density=rho_density,
        method=method,
    )
    out["time"] = np.float64(t)
    out["read_time_s"] = np.float64(t_read - t0)
    out["n_cells"] = np.int64(internal.n_cells)
    return out


def _read_kept_means(case: Path, mean_times: list[str], wall_patch: str) -> tuple[Any, dict[str, Any]]:
    """The internal mesh and patches of a pulsatile case with U, p, wallShearStress and TAWSS the
    averages of the kept cycles' means (each cycle's end folder holds that cycle's means; cycles of
    equal length, so their average is the kept window's time average), OSI from those averages."""
    internal, patches, _ = read_case(case, time=float(mean_times[0]), wall_patch=wall_patch, fields="time_average")
    names = ("U", "p", "wallShearStress", "TAWSS")
    for t in mean_times[1:]:
        other_int, other_pat, _ = read_case(case, time=float(t), wall_patch=wall_patch, fields="time_average")
        for ds, ods in [(internal, other_int), *((patches[k], other_pat[k]) for k in patches if k in other_pat)]:
            for data, odata in ((ds.cell_data, ods.cell_data), (ds.point_data, ods.point_data)):
                for name in names:
                    if name in data and name in odata:
                        data[name] = np.asarray(data[name], float) + np.asarray(odata[name], float)
    n = len(mean_times)
    for ds in [internal, *patches.values()]:
        for data in (ds.cell_data, ds.point_data):
            for name in names:
                if name in data:
                    data[name] = np.asarray(data[name], float) / n
    wall = patches[wall_patch]
    for data in (wall.cell_data, wall.point_data):
        if "TAWSS" in data and "wallShearStress" in data:
            data["OSI"] = oscillatory_shear_index(np.asarray(data["wallShearStress"], float), np.asarray(data["TAWSS"]))
    return internal, patches


PHASE_KEYS = ("U", "U_vcs", "p", "p_kinematic", "WSS", "WSS_vcs", "WSS_kinematic")


def sample_pulsatile(
    case_dir: Path | str,
    model: VesselModel,
    pulsatile: dict[str, Any],
    *,
    n_tau: int = GRID_DEFAULTS["n_tau"],
    n_theta: int = GRID_DEFAULTS["n_theta"],
    n_rho: int = GRID_DEFAULTS["n_rho"],
    rho_scale: float = 1e-3,
    rho_density: float = 1060.0,
    method: str = "mls",
) -> dict[str, Any]:
    """Sample a pulsatile case (:func:`vcs.cfd.pulsatile.pulsatile_solve`) on the patient's grid:
    the time averages and wall markers over the kept cycles, and the phase fields.

    The kept cycles' means (fieldAverage, accumulated at every time step) are averaged, then
    sampled as a time-averaged case: U, p, WSS (the time-averaged vector) and, on the wall grid,
    TAWSS = (1/T) int |tau| dt and OSI = 0.5 (1 - |int tau dt| / int |tau| dt) (:func:`read_case`);
    from those RRT and ECAP (:func:`vcs.cfd.markers.rrt`, :func:`vcs.cfd.markers.ecap`). Every
    phase instant of the last cycle is sampled from its instantaneous fields under
    ``phase/<name>/<U|U_vcs|p|p_kinematic|WSS|WSS_vcs|WSS_kinematic>``.

    Parameters
    ----------
    case_dir : Path or str
        The reconstructed case.
    model : VesselModel
        The vessel (mm) the case was built from.
    pulsatile : dict
        ``status["pulsatile"]`` of the case (``mean_times``, ``phases``).
    n_tau, n_theta, n_rho, rho_scale, rho_density, method
        As for :func:`sample_case`.

    Returns
    -------
    dict of arrays
        As :func:`sample_case`, with ``field_source`` "pulsatile", ``TAWSS`` (Pa), ``OSI`` (1),
        ``RRT`` (1/Pa; inf where OSI = 0.5 or TAWSS = 0), ``ECAP`` (1/Pa) (n_tau, n_theta),
        ``phase_names`` and the phase fields, ``phase_times`` (s, in the solver's time),
        ``cycle_window`` (s, the kept cycles).
    """
    from vcs.cfd.markers import ecap, rrt

    t0 = _time.perf_counter()
    case = Path(case_dir)
    kw: dict[str, Any] = {
        "n_tau": n_tau,
        "n_theta": n_theta,
        "n_rho": n_rho,
        "rho_scale": rho_scale,
        "rho_density": rho_density,
    }
    internal, patches = _read_kept_means(case, list(pulsatile["mean_times"]), "wall")
    t_read = _time.perf_counter()
    out = sample_mesh(internal, patches, model, method=method, **kw)
    if "TAWSS" not in out or "OSI" not in out:
        raise VCSInputError(f"case '{case}': the kept cycles have no TAWSS/OSI on the wall (magWallShearStressMean)")
    out["RRT"] = rrt(out["TAWSS"], out["OSI"])
    out["ECAP"] = ecap(out["TAWSS"], out["OSI"])
    names = list(pulsatile.get("phases") or {})
    for name in names:
        ph = pulsatile["phases"][name]
        pi, pp, _ = read_case(case, time=float(ph["time_s"]), fields="instantaneous")
        sampled = sample_mesh(pi, pp, model, method=method, **kw)
        for key in PHASE_KEYS:
            if key in sampled:
                out[f"phase/{name}/{key}"] = sampled[key]
    out["phase_names"] = np.array(names, dtype=str)
    out["phase_times"] = np.array([float(pulsatile["phases"][n]["time_s"]) for n in names])
    out["cycle_window"] = np.asarray(pulsatile["window"], float)
    out["field_source"] = np.str_("pulsatile")
    out["time"] = np.float64(pulsatile["window"][1])
    out["read_time_s"] = np.float64(t_read - t0)
    out["n_cells"] = np.int64(internal.n_cells)
    out["sample_time_s"] = np.float64(_time.perf_counter() - t0)
    return out


# ---------------------------------------------------------------------------------------------
# Writing
# ---------------------------------------------------------------------------------------------
COUNT_KEYS = (
    "n_points",
    "n_outside_mesh",
    "n_wall_noslip",
    "n_wall_outside_mesh",
    "n_interior_nearest",
    "interior_nearest_max_distance",
    "wall_distance_max",
    "wall_distance_mean",
    "n_ostium",
    "ostium_fraction",
    "wall_gap_max_kept",
    "ostium_criterion",
    "n_cells",
    "time",
    "read_time_s",
    "interpolation_time_s",
    "sample_time_s",
    "method",
    "field_source",
)


def summary(fields: dict[str, Any]) -> dict[str, Any]:
    """Counts and timings of a resampling as plain JSON values.

    Parameters
    ----------
    fields : dict of str -> array
        Output of :func:`sample_case` or :func:`load_fields`.

    Returns
    -------
    dict
        The entries of :data:`COUNT_KEYS` present in ``fields``, as Python scalars (distances in
        case units, times in s; a non-finite number as None), among them the wall grid points at
        an ostium (``n_ostium``, ``ostium_fraction``) and the ``ostium_criterion`` that marked
        them (:func:`ostium_mask`).
    """
    out = {k: fields[k].item() for k in COUNT_KEYS if k in fields}
    return {k: None if isinstance(v, float) and not np.isfinite(v) else v for k, v in out.items()}


TIMING_KEYS = ("read_time_s", "interpolation_time_s", "sample_time_s")
"""Wall-clock timings of a resampling: in ``fields.json``, never in ``fields.npz`` (whose bytes the
same inputs must reproduce)."""


def write_fields(fields: dict[str, Any], npz_path: Path | str, *, vtu_path: Path | str | None = None) -> None:
    """Write ``fields.npz`` (every array but the timings: the same inputs give the same bytes),
    ``<npz stem>.json`` (counts and timings) and optionally a VTU.

    Parameters
    ----------
    fields : dict of str -> array
        Output of :func:`sample_case`.
    npz_path : Path or str
        The ``.npz`` file (compressed); the ``.json`` summary goes next to it.
    vtu_path : Path, str or None
        A VTU of the grid (case units) with U, U_vcs, p, p_kinematic, rho_n and WSS (and TAWSS,
        OSI of a time-averaged case, RRT, ECAP of a pulsatile one, and the ostium mask as 0/1; on
        the rho_n = 1 layer, zero inside; NaN at an ostium), for ParaView.
    """
    npz_path = Path(npz_path)
    np.savez_compressed(npz_path, **{k: v for k, v in fields.items() if k not in TIMING_KEYS})
    npz_path.with_suffix(".json").write_text(json.dumps(summary(fields), indent=1, sort_keys=True) + "\n")
    if vtu_path is not None:
        data = {k: fields[k] for k in ("U", "U_vcs", "p", "p_kinematic")}
        n_rho = fields["rho_n"].shape[0]
        data["rho_n"] = np.broadcast_to(fields["rho_n"], fields["p"].shape)
        if "WSS" in fields:  # wall data on the rho_n = 1 layer, zero inside
            w = np.zeros(fields["U"].shape)
            w[:, :, n_rho - 1] = fields["WSS"]
            data["WSS"] = w
        for name in ("TAWSS", "OSI", "RRT", "ECAP", "ostium"):
            if name in fields:
                s = np.zeros(fields["p"].shape)
                s[:, :, n_rho - 1] = fields[name]
                data[name] = s
        grid_to_vtk(fields["points"], data).save(str(vtu_path))


def load_fields(path: Path | str) -> dict[str, NDArray[Any]]:
    """Read a fields.npz written by :func:`write_fields`.

    Parameters
    ----------
    path : Path or str
        The ``.npz`` file.

    Returns
    -------
    dict of str -> array
        Every array of the file (see :func:`sample_case` for names, shapes and units).
    """
    with np.load(path) as z:
        return {k: z[k] for k in z.files}
