"""The Vessel Coordinate System of one vessel section: build from a surface, use, save, reload."""

from __future__ import annotations

import logging
import time

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline

import vcs.coords as _coords
from vcs.centerline import (
    VoxelLumen,
    choose_n_knots,
    curve_length,
    end_tangents,
    fit_centerline,
    fit_to_curve,
    interior_samples,
    lumen_path,
    lumen_voxels,
    section_centres,
    speed_deviation,
    voxel_size,
    working_knots,
)
from vcs.ends import End, Ends
from vcs.errors import VCSInputError
from vcs.frame import ParallelTransportFrame, initial_v1_from_wall, wall_centroid
from vcs.mesh import point_triangle_distance

log = logging.getLogger(__name__)

#: Smoothing length of the working centerline, in median lumen radii (:func:`vcs.centerline.fit_spline`):
#: wiggles of the section centres shorter than pi radii (ostia of side branches, a bumpy
#: marching-cubes wall) are damped; arcs of the curve's own curvature are not (the penalty is on
#: the change of curvature). 0.4 needed L = 25 on AortaCFD and left residuals 17 % higher, 0.6
#: moved the aorta phantoms' centerlines 0.1-0.2 mm further from the exact ones.
SMOOTHING_RADII = 0.5


class VesselCoordinateSystem:
    """Centerline c(tau), parallel-transport frame and the (tau, theta, rho) coordinates.

    Build with :meth:`from_surface` (or :meth:`from_dict` to reload); the object is immutable
    after construction.

    Parameters
    ----------
    curve : BSpline
        Centerline c(tau), cubic, tau in [0, 1] proportional to arc length; control points (L + 4, 3) in mm.
    v1_0 : (3,) float
        Unit vector normal to t(0), the start of the parallel-transport frame.
    v1_0_from : str
        How ``v1_0`` was chosen (kept in the report and model.json).

    Attributes
    ----------
    frame : ParallelTransportFrame
        {t, v1, v2}(tau).
    length : float, mm
        Length of the centerline.
    index : vcs.coords.CurveIndex
        Search structure for the closest point (tau) of a point.
    report : dict
        Build report of :meth:`from_surface` (empty otherwise).

    Examples
    --------
    The VCS of a torus arc (radius 40 mm, 180 degrees), from its exact centreline; points given
    in vessel coordinates come back from Cartesian ones unchanged (paper Eqs. 1-4):

    >>> import numpy as np
    >>> from vcs import VesselCoordinateSystem, make_phantom
    >>> from vcs.centerline import fit_centerline
    >>> torus = make_phantom("torus")
    >>> curve = fit_centerline(torus.centerline(np.linspace(0.0, 1.0, 200)), 9)
    >>> vcs = VesselCoordinateSystem(curve, torus.frame(0.0)[1])
    >>> round(vcs.length, 4), round(np.pi * 40.0, 4)
    (125.6637, 125.6637)
    >>> rng = np.random.default_rng(0)
    >>> tau, theta, rho = rng.uniform(0.05, 0.95, 100), rng.uniform(0, 2 * np.pi, 100), rng.uniform(0, 4, 100)
    >>> x = vcs.to_cartesian(tau, theta, rho)
    >>> tau2, theta2, rho2, in_omega = vcs.to_vcs(x)
    >>> bool(in_omega.all())
    True
    >>> err = np.abs([tau2 - tau, np.angle(np.exp(1j * (theta2 - theta))), rho2 - rho]).max()
    >>> bool(err < 1e-9)
    True
    """

    def __init__(self, curve: BSpline, v1_0: ArrayLike, *, v1_0_from: str = "given") -> None:
        self.curve = curve
        self.v1_0 = np.asarray(v1_0, float)
        self.v1_0_from = v1_0_from
        self.frame = ParallelTransportFrame(curve, self.v1_0)
        self.length = curve_length(curve)
        self.index = _coords.CurveIndex.from_curve(curve, self.length)
        self.report: dict = {}

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_surface(
        cls,
        vertices: NDArray[np.floating],
        faces: NDArray[np.integer],
        ends: Ends,
        *,
        n_knots: int | str = "auto",
        voxels_per_radius: float = 6.0,
        max_voxels: float = 4e6,
        recentre_iterations: int = 3,
    ) -> VesselCoordinateSystem:
        """Build the VCS of the section between ``ends`` (paper Sections 2.2.1-2.2.2).

        The steps, each a function of :mod:`vcs.centerline` or :mod:`vcs.frame`: lumen voxels and
        their distance d to the wall; the lowest-cost path (cost 1/d) from p_A to p_B; a working
        spline (:func:`vcs.centerline.working_knots` knots, one span per lumen radius, smoothed
        over :data:`SMOOTHING_RADII` median lumen radii) re-centred on the wall's cross-sections
        (beyond the paper, :func:`vcs.centerline.section_centres`); the centerline with L knots
        fitted to that curve at equal arc length (Eq. 1, :func:`vcs.centerline.fit_to_curve`),
        L given or chosen (:func:`vcs.centerline.choose_n_knots`); v1(0) from the wall centroid
        and the parallel-transport frame. With ``recentre_iterations`` = 0 and L given, the
        centerline is fitted to the lumen path itself (the paper's curve).

        Parameters
        ----------
        vertices : (N, 3) float, mm
        faces : (M, 3) int
            The vessel surface; ``faces[ends.wall_mask]`` is the wall.
        ends : Ends
            From :func:`vcs.ends.find_ends`.
        n_knots : int or "auto"
            L, the centerline's uniform interior knots (paper default 9); "auto": the smallest
            L >= 9 keeping the curve inside the lumen with a margin and |c'| constant within 2 %.
        voxels_per_radius : float
            Voxels across the smaller end radius.
        max_voxels : float
            Upper bound on the voxel grid's size.
        recentre_iterations : int
            Re-centring steps (0 gives the paper's curve).

        Returns
        -------
        VesselCoordinateSystem
            The build report (voxel size, L and how it was chosen, timings, checks) is in ``.report``.
        """
        auto = isinstance(n_knots, str)
        if auto and n_knots != "auto":
            raise VCSInputError(f"L = {n_knots!r}: give a number of knots (paper default 9) or 'auto'")
        if not auto and int(n_knots) < 1:
            raise VCSInputError(f"L = {n_knots} knots is too few; use L >= 1 (paper default 9)")
        t0 = time.perf_counter()
        h = voxel_size(ends, voxels_per_radius=voxels_per_radius, max_voxels=max_voxels)
        lumen = lumen_voxels(vertices, faces, ends, h)
        t_vox = time.perf_counter()
        path, inlet, outlet = lumen_path(vertices, faces, ends, lumen)
        t_path = time.perf_counter()
        if not auto and int(n_knots) > max(9, len(path)):  # at most one knot per path voxel
            raise VCSInputError(
                f"L = {n_knots} centerline knots is too many for a lumen path of {len(path)} voxels; "
                f"use L <= {max(9, len(path))} (paper default 9)"
            )
        dirs = end_tangents(inlet, outlet)
        pts = np.vstack([inlet.center, path, outlet.center])
        wall_faces = faces[ends.wall_mask]
        tri = vertices[wall_faces]
        edge = float(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).mean())
        path_len = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
        radius = float(np.median(lumen.distance_at(path)))
        L_work = working_knots(path_len, radius, edge)
        L_work = min(L_work, max(9, len(path) // 2))
        ell = SMOOTHING_RADII * radius
        working = fit_centerline(pts, L_work, end_directions=dirs, smoothing_mm=ell)
        t_fit = time.perf_counter()
        shifts: list[float] = []
        data = pts
        short = path_len < 2.0 * radius
        if short:  # no longer than its diameter: no room for a bend, and too few voxels to follow
            data = inlet.center + np.linspace(0.0, 1.0, 17)[:, None] * (outlet.center - inlet.center)
            working = fit_centerline(data, L_work, end_directions=dirs)
        elif recentre_iterations > 0:
            working, shifts, _ = section_centres(
                working,
                vertices,
                wall_faces,
                iterations=recentre_iterations,
                end_directions=dirs,
                smoothing_mm=ell,
            )
        t_recentre = time.perf_counter()
        choice = None
        if auto:
            choice = choose_n_knots(working, lumen, end_directions=dirs, max_knots=max(9, L_work))
            curve = choice.curve
        elif recentre_iterations > 0 and not short:
            curve = fit_to_curve(working, int(n_knots), end_directions=dirs)
        else:  # the paper's curve: least squares to the lumen path (a short section: its chord)
            curve = fit_centerline(data, int(n_knots), end_directions=dirs)
        t_choose = time.perf_counter()
        v1_0, how = initial_v1_from_wall(curve, wall_centroid(vertices, wall_faces))
        self = cls(curve, v1_0, v1_0_from=how)
        t_frame = time.perf_counter()
        # "astar": the lumen path search (key kept from the former A* implementation)
        timings = {
            "voxelize": t_vox - t0,
            "astar": t_path - t_vox,
            "spline_fit": t_fit - t_path,
            "recentre": t_recentre - t_fit,
            "choose_L": t_choose - t_recentre,
            "frame": t_frame - t_choose,
        }
        self.report = _build_report(self, ends, inlet, outlet, lumen, path, shifts, timings)
        self.report.update(
            _centerline_checks(curve, working, lumen, vertices[wall_faces]),
            L_source="auto" if auto else "given",
            L_working=int(L_work),
            centerline_smoothing_mm=ell,
            short_section=bool(short),
        )
        timings["checks"] = time.perf_counter() - t_frame  # the report: speed deviation, wall distance
        if choice is not None:
            self.report["L_auto"] = {
                "criteria_met": choice.met,
                "max_speed_deviation": 0.02,
                "min_wall_distance_ratio": 0.5,
                "tried": choice.trials,
            }
        if not self.report["centerline_inside_lumen"]:
            log.info(  # in fit_report.json: warnings and quality_reasons (vcs.vessel.fit_vessel)
                "centerline leaves the voxelised lumen (min distance %.3f mm)",
                self.report["centerline_min_wall_distance_mm"],
            )
        return self

    # -- use ----------------------------------------------------------------------------------
    def to_vcs(
        self, points: ArrayLike
    ) -> tuple[NDArray[np.floating], NDArray[np.floating], NDArray[np.floating], NDArray[np.bool_]]:
        """Vessel coordinates of points (paper Eqs. 2-4); see :func:`vcs.coords.to_vcs`.

        Parameters
        ----------
        points : (N, 3) float, mm

        Returns
        -------
        tau : (N,) float, in [0, 1]
        theta : (N,) float, rad, in [0, 2 pi)
        rho : (N,) float, mm
        in_omega : (N,) bool
            True inside the validity region Omega.
        """
        return _coords.to_vcs(self.curve, self.frame, self.index, points)

    def to_cartesian(self, tau: ArrayLike, theta: ArrayLike, rho: ArrayLike) -> NDArray[np.floating]:
        """Points from vessel coordinates (paper Eq. 1); see :func:`vcs.coords.to_cartesian`.

        Parameters
        ----------
        tau, theta, rho : float arrays broadcasting to a shape (...)
            tau in [0, 1], theta in rad, rho in mm.

        Returns
        -------
        (..., 3) float, mm
        """
        return _coords.to_cartesian(self.curve, self.frame, tau, theta, rho)

    def curvature(self, tau: ArrayLike) -> NDArray[np.floating]:
        """Curvature kappa(tau) of the centerline, 1/mm, shape of ``tau``; see :func:`vcs.coords.curvature`."""
        return _coords.curvature(self.curve, tau)

    # -- (de)serialisation --------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The centerline and v1(0) as plain JSON types (knots, control points in mm, length in mm)."""
        return {
            "degree": int(self.curve.k),
            "n_knots": int(len(self.curve.t) - 2 * (self.curve.k + 1)),
            "knots": [float(v) for v in self.curve.t],
            "control_points": [[float(v) for v in row] for row in self.curve.c],
            "length_mm": self.length,
            "v1_0": [float(v) for v in self.v1_0],
            "v1_0_from": self.v1_0_from,
        }

    @classmethod
    def from_dict(cls, d: dict) -> VesselCoordinateSystem:
        """Rebuild from :meth:`to_dict` output (the frame, length and index are recomputed)."""
        curve = BSpline(np.array(d["knots"]), np.array(d["control_points"]), int(d["degree"]))
        return cls(curve, np.array(d["v1_0"]), v1_0_from=d.get("v1_0_from", "given"))

    @property
    def control_points(self) -> NDArray[np.floating]:
        """Control points c_i of the centerline, (L + 4, 3) float, mm."""
        return np.asarray(self.curve.c)


def _build_report(
    vcs: VesselCoordinateSystem,
    ends: Ends,
    inlet: End,
    outlet: End,
    lumen: VoxelLumen,
    path: NDArray[np.floating],
    shifts: list[float],
    timings: dict[str, float],
) -> dict:
    """The build report of :meth:`VesselCoordinateSystem.from_surface` (keys as in fit_report.json)."""
    curve = vcs.curve
    return {
        "ends_method": ends.method,
        "inlet": _end_report(inlet),
        "outlet": _end_report(outlet),
        "ends_notes": list(ends.notes),
        "voxel_size_mm": lumen.h,
        "voxel_grid": list(lumen.inside.shape),
        "lumen_voxels": int(lumen.inside.sum()),
        "path_voxels": int(len(path)),
        "L": int(len(curve.t) - 2 * (curve.k + 1)),
        "centerline_length_mm": vcs.length,
        "arc_length_speed_deviation": speed_deviation(curve),
        "v1_0_from": vcs.v1_0_from,
        "recentre_max_shift_mm": [float(v) for v in shifts],
        "timings_s": timings,
    }


def _centerline_checks(
    curve: BSpline, reference: BSpline, lumen: VoxelLumen, wall_tris: NDArray[np.floating]
) -> dict[str, float | bool]:
    """Where the centerline is closest to the wall (fit_report.json keys).

    The distance d to the wall along c(tau) (tau in [0.005, 0.995], 991 samples) from the voxel
    distance field; at the 8 samples where it is smallest, the exact point-to-triangle distance
    to the wall (:func:`vcs.mesh.point_triangle_distance`) replaces it. The ratio compares d with
    the lumen radius there (d at the nearest point of the re-centred ``reference`` curve).

    Parameters
    ----------
    curve, reference : BSpline
        The centerline and the re-centred working curve, mm.
    lumen : VoxelLumen
        The voxelised lumen and its distance field.
    wall_tris : (M, 3, 3) float, mm
        Wall triangles.

    Returns
    -------
    dict
        ``centerline_min_wall_distance_mm`` (0 where the curve is outside the lumen) and its
        ``centerline_min_wall_distance_tau``, ``centerline_min_wall_distance_ratio``
        (dimensionless), ``centerline_inside_lumen``.
    """
    from scipy.spatial import cKDTree

    tau = np.linspace(0.005, 0.995, 991)
    c = curve(tau)
    d = lumen.distance_at(c)
    inside = d > 0
    worst = np.argsort(d)[:8]
    d[worst] = np.where(inside[worst], point_triangle_distance(c[worst], wall_tris), 0.0)
    ref = reference(np.linspace(0.0, 1.0, 2001))
    ref_d = np.maximum(lumen.distance_at(ref), lumen.h)
    tree = cKDTree(ref)
    # the margin away from the ends (where the curve is pinned to the end centres)
    tau_i = interior_samples(ref_d[[0, -1]], curve_length(reference))
    c_i = curve(tau_i)
    ratio = lumen.distance_at(c_i) / ref_d[tree.query(c_i)[1]]
    return {
        "centerline_min_wall_distance_mm": float(d.min()),
        "centerline_min_wall_distance_tau": float(tau[int(np.argmin(d))]),
        "centerline_min_wall_distance_ratio": float(ratio.min()),
        "centerline_inside_lumen": bool(inside.all() and d.min() > 0),
    }


def _end_report(e: End) -> dict:
    return {
        "center_mm": [float(v) for v in e.center],
        "normal": None if e.normal is None else [float(v) for v in e.normal],
        "radius_mm": e.radius,
        "source": e.source,
    }
