"""Wall model rho_w(tau, theta): bicubic tensor-product B-spline, periodic in theta.

Paper Section 2.3.1 (Eqs. 5-7): rho_w(tau, theta) = sum_ij b_ij B_i(tau) B_j(theta), K uniform
interior knots in tau (clamped, K + 4 functions) and R uniform interior knots in theta on
[0, 2 pi) (periodic, C2: R + 1 functions). Fitted here by one sparse linear least-squares solve
with a small second-difference penalty (instead of the paper's SLSQP on a penalised loss).
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.interpolate import BSpline, NdBSpline
from scipy.sparse import linalg as sparse_linalg

from vcs.centerline import group_median, uniform_knots
from vcs.errors import VCSInputError
from vcs.mesh import edge_topology, triangle_cross, vertex_adjacency, vertex_normals

if TYPE_CHECKING:
    from vcs.model import VesselCoordinateSystem

log = logging.getLogger(__name__)

TWO_PI = 2.0 * np.pi


def periodic_knots(n_interior: int, k: int = 3) -> NDArray[np.floating]:
    """Uniform knot vector of a periodic spline in theta on [0, 2 pi) (paper Section 2.3.1, Eq. 5).

    With R = ``n_interior`` interior knots the period holds R + 1 equal spans; the vector is
    extended by ``k`` spans on both sides, so there are R + 1 distinct basis functions (the
    coefficient index is folded modulo R + 1).

    Parameters
    ----------
    n_interior : int
        R, the number of interior knots in [0, 2 pi) (R >= 0).
    k : int
        Spline degree (3: cubic).

    Returns
    -------
    (R + 2 k + 2,) float, rad
        Knots d * (-k, ..., R + 1 + k) with d = 2 pi / (R + 1).
    """
    n = n_interior + 1
    d = TWO_PI / n
    return d * np.arange(-k, n + k + 1)


def periodic_design_matrix(theta: ArrayLike, n_interior: int, k: int = 3) -> sparse.csr_matrix:
    """Periodic B-spline basis B_j(theta) of the wall model at the given angles (Eq. 5, theta part).

    Parameters
    ----------
    theta : (N,) float, rad
        Angles, any real value (wrapped to [0, 2 pi)).
    n_interior : int
        R, the number of interior knots in theta.
    k : int
        Spline degree (3: cubic).

    Returns
    -------
    scipy.sparse.csr_matrix, (N, R + 1) float
        Row i holds B_j(theta_i), j = 0..R (dimensionless, each row sums to 1).
    """
    n = n_interior + 1
    th = np.mod(np.asarray(theta, float), TWO_PI)
    B = BSpline.design_matrix(th, periodic_knots(n_interior, k), k).tocoo()
    return sparse.csr_matrix((B.data, (B.row, B.col % n)), shape=(len(th), n))


def tensor_design_matrix(tau: ArrayLike, theta: ArrayLike, K: int, R: int) -> sparse.csr_matrix:
    """Tensor-product basis B_i(tau) B_j(theta) of the wall model at samples (Eq. 5).

    Row-wise Kronecker product of the clamped cubic basis in tau and the periodic cubic basis in
    theta.

    Parameters
    ----------
    tau : (N,) float
        Normalised arc length in [0, 1] (clipped to it).
    theta : (N,) float, rad
        Angles, any real value (wrapped).
    K : int
        Interior knots in tau (K + 4 functions).
    R : int
        Interior knots in theta (R + 1 functions).

    Returns
    -------
    scipy.sparse.csr_matrix, (N, (K + 4) (R + 1)) float
        Column i (R + 1) + j holds B_i(tau) B_j(theta), matching ``coefficients.ravel()`` of a
        :class:`WallModel`.
    """
    Bt = BSpline.design_matrix(np.clip(tau, 0, 1), uniform_knots(K), 3).tocsr()
    Bp = periodic_design_matrix(theta, R)
    nt, nth = Bt.shape[1], Bp.shape[1]
    Bt.sort_indices()
    Bp.sort_indices()
    it = Bt.indices.reshape(-1, 4)
    ip = Bp.indices.reshape(-1, 4) if Bp.nnz == 4 * Bp.shape[0] else None
    if ip is None:  # duplicate folded columns summed: fall back to a generic product
        rows = [sparse.kron(Bt[i], Bp[i]) for i in range(Bt.shape[0])]
        return sparse.vstack(rows).tocsr()
    vt = Bt.data.reshape(-1, 4)
    vp = Bp.data.reshape(-1, 4)
    cols = (it[:, :, None] * nth + ip[:, None, :]).reshape(len(it), 16)
    vals = (vt[:, :, None] * vp[:, None, :]).reshape(len(it), 16)
    indptr = np.arange(0, 16 * len(it) + 1, 16)
    return sparse.csr_matrix((vals.ravel(), cols.ravel(), indptr), shape=(len(it), nt * nth))


@dataclass(frozen=True)
class WallModel:
    """Wall model rho_w(tau, theta): a bicubic B-spline, clamped in tau, periodic in theta (Eq. 5).

    rho_w(tau, theta) = sum_ij b_ij B_i(tau) B_j(theta) (paper Section 2.3.1, Eqs. 5-7).

    Attributes
    ----------
    K : int
        Interior knots in tau (uniform, clamped: K + 4 basis functions), K >= 0.
    R : int
        Interior knots in theta (uniform, periodic on [0, 2 pi): R + 1 basis functions), R >= 0.
    coefficients : (K + 4, R + 1) float, mm
        The coefficients b_ij.

    Raises
    ------
    VCSInputError
        When K or R is negative or ``coefficients`` is not of shape (K + 4, R + 1).
    """

    K: int
    R: int
    coefficients: NDArray[np.floating]
    # the evaluator, built in __post_init__ (not an argument, not compared, not shown)
    _spline: NdBSpline = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Check the sizes and build the tensor-product spline evaluator."""
        k = self.K + 4
        n = self.R + 1
        if self.K < 0 or self.R < 0:
            raise VCSInputError(f"the wall model needs K >= 0 and R >= 0 interior knots, got K={self.K}, R={self.R}")
        if np.shape(self.coefficients) != (k, n):
            raise VCSInputError(
                f"wall model coefficients have shape {np.shape(self.coefficients)}, "
                f"but K={self.K}, R={self.R} need (K + 4, R + 1) = ({k}, {n})"
            )
        ext = self.coefficients[:, np.arange(n + 3) % n]  # periodic extension for NdBSpline
        object.__setattr__(self, "_spline", NdBSpline((uniform_knots(self.K), periodic_knots(self.R)), ext, 3))

    def __call__(self, tau: ArrayLike, theta: ArrayLike) -> NDArray[np.floating]:
        """Wall radius rho_w(tau, theta) (Eq. 5), vectorised over broadcastable inputs.

        Parameters
        ----------
        tau : float or array of float
            Normalised arc length; clipped to [0, 1].
        theta : float or array of float, rad
            Angle about the centerline; wrapped to [0, 2 pi).

        Returns
        -------
        array of float, mm
            rho_w, of the broadcast shape of ``tau`` and ``theta``.
        """
        tau, theta = np.broadcast_arrays(np.asarray(tau, float), np.asarray(theta, float))
        xi = np.stack([np.clip(tau, 0, 1).ravel(), np.mod(theta, TWO_PI).ravel()], axis=-1)
        return self._spline(xi).reshape(tau.shape)

    def with_coefficients(self, b: ArrayLike) -> WallModel:
        """The same knots with other coefficients.

        Parameters
        ----------
        b : (K + 4, R + 1) or ((K + 4) (R + 1),) float, mm
            New coefficients b_ij (row-major when flat, as in the feature vector).

        Returns
        -------
        WallModel
        """
        return WallModel(self.K, self.R, np.asarray(b, float).reshape(self.coefficients.shape))

    def to_dict(self) -> dict[str, Any]:
        """The model as plain JSON values (the ``wall`` block of model.json).

        Returns
        -------
        dict
            ``K``, ``R``, ``degree`` (3), descriptions of the knots and ``coefficients``
            ((K + 4) lists of R + 1 floats, mm).
        """
        return {
            "K": int(self.K),
            "R": int(self.R),
            "degree": 3,
            "tau_knots": "clamped uniform, K interior",
            "theta_knots": "periodic uniform on [0, 2pi), R interior (R + 1 functions)",
            "coefficients": [[float(v) for v in row] for row in self.coefficients],
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> WallModel:
        """Rebuild a model from :meth:`to_dict` output.

        Parameters
        ----------
        d : dict
            With keys ``K``, ``R`` and ``coefficients`` ((K + 4) x (R + 1) nested list, mm).

        Returns
        -------
        WallModel
        """
        return cls(int(d["K"]), int(d["R"]), np.array(d["coefficients"], float))


@functools.lru_cache(maxsize=8)
def _penalty_gram(K: int, R: int) -> sparse.csr_matrix:
    """P^T P of the second-difference penalty :func:`_penalty` (built once per K, R; not to be modified)."""
    P = _penalty(K, R)
    return P.T @ P


def _penalty(K: int, R: int) -> sparse.csr_matrix:
    """Second differences of the coefficient grid along tau (open) and theta (periodic)."""
    nt, nth = K + 4, R + 1
    Dt = sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(nt - 2, nt))
    Dp = sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(nth, nth + 2)).tolil()
    Dp = sparse.csr_matrix(Dp)
    fold = sparse.csr_matrix((np.ones(nth + 2), (np.arange(nth + 2), np.arange(nth + 2) % nth)), shape=(nth + 2, nth))
    Dp = Dp @ fold
    return sparse.vstack([sparse.kron(Dt, sparse.eye(nth)), sparse.kron(sparse.eye(nt), Dp)]).tocsr()


