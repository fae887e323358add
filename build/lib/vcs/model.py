"""The Vessel Coordinate System of one vessel section: build from a surface, use, save, reload."""
from __future__ import annotations

import logging
import time

import numpy as np
from scipy import ndimage
from scipy.interpolate import BSpline

from vcs import coords as _coords
from vcs.centerline import VoxelLumen, arc_length_table, astar_path, fit_centerline, voxelize
from vcs.ends import End, Ends
from vcs.errors import VCSInputError
from vcs.frame import ParallelTransportFrame, initial_v1
from vcs.mesh import triangle_cross

log = logging.getLogger(__name__)


class VesselCoordinateSystem:
    """Centerline c(tau), parallel-transport frame and the (tau, theta, rho) coordinates.

    Build with :meth:`from_surface` (or :meth:`from_dict` to reload); the object is immutable
    after construction.
    """

    def __init__(self, curve: BSpline, v1_0: np.ndarray, *, v1_0_from: str = "given"):
        self.curve = curve
        self.v1_0 = np.asarray(v1_0, float)
        self.v1_0_from = v1_0_from
        self.frame = ParallelTransportFrame(curve, self.v1_0)
        self.length = float(arc_length_table(curve, np.linspace(0, 1, 2049))[-1])
        self.index = _coords.CurveIndex.from_curve(curve, self.length)
        self.report: dict = {}

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_surface(
        cls,
        vertices: np.ndarray,
        faces: np.ndarray,
        ends: Ends,
        *,
        n_knots: int = 9,
        voxels_per_radius: float = 6.0,
        max_voxels: float = 4e6,
        recentre_iterations: int = 3,
    ) -> "VesselCoordinateSystem":
        """Build the VCS of the section between ``ends`` (paper Sections 2.2.1-2.2.2).

        ``vertices``/``faces`` are the wall in mm; ``ends`` comes from :func:`vcs.ends.find_ends`.
        The build report (voxel size, timings, checks) is in ``.report``.

        Beyond the paper: the voxel path cuts bends and carries the voxel staircase (errors of a
        few tenths of a mm). ``recentre_iterations`` (default 3; 0 gives the paper's curve) moves
        the curve to the centres of the wall cross-sections: per tau bin, the first Fourier
        harmonic of rho(theta) of the wall points is the offset of the true centre, and the spline
        (same L, same end points) is refitted to the shifted bin centres.
        """
        if n_knots < 1:
            raise VCSInputError(f"L = {n_knots} knots is too few; use L >= 1 (paper default 9)")
        t0 = time.perf_counter()
        cv, cf = ends.closed_vertices, ends.closed_faces
        radii = [e.radius for e in (ends.inlet, ends.outlet) if e.radius]
        if radii:
            r_ref = min(radii)
        else:  # explicit points on a closed surface: radius from a coarse voxelisation
            coarse = voxelize(cv, cf, float(np.ptp(cv, axis=0).max()) / 80.0)
            if not coarse.inside.any():
                raise VCSInputError("the surface encloses no volume; give a closed or open-ended tube surface")
            r_ref = 3.0 * float(coarse.distance[coarse.inside].mean())
        h = r_ref / voxels_per_radius
        extent = np.ptp(cv, axis=0) + 5 * h
        n_vox = np.prod(extent / h)
        if n_vox > max_voxels:
            h *= (n_vox / max_voxels) ** (1 / 3)
        lumen = voxelize(cv, cf, h, distance=False)  # the distance is to the wall only, below
        if not lumen.inside.any():
            raise VCSInputError("the surface encloses no voxel of the lumen; check the units (--units) and that it is a tube")
        lumen = _wall_distance(lumen, vertices, faces[ends.wall_mask])
        t_vox = time.perf_counter()

        inlet, outlet = ends.inlet, ends.outlet
        start = _start_voxel(lumen, inlet, "inlet")
        goal = _start_voxel(lumen, outlet, "outlet")
        path = lumen.centers(astar_path(lumen, start, goal))
        if inlet.normal is None:  # explicit points: end planes from the path and the wall
            inlet, path = _point_end_plane(vertices, faces, lumen, inlet, path)
        if outlet.normal is None:
            outlet, rev = _point_end_plane(vertices, faces, lumen, outlet, path[::-1])
            path = rev[::-1]
        t_path = time.perf_counter()
        if n_knots > max(9, len(path)):  # at most one knot per path voxel (the default always fits)
            raise VCSInputError(
                f"L = {n_knots} centerline knots is too many for a lumen path of {len(path)} voxels; "
                f"use L <= {max(9, len(path))} (paper default 9)"
            )
        pts = np.vstack([inlet.center, path, outlet.center])
        dirs = None
        if inlet.normal is not None and outlet.normal is not None:  # end planes known: meet them square
            dirs = (inlet.normal, -outlet.normal)
        curve = fit_centerline(pts, n_knots, end_directions=dirs)
        t_fit = time.perf_counter()

        wall_faces = faces[ends.wall_mask]
        tri = vertices[wall_faces]
        area = 0.5 * np.linalg.norm(triangle_cross(tri), axis=1)
        centroid = (tri.mean(axis=1) * area[:, None]).sum(axis=0) / area.sum()
        w_vert = np.bincount(wall_faces.ravel(), np.repeat(area / 3.0, 3), minlength=len(vertices))
        used = w_vert > 0
        shifts = []
        for _ in range(recentre_iterations):
            curve, shift = _recentre(curve, vertices[used], w_vert[used], inlet.center, outlet.center, n_knots, dirs)
            shifts.append(shift)
        t_recentre = time.perf_counter()
        d1 = curve.derivative()(0.0)
        v1_0, how = initial_v1(d1, curve(0.0), centroid)
        self = cls(curve, v1_0, v1_0_from=how)
        t_frame = time.perf_counter()

        tau = np.linspace(0.02, 0.98, 961)
        wall_d = _interp_distance(lumen, curve(tau))
        speed = np.linalg.norm(curve.derivative()(np.linspace(0, 1, 1001)), axis=1)
        self.report = {
            "ends_method": ends.method,
            "inlet": _end_report(inlet),
            "outlet": _end_report(outlet),
            "ends_notes": list(ends.notes),
            "voxel_size_mm": h,
            "voxel_grid": list(lumen.inside.shape),
            "lumen_voxels": int(lumen.inside.sum()),
            "path_voxels": int(len(path)),
            "L": int(n_knots),
            "centerline_length_mm": self.length,
            "arc_length_speed_deviation": float(np.ptp(speed) / speed.mean()),
            "centerline_min_wall_distance_mm": float(wall_d.min()),
            "centerline_inside_lumen": bool(wall_d.min() > 0),
            "v1_0_from": how,
            "recentre_max_shift_mm": [float(v) for v in shifts],
            "timings_s": {
                "voxelize": t_vox - t0,
                "astar": t_path - t_vox,
                "spline_fit": t_fit - t_path,
                "recentre": t_recentre - t_fit,
                "frame": t_frame - t_recentre,
            },
        }
        if wall_d.min() <= 0:
            log.warning("centerline leaves the voxelised lumen (min distance %.3f mm)", wall_d.min())
        return self

    # -- use ----------------------------------------------------------------------------------
    def to_vcs(self, points: np.ndarray):
        """(tau, theta, rho, in_omega) of (N, 3) points in mm; see :func:`vcs.coords.to_vcs`."""
        return _coords.to_vcs(self.curve, self.frame, self.index, points)

    def to_cartesian(self, tau, theta, rho) -> np.ndarray:
        """Points (..., 3) in mm from VCS coordinates; see :func:`vcs.coords.to_cartesian`."""
        return _coords.to_cartesian(self.curve, self.frame, tau, theta, rho)

    def curvature(self, tau) -> np.ndarray:
        return _coords.curvature(self.curve, tau)

    # -- (de)serialisation --------------------------------------------------------------------
    def to_dict(self) -> dict:
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
    def from_dict(cls, d: dict) -> "VesselCoordinateSystem":
        curve = BSpline(np.array(d["knots"]), np.array(d["control_points"]), int(d["degree"]))
        return cls(curve, np.array(d["v1_0"]), v1_0_from=d.get("v1_0_from", "given"))

    @property
    def control_points(self) -> np.ndarray:
        return np.asarray(self.curve.c)


