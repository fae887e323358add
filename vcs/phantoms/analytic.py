"""Analytic phantoms with exact truth: straight tube, torus arc and helix (lengths in mm).

Their centreline, rotation-minimising frame, radius (constant) and curvature are known in closed
form, so tests can compare a VCS fit against analytic values. Each is an open circular tube of
constant radius meshed by the shared sweep (:mod:`vcs.phantoms.sweep`); build them with
:func:`vcs.phantoms.make_phantom`.

``tube``   straight circular tube along +z from the origin (radius 10, length 100); curvature 0.
``torus``  arc of a torus in the xy-plane, centre circle radius R = 40 about the origin starting
           at (40, 0, 0) and turning counter-clockwise by 180 deg, tube radius 8; curvature 1/R.
``helix``  c = (a cos u, a sin u, b u), a = 20, pitch 2 pi b = 50, 1.5 turns, tube radius 5;
           curvature a / (a^2 + b^2), torsion b / (a^2 + b^2).

:func:`write_closed_tube_stl` writes a closed straight tube (lengths in metres) as a multi-solid
ASCII STL ``wall``/``inlet``/``outlet`` for OpenFOAM tests against the Hagen-Poiseuille solution.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError
from vcs.mesh import write_stl_ascii
from vcs.phantoms.sweep import (
    CenterlineFn,
    FrameFn,
    SweptSurface,
    _const_radius,
    _grid_mesh,
    _merge,
    _n_around,
    _s_array,
)

__all__ = ["write_closed_tube_stl"]

_Frame = tuple[NDArray[np.floating], NDArray[np.floating], NDArray[np.floating]]


def _tube(h: float, **overrides: float) -> SweptSurface:
    """Straight tube along +z from the origin: c(s) = (0, 0, L s), frame (e_z, e_x, e_y).

    ``h``: target edge (mm); ``overrides``: ``radius_mm`` (10), ``length_mm`` (100).
    """
    p = _merge({"radius_mm": 10.0, "length_mm": 100.0}, overrides, "tube")
    r0, L = p["radius_mm"], p["length_mm"]
    if r0 <= 0 or L <= 0:
        raise VCSInputError("tube phantom: radius_mm and length_mm must be positive")
    ez, ex, ey = np.eye(3)[2], np.eye(3)[0], np.eye(3)[1]

    def centerline(s: ArrayLike) -> NDArray[np.floating]:
        s = _s_array(s)
        return np.stack([0 * s, 0 * s, L * s], -1)

    def frame(s: ArrayLike) -> _Frame:
        shape = np.shape(_s_array(s)) + (3,)
        return np.broadcast_to(ez, shape).copy(), np.broadcast_to(ex, shape).copy(), np.broadcast_to(ey, shape).copy()

    return _circular(centerline, frame, L, r0, h, p)


def _circular(
    centerline: CenterlineFn, frame: FrameFn, L: float, r0: float, h: float, p: dict, **derived: float
) -> SweptSurface:
    """Mesh of a constant-radius tube of length L around ``centerline`` in ``frame`` (edges ~h).

    ``L``, ``r0``, ``h`` in mm; rings equally spaced in s. ``p`` gains ``length_mm``, then
    ``derived`` (in order), then ``n_phi`` and ``n_s``.
    """
    n_phi = _n_around(r0, h)
    ring = np.linspace(0.0, 1.0, max(2, int(np.ceil(L / h))) + 1)
    _, v1, v2 = frame(ring)
    V, F = _grid_mesh(centerline(ring), v1, v2, np.full((len(ring), n_phi), r0), 2 * np.pi * np.arange(n_phi) / n_phi)
    p.update(length_mm=L, **derived, n_phi=n_phi, n_s=len(ring))
    return SweptSurface(V, F, p, centerline, _const_radius(r0), frame, ring)


def _torus(h: float, **overrides: float) -> SweptSurface:
    """Torus arc in the xy-plane: c(s) = R (cos A s, sin A s, 0), v1 towards the axis, v2 = +z.

    ``h``: target edge (mm); ``overrides``: ``major_radius_mm`` R (40), ``tube_radius_mm`` (8),
    ``arc_angle_deg`` A (180).
    """
    p = _merge({"major_radius_mm": 40.0, "tube_radius_mm": 8.0, "arc_angle_deg": 180.0}, overrides, "torus")
    R, r0, A = p["major_radius_mm"], p["tube_radius_mm"], np.deg2rad(p["arc_angle_deg"])
    if not (0 < r0 < R) or not (0 < A < 2 * np.pi):
        raise VCSInputError("torus phantom: need 0 < tube_radius_mm < major_radius_mm and 0 < arc_angle_deg < 360")

    def centerline(s: ArrayLike) -> NDArray[np.floating]:
        a = A * _s_array(s)
        return np.stack([R * np.cos(a), R * np.sin(a), 0 * a], -1)

    def frame(s: ArrayLike) -> _Frame:
        a = A * _s_array(s)
        c, sn, z = np.cos(a), np.sin(a), 0 * a
        # t, v1 = principal normal (towards the torus axis), v2 = t x v1 = +z
        return np.stack([-sn, c, z], -1), np.stack([-c, -sn, z], -1), np.stack([z, z, 1 + z], -1)

    return _circular(centerline, frame, R * A, r0, h, p)


def _helix(h: float, **overrides: float) -> SweptSurface:
    """Helix c(u) = (a cos u, a sin u, b u), u = 2 pi turns s, with its exact rotation-minimising frame.

    ``h``: target edge (mm); ``overrides``: ``helix_radius_mm`` a (20), ``pitch_mm`` 2 pi b (50),
    ``turns`` (1.5), ``tube_radius_mm`` (5). Adds ``curvature_radius_mm`` and ``torsion_per_mm``
    to the parameters.
    """
    p = _merge({"helix_radius_mm": 20.0, "pitch_mm": 50.0, "turns": 1.5, "tube_radius_mm": 5.0}, overrides, "helix")
    a, pitch, turns, r0 = p["helix_radius_mm"], p["pitch_mm"], p["turns"], p["tube_radius_mm"]
    if min(a, pitch, turns, r0) <= 0:
        raise VCSInputError("helix phantom: helix_radius_mm, pitch_mm, turns and tube_radius_mm must be positive")
    b = pitch / (2 * np.pi)
    w = np.hypot(a, b)
    U = 2 * np.pi * turns
    L = w * U
    kappa, torsion = a / w**2, b / w**2
    if r0 * kappa >= 0.8:
        raise VCSInputError(
            f"helix phantom: tube radius {r0:g} mm must be below 0.8 x the radius of curvature "
            f"{1 / kappa:.2f} mm; lower tube_radius_mm or raise helix_radius_mm/pitch_mm"
        )
    if turns > 1 and pitch <= 2.2 * r0 * w / a:
        raise VCSInputError(
            f"helix phantom: successive turns overlap (pitch {pitch:g} mm <= {2.2 * r0 * w / a:.2f} mm); raise pitch_mm"
        )

    def centerline(s: ArrayLike) -> NDArray[np.floating]:
        u = U * _s_array(s)
        return np.stack([a * np.cos(u), a * np.sin(u), b * u], -1)

    def frame(s: ArrayLike) -> _Frame:
        u = U * _s_array(s)
        c, sn = np.cos(u), np.sin(u)
        t = np.stack([-a * sn, a * c, np.full_like(u, b)], -1) / w
        N = np.stack([-c, -sn, 0 * u], -1)
        B = np.stack([b * sn, -b * c, np.full_like(u, a)], -1) / w
        ang = -torsion * w * u  # exact rotation-minimising angle from the Frenet normal
        ca, sa = np.cos(ang)[..., None], np.sin(ang)[..., None]
        v1 = ca * N + sa * B
        v2 = ca * B - sa * N
        return t, v1, v2

    return _circular(centerline, frame, L, r0, h, p, curvature_radius_mm=1 / kappa, torsion_per_mm=torsion)


# ----------------------------------------------------------------------------------------------
# closed tube for OpenFOAM (metres)


def _axis_frame(axis: ArrayLike) -> NDArray[np.floating]:
    """(3, 3) rotation whose columns are e1, e2 and the unit ``axis`` (right-handed, e2 = axis x e1)."""
    a = np.asarray(axis, float)
    n = np.linalg.norm(a)
    if a.shape != (3,) or not np.isfinite(n) or n == 0:
        raise VCSInputError(f"closed tube: axis must be a non-zero 3-vector, got {axis!r}")
    a = a / n
    t = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(a, t)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(a, e1), a], 1)


def write_closed_tube_stl(
    path: str | Path,
    radius: float = 0.01,
    length: float = 0.2,
    n_theta: int = 96,
    n_z: int = 80,
    origin: ArrayLike = (0.0, 0.0, 0.0),
    axis: ArrayLike = (0.0, 0.0, 1.0),
) -> Path:
    """Closed straight circular tube as a multi-solid ASCII STL (metres), for Hagen-Poiseuille tests.

    The wall is ``n_z`` rings of ``n_theta`` quads (two triangles each) from ``origin`` along
    ``axis``; the inlet disc (at ``origin``) and the outlet disc (at ``origin + length * axis``)
    are fans of ``n_theta`` triangles around their centres. All normals point out of the lumen:
    the wall radially outward, the inlet towards -axis, the outlet towards +axis. Merged, the
    three solids form a closed, consistently wound surface enclosing the regular-polygon prism of
    volume ``n_theta / 2 * radius**2 * sin(2 pi / n_theta) * length``. A slightly tilted axis
    avoids axis-aligned flow, whose round-off transverse components keep OpenFOAM's normalised
    Ux/Uy residuals from dropping below ~1e-4.

    Parameters
    ----------
    path : str or Path
        Output ASCII STL.
    radius : float
        Tube radius (m), > 0.
    length : float
        Tube length (m), > 0.
    n_theta : int
        Vertices around each ring (>= 3); vertex j at angle 2 pi j / n_theta from e1 towards e2.
    n_z : int
        Axial wall segments (>= 1), equally spaced.
    origin : (3,) float
        Inlet centre (m).
    axis : (3,) float
        Tube direction (normalised here). The section frame is e1 = axis x x_hat (axis x y_hat
        when |axis_x| >= 0.9, normalised), e2 = axis x e1.

    Returns
    -------
    Path
        ``path``, holding the solids ``wall`` (2 n_z n_theta triangles), ``inlet`` and ``outlet``
        (n_theta triangles each), in that order.

    Raises
    ------
    VCSInputError
        Non-positive radius or length, n_theta < 3, n_z < 1 or a zero axis.
    """
    path = Path(path)
    if not (radius > 0 and length > 0) or int(n_theta) < 3 or int(n_z) < 1:
        raise VCSInputError(
            f"closed tube: need radius > 0, length > 0, n_theta >= 3 and n_z >= 1 "
            f"(got {radius}, {length}, {n_theta}, {n_z})"
        )
    n_theta, n_z = int(n_theta), int(n_z)
    o = np.asarray(origin, float).reshape(3)
    rot = _axis_frame(axis)
    th = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)
    zs = np.linspace(0.0, length, n_z + 1)
    # local coordinates (e1, e2, axis): rings k = 0..n_z, then the inlet and outlet centres
    local = np.empty(((n_z + 1) * n_theta + 2, 3))
    local[:-2, 0] = np.tile(radius * np.cos(th), n_z + 1)
    local[:-2, 1] = np.tile(radius * np.sin(th), n_z + 1)
    local[:-2, 2] = np.repeat(zs, n_theta)
    local[-2:] = [[0.0, 0.0, 0.0], [0.0, 0.0, length]]
    vertices = o + local @ rot.T
    ring = np.arange((n_z + 1) * n_theta).reshape(n_z + 1, n_theta)
    lo, hi = ring[:-1], ring[1:]
    lo_next, hi_next = np.roll(lo, -1, axis=1), np.roll(hi, -1, axis=1)
    # per quad (ring k, angle i): (lo_i, lo_i+1, hi_i+1) and (lo_i, hi_i+1, hi_i); normal e_theta x axis = +e_r
    wall = np.stack([np.stack([lo, lo_next, hi_next], -1), np.stack([lo, hi_next, hi], -1)], axis=2).reshape(-1, 3)
    c_in, c_out = len(vertices) - 2, len(vertices) - 1
    first, last = ring[0], ring[-1]
    inlet = np.stack([np.full(n_theta, c_in), np.roll(first, -1), first], -1)  # clockwise seen from +axis: -axis
    outlet = np.stack([np.full(n_theta, c_out), last, np.roll(last, -1)], -1)  # counter-clockwise: +axis
    write_stl_ascii(path, {"wall": vertices[wall], "inlet": vertices[inlet], "outlet": vertices[outlet]})
    return path