def lsq_wall(
    tau: ArrayLike, theta: ArrayLike, rho: ArrayLike, weights: ArrayLike, K: int, R: int, smoothing: float = 1e-5
) -> WallModel:
    """Weighted least-squares fit of the wall model rho_w to (tau, theta, rho) samples (Eqs. 5-7).

    Minimises sum_i w_i (rho_w(tau_i, theta_i) - rho_i)^2 + lambda |D b|^2, with D the second
    differences of the coefficient grid and lambda = ``smoothing`` * mean diagonal of B^T W B
    (a tiny, documented penalty: knot spans without data get a smooth in-fill instead of an
    ill-posed solve). One sparse Cholesky-free solve of a (K+4)(R+1) system.

    Parameters
    ----------
    tau : (N,) float
        Normalised arc length of the samples, in [0, 1].
    theta : (N,) float, rad
        Angles of the samples.
    rho : (N,) float, mm
        Distances of the samples from the centerline.
    weights : (N,) float
        Sample weights w_i (e.g. vertex areas, mm^2; only their ratios matter).
    K : int
        Interior knots in tau.
    R : int
        Interior knots in theta.
    smoothing : float
        Relative penalty weight (dimensionless).

    Returns
    -------
    WallModel
    """
    return _solve_wall(tensor_design_matrix(tau, theta, K, R), rho, weights, K, R, smoothing)


