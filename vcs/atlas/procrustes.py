"""Coregistration of vessel models (paper Section 2.3.2): Procrustes alignment on Eq. 8 wall grids.

The correspondences are the Eq. 8 wall points on one (tau, theta) grid (:func:`wall_grid_points`),
the same for every vessel by construction of the VCS. :func:`transform_model` applies a transform
to a :class:`~vcs.vessel.VesselModel`: the centerline control points move (B-splines are affine
invariant), v1(0) rotates with them (parallel transport commutes with rotations), the wall
coefficients are frame-relative and do not change (they are multiplied by the scale when a
similarity transform is used).

Pure numpy/scipy; never imports plotting (:mod:`vcs.atlas.plots`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import BSpline

from vcs.errors import VCSInputError

if TYPE_CHECKING:
    from vcs.vessel import VesselModel

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class RigidTransform:
    """x -> scale * R x + translation (R a proper rotation; scale 1 for a rigid transform).

    Attributes
    ----------
    rotation : (3, 3) float
        Proper rotation matrix R (det R = +1).
    translation : (3,) float, mm
    scale : float
        Isotropic scale s (1 for a rigid transform).
    """

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale: float = 1.0

    def __call__(self, points: ArrayLike) -> NDArray[np.float64]:
        """Transform points.

        Parameters
        ----------
        points : (..., 3) float, mm

        Returns
        -------
        (..., 3) float, mm
            ``scale * points @ rotation.T + translation``.
        """
        return self.scale * np.asarray(points, float) @ self.rotation.T + self.translation

    def inverse(self) -> RigidTransform:
        """The inverse transform.

        Returns
        -------
        RigidTransform
            x -> (1 / s) R^T (x - translation).
        """
        r = self.rotation.T
        return RigidTransform(r, -(self.translation @ r.T) / self.scale, 1.0 / self.scale)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (as in atlas.json).

        Returns
        -------
        dict
            ``rotation`` (3 x 3 nested list), ``translation_mm`` (3 floats, mm), ``scale`` (float).
        """
        return {
            "rotation": self.rotation.tolist(),
            "translation_mm": self.translation.tolist(),
            "scale": float(self.scale),
        }