def _recentre(curve, pts, w, p0, p1, n_knots, dirs=None, n_bins=None):
    """One re-centring step (see :meth:`VesselCoordinateSystem.from_surface`).

    Returns the refitted curve and the largest centre shift applied (mm).
    """
    vcs = VesselCoordinateSystem(curve, _any_normal(curve.derivative()(0.0)))
    tau, theta, rho, ok = vcs.to_vcs(pts)
    n_bins = n_bins or max(32, 6 * (n_knots + 4))
    ok &= (tau > 0) & (tau < 1)
    b = np.minimum((tau * n_bins).astype(int), n_bins - 1)
    # robust: points far beyond their bin's median radius (branches, outliers) do not vote
    med = np.zeros(n_bins)
    for k in np.unique(b[ok]):
        med[k] = np.median(rho[ok & (b == k)])
    ok &= rho < 1.5 * med[b]
    X = np.column_stack([np.ones_like(theta), np.cos(theta), np.sin(theta), np.cos(2 * theta), np.sin(2 * theta)])
    Xw = X * (w * ok)[:, None]
    A = np.zeros((n_bins, 5, 5))
    y = np.zeros((n_bins, 5))
    np.add.at(A, b, Xw[:, :, None] * X[:, None, :])
    np.add.at(y, b, Xw * rho[:, None])
    tsum = np.bincount(b, w * ok, minlength=n_bins)
    tmean = np.bincount(b, w * ok * tau, minlength=n_bins) / np.where(tsum > 0, tsum, 1)
    cnt = np.bincount(b, ok.astype(float), minlength=n_bins)
    # a bin votes only when its wall points surround the curve (all 8 theta octants present):
    # bins cut by an oblique end plane or a gap would give a biased centre
    octant = np.minimum((theta / (np.pi / 4)).astype(int), 7)
    cover = np.zeros((n_bins, 8), bool)
    cover[b[ok], octant[ok]] = True
    good = (cnt >= 12) & cover.all(axis=1)
    good[good] &= np.linalg.cond(A[good]) < 1e8
    coef = np.zeros((n_bins, 5))
    coef[good] = np.linalg.solve(A[good], y[good][..., None])[..., 0]
    # bins that do not vote keep the current curve, so the refit is constrained everywhere
    tb = np.where(good, tmean, (np.arange(n_bins) + 0.5) / n_bins)
    _, v1, v2 = vcs.frame(tb)
    shift = (coef[:, 1:2] * v1 + coef[:, 2:3] * v2) * good[:, None]
    size = np.linalg.norm(shift, axis=1, keepdims=True)
    cap = 0.25 * np.abs(coef[:, :1])  # never move by more than a quarter of the local radius per step
    shift *= np.minimum(1.0, cap / np.maximum(size, 1e-300))
    new = curve(tb) + shift
    order = np.argsort(tb)
    fitted = fit_centerline(np.vstack([p0, new[order], p1]), n_knots, end_directions=dirs)
    return fitted, float(np.linalg.norm(shift, axis=1).max(initial=0.0))