def _solve_wall(
    B: sparse.csr_matrix, rho: ArrayLike, weights: ArrayLike, K: int, R: int, smoothing: float
) -> WallModel:
    """The solve of :func:`lsq_wall` given its design matrix ``B`` (N, (K + 4) (R + 1)) at the samples."""
    W = sparse.diags(np.asarray(weights, float))
    A = (B.T @ W @ B).tocsc()
    lam = smoothing * A.diagonal().mean()
    M = A + lam * _penalty_gram(K, R)
    b = sparse_linalg.spsolve(M.tocsc(), B.T @ (np.asarray(weights) * rho))
    return WallModel(K, R, b.reshape(K + 4, R + 1))


@dataclass(frozen=True)
class WallFit:
    """Result of :func:`fit_wall`: the model, per-vertex arrays and the report.

    The arrays hold the n wall vertices that were evaluated (those used by a wall face).

    Attributes
    ----------
    model : WallModel
    points : (n, 3) float, mm
        Wall vertices.
    tau, theta, rho : (n,) float
        Their VCS coordinates (theta in rad, rho in mm).
    residual : (n,) float, mm
        |p - x(tau(p), theta(p))| = |rho - rho_w(tau, theta)| (Eq. 11).
    used : (n,) bool
        The vertex took part in the final fit.
    reason : (n,) int
        Why a vertex was (not) used, a key of :data:`REASONS`.
    report : dict
        JSON-ready summary: counts per reason, residual statistics (mm), K, R, smoothing.
    """

    model: WallModel
    points: NDArray[np.floating]  # (n, 3) wall vertices, mm
    tau: NDArray[np.floating]
    theta: NDArray[np.floating]
    rho: NDArray[np.floating]
    residual: NDArray[np.floating]  # |p - x(tau(p), theta(p))| (Eq. 11), mm; nan where not evaluated
    used: NDArray[np.bool_]  # bool
    reason: NDArray[np.integer]  # int code, see REASONS
    report: dict[str, Any]


