"""Statistical atlas of vessel shape and flow (paper Section 2.3: coregistration, PCA).

Pure numpy/scipy. The pieces, each a plain function or a small frozen value object:

* :func:`procrustes` / :func:`generalized_procrustes`: rigid (optionally similarity) alignment of
  corresponding point sets (Section 2.3.2). The correspondences are the Eq. 8 wall points on one
  (tau, theta) grid (:func:`wall_grid_points`), the same for every vessel by construction of the VCS.
* :func:`transform_model` applies a transform to a :class:`~vcs.vessel.VesselModel`: the centerline
  control points move (B-splines are affine invariant), v1(0) rotates with them (parallel transport
  commutes with rotations), the wall coefficients are frame-relative and do not change (they are
  multiplied by the scale when a similarity transform is used).
* :class:`PCA` (Section 2.3.3) of feature vectors (shape) or of resampled flow fields (flow).
* :func:`mode_deformation`: a shape mode split into centerline displacement |delta c(tau)| and radius
  change delta rho_w(tau, theta) (paper Fig. 7).
* :func:`ridge_loo` (beyond the paper): shape scores -> flow scores ridge regression with leave-one-out
  cross-validated R^2.
* :func:`compute_atlas` / :func:`build_atlas`: the whole cohort pipeline; ``build_atlas`` writes
  ``atlas.json`` and ``atlas.npz`` (and figures through :mod:`vcs.atlas_plots`, imported only then).
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import BSpline

from vcs.errors import VCSInputError

log = logging.getLogger(__name__)

TWO_PI = 2.0 * np.pi
FLOW_FIELDS = ("U", "p", "WSS")


# ---------------------------------------------------------------------------------------------
# Coregistration (Section 2.3.2)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RigidTransform:
    """x -> scale * R x + translation (R a proper rotation; scale 1 for a rigid transform)."""

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Transform (..., 3) points."""
        return self.scale * np.asarray(points, float) @ self.rotation.T + self.translation

    def inverse(self) -> "RigidTransform":
        r = self.rotation.T
        return RigidTransform(r, -(self.translation @ r.T) / self.scale, 1.0 / self.scale)

    def to_dict(self) -> dict:
        return {
            "rotation": self.rotation.tolist(),
            "translation_mm": self.translation.tolist(),
            "scale": float(self.scale),
        }