def _any_normal(t: np.ndarray) -> np.ndarray:
    return initial_v1(t, np.zeros(3), np.zeros(3))[0]


def _end_report(e: End) -> dict:
    return {
        "center_mm": [float(v) for v in e.center],
        "normal": None if e.normal is None else [float(v) for v in e.normal],
        "radius_mm": e.radius,
        "source": e.source,
    }


def _wall_distance(lumen: VoxelLumen, vertices: np.ndarray, faces: np.ndarray) -> VoxelLumen:
    """Replace the voxel distance by the distance to the *wall* only (end caps are not walls).

    With caps counted as walls the path near an end is pushed only by the cap and wanders
    sideways, giving hooks at the ends of the centerline. Distances are to wall samples
    (vertices, edge midpoints, centroids, and a finer barycentric grid on triangles larger than
    half a voxel), rasterised into wall voxels; then one Euclidean distance transform.
    """
    tri = vertices[faces]
    samples = [vertices[np.unique(faces)], tri.mean(axis=1), 0.5 * (tri[:, 0] + tri[:, 1]),
               0.5 * (tri[:, 1] + tri[:, 2]), 0.5 * (tri[:, 2] + tri[:, 0])]
    edge = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max(axis=1)
    # triangles larger than half a voxel get a barycentric grid of n x n points, n per triangle
    n_sub = np.minimum(np.ceil(edge / (0.5 * lumen.h)), 24).astype(int)
    for n in np.unique(n_sub[n_sub > 1]):
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        w1, w2 = i[keep] / n, j[keep] / n
        w0 = 1 - w1 - w2
        tb = tri[n_sub == n]
        samples.append((w0[None, :, None] * tb[:, None, 0] + w1[None, :, None] * tb[:, None, 1]
                        + w2[None, :, None] * tb[:, None, 2]).reshape(-1, 3))
    ijk_w = lumen.index_of(np.concatenate(samples))
    ok = np.all((ijk_w >= 0) & (ijk_w < np.array(lumen.inside.shape)), axis=1)
    wall = np.zeros(lumen.inside.shape, bool)
    wall[tuple(ijk_w[ok].T)] = True
    dist = ndimage.distance_transform_edt(~wall, sampling=lumen.h)
    dist = np.where(lumen.inside, np.maximum(dist, 0.5 * lumen.h), 0.0)
    return VoxelLumen(lumen.inside, dist, lumen.origin, lumen.h)


