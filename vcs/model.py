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
    curve_length,
    end_tangents,
    fit_spline,
    lumen_path,
    lumen_voxels,
    recentre,
    reparametrise_by_arc_length,
    voxel_size,
)
from vcs.ends import End, Ends
from vcs.errors import VCSInputError
from vcs.frame import ParallelTransportFrame, initial_v1_from_wall, wall_centroid

log = logging.getLogger(__name__)


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
        n_knots: int = 9,
        voxels_per_radius: float = 6.0,
        max_voxels: float = 4e6,
        recentre_iterations: int = 3,
    ) -> VesselCoordinateSystem:
        """Build the VCS of the section between ``ends`` (paper Sections 2.2.1-2.2.2).

        The steps, each a function of :mod:`vcs.centerline` or :mod:`vcs.frame`: lumen voxels and
        their distance d to the wall; the lowest-cost path (cost 1/d) from p_A to p_B; the
        least-squares spline with L knots; its arc-length reparametrisation; re-centring on the
        wall (beyond the paper, see :func:`vcs.centerline.recentre`); v1(0) from the wall
        centroid and the parallel-transport frame.

        Parameters
        ----------
        vertices : (N, 3) float, mm
        faces : (M, 3) int
            The vessel surface; ``faces[ends.wall_mask]`` is the wall.
        ends : Ends
            From :func:`vcs.ends.find_ends`.
        n_knots : int
            L, the centerline's uniform interior knots (paper default 9).
        voxels_per_radius : float
            Voxels across the smaller end radius.
        max_voxels : float
            Upper bound on the voxel grid's size.
        recentre_iterations : int
            Re-centring steps (0 gives the paper's curve).

        Returns
        -------
        VesselCoordinateSystem
            The build report (voxel size, timings, checks) is in ``.report``.
        """
        if n_knots < 1:
            raise VCSInputError(f"L = {n_knots} knots is too few; use L >= 1 (paper default 9)")
        t0 = time.perf_counter()
        h = voxel_size(ends, voxels_per_radius=voxels_per_radius, max_voxels=max_voxels)
        lumen = lumen_voxels(vertices, faces, ends, h)
        t_vox = time.perf_counter()
        path, inlet, outlet = lumen_path(vertices, faces, ends, lumen)
        t_path = time.perf_counter()
        if n_knots > max(9, len(path)):  # at most one knot per path voxel (the default always fits)
            raise VCSInputError(
                f"L = {n_knots} centerline knots is too many for a lumen path of {len(path)} voxels; "
                f"use L <= {max(9, len(path))} (paper default 9)"
            )
        dirs = end_tangents(inlet, outlet)
        curve = fit_spline(np.vstack([inlet.center, path, outlet.center]), n_knots, end_directions=dirs)
        curve = reparametrise_by_arc_length(curve, end_directions=dirs)
        t_fit = time.perf_counter()
        wall_faces = faces[ends.wall_mask]
        curve, shifts = recentre(curve, vertices, wall_faces, iterations=recentre_iterations, end_directions=dirs)
        t_recentre = time.perf_counter()
        v1_0, how = initial_v1_from_wall(curve, wall_centroid(vertices, wall_faces))
        self = cls(curve, v1_0, v1_0_from=how)
        t_frame = time.perf_counter()
        # "astar": the lumen path search (key kept from the former A* implementation)
        timings = {
            "voxelize": t_vox - t0,
            "astar": t_path - t_vox,
            "spline_fit": t_fit - t_path,
            "recentre": t_recentre - t_fit,
            "frame": t_frame - t_recentre,
        }
        self.report = _build_report(self, ends, inlet, outlet, lumen, path, shifts, timings)
        if not self.report["centerline_inside_lumen"]:
            log.warning(
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
    wall_d = lumen.distance_at(curve(np.linspace(0.02, 0.98, 961)))
    speed = np.linalg.norm(curve.derivative()(np.linspace(0, 1, 1001)), axis=1)
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
        "arc_length_speed_deviation": float(np.ptp(speed) / speed.mean()),
        "centerline_min_wall_distance_mm": float(wall_d.min()),
        "centerline_inside_lumen": bool(wall_d.min() > 0),
        "v1_0_from": vcs.v1_0_from,
        "recentre_max_shift_mm": [float(v) for v in shifts],
        "timings_s": timings,
    }


def _end_report(e: End) -> dict:
    return {
        "center_mm": [float(v) for v in e.center],
        "normal": None if e.normal is None else [float(v) for v in e.normal],
        "radius_mm": e.radius,
        "source": e.source,
    }