def wall_grid(n_tau: int = 40, n_theta: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """The (tau, theta) grid of corresponding wall points: tau in [0, 1] inclusive, theta
    2 pi j / n_theta. Returns two (n_tau, n_theta) arrays."""
    return np.meshgrid(np.linspace(0.0, 1.0, n_tau), TWO_PI * np.arange(n_theta) / n_theta, indexing="ij")


def wall_grid_points(model, n_tau: int = 40, n_theta: int = 24) -> np.ndarray:
    """Eq. 8 wall points x(tau, theta) of ``model`` on :func:`wall_grid`: (n_tau * n_theta, 3) mm.

    Point i of every vessel has the same (tau, theta): these are the correspondences of the
    Procrustes alignment.
    """
    tau, theta = wall_grid(n_tau, n_theta)
    return model.surface_points(tau, theta).reshape(-1, 3)


def procrustes(source: np.ndarray, target: np.ndarray, *, scale: bool = False, weights=None) -> RigidTransform:
    """Least-squares transform T minimising sum_i w_i |T(source_i) - target_i|^2 (Kabsch / Umeyama).

    Parameters
    ----------
    source, target : (N, 3) float
        Corresponding points.
    scale : bool
        Also fit an isotropic scale (similarity transform). Default False: rigid.
    weights : (N,) float, optional

    Returns
    -------
    RigidTransform with a proper rotation (det R = +1; reflections are never returned).
    """
    X = np.asarray(source, float)
    Y = np.asarray(target, float)
    if X.shape != Y.shape or X.ndim != 2 or X.shape[1] != 3:
        raise VCSInputError(f"procrustes needs two (N, 3) arrays of corresponding points, got {X.shape} and {Y.shape}")
    w = np.ones(len(X)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    mx, my = w @ X, w @ Y
    Xc, Yc = X - mx, Y - my
    C = (Yc * w[:, None]).T @ Xc  # cross-covariance, 3 x 3
    U, S, Vt = np.linalg.svd(C)
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    D = np.diag([1.0, 1.0, d])
    R = U @ D @ Vt
    s = float(np.sum(S * np.diag(D)) / np.sum(w * np.einsum("ij,ij->i", Xc, Xc))) if scale else 1.0
    return RigidTransform(R, my - s * mx @ R.T, s)


def generalized_procrustes(
    point_sets, *, scale: bool = False, reference: int = 0, max_iter: int = 100, tol: float = 1e-10
) -> tuple[list[RigidTransform], np.ndarray, dict]:
    """Generalised Procrustes analysis of corresponding point sets (paper Section 2.3.2).

    Iterates: align every set to the current mean, average, re-anchor the mean onto set
    ``reference`` (so the result lives in that patient's coordinates and, with ``scale``, has
    its size), until the mean moves by less than ``tol`` times its RMS size.

    Parameters
    ----------
    point_sets : sequence of (N, 3) float
    scale : bool
        Similarity instead of rigid alignment. Default False: vessel size is kept as a shape
        variable (the calibre is clinically meaningful and is the dominant mode of aortas).

    Returns
    -------
    transforms : list of RigidTransform, one per set (set -> atlas space)
    mean : (N, 3) float
    report : dict (iterations, rms residual per set in mm)
    """
    sets = [np.asarray(p, float) for p in point_sets]
    if len(sets) < 1:
        raise VCSInputError("generalised Procrustes needs at least one point set")
    ref = sets[reference]
    mean = ref.copy()
    size = np.sqrt(np.mean(np.sum((ref - ref.mean(0)) ** 2, axis=1)))
    it = 0
    for it in range(1, max_iter + 1):
        transforms = [procrustes(p, mean, scale=scale) for p in sets]
        new = np.mean([t(p) for t, p in zip(transforms, sets)], axis=0)
        new = procrustes(new, ref, scale=scale)(new)
        change = np.sqrt(np.mean(np.sum((new - mean) ** 2, axis=1)))
        mean = new
        if change < tol * size:
            break
    transforms = [procrustes(p, mean, scale=scale) for p in sets]
    rms = [float(np.sqrt(np.mean(np.sum((t(p) - mean) ** 2, axis=1)))) for t, p in zip(transforms, sets)]
    return transforms, mean, {"iterations": it, "scale": bool(scale), "reference": int(reference), "rms_to_mean_mm": rms}


def transform_model(model, transform: RigidTransform):
    """The model moved by ``transform``: Eq. 8 points of the result are ``transform`` of the
    original's (to the accuracy of the frame table, ~1e-8 mm).

    Control points c_i -> s R c_i + t; v1(0) -> R v1(0) (the rotation-minimising frame of a
    rotated curve is the rotated frame); wall coefficients unchanged for a rigid transform,
    multiplied by s for a similarity transform (rho_w is a length).
    """
    from vcs.model import VesselCoordinateSystem
    from vcs.vessel import VesselModel

    v = model.vcs
    curve = BSpline(v.curve.t, transform(v.control_points), v.curve.k)
    vcs = VesselCoordinateSystem(curve, transform.rotation @ v.v1_0, v1_0_from=f"{v.v1_0_from}; rotated by the alignment")
    wall = model.wall
    if wall is not None and transform.scale != 1.0:
        wall = wall.with_coefficients(wall.coefficients * transform.scale)
    return VesselModel(vcs, wall, model.units, dict(model.meta))


def check_compatible(models) -> None:
    """All models must share the centerline knots and the wall's K, R (same feature vector layout)."""
    m0 = models[0]
    for i, m in enumerate(models[1:], 1):
        if m.wall is None or m0.wall is None:
            raise VCSInputError("every model of an atlas needs a wall model; refit with `vcs fit` (K, R)")
        if not (np.array_equal(m.vcs.curve.t, m0.vcs.curve.t) and m.vcs.curve.k == m0.vcs.curve.k):
            raise VCSInputError(f"model {i} has other centerline knots than model 0; fit every vessel with the same L")
        if (m.wall.K, m.wall.R) != (m0.wall.K, m0.wall.R):
            raise VCSInputError(
                f"model {i} has wall K, R = {m.wall.K}, {m.wall.R}, model 0 {m0.wall.K}, {m0.wall.R}; fit every vessel with the same K, R"
            )


def align_models(models, *, n_tau: int = 40, n_theta: int = 24, scale: bool = False, reference: int = 0):
    """Coregister vessel models by GPA on their Eq. 8 wall grids (paper Section 2.3.2).

    Returns (aligned models, transforms, report); ``report["mean_points_mm"]`` is the GPA mean
    wall grid ((n_tau * n_theta, 3) array), the target a new vessel is aligned to.
    """
    models = list(models)
    check_compatible(models)
    pts = [wall_grid_points(m, n_tau, n_theta) for m in models]
    transforms, mean, report = generalized_procrustes(pts, scale=scale, reference=reference)
    report.update({"n_tau": n_tau, "n_theta": n_theta, "mean_points_mm": mean})
    return [transform_model(m, t) for m, t in zip(models, transforms)], transforms, report


SHAPE_BLOCKS = ("all", "wall", "centerline")


def shape_matrix(models, block: str = "all") -> np.ndarray:
    """(n, d) feature vectors a = (c, b) of (aligned) models (paper Section 2.3.1).

    ``block`` = ``"all"`` (the paper: centerline control points and wall coefficients together),
    ``"wall"`` or ``"centerline"`` (beyond the paper): the other block is replaced by its cohort
    mean, so it has no variance and the PCA modes live in the chosen block only, while every
    vector stays a complete, rebuildable feature vector (mean shapes, +- sigma shapes and Fig. 7
    work unchanged). The centerline carries length and arch geometry, the wall the calibre; in a
    joint PCA the first mode mixes them (see tests/vcs/test_atlas.py, phantom cohort).
    """
    if block not in SHAPE_BLOCKS:
        raise VCSInputError(f"shape block must be one of {SHAPE_BLOCKS}, not {block!r}")
    X = np.array([m.feature_vector() for m in models])
    nc = models[0].vcs.control_points.size
    if block == "wall":
        X[:, :nc] = X[:, :nc].mean(axis=0)
    elif block == "centerline":
        X[:, nc:] = X[:, nc:].mean(axis=0)
    return X


# ---------------------------------------------------------------------------------------------
# PCA (Section 2.3.3)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PCA:
    """Principal components of n samples of dimension d.

    Attributes
    ----------
    mean : (d,) float
    components : (k, d) float
        Orthonormal modes, sign fixed so the largest-magnitude entry of each is positive.
    sigma : (k,) float
        Standard deviation of the scores along each mode (ddof = 1).
    explained_variance_ratio : (k,) float
        Fraction of the total variance per mode.
    scores : (n, k) float
        Scores of the training samples.
    """

    mean: np.ndarray
    components: np.ndarray
    sigma: np.ndarray
    explained_variance_ratio: np.ndarray
    scores: np.ndarray

    @classmethod
    def from_data(cls, X: np.ndarray, n_modes: int | None = None) -> "PCA":
        """PCA by SVD of the centred (n, d) data; at most min(n - 1, d) modes."""
        X = np.asarray(X, float)
        if X.ndim != 2 or len(X) < 2:
            raise VCSInputError(f"PCA needs an (n >= 2, d) array, got shape {X.shape}")
        n = len(X)
        mean = X.mean(axis=0)
        U, S, Vt = np.linalg.svd(X - mean, full_matrices=False)
        k = min(n - 1, X.shape[1]) if n_modes is None else min(n_modes, n - 1, X.shape[1])
        var = S**2 / (n - 1)
        total = var.sum()
        comps = Vt[:k]
        sign = np.sign(comps[np.arange(k), np.argmax(np.abs(comps), axis=1)])
        sign[sign == 0] = 1.0
        comps = comps * sign[:, None]
        scores = (U[:, :k] * S[:k]) * sign
        ratio = var[:k] / total if total > 0 else np.zeros(k)
        return cls(mean, comps, np.sqrt(var[:k]), ratio, scores)

    @property
    def n_modes(self) -> int:
        return len(self.sigma)

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Scores (n, k) (or (k,)) of samples (n, d) (or (d,))."""
        return (np.asarray(X, float) - self.mean) @ self.components.T

    def inverse_transform(self, scores: np.ndarray) -> np.ndarray:
        return self.mean + np.asarray(scores, float) @ self.components

    def project(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """A new sample's scores, its reconstruction from the modes and the reconstruction
        error |x - x_hat| (same units as x)."""
        s = self.transform(x)
        xh = self.inverse_transform(s)
        return s, xh, float(np.linalg.norm(np.asarray(x, float) - xh))

    def mode_sample(self, mode: int, n_sigma: float) -> np.ndarray:
        """mean + n_sigma * sigma_m * u_m (0-based ``mode``)."""
        return self.mean + n_sigma * self.sigma[mode] * self.components[mode]

    def arrays(self, prefix: str) -> dict:
        return {
            f"{prefix}_mean": self.mean,
            f"{prefix}_components": self.components,
            f"{prefix}_sigma": self.sigma,
            f"{prefix}_explained_variance_ratio": self.explained_variance_ratio,
            f"{prefix}_scores": self.scores,
        }


def mode_deformation(pca: PCA, template, mode: int, *, n_sigma: float = 2.0, n_tau: int = 101, n_theta: int = 48) -> dict:
    """Split a shape mode into centerline displacement and radius change (paper Fig. 7).

    Compares the shapes mean + n_sigma sigma_m u_m and the mean (feature vectors rebuilt with
    ``template``'s knots and frame rule): |delta c(tau)| = |c_plus(tau) - c_mean(tau)| in mm on
    ``n_tau`` samples, delta rho_w(tau, theta) = rho_w_plus - rho_w_mean in mm on the wall grid.

    Returns dict with tau (n_tau,), theta (n_theta,), centerline_displacement (n_tau,),
    radius_change (n_tau, n_theta), and the two models (``mean_model``, ``mode_model``).
    """
    from vcs.vessel import VesselModel

    m0 = VesselModel.from_feature_vector(pca.mean, template)
    m1 = VesselModel.from_feature_vector(pca.mode_sample(mode, n_sigma), template)
    tau = np.linspace(0.0, 1.0, n_tau)
    theta = TWO_PI * np.arange(n_theta) / n_theta
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    dc = np.linalg.norm(m1.vcs.curve(tau) - m0.vcs.curve(tau), axis=1)
    dr = m1.wall(T, TH) - m0.wall(T, TH)
    return {"tau": tau, "theta": theta, "centerline_displacement": dc, "radius_change": dr,
            "mean_model": m0, "mode_model": m1, "mode": int(mode), "n_sigma": float(n_sigma)}


# ---------------------------------------------------------------------------------------------
# Flow measurement vectors
# ---------------------------------------------------------------------------------------------
def flow_vector(fields: dict, name: str, *, frame: str = "vcs") -> np.ndarray:
    """Flatten one resampled field of one patient into a measurement vector.

    ``frame="vcs"`` (default) uses the vector components in the local VCS frame
    (``U_vcs``/``WSS_vcs``: along t, e_theta, e_rho), which are invariant to the rigid alignment
    and comparable across patients; ``"cartesian"`` uses ``U``/``WSS`` as sampled. Pressures are
    taken in Pa (``p``).
    """
    key = f"{name}_vcs" if frame == "vcs" and name in ("U", "WSS") else name
    if key not in fields:
        raise VCSInputError(f"the resampled fields have no '{key}'; resample the case with vcs.cfd.resample.sample_case")
    return np.asarray(fields[key], float).ravel()


def top_variation_mask(pca: PCA, mode: int, field_shape: tuple, *, vector: bool, fraction: float = 0.2) -> np.ndarray:
    """Grid cells in the top ``fraction`` of mode ``mode``'s variation: sigma_m |u_m| per cell, the
    norm taken over the trailing 3 components when ``vector``. Returns a bool array of the field's
    grid shape (``field_shape`` without the trailing 3 of vector fields)."""
    u = np.abs(pca.components[mode] * pca.sigma[mode]).reshape(field_shape)
    if vector:
        u = np.linalg.norm(u, axis=-1)
    return u >= np.quantile(u, 1.0 - fraction)


VECTOR_FIELDS = ("U", "WSS")


# ---------------------------------------------------------------------------------------------
# Shape -> flow regression (beyond the paper)
# ---------------------------------------------------------------------------------------------
def _safe_std(X):
    """Column standard deviations; columns that are constant (to round-off, e.g. the scores of a
    mode with no variance among the training samples) get inf, i.e. a standardised value of 0."""
    sx = X.std(0)
    return np.where(sx > 1e-9 * max(float(sx.max(initial=0.0)), 1e-300), sx, np.inf)


def _ridge_solve(X, Y, alpha):
    """Ridge with unpenalised intercept on standardised X. Returns a predict function."""
    mx, sx = X.mean(0), _safe_std(X)
    my = Y.mean(0)
    Z = (X - mx) / sx
    B = np.linalg.solve(Z.T @ Z + alpha * np.eye(Z.shape[1]), Z.T @ (Y - my))
    return lambda Xn: ((np.asarray(Xn) - mx) / sx) @ B + my


def _gcv_alpha(X, Y, alphas):
    """alpha minimising the exact leave-one-out error of the ridge fit (hat-matrix shortcut)."""
    Z = (X - X.mean(0)) / _safe_std(X)
    Yc = Y - Y.mean(0)
    n = len(X)
    best, best_err = alphas[0], np.inf
    for a in alphas:
        H = Z @ np.linalg.solve(Z.T @ Z + a * np.eye(Z.shape[1]), Z.T) + 1.0 / n  # + intercept
        r = (Yc - (H - 1.0 / n) @ Yc) / np.maximum(1.0 - np.diag(H), 1e-12)[:, None]
        err = float(np.sum(r**2))
        if err < best_err:
            best, best_err = a, err
    return best


DEFAULT_ALPHAS = tuple(np.logspace(-6, 4, 21))


def ridge_loo(X: np.ndarray, Y: np.ndarray, *, alphas=DEFAULT_ALPHAS) -> dict:
    """Leave-one-out cross-validated ridge regression Y ~ X (beyond the paper).

    For each left-out sample, the regularisation alpha is chosen on the remaining samples by
    their own exact leave-one-out error (nested, so the reported R^2 is honest), the model
    (standardised X, unpenalised intercept) is fitted on them and predicts the left-out sample.

    Parameters
    ----------
    X : (n, k) float, e.g. the first k shape scores
    Y : (n, m) float, e.g. flow scores

    Returns
    -------
    dict: ``r2`` (m,) = 1 - sum (y - y_loo)^2 / sum (y - mean y)^2 per column (can be negative),
    nan for a column without variance; ``predictions`` (n, m); ``alphas`` (n,) chosen per fold;
    ``alpha_full`` chosen on all samples.
    """
    X = np.asarray(X, float)
    Y = np.asarray(Y, float)
    if X.ndim == 1:
        X = X[:, None]
    squeeze = Y.ndim == 1
    if squeeze:
        Y = Y[:, None]
    n = len(X)
    if n < 3:
        raise VCSInputError(f"leave-one-out regression needs at least 3 samples, got {n}")
    alphas = np.asarray(alphas, float)
    pred = np.empty_like(Y)
    chosen = np.empty(n)
    for i in range(n):
        keep = np.arange(n) != i
        a = _gcv_alpha(X[keep], Y[keep], alphas) if len(alphas) > 1 else alphas[0]
        chosen[i] = a
        pred[i] = _ridge_solve(X[keep], Y[keep], a)(X[i : i + 1])[0]
    ss = np.sum((Y - Y.mean(0)) ** 2, axis=0)
    # columns without variance (a PCA mode of round-off size) have no R^2: nan (null in atlas.json)
    r2 = 1.0 - np.sum((Y - pred) ** 2, axis=0) / np.where(ss > 1e-12 * max(float(ss.max()), 1e-300), ss, np.nan)
    return {"r2": r2[0] if squeeze else r2, "predictions": pred[:, 0] if squeeze else pred,
            "alphas": chosen, "alpha_full": float(_gcv_alpha(X, Y, alphas))}


# ---------------------------------------------------------------------------------------------
# Cohort pipeline
# ---------------------------------------------------------------------------------------------
def status_exclusion(status: dict | None, *, accept_relaxed: bool = False) -> str | None:
    """Reason to exclude a patient from its case ``status.json`` (None: include).

    Excluded when the file is missing, ``failed`` is true, ``status``/``state`` names a failure,
    or ``converged`` is false (vcs.cfd.run_case writes ``converged`` and ``reason``). With
    ``accept_relaxed``, a case whose SIMPLE run did not converge but whose time-averaged fallback
    met the relaxed criterion (``converged_relaxed`` true) is included. The reason quotes the
    status's own ``reason``/``error``/``message``.
    """
    if status is None:
        return "no status.json"
    detail = next((str(status[k]) for k in ("reason", "error", "message") if status.get(k)), "")
    detail = f": {detail}" if detail else ""
    state = str(status.get("status", status.get("state", ""))).lower()
    if status.get("failed") is True or state in ("failed", "error", "crashed", "diverged", "timeout"):
        return f"solver failed ({state or 'failed'}){detail}"
    if status.get("converged") is False:
        if accept_relaxed and status.get("converged_relaxed") is True:
            return None
        return f"not converged{detail}"
    return None


@dataclass(frozen=True)
class Atlas:
    """Result of :func:`compute_atlas` (all arrays; no files)."""

    patients: list
    excluded: dict
    aligned_models: list
    transforms: list
    alignment_report: dict
    shape: PCA
    flow: dict  # field -> PCA
    field_shapes: dict  # field -> grid shape of the measurement vector
    grid: dict  # tau, theta, rho_n of the resampled fields
    regression: dict  # field -> ridge_loo result
    options: dict
    alignment_mean: np.ndarray  # (n_tau_align * n_theta_align, 3) GPA mean wall grid, mm


def compute_atlas(models: dict, fields: dict, statuses: dict, *, n_modes: int = 3, n_regression_scores: int | None = None,
                  scale: bool = False, n_tau_align: int = 40, n_theta_align: int = 24, flow_frame: str = "vcs",
                  flow_fields=FLOW_FIELDS, shape_block: str = "all", accept_relaxed: bool = False) -> Atlas:
    """Coregistration, shape PCA, flow PCA and shape -> flow regression of a cohort.

    Parameters
    ----------
    models : {patient id: VesselModel}
    fields : {patient id: dict of resampled arrays} (as returned by :func:`vcs.cfd.resample.sample_case`
        or loaded from ``fields.npz``); a patient without fields is excluded.
    statuses : {patient id: status dict or None} from each case's status.json; see
        :func:`status_exclusion`. Patients absent from ``statuses`` count as included.
    n_modes : modes kept per PCA (at most n_included - 1)
    n_regression_scores : k shape scores used to predict flow scores (default ``n_modes``)
    scale : similarity instead of rigid alignment (default rigid; see :func:`generalized_procrustes`)
    shape_block : which part of the feature vector the shape PCA varies (:func:`shape_matrix`)
    flow_frame : ``"vcs"`` (local-frame vector components, default) or ``"cartesian"``
    accept_relaxed : include time-averaged cases that met the relaxed criterion (:func:`status_exclusion`)
    """
    excluded = {}
    for pid in models:
        reason = status_exclusion(statuses[pid], accept_relaxed=accept_relaxed) if pid in statuses else None
        if reason is None and pid not in fields:
            reason = "no resampled fields"
        if reason is not None:
            excluded[pid] = reason
    patients = [pid for pid in models if pid not in excluded]
    if len(patients) < 3:
        raise VCSInputError(f"an atlas needs at least 3 included patients, got {len(patients)} (excluded: {excluded})")
    shapes0 = {f: np.shape(fields[patients[0]][f"{f}_vcs" if flow_frame == "vcs" and f != "p" else f]) for f in flow_fields}
    for pid in patients:
        for f in flow_fields:
            key = f"{f}_vcs" if flow_frame == "vcs" and f != "p" else f
            if np.shape(fields[pid].get(key)) != shapes0[f]:
                raise VCSInputError(
                    f"patient {pid}: field {key} has shape {np.shape(fields[pid].get(key))}, patient {patients[0]} "
                    f"{shapes0[f]}; resample every case on the same (n_tau, n_theta, n_rho) grid"
                )
    aligned, transforms, report = align_models([models[p] for p in patients], n_tau=n_tau_align,
                                               n_theta=n_theta_align, scale=scale)
    gpa_mean = report.pop("mean_points_mm")
    shape = PCA.from_data(shape_matrix(aligned, shape_block), n_modes)
    flow = {f: PCA.from_data(np.array([flow_vector(fields[p], f, frame=flow_frame) for p in patients]), n_modes)
            for f in flow_fields}
    k = min(n_regression_scores or n_modes, shape.n_modes)
    regression = {f: ridge_loo(shape.scores[:, :k], flow[f].scores) for f in flow_fields}
    f0 = fields[patients[0]]
    grid = {key: np.asarray(f0[key]) for key in ("tau", "theta", "rho_n") if key in f0}
    return Atlas(patients, excluded, aligned, transforms, report, shape, flow, shapes0, grid, regression,
                 {"n_modes": n_modes, "n_regression_scores": k, "scale": scale, "flow_frame": flow_frame,
                  "n_tau_align": n_tau_align, "n_theta_align": n_theta_align,
                  "shape_block": shape_block, "accept_relaxed": accept_relaxed}, gpa_mean)


def project_model(atlas: Atlas, model, *, n_modes: int | None = None) -> dict:
    """Project a new vessel onto the atlas's shape modes.

    The model is first aligned rigidly (or by similarity, as the atlas) to the atlas's GPA mean wall
    grid by :func:`procrustes` on its Eq. 8 wall grid (as the cohort was); its feature vector is
    then projected.

    Returns dict: ``scores`` (k,), ``scores_sigma`` (scores / sigma), ``reconstruction`` (feature
    vector from the first ``n_modes`` modes), ``error`` (|a - a_hat|, mm, over the whole vector),
    ``transform`` (model -> atlas space), ``aligned_model``.
    """
    template = atlas.aligned_models[0]
    check_compatible([template, model])
    n_tau, n_theta = atlas.options["n_tau_align"], atlas.options["n_theta_align"]
    T = procrustes(wall_grid_points(model, n_tau, n_theta), atlas.alignment_mean, scale=atlas.options["scale"])
    aligned = transform_model(model, T)
    a = aligned.feature_vector()
    k = atlas.shape.n_modes if n_modes is None else min(n_modes, atlas.shape.n_modes)
    s = atlas.shape.transform(a)[:k]
    a_hat = atlas.shape.mean + s @ atlas.shape.components[:k]
    return {"scores": s, "scores_sigma": s / atlas.shape.sigma[:k], "reconstruction": a_hat,
            "error": float(np.linalg.norm(a - a_hat)), "transform": T, "aligned_model": aligned}


def atlas_summary(atlas: Atlas) -> dict:
    """The content of atlas.json."""
    return {
        "patients_included": list(atlas.patients),
        "patients_excluded": [{"id": p, "reason": r} for p, r in atlas.excluded.items()],
        "options": atlas.options,
        "alignment": {**atlas.alignment_report,
                      "transforms": {p: t.to_dict() for p, t in zip(atlas.patients, atlas.transforms)}},
        "shape_explained_variance": atlas.shape.explained_variance_ratio.tolist(),
        "shape_sigma": atlas.shape.sigma.tolist(),
        "shape_scores": {p: s.tolist() for p, s in zip(atlas.patients, atlas.shape.scores)},
        "flow_explained_variance": {f: pca.explained_variance_ratio.tolist() for f, pca in atlas.flow.items()},
        "flow_sigma": {f: pca.sigma.tolist() for f, pca in atlas.flow.items()},
        "flow_scores": {f: {p: s.tolist() for p, s in zip(atlas.patients, pca.scores)} for f, pca in atlas.flow.items()},
        "shape_to_flow_regression": {
            "method": "ridge on the first k standardised shape scores, alpha by inner leave-one-out; "
                      "R^2 by outer leave-one-out (1 - PRESS / SS_tot)",
            "k_shape_scores": atlas.options["n_regression_scores"],
            "loo_r2": {f: [None if not np.isfinite(v) else float(v) for v in r["r2"]] for f, r in atlas.regression.items()},
        },
    }


def build_atlas(models: dict, fields: dict, statuses: dict, out_dir, *, n_modes: int = 3, figures: bool = True,
                **options) -> Atlas:
    """Compute the atlas (:func:`compute_atlas`) and write it to ``out_dir``.

    Writes ``atlas.json`` (patients included/excluded with reasons, explained variances, scores,
    regression R^2), ``atlas.npz`` (every PCA's mean, modes, sigma, scores; the field grid) and,
    with ``figures``, the VTP/VTU/PNG files of :func:`vcs.atlas_plots.write_atlas_figures`.
    ``fields`` values may be dicts of arrays or paths of ``fields.npz`` files.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    loaded = {}
    for pid, f in fields.items():
        if isinstance(f, (str, Path)):
            with np.load(f) as z:
                loaded[pid] = {k: z[k] for k in z.files}
        else:
            loaded[pid] = f
    atlas = compute_atlas(models, loaded, statuses, n_modes=n_modes, **options)
    summary = atlas_summary(atlas)
    arrays = {**atlas.shape.arrays("shape"), **{k: v for f, p in atlas.flow.items() for k, v in p.arrays(f"flow_{f}").items()}}
    arrays.update({f"grid_{k}": v for k, v in atlas.grid.items()})
    np.savez_compressed(out / "atlas.npz", **arrays)
    if figures:
        from vcs import atlas_plots

        written = atlas_plots.write_atlas_figures(atlas, out)
        summary["files"], summary["renderer"] = written["files"], written["renderer"]
    (out / "atlas.json").write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
    log.info("atlas of %d patients (%d excluded) written to %s", len(atlas.patients), len(atlas.excluded), out)
    return atlas