def _interp_distance(lumen: VoxelLumen, pts: np.ndarray) -> np.ndarray:
    ijk = ((pts - lumen.origin) / lumen.h).T
    return ndimage.map_coordinates(lumen.distance, ijk, order=1, mode="constant", cval=0.0)


def _start_voxel(lumen: VoxelLumen, end: End, name: str) -> np.ndarray:
    """Inside voxel where the path search starts: nearest to a point 1.5 voxels into the lumen."""
    target = end.center + (1.5 * lumen.h * end.normal if end.normal is not None else 0.0)
    inside = np.argwhere(lumen.inside)
    d = np.linalg.norm(lumen.centers(inside) - target, axis=1)
    i = int(np.argmin(d))
    if d[i] > 3 * lumen.h + 1.0:
        c = end.center
        raise VCSInputError(
            f"the {name} point ({c[0]:.2f}, {c[1]:.2f}, {c[2]:.2f}) mm (converted from the mesh units) is "
            f"{d[i]:.1f} mm outside the lumen; give a point inside the vessel in or near the {name} end plane"
        )
    return inside[i]


def _point_end_plane(vertices, faces, lumen: VoxelLumen, end: End, path: np.ndarray):
    """End plane of an explicit end point, from the lumen path that starts there.

    The normal is the path's direction between one and three local radii from its start (past
    the first voxels, which head from an off-centre point to the middle); the centre is the
    centroid of the wall's cut by the plane through the point. Path points within one local
    radius of the start are dropped so the curve starts at the centre without a kink.
    Returns (end, path).
    """
    ijk = np.rint((path - lumen.origin) / lumen.h).astype(int)
    d = lumen.distance[tuple(ijk.T)]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    r_loc = float(np.median(d[s <= max(s[-1] / 4, 2 * lumen.h)]))
    a = path[np.searchsorted(s, min(r_loc, s[-1] / 3))]
    b = path[np.searchsorted(s, min(3 * r_loc, 2 * s[-1] / 3))]
    normal = (b - a) / max(np.linalg.norm(b - a), 1e-300)
    center, radius = _plane_section(vertices, faces, end.center, normal, 3.0 * max(r_loc, lumen.h))
    keep = s > r_loc
    path = path[keep] if keep.sum() >= 4 else path
    if center is None:
        log.warning("no wall cross-section found at the %s point; the path start is used", end.source)
        return End(path[0], normal, None, "point (no wall cross-section found: path start used)"), path
    return End(center, normal, radius, "point, centred on the wall cross-section"), path


def _plane_section(vertices, faces, p, n, r_max):
    """Centroid and equivalent radius of the wall's cut by the plane (p, n), within r_max of p."""
    sd = (vertices - p) @ n
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    a, b = sd[e[:, 0]], sd[e[:, 1]]
    cross = (a * b) < 0
    ea, eb = e[cross, 0], e[cross, 1]
    w = (a[cross] / (a[cross] - b[cross]))[:, None]
    on = np.abs(sd) <= 1e-9 * max(float(np.ptp(vertices)), 1.0)  # vertices lying in the plane
    x = np.vstack([vertices[ea] + w * (vertices[eb] - vertices[ea]), vertices[np.unique(faces)[on[np.unique(faces)]]]])
    x = x[np.linalg.norm(x - p, axis=1) < r_max]
    if len(x) < 3:
        return None, None
    c = x.mean(axis=0)
    return c, float(np.median(np.linalg.norm(x - c, axis=1)))
