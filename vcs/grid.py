"""The measurement grid: one regular (tau, theta, rho_n) grid per vessel (paper Section 2.4.2).

Every patient of an atlas is sampled at the same VCS coordinates, so its flow fields become one
fixed-length measurement vector:

    tau_i = i / (n_tau - 1),  theta_j = 2 pi j / n_theta,  rho_n,k = k / (n_rho - 1)
    x(tau, theta, rho_n) = c(tau) + rho_n rho_w(tau, theta) (v1 cos theta + v2 sin theta)   (Eq. 8 scaled)

``n_tau``, ``n_theta`` and ``n_rho`` are NODE counts everywhere (``vcs grid``, ``fields.npz``,
the ``grid:`` block of the workflow config): both ends of tau, the axis and the wall are nodes;
theta = 2 pi is not repeated. :func:`grid_axes` is the single definition; :func:`grid_points` maps
it through a model, :func:`measurement_grid` adds hexahedral cells for ``vcs grid``, and
:func:`vcs.cfd.resample.sample_case` samples CFD fields on exactly these nodes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError

if TYPE_CHECKING:
    import pyvista as pv

    from vcs.vessel import VesselModel

TWO_PI = 2.0 * np.pi
GRID_DEFAULTS = {"n_tau": 64, "n_theta": 32, "n_rho": 11}


# ---------------------------------------------------------------------------------------------
# The measurement grid (pure numpy)
# ---------------------------------------------------------------------------------------------
def grid_axes(
    n_tau: int, n_theta: int, n_rho: int
) -> tuple[NDArray[np.floating], NDArray[np.floating], NDArray[np.floating]]:
    """The grid's node coordinates along each axis (the single grid definition of the package).

    Parameters
    ----------
    n_tau, n_theta, n_rho : int, each >= 2
        Node counts along tau, around theta and along rho_n.

    Returns
    -------
    tau : (n_tau,) float
        Uniform on [0, 1], both ends included.
    theta : (n_theta,) float, rad
        2 pi j / n_theta (2 pi itself is not repeated).
    rho_n : (n_rho,) float
        Uniform on [0, 1]: the axis (0) and the wall (1) included.

    Raises
    ------
    VCSInputError
        When a count is below 2.

    Examples
    --------
    >>> from vcs.grid import grid_axes
    >>> tau, theta, rho_n = grid_axes(5, 4, 3)
    >>> tau
    array([0.  , 0.25, 0.5 , 0.75, 1.  ])
    >>> theta.round(4)
    array([0.    , 1.5708, 3.1416, 4.7124])
    >>> rho_n
    array([0. , 0.5, 1. ])
    """
    if min(n_tau, n_theta, n_rho) < 2:
        raise VCSInputError(f"the grid needs n_tau, n_theta, n_rho >= 2, got {n_tau}, {n_theta}, {n_rho}")
    return np.linspace(0.0, 1.0, n_tau), TWO_PI * np.arange(n_theta) / n_theta, np.linspace(0.0, 1.0, n_rho)


def grid_points(
    model: VesselModel, tau: ArrayLike, theta: ArrayLike, rho_n: ArrayLike
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Map the grid axes through a model: x = c(tau) + rho_n rho_w (v1 cos theta + v2 sin theta) (Eq. 8 scaled).

    Parameters
    ----------
    model : VesselModel
        With a wall model; lengths in mm.
    tau : (n_tau,) float
        Normalised arc length in [0, 1].
    theta : (n_theta,) float, rad
    rho_n : (n_rho,) float
        Radius as a fraction of rho_w (0 axis, 1 wall).

    Returns
    -------
    points : (n_tau, n_theta, n_rho, 3) float, mm
    rho_w : (n_tau, n_theta) float, mm
        The wall radius rho_w(tau, theta) (Eq. 5).

    Raises
    ------
    VCSInputError
        When the model has no wall model.
    """
    if model.wall is None:
        raise VCSInputError("the model has no wall model; refit it with `vcs fit` (K, R)")
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    rho_w = model.wall(T, TH)
    rho = rho_w[:, :, None] * np.asarray(rho_n)[None, None, :]
    pts = model.vcs.to_cartesian(T[:, :, None], TH[:, :, None], rho)
    return pts, rho_w


