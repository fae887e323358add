"""Meshing shared by every synthetic phantom: a tube swept around a centreline (lengths in mm).

A phantom's surface is a regular (s, phi) grid of rings around its centreline c(s):

    x(s, phi) = c(s) + r(s, phi) * (cos(phi) v1(s) + sin(phi) v2(s)),

with s in [0, 1] proportional to arc length, {t, v1, v2} a right-handed rotation-minimising frame
(v2 = t x v1) and phi the angle from v1 towards v2. Each quad of the grid is split into two
triangles, oriented so that their normals point out of the lumen. The two ends are left open
(two boundary loops; the loop at s = 0 is the inlet). Vertices are stored ring by ring
(``params["n_s"]`` rings of ``params["n_phi"]`` vertices, phi_j = 2 pi j / n_phi).

This module holds the :class:`Phantom` record, what a kind's generator hands back
(:class:`SweptSurface`), the rings -> triangles meshing (:func:`sweep_tube` for any polyline),
ring spacing, the reach (self-intersection) check, the parameter helpers and the STL writer
(through :func:`vcs.mesh.write_stl_binary`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from vcs.errors import VCSInputError
from vcs.frame import rotation_minimizing_frame
from vcs.mesh import write_stl_binary

__all__ = ["CenterlineFn", "FrameFn", "Phantom", "RadiusFn", "SweptSurface", "sweep_tube", "write_stl"]

#: ``centerline(s)``: s (...) in [0, 1] -> points (..., 3) in mm.
CenterlineFn = Callable[[ArrayLike], NDArray[np.floating]]
#: ``radius(s, phi)``: s in [0, 1] and phi in rad, broadcast together -> wall radius in mm.
RadiusFn = Callable[[ArrayLike, ArrayLike], NDArray[np.floating]]
#: ``frame(s)``: s (...) in [0, 1] -> unit vectors ``(t, v1, v2)``, each (..., 3).
FrameFn = Callable[[ArrayLike], tuple[NDArray[np.floating], NDArray[np.floating], NDArray[np.floating]]]


@dataclass(frozen=True)
class Phantom:
    """A synthetic vessel surface with its exact generating geometry (mm).

    Attributes
    ----------
    vertices : (n_s * n_phi, 3) float
        Surface vertices (mm), ring by ring from the inlet.
    faces : (2 (n_s - 1) n_phi, 3) int64
        Triangles, outward normals; both ends open.
    kind : str
        ``"tube"``, ``"torus"``, ``"helix"`` or ``"aorta"``.
    params : dict
        Every generator parameter, given, drawn or derived (JSON-serialisable scalars), with
        ``n_s``, ``n_phi``, ``n_vertices`` and ``n_triangles``.
    inlet_center, outlet_center : (3,) float
        ``centerline(0)`` and ``centerline(1)`` (mm).
    centerline : callable
        ``centerline(s)``: s (...) in [0, 1], proportional to arc length -> (..., 3) points (mm).
    radius : callable
        ``radius(s, phi)``: wall distance (mm) from ``centerline(s)`` at angle phi (rad),
        broadcasting s against phi.
    frame : callable or None
        ``frame(s)`` -> ``(t, v1, v2)``, each (..., 3): the generator's rotation-minimising frame,
        in which phi is measured (phi = 0 along v1, pi/2 along v2 = t x v1).
    """

    vertices: NDArray[np.floating]
    faces: NDArray[np.integer]
    kind: str
    params: dict
    inlet_center: NDArray[np.floating]
    outlet_center: NDArray[np.floating]
    centerline: CenterlineFn
    radius: RadiusFn
    frame: FrameFn | None = None


class SweptSurface(NamedTuple):
    """What a phantom kind's generator returns, before :func:`_finish` makes it a :class:`Phantom`.

    Attributes
    ----------
    vertices : (n_s * n_phi, 3) float
        Ring-by-ring grid vertices (mm).
    faces : (2 (n_s - 1) n_phi, 3) int64
        Outward triangles.
    params : dict
        Generator parameters (given, drawn and derived), including ``length_mm``, ``n_phi`` and
        ``n_s``.
    centerline : callable
        ``centerline(s)``, s in [0, 1] -> (..., 3) mm.
    radius : callable
        ``radius(s, phi)`` -> mm.
    frame : callable
        ``frame(s)`` -> ``(t, v1, v2)``, each (..., 3).
    ring_s : (n_s,) float
        s of each ring, increasing from 0 to 1.
    """

    vertices: NDArray[np.floating]
    faces: NDArray[np.integer]
    params: dict
    centerline: CenterlineFn
    radius: RadiusFn
    frame: FrameFn
    ring_s: NDArray[np.floating]


# ----------------------------------------------------------------------------------------------
# generic sweep


def _grid_mesh(
    centers: ArrayLike, v1: ArrayLike, v2: ArrayLike, r: NDArray[np.floating], phi: NDArray[np.floating]
) -> tuple[NDArray[np.floating], NDArray[np.int64]]:
    """Vertices/faces of the (s, phi) grid; outward when v2 = t x v1 and s runs along t.

    ``centers``, ``v1``, ``v2``: (n_s, 3); ``r``: (n_s, n_phi) mm; ``phi``: (n_phi,) rad.
    Returns vertices (n_s * n_phi, 3) and faces (2 (n_s - 1) n_phi, 3) int64.
    """
    centers, v1, v2 = (np.asarray(a, float) for a in (centers, v1, v2))
    n_s, n_phi = r.shape
    d = np.cos(phi)[None, :, None] * v1[:, None, :] + np.sin(phi)[None, :, None] * v2[:, None, :]
    V = (centers[:, None, :] + r[..., None] * d).reshape(-1, 3)
    idx = np.arange(n_s * n_phi).reshape(n_s, n_phi)
    a, b = idx[:-1], idx[1:]
    a2, b2 = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
    # (a -> a2) runs along +phi, (a2 -> b2) along +s: normal e_phi x t = +e_r (outward)
    F = np.stack([np.stack([a, a2, b2], -1), np.stack([a, b2, b], -1)], axis=2).reshape(-1, 3)
    return V, F.astype(np.int64)


def _least_aligned_normal(t: NDArray[np.floating]) -> NDArray[np.floating]:
    """Unit vector normal to the unit vector ``t`` (3,): the coordinate axis least aligned with it."""
    axis = np.eye(3)[int(np.argmin(np.abs(t)))]
    p = axis - (axis @ t) * t
    return p / np.linalg.norm(p)


def sweep_tube(
    centerline_pts: ArrayLike,
    radius_fn: float | RadiusFn,
    *,
    n_phi: int | None = None,
    edge: float = 1.0,
    tangents: ArrayLike | None = None,
    v1_0: ArrayLike | None = None,
    frames: tuple[ArrayLike, ArrayLike] | None = None,
) -> tuple[NDArray[np.floating], NDArray[np.int64]]:
    """Open tube around a polyline: one ring of ``n_phi`` vertices per centreline point.

    Parameters
    ----------
    centerline_pts : (n, 3) float, n >= 2
        Ring centres (mm), in order from the inlet (s = 0) to the outlet (s = 1).
    radius_fn : float or callable ``(s, phi) -> r``
        Lumen radius (mm); ``s`` is the normalised cumulative polyline length, broadcast as an
        (n, 1) column against phi as a (1, n_phi) row. Must be positive (star-shaped sections).
    n_phi : int, optional
        Vertices per ring. Default: ``ceil(2 pi r_max / edge)`` (at least 8), r_max taken from
        ``radius_fn`` on a 64-angle probe.
    edge : float
        Target circumferential edge (mm) used when ``n_phi`` is not given.
    tangents : (n, 3) float, optional
        Unit tangents; default: arc-length finite differences of the polyline.
    v1_0 : (3,) float, optional
        v1 at the first point (projected onto its normal plane); default: the coordinate axis
        least aligned with the first tangent.
    frames : ((n, 3), (n, 3)), optional
        Explicit (v1, v2) at every point (bypasses the rotation-minimising transport).

    Returns
    -------
    vertices : (n * n_phi, 3) float
        Ring by ring (mm), phi_j = 2 pi j / n_phi from v1 towards v2.
    faces : (2 (n - 1) n_phi, 3) int64
        Outward normals (flipped if the frame is left-handed), open ends.

    Raises
    ------
    VCSInputError
        Fewer than two points, repeated consecutive points or a non-positive radius.
    """
    P = np.asarray(centerline_pts, float)
    if P.ndim != 2 or P.shape[1] != 3 or len(P) < 2:
        raise VCSInputError("sweep_tube needs centreline points as an (n >= 2, 3) array")
    seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
    if np.any(seg <= 0):
        raise VCSInputError("sweep_tube: consecutive centreline points must be distinct")
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    s = arc / arc[-1]
    if tangents is None:
        t = np.gradient(P, arc, axis=0, edge_order=2 if len(P) > 2 else 1)
    else:
        t = np.asarray(tangents, float)
    t = t / np.linalg.norm(t, axis=1, keepdims=True)
    if frames is None:
        if v1_0 is None:
            v = _least_aligned_normal(t[0])
        else:
            v = np.asarray(v1_0, float)
            v = v - (v @ t[0]) * t[0]
            v = v / np.linalg.norm(v)
        v1 = rotation_minimizing_frame(P, t, v)
        v2 = np.cross(t, v1)
    else:
        v1, v2 = (np.asarray(f, float) for f in frames)

    if callable(radius_fn):
        rfun = radius_fn
    else:
        rconst = float(radius_fn)
        rfun = lambda ss, pp: np.full(np.broadcast_shapes(np.shape(ss), np.shape(pp)), rconst)  # noqa: E731
    if n_phi is None:
        probe = np.linspace(0, 2 * np.pi, 64, endpoint=False)
        r_max = float(np.max(rfun(s[:, None], probe[None, :])))
        n_phi = max(8, int(np.ceil(2 * np.pi * r_max / edge)))
    phi = 2 * np.pi * np.arange(n_phi) / n_phi
    r = np.broadcast_to(rfun(s[:, None], phi[None, :]), (len(P), n_phi)).astype(float)
    if np.any(r <= 0):
        raise VCSInputError("sweep_tube: the radius must be positive everywhere")
    V, F = _grid_mesh(P, v1, v2, r, phi)
    if np.mean(np.sum(np.cross(v1, v2) * t, axis=1)) < 0:  # left-handed frame: flip to outward
        F = F[:, ::-1].copy()
    return V, F


# ----------------------------------------------------------------------------------------------
# grid helpers


def _n_around(r: float, h: float) -> int:
    """Vertices per ring for edges of about ``h`` mm around a circle of radius ``r`` mm (>= 12)."""
    return max(12, int(np.ceil(2 * np.pi * r / h)))


def _ring_s(
    length: float, mean_r: Callable[[NDArray[np.floating]], NDArray[np.floating]], n_phi: int
) -> NDArray[np.floating]:
    """Ring parameters (n_s,) in [0, 1] with axial spacing equal to the local circumferential edge.

    ``length``: centreline length (mm); ``mean_r(s)``: mean radius (mm) of the section at s.
    """
    u = np.linspace(0.0, 1.0, 4001)
    dens = n_phi / (2 * np.pi * mean_r(u)) * length  # rings per unit s
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(u))])
    n = max(2, int(np.ceil(cum[-1])))
    s = np.interp(np.linspace(0.0, cum[-1], n + 1), cum, u)
    s[0], s[-1] = 0.0, 1.0
    return s


def _reach_ok(
    vertices: NDArray[np.floating],
    ring_s: NDArray[np.floating],
    n_phi: int,
    centerline: CenterlineFn,
    length: float,
    tol_mm: float | None = None,
) -> bool:
    """True when every vertex's nearest centreline point is its own ring (no self-intersection).

    ``vertices`` (n_s * n_phi, 3) mm, ring by ring at ``ring_s`` (n_s,); ``length`` (mm) of the
    centreline; ``tol_mm`` the allowed axial mismatch (default 2 mm plus two probe steps).
    """
    n = max(200, int(np.ceil(length / 0.5)))
    u = np.linspace(0.0, 1.0, n + 1)
    tree = cKDTree(centerline(u))
    _, j = tree.query(vertices)
    tol = (tol_mm if tol_mm is not None else 2.0 + 2 * length / n) / length
    return bool(np.all(np.abs(u[j] - np.repeat(ring_s, n_phi)) <= tol))


def _const_radius(r0: float) -> RadiusFn:
    """``radius(s, phi)`` equal to ``r0`` mm everywhere (shape of s and phi broadcast)."""

    def radius(s: ArrayLike, phi: ArrayLike) -> NDArray[np.floating]:
        return np.full(np.broadcast_shapes(np.shape(s), np.shape(phi)), float(r0))

    return radius


def _finish(
    kind: str,
    V: ArrayLike,
    F: ArrayLike,
    params: dict,
    centerline: CenterlineFn,
    radius: RadiusFn,
    frame: FrameFn | None,
) -> Phantom:
    """The :class:`Phantom` of a meshed surface: contiguous arrays, plain-typed params with counts."""
    V = np.ascontiguousarray(V, dtype=float)
    F = np.ascontiguousarray(F, dtype=np.int64)
    params = {k: _plain(v) for k, v in params.items()}
    params["n_vertices"] = int(len(V))
    params["n_triangles"] = int(len(F))
    return Phantom(
        vertices=V,
        faces=F,
        kind=kind,
        params=params,
        inlet_center=np.asarray(centerline(np.array([0.0]))[0], float),
        outlet_center=np.asarray(centerline(np.array([1.0]))[0], float),
        centerline=centerline,
        radius=radius,
        frame=frame,
    )


def _plain(v: object) -> bool | int | float | str:
    """``v`` as a plain Python scalar (numpy scalars converted); TypeError for anything else."""
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, str):
        return v
    raise TypeError(f"phantom parameter of type {type(v).__name__} is not JSON-serialisable")


def _merge(defaults: dict, overrides: dict, kind: str) -> dict:
    """``defaults`` updated by ``overrides`` (cast to the default's type); unknown names are an error."""
    unknown = sorted(set(overrides) - set(defaults))
    if unknown:
        raise VCSInputError(
            f"unknown {kind} phantom parameter(s) {', '.join(unknown)}; allowed: {', '.join(sorted(defaults))}"
        )
    p = dict(defaults)
    for k, v in overrides.items():
        p[k] = type(defaults[k])(v)
    return p


def _s_array(s: ArrayLike) -> NDArray[np.floating]:
    """``s`` as a float array."""
    return np.asarray(s, float)


def write_stl(phantom: Phantom, path: str | Path) -> None:
    """Binary STL (single solid, float32, outward facet normals) of ``phantom``'s open surface (mm).

    Parameters
    ----------
    phantom : Phantom
        Surface to write (vertices in mm).
    path : str or Path
        Output file; the 80-byte header reads ``vcs phantom kind=<kind> seed=<seed> units=mm``.
    """
    header = f"vcs phantom kind={phantom.kind} seed={phantom.params.get('seed', 0)} units=mm"
    write_stl_binary(path, np.asarray(phantom.vertices, float), np.asarray(phantom.faces), header)