REASONS = {0: "used", 1: "beyond_end_planes", 2: "outside_omega", 3: "not_first_crossing", 4: "branch"}


def _too_few_points_message(
    vcs: VesselCoordinateSystem, rho: NDArray[np.floating], tri: NDArray[np.floating], n: int, K: int, R: int
) -> str:
    """The one-line error when fewer wall vertices than wall coefficients lie inside the section.

    Two causes, told apart by the knot span along tau, length / (K + 1): a section shorter than
    (K + 1) / 2 lumen radii is too short for K (the README's rule is K + 1 ~ length / radius; a
    smaller K is the fix, a finer mesh would only fit noise); otherwise the mesh is coarse for
    the knot spans (remesh finer, or lower K/R).

    Parameters
    ----------
    vcs : VesselCoordinateSystem
        The section's coordinate system (mm).
    rho : (n,) float, mm
        Radii of the usable wall vertices.
    tri : (M, 3, 3) float, mm
        Wall triangles.
    n : int
        Number of usable wall vertices.
    K, R : int
        Interior knots in tau and theta.

    Returns
    -------
    str
    """
    n_min = (K + 4) * (R + 1)
    length = float(vcs.length)
    radius = float(np.median(rho)) if len(rho) else float("nan")
    edge = float(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).mean()) if len(tri) else float("nan")
    head = f"only {n} wall vertices lie inside the section, fewer than the {n_min} wall coefficients (K={K}, R={R})"
    k_max = n // (R + 1) - 4  # the largest K these vertices can determine with this R
    if np.isfinite(radius) and length < 0.5 * (K + 1) * radius:
        k_rule = max(1, int(round(length / radius)) - 1)
        fix = f"give --K {max(1, min(k_rule, k_max))}" if k_max >= 1 else "give a smaller --K and --R"
        return (
            f"{head}: the section is only {length:.3g} mm long ({length / radius:.2g} lumen radii of "
            f"{radius:.3g} mm), too short for K={K} (knots {length / (K + 1):.2g} mm apart, mesh edges "
            f"{edge:.2g} mm); {fix} (K + 1 ~ length / radius)"
        )
    return (
        f"{head}: the mesh is too coarse (edges {edge:.2g} mm for wall knots {length / (K + 1):.2g} mm apart "
        f"along a {length:.3g} mm section); remesh it finer or lower --K/--R"
    )