def local_frame(model: VesselModel, tau: ArrayLike, theta: ArrayLike) -> NDArray[np.floating]:
    """The local VCS frame (e_t, e_theta, e_rho) at each (tau, theta) of a grid.

    e_t = t(tau), e_theta = -v1 sin theta + v2 cos theta, e_rho = v1 cos theta + v2 sin theta
    (the unit vectors of Eq. 1's cylindrical coordinates).

    Parameters
    ----------
    model : VesselModel
    tau : (n_tau,) float
        Normalised arc length in [0, 1].
    theta : (n_theta,) float, rad

    Returns
    -------
    (n_tau, n_theta, 3, 3) float
        Rows e_t, e_theta, e_rho (unit vectors, dimensionless).
    """
    t, v1, v2 = model.vcs.frame(np.asarray(tau, float))
    c, s = np.cos(theta)[None, :, None], np.sin(theta)[None, :, None]
    t, v1, v2 = t[:, None, :], v1[:, None, :], v2[:, None, :]
    e_rho = c * v1 + s * v2
    e_th = -s * v1 + c * v2
    return np.stack(np.broadcast_arrays(t, e_th, e_rho), axis=-2)


def to_vcs_components(vectors: NDArray[np.floating], frame: NDArray[np.floating]) -> NDArray[np.floating]:
    """Components (u_t, u_theta, u_rho) of Cartesian vectors in the local VCS frame.

    Parameters
    ----------
    vectors : (n_tau, n_theta, 3) or (n_tau, n_theta, n_rho, 3) float
        Cartesian vectors (any unit, e.g. m/s or Pa).
    frame : (n_tau, n_theta, 3, 3) float
        From :func:`local_frame`.

    Returns
    -------
    float array of the shape of ``vectors``
        Components along e_t, e_theta, e_rho, in the unit of ``vectors``.
    """
    if vectors.ndim == 4:
        return np.einsum("ijab,ijkb->ijka", frame, vectors)
    return np.einsum("ijab,ijb->ija", frame, vectors)


def from_vcs_components(components: NDArray[np.floating], frame: NDArray[np.floating]) -> NDArray[np.floating]:
    """Cartesian vectors from their local VCS components (inverse of :func:`to_vcs_components`).

    Parameters
    ----------
    components : (n_tau, n_theta, 3) or (n_tau, n_theta, n_rho, 3) float
        Components along e_t, e_theta, e_rho (any unit).
    frame : (n_tau, n_theta, 3, 3) float
        From :func:`local_frame`.

    Returns
    -------
    float array of the shape of ``components``
        Cartesian vectors, in the unit of ``components``.
    """
    if components.ndim == 4:
        return np.einsum("ijab,ijka->ijkb", frame, components)
    return np.einsum("ijab,ija->ijb", frame, components)