def wall_grid(n_tau: int = 40, n_theta: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """The (tau, theta) grid of corresponding wall points.

    Parameters
    ----------
    n_tau : int
        Samples of tau in [0, 1], both ends included.
    n_theta : int
        Samples of theta = 2 pi j / n_theta, j = 0 .. n_theta - 1 (rad).

    Returns
    -------
    tau, theta : (n_tau, n_theta) float
        ``np.meshgrid(..., indexing="ij")``; theta in rad.
    """
    return np.meshgrid(np.linspace(0.0, 1.0, n_tau), TWO_PI * np.arange(n_theta) / n_theta, indexing="ij")


def wall_grid_points(model: VesselModel, n_tau: int = 40, n_theta: int = 24) -> np.ndarray:
    """Eq. 8 wall points x(tau, theta) of ``model`` on :func:`wall_grid`.

    Point i of every vessel has the same (tau, theta): these are the correspondences of the
    Procrustes alignment.

    Parameters
    ----------
    model : VesselModel
        A model with a wall model.
    n_tau, n_theta : int
        Grid size (:func:`wall_grid`).

    Returns
    -------
    (n_tau * n_theta, 3) float, mm
        Row-major over (tau, theta).
    """
    tau, theta = wall_grid(n_tau, n_theta)
    return model.surface_points(tau, theta).reshape(-1, 3)


def procrustes(
    source: ArrayLike, target: ArrayLike, *, scale: bool = False, weights: ArrayLike | None = None
) -> RigidTransform:
    """Least-squares transform T minimising sum_i w_i |T(source_i) - target_i|^2 (Kabsch / Umeyama).

    Parameters
    ----------
    source, target : (N, 3) float, mm
        Corresponding points.
    scale : bool
        Also fit an isotropic scale (similarity transform). Default False: rigid.
    weights : (N,) float, optional
        Non-negative weights (normalised to sum 1); default uniform.

    Returns
    -------
    RigidTransform
        With a proper rotation (det R = +1; reflections are never returned).

    Raises
    ------
    VCSInputError
        ``source`` and ``target`` are not two (N, 3) arrays of the same shape.
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
    point_sets: Sequence[ArrayLike],
    *,
    scale: bool = False,
    reference: int = 0,
    max_iter: int = 100,
    tol: float = 1e-10,
) -> tuple[list[RigidTransform], np.ndarray, dict[str, Any]]:
    """Generalised Procrustes analysis of corresponding point sets (paper Section 2.3.2).

    Iterates: align every set to the current mean, average, re-anchor the mean onto set
    ``reference`` (so the result lives in that patient's coordinates and, with ``scale``, has
    its size), until the mean moves by less than ``tol`` times its RMS size.

    Parameters
    ----------
    point_sets : sequence of (N, 3) float, mm
        Corresponding points, one set per vessel.
    scale : bool
        Similarity instead of rigid alignment. Default False: vessel size is kept as a shape
        variable (the calibre is clinically meaningful and is the dominant mode of aortas).
    reference : int
        Index of the set whose coordinates (and size) the mean is anchored to.
    max_iter : int
        Maximum number of iterations.
    tol : float
        Convergence threshold on the RMS change of the mean, relative to the reference's RMS size.

    Returns
    -------
    transforms : list of RigidTransform
        One per set (set -> atlas space).
    mean : (N, 3) float, mm
        The GPA mean.
    report : dict
        ``iterations``, ``scale``, ``reference`` and ``rms_to_mean_mm`` (one float per set, mm).

    Raises
    ------
    VCSInputError
        No point sets.
    """
    sets = [np.asarray(p, float) for p in point_sets]
    if len(sets) < 1:
        raise VCSInputError("generalised Procrustes needs at least one point set")
    ref = sets[reference]
    mean = ref.copy()
    size = np.sqrt(np.mean(np.sum((ref - ref.mean(0)) ** 2, axis=1)))
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 (`it` is reported after the loop)
        transforms = [procrustes(p, mean, scale=scale) for p in sets]
        new = np.mean([t(p) for t, p in zip(transforms, sets)], axis=0)
        new = procrustes(new, ref, scale=scale)(new)
        change = np.sqrt(np.mean(np.sum((new - mean) ** 2, axis=1)))
        mean = new
        if change < tol * size:
            break
    transforms = [procrustes(p, mean, scale=scale) for p in sets]
    rms = [float(np.sqrt(np.mean(np.sum((t(p) - mean) ** 2, axis=1)))) for t, p in zip(transforms, sets)]
    return (
        transforms,
        mean,
        {"iterations": it, "scale": bool(scale), "reference": int(reference), "rms_to_mean_mm": rms},
    )


def transform_model(model: VesselModel, transform: RigidTransform) -> VesselModel:
    """The model moved by ``transform``.

    Eq. 8 points of the result are ``transform`` of the original's (to the accuracy of the frame
    table, ~1e-8 mm). Control points c_i -> s R c_i + t; v1(0) -> R v1(0) (the rotation-minimising
    frame of a rotated curve is the rotated frame); wall coefficients unchanged for a rigid
    transform, multiplied by s for a similarity transform (rho_w is a length).

    Parameters
    ----------
    model : VesselModel
    transform : RigidTransform

    Returns
    -------
    VesselModel
        A new model (same units and a copy of ``meta``); ``model`` is not modified.
    """
    from vcs.model import VesselCoordinateSystem
    from vcs.vessel import VesselModel

    v = model.vcs
    curve = BSpline(v.curve.t, transform(v.control_points), v.curve.k)
    vcs = VesselCoordinateSystem(
        curve, transform.rotation @ v.v1_0, v1_0_from=f"{v.v1_0_from}; rotated by the alignment"
    )
    wall = model.wall
    if wall is not None and transform.scale != 1.0:
        wall = wall.with_coefficients(wall.coefficients * transform.scale)
    return VesselModel(vcs, wall, model.units, dict(model.meta))


def check_compatible(models: Sequence[VesselModel]) -> None:
    """Check that all models share the feature vector layout.

    Parameters
    ----------
    models : sequence of VesselModel
        Compared with ``models[0]``: same centerline knots and degree, a wall model with the
        same K, R.

    Raises
    ------
    VCSInputError
        Naming the first incompatible model and the fix (refit with the same L, K, R).
    """
    m0 = models[0]
    for i, m in enumerate(models[1:], 1):
        if m.wall is None or m0.wall is None:
            raise VCSInputError("every model of an atlas needs a wall model; refit with `vcs fit` (K, R)")
        if not (np.array_equal(m.vcs.curve.t, m0.vcs.curve.t) and m.vcs.curve.k == m0.vcs.curve.k):
            raise VCSInputError(f"model {i} has other centerline knots than model 0; fit every vessel with the same L")
        if (m.wall.K, m.wall.R) != (m0.wall.K, m0.wall.R):
            raise VCSInputError(
                f"model {i} has wall K, R = {m.wall.K}, {m.wall.R}, model 0 {m0.wall.K}, {m0.wall.R}; "
                "fit every vessel with the same K, R"
            )


def align_models(
    models: Sequence[VesselModel], *, n_tau: int = 40, n_theta: int = 24, scale: bool = False, reference: int = 0
) -> tuple[list[VesselModel], list[RigidTransform], dict[str, Any]]:
    """Coregister vessel models by GPA on their Eq. 8 wall grids (paper Section 2.3.2).

    Parameters
    ----------
    models : sequence of VesselModel
        Compatible models (:func:`check_compatible`).
    n_tau, n_theta : int
        Wall grid of the correspondences (:func:`wall_grid_points`).
    scale : bool
        Similarity instead of rigid alignment (:func:`generalized_procrustes`).
    reference : int
        Index of the model whose coordinates the atlas space takes.

    Returns
    -------
    aligned : list of VesselModel
        The models moved into atlas space.
    transforms : list of RigidTransform
        Model -> atlas space, one per model.
    report : dict
        The GPA report plus ``n_tau``, ``n_theta`` and ``mean_points_mm``, the GPA mean wall grid
        ((n_tau * n_theta, 3) float, mm), the target a new vessel is aligned to.
    """
    models = list(models)
    check_compatible(models)
    pts = [wall_grid_points(m, n_tau, n_theta) for m in models]
    transforms, mean, report = generalized_procrustes(pts, scale=scale, reference=reference)
    report.update({"n_tau": n_tau, "n_theta": n_theta, "mean_points_mm": mean})
    return [transform_model(m, t) for m, t in zip(models, transforms)], transforms, report