def fit_wall(
    vcs: VesselCoordinateSystem,
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    *,
    K: int = 19,
    R: int = 15,
    smoothing: float = 1e-5,
    branch_rel: float = 0.12,
    reach_rel: float = 0.5,
    grow_rel: float = 0.3,
    orientation: float | None = None,
) -> WallFit:
    """Fit the wall model rho_w to the wall vertices of a section and compute residuals (Eqs. 5-7, 11).

    Vertices are left out, and counted by reason, when they lie beyond an end plane, outside
    Omega, when the ray from c(tau) does not reach them first (their outward normal faces the
    centerline: the wall is not star-convex there), or on a side branch: a connected region of
    vertices with rho above the fit by more than ``branch_rel`` of the local radius, or above the
    median radius of their tau ring by more than 2.5 ``branch_rel``, of which some vertex reaches
    more than ``reach_rel`` of the local radius out of the tube (hysteresis: bumps and oval
    sections never do); such regions are grown by ``grow_rel`` times the median vessel radius,
    to take the flare of the ostium too, and take the vertices outside Omega that they touch.

    Parameters
    ----------
    vcs : VesselCoordinateSystem
        The section's coordinate system (mm).
    vertices : (N, 3) float, mm
        Mesh vertices.
    faces : (M, 3) int
        Wall triangles (caps left out); only their vertices are evaluated.
    K : int
        Interior knots in tau.
    R : int
        Interior knots in theta.
    smoothing : float
        Relative second-difference penalty, see :func:`lsq_wall`.
    branch_rel : float
        Side-branch threshold, as a fraction of the local radius (dimensionless).
    reach_rel : float
        A branch region must reach rho > (1 + ``reach_rel``) times the local radius somewhere
        (dimensionless).
    grow_rel : float
        Growth of the side-branch regions, in median vessel radii (dimensionless).
    orientation : float or None
        +1 when the faces are wound outward, -1 inward; None: decided from the area-weighted
        majority of the vertex normals.

    Returns
    -------
    WallFit

    Raises
    ------
    VCSInputError
        When fewer wall vertices are usable than there are coefficients, (K + 4) (R + 1).
    """
    used_v = np.unique(faces)
    tau = np.full(len(vertices), np.nan)
    theta = np.full(len(vertices), np.nan)
    rho = np.full(len(vertices), np.nan)
    t_, th_, r_, om = vcs.to_vcs(vertices[used_v])
    tau[used_v], theta[used_v], rho[used_v] = t_, th_, r_
    reason = np.full(len(vertices), -1)
    reason[used_v] = 0
    at_end = (t_ <= 0) | (t_ >= 1)
    # vertices of the end rings lie on the end planes, which may be tilted by a degree or so
    # against t(0)/t(1): they are kept when within 2% of rho of the plane through c(0)/c(1)
    t_end, _, _ = vcs.frame(t_)
    along = np.abs(np.einsum("ij,ij->i", vertices[used_v] - vcs.curve(t_), t_end))
    on_ring = at_end & (along <= 0.02 * r_) & (r_ * np.interp(t_, vcs.index.tau, vcs.index.curvature) < 1)
    # ...but not the inside of a flat cap lying in the end plane (closed surfaces): only vertices
    # at about the radius of the wall just inside the section
    for end, near in ((0.0, (t_ > 0) & (t_ < 0.02)), (1.0, (t_ < 1) & (t_ > 0.98))):
        ring = on_ring & (t_ == end)
        if ring.any() and near.any():
            on_ring[ring] &= r_[ring] >= 0.85 * np.median(r_[near])
    valid = np.where(at_end, on_ring, om)  # at tau = 0 or 1: only the end rings count as wall
    reason[used_v[~valid & at_end]] = 1
    reason[used_v[~valid & ~at_end]] = 2

    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(triangle_cross(tri), axis=1)
    w = np.bincount(faces.ravel(), np.repeat(area / 3.0, 3), minlength=len(vertices))
    normals = vertex_normals(vertices, faces)
    c = vcs.curve(np.nan_to_num(tau))
    radial = (vertices - c) / np.maximum(rho, 1e-300)[:, None]
    facing = np.einsum("ij,ij->i", normals, radial)
    if orientation is None:
        sel = reason == 0
        orientation = 1.0 if np.sum(facing[sel] * w[sel]) >= 0 else -1.0
    facing *= orientation
    reason[(reason == 0) & (facing < 0)] = 3

    n_min = (K + 4) * (R + 1)
    if (reason == 0).sum() < n_min:
        raise VCSInputError(_too_few_points_message(vcs, rho[reason == 0], tri, int((reason == 0).sum()), K, R))
    adj = vertex_adjacency(faces, len(vertices))
    # branch regions are grown by ~ grow_rel x the vessel radius (the ostium's flare), in rings
    edge_len = np.linalg.norm(tri[:, 0] - tri[:, 1], axis=1).mean()
    n_grow = int(np.clip(np.ceil(grow_rel * np.nanmedian(rho[reason == 0]) / edge_len), 1, 30))
    n_bins = 4 * (K + 4)
    b = np.minimum((np.nan_to_num(tau) * n_bins).astype(int), n_bins - 1)

    def ring_median() -> np.ndarray:
        """Median radius of the wall kept so far, per tau ring (branches found so far left out)."""
        keep = reason == 0
        med = np.where(np.bincount(b[keep], minlength=n_bins) > 0, group_median(b[keep], rho[keep], n_bins), np.nan)
        ok = np.isfinite(med)
        return np.interp(np.arange(n_bins), np.flatnonzero(ok), med[ok]) if ok.any() else med

    kept_tau = np.nan_to_num(tau[reason == 0])
    end_radii = [
        float(np.median(rho[reason == 0][near])) if near.sum() >= 8 else float(np.nanmedian(rho[reason == 0]))
        for near in (kept_tau < 0.02, kept_tau > 0.98)
    ]
    anchors = _end_sections(vcs, vertices, faces, float(np.nanmedian(rho[reason == 0])), end_radii)
    w_anchor = float(np.median(w[reason == 0]))
    # the design matrix (Eq. 5) of every wall vertex that may take part, then of the anchors, built
    # once: each fit takes its rows (the same rows, in the same order, as built afresh)
    cand_v = np.flatnonzero((reason == 0) | (reason == 2))
    row_of = np.full(len(vertices), -1)
    row_of[cand_v] = np.arange(len(cand_v))
    B_all = tensor_design_matrix(
        np.concatenate([tau[cand_v], anchors[0]]), np.concatenate([theta[cand_v], anchors[1]]), K, R
    )
    anchor_rows = len(cand_v) + np.arange(len(anchors[0]))

    def fit(ring: np.ndarray) -> WallModel:
        """LSQ on the kept wall; where branches were cut out, the ring's median radius (``ring``,
        :func:`ring_median` now) stands in (so the gap is filled like the wall around it instead of
        by unconstrained spline); the wall's cuts by the two end planes pin rho_w at tau = 0 and 1
        (no extrapolation there)."""
        sel, fill = reason == 0, reason == 4
        rows = np.concatenate([row_of[sel], row_of[fill], anchor_rows])
        r_ = np.concatenate([rho[sel], ring[b[fill]], anchors[2]])
        w_ = np.concatenate([w[sel], w[fill], np.full(len(anchors[0]), w_anchor)])
        return _solve_wall(B_all[rows], r_, w_, K, R, smoothing)

    model: WallModel  # assigned by the first pass of the loop
    for _ in range(6):
        ring = ring_median()
        model = fit(ring)
        cand = (reason == 0) | (reason == 4)
        pred = model(np.nan_to_num(tau), np.nan_to_num(theta))
        # candidates: far above the fit, or far above the median radius of their tau ring (the
        # fit itself bends toward wide ostia, the ring median does not); a branch is a connected
        # region of candidates that reaches well out of the tube somewhere (hysteresis): bumps,
        # oval sections and a badly fitted stretch stay below ``reach_rel`` and are kept
        med = ring[b]
        weak = cand & ((rho - pred > branch_rel * pred) | (rho > (1.0 + 2.5 * branch_rel) * med))
        # a stub reaching past the centre of curvature is outside Omega: it links and seeds too
        far_out = (reason == 2) & (rho > (1.0 + 2.5 * branch_rel) * med)
        linked = weak | far_out
        strong = linked & (rho > (1.0 + reach_rel) * np.where(cand, np.minimum(pred, med), med))
        out = _regions_with_seeds(adj, linked, strong) & cand
        grown = out.copy()
        for _ in range(n_grow):
            grown = grown | (adj @ grown.astype(float) > 0)
        new_branch = cand & grown
        if np.array_equal(new_branch, reason == 4):
            break
        reason[cand] = 0
        reason[new_branch] = 4
    # points outside Omega that touch a branch region (stubs reaching past the centre of
    # curvature, a branch beyond the reach of the curve) belong to that branch
    if (reason == 4).any() and (reason == 2).any():
        far_out = (reason == 2) & (rho > (1.0 + 2.5 * branch_rel) * ring_median()[b])
        reason[_regions_with_seeds(adj, far_out | (reason == 4), reason == 4) & far_out] = 4
    sel = reason == 0
    if (reason == 4).any():
        model = fit(ring_median())
    residual = np.full(len(vertices), np.nan)
    ev = reason >= 0
    residual[ev] = np.abs(rho[ev] - model(np.nan_to_num(tau[ev]), np.nan_to_num(theta[ev])))
    r_used = residual[sel]
    n_wall = int(ev.sum())
    report = {
        "K": int(K),
        "R": int(R),
        "n_wall_points": n_wall,
        "n_points_used": int(sel.sum()),
        "points_not_used": {REASONS[k]: int((reason == k).sum()) for k in (1, 2, 3, 4)},
        "residual_mean_mm": float(r_used.mean()) if r_used.size else None,
        "residual_p75_mm": float(np.percentile(r_used, 75)) if r_used.size else None,
        "residual_max_mm": float(r_used.max()) if r_used.size else None,
        "not_star_convex_fraction": float((reason == 3).sum() / max(n_wall, 1)),
        "wall_smoothing": smoothing,
    }
    keep = ev
    return WallFit(
        model, vertices[keep], tau[keep], theta[keep], rho[keep], residual[keep], sel[keep], reason[keep], report
    )