def grid_to_vtk(
    points: NDArray[np.floating],
    point_arrays: dict[str, NDArray[np.floating]] | None = None,
    *,
    close_theta: bool = True,
) -> pv.UnstructuredGrid | pv.PolyData:
    """A (n_tau, n_theta, n_rho) or (n_tau, n_theta) grid as a pyvista UnstructuredGrid/PolyData.

    With ``close_theta`` the theta = 0 layer is repeated at 2 pi so the surface has no seam.
    Arrays have the grid's leading shape (plus a trailing 3 for vectors).

    Parameters
    ----------
    points : (n_tau, n_theta, n_rho, 3) or (n_tau, n_theta, 3) float
        Grid points (any length unit; written as given).
    point_arrays : dict of str -> float array, optional
        Point data, each of shape (n_tau, n_theta[, n_rho]) or with a trailing component axis.
    close_theta : bool
        Repeat the theta = 0 layer at theta = 2 pi.

    Returns
    -------
    pyvista.UnstructuredGrid or pyvista.PolyData
        Hexahedra for a volume grid, the quad surface for a (n_tau, n_theta) grid.
    """
    import pyvista as pv

    point_arrays = point_arrays or {}
    if close_theta:
        points = np.concatenate([points, points[:, :1]], axis=1)
        point_arrays = {k: np.concatenate([v, v[:, :1]], axis=1) for k, v in point_arrays.items()}
    if points.ndim == 3:
        points = points[:, :, None]
        point_arrays = {k: v[:, :, None] for k, v in point_arrays.items()}
    n0, n1, n2 = points.shape[:3]
    g = pv.StructuredGrid()
    g.points = points.transpose(2, 1, 0, 3).reshape(-1, 3)  # VTK: first index fastest
    g.dimensions = (n0, n1, n2)
    for k, v in point_arrays.items():
        v = np.asarray(v)
        tail = v.shape[3:]
        g.point_data[k] = v.transpose(2, 1, 0, *range(3, v.ndim)).reshape(-1, *tail)
    if n2 == 1:
        return g.extract_surface(algorithm="dataset_surface")
    return g.cast_to_unstructured_grid()


@dataclass(frozen=True)
class MeasurementGrid:
    """Hexahedral grid of the lumen in (tau, theta, rho_n).

    Attributes
    ----------
    points : (N, 3) float, mm
    cells : (C, 8) int
        Point indices in VTK hexahedron order.
    tau, theta, rho_n : (N,) float
        VCS coordinates of every point (theta in rad).
    """

    points: NDArray[np.floating]
    cells: NDArray[np.integer]
    tau: NDArray[np.floating]
    theta: NDArray[np.floating]
    rho_n: NDArray[np.floating]