def _regions_with_seeds(
    adj: sparse.csr_matrix, member: NDArray[np.bool_], seed: NDArray[np.bool_]
) -> NDArray[np.bool_]:
    """Vertices of the connected regions of ``member`` (over the mesh edges) that contain a ``seed``.

    Parameters
    ----------
    adj : (N, N) sparse
        Vertex adjacency of the mesh.
    member : (N,) bool
        Vertices that may belong to a region.
    seed : (N,) bool
        Vertices that make their region count (only those inside ``member`` do).

    Returns
    -------
    (N,) bool
    """
    idx = np.flatnonzero(member)
    out = np.zeros(len(member), bool)
    if len(idx) == 0 or not (seed & member).any():
        return out
    from scipy.sparse import csgraph

    _, lab = csgraph.connected_components(adj[idx][:, idx], directed=False)
    keep = np.zeros(lab.max() + 1, bool)
    keep[lab[seed[idx]]] = True
    out[idx[keep[lab]]] = True
    return out


def _end_sections(
    vcs: VesselCoordinateSystem,
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    radius: float,
    end_radii: tuple[float, float] | list[float] | None = None,
) -> tuple[NDArray[np.floating], NDArray[np.floating], NDArray[np.floating]]:
    """(tau, theta, rho) of the wall's cuts by the two end planes (paper Section 2.2.1 end planes).

    The wall edges crossing the plane through c(0) (c(1)) normal to t(0) (t(1)), within 2.5
    ``radius`` of it, give points at tau = 0 (1) of known theta and rho: data for rho_w where
    the wall vertices themselves stop short of the end plane (a cut closed surface, a coarse mesh).

    Parameters
    ----------
    vcs : VesselCoordinateSystem
    vertices : (N, 3) float, mm
    faces : (M, 3) int
        Wall triangles.
    radius : float, mm
        Typical lumen radius (search radius around the end centres).
    end_radii : (2,) float, mm, or None
        Median radius of the wall just inside each end: crossings beyond 1.5 times it are not
        the section's ring (None: no such limit).

    Returns
    -------
    tau, theta, rho : (n,) float
        theta in rad, rho in mm.
    """
    out: list[list[float]] = [[], [], []]
    e = edge_topology(faces)[0]  # unique edges, rows sorted, in lexicographic order
    for t_end, r_end in zip((0.0, 1.0), end_radii if end_radii is not None else (np.inf, np.inf)):
        t, v1, v2 = (a[0] for a in vcs.frame(np.array([t_end])))
        c = vcs.curve(t_end)
        sd = (vertices - c) @ t
        a, bb = sd[e[:, 0]], sd[e[:, 1]]
        cross = a * bb < 0
        wgt = (a[cross] / (a[cross] - bb[cross]))[:, None]
        x = vertices[e[cross, 0]] + wgt * (vertices[e[cross, 1]] - vertices[e[cross, 0]]) - c
        x = x[np.linalg.norm(x, axis=1) < 2.5 * radius]
        th = np.mod(np.arctan2(x @ v2, x @ v1), TWO_PI)
        rho = np.linalg.norm(x, axis=1)
        # the section's own ring only: the plane may also cut another part of the vessel within
        # 2.5 radii (the ascending aorta next to a descending outlet: anchors at 40 mm pulled
        # rho_w to 41 mm at the outlet of a 17 mm aorta phantom); crossings beyond 1.5 times the
        # wall's radius just inside the end, or, per 10 deg sector, beyond 1.3 times the nearest
        # crossing, are that other wall (the ring of an open end lying in the plane has none)
        sector = np.minimum((th / (TWO_PI / 36)).astype(int), 35)
        nearest = np.full(36, np.inf)
        np.minimum.at(nearest, sector, rho)
        keep = (rho <= 1.3 * nearest[sector]) & (rho <= 1.5 * r_end)
        out[0].extend([t_end] * int(keep.sum()))
        out[1].extend(th[keep])
        out[2].extend(rho[keep])
    return np.array(out[0]), np.array(out[1]), np.array(out[2])