def _ogrid_pattern(n_theta: int, n_rho: int) -> tuple[NDArray[np.floating], NDArray[np.integer], NDArray[np.floating]]:
    """O-grid cross-section: (P, 2) points in the unit disk, (Q, 4) quads (counter-clockwise about
    t) and (P,) theta. A Cartesian core square (half-width 0.5 / sqrt 2, n_theta / 4 cells a side)
    is blended ring by ring into the circle rho_n = 1 (n_rho // 2 rings): no degenerate cell."""
    if n_theta % 4:
        raise VCSInputError(f"--n-theta {n_theta} must be a multiple of 4 for the ogrid scheme")
    m = n_theta // 4
    half = 0.5 / np.sqrt(2.0)
    g = np.linspace(-half, half, m + 1)
    X, Y = np.meshgrid(g, g, indexing="ij")
    core = np.column_stack([X.ravel(), Y.ravel()])
    cid = np.arange((m + 1) ** 2).reshape(m + 1, m + 1)
    Qc = np.stack([cid[:-1, :-1], cid[1:, :-1], cid[1:, 1:], cid[:-1, 1:]], -1).reshape(-1, 4)
    # boundary of the core, counter-clockwise from (half, -half) ... as a ring of 4 m points
    ring_ids = np.concatenate([cid[m, :m], cid[m:0:-1, m], cid[0, m:0:-1], cid[:m, 0]])
    sq = core[ring_ids]
    ang = np.arctan2(sq[:, 1], sq[:, 0])
    circ = np.column_stack([np.cos(ang), np.sin(ang)])
    n_out = max(1, n_rho // 2)
    P = [core]
    prev = ring_ids
    Q = [Qc]
    start = len(core)
    for k in range(1, n_out + 1):
        s = k / n_out
        ring = (1 - s) * sq + s * circ
        ids = start + np.arange(len(ring))
        P.append(ring)
        Q.append(np.stack([prev, ids, np.roll(ids, -1), np.roll(prev, -1)], -1))  # CCW about t
        prev, start = ids, start + len(ring)
    P_all, Q_all = np.concatenate(P), np.concatenate(Q)
    return P_all, Q_all, np.mod(np.arctan2(P_all[:, 1], P_all[:, 0]), TWO_PI)


def _cylindrical_cells(n_tau: int, n_theta: int, n_rho: int) -> NDArray[np.integer]:
    """Hexahedra between the nodes (i, j, k) of a (n_tau, n_theta, n_rho) C-ordered node array,
    periodic in theta; cells touching the axis (k = 0) are degenerate, as in the paper's grid."""
    idx = np.arange(n_tau * n_theta * n_rho).reshape(n_tau, n_theta, n_rho)
    nxt = np.roll(idx, -1, axis=1)  # theta + 1 (periodic)
    a, b = idx[:, :, :-1], idx[:, :, 1:]  # rho k, k + 1
    c, d = nxt[:, :, 1:], nxt[:, :, :-1]
    quad = np.stack([a, b, c, d], -1)  # counter-clockwise about t
    return np.concatenate([quad[:-1], quad[1:]], axis=-1).reshape(-1, 8)


def measurement_grid(
    model: VesselModel,
    *,
    n_tau: int = GRID_DEFAULTS["n_tau"],
    n_theta: int = GRID_DEFAULTS["n_theta"],
    n_rho: int = GRID_DEFAULTS["n_rho"],
    scheme: str = "cylindrical",
) -> MeasurementGrid:
    """The measurement grid of a vessel model with hexahedral cells (paper Section 2.4.2).

    Parameters
    ----------
    model : VesselModel
        With a wall model; lengths in mm.
    n_tau, n_theta, n_rho : int
        Node counts, as for :func:`grid_axes`.
    scheme : {"cylindrical", "ogrid"}
        ``cylindrical`` (the paper's): exactly the nodes of :func:`grid_points` in its C order
        (tau, theta, rho_n), i.e. the nodes ``fields.npz`` holds for the same counts.
        ``ogrid``: a visual alternative with a Cartesian core (no degenerate cell at the axis):
        the same tau nodes, n_theta points on the wall, n_rho // 2 blending rings.

    Returns
    -------
    MeasurementGrid
        Points in mm.

    Raises
    ------
    VCSInputError
        For an unknown scheme, counts below 2, n_theta not a multiple of 4 (``ogrid``), or a
        model without a wall model.
    """
    if scheme not in ("cylindrical", "ogrid"):
        raise VCSInputError(f"unknown grid scheme '{scheme}'; use cylindrical or ogrid")
    tau, theta, rho_n = grid_axes(n_tau, n_theta, n_rho)
    if scheme == "cylindrical":
        pts, _ = grid_points(model, tau, theta, rho_n)
        T, TH, RN = np.meshgrid(tau, theta, rho_n, indexing="ij")
        return MeasurementGrid(
            pts.reshape(-1, 3), _cylindrical_cells(n_tau, n_theta, n_rho), T.ravel(), TH.ravel(), RN.ravel()
        )
    if model.wall is None:
        raise VCSInputError("the model has no wall model; refit it with `vcs fit` (K, R)")
    P, Q, theta_p = _ogrid_pattern(n_theta, n_rho)
    rho_p = np.linalg.norm(P, axis=1)
    T = np.repeat(tau, len(P))
    TH = np.tile(theta_p, len(tau))
    RN = np.tile(rho_p, len(tau))
    pts = model.vcs.to_cartesian(T, TH, RN * model.wall(T, TH))
    n = len(P)
    layer = np.arange(n_tau - 1)[:, None, None] * n
    cells = np.concatenate([Q[None] + layer, Q[None] + layer + n], axis=2).reshape(-1, 8)
    return MeasurementGrid(pts, cells, T, TH, RN)
