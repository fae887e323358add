"""Principal component analysis of shapes and flows (paper Section 2.3.3) and what is built on it.

:class:`PCA` of feature vectors (shape, :func:`shape_matrix`) or of resampled flow fields (flow,
:func:`flow_vector`); :func:`mode_deformation` splits a shape mode into centerline displacement
|delta c(tau)| and radius change delta rho_w(tau, theta) (paper Fig. 7);
:func:`top_variation_mask` marks where a flow mode varies most.

Pure numpy; never imports plotting (:mod:`vcs.atlas.plots`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.atlas.procrustes import TWO_PI
from vcs.errors import VCSInputError

if TYPE_CHECKING:
    from vcs.vessel import VesselModel

FLOW_FIELDS = ("U", "p", "WSS")
VECTOR_FIELDS = ("U", "WSS")
SHAPE_BLOCKS = ("all", "wall", "centerline")


def shape_matrix(models: Sequence[VesselModel], block: str = "all") -> np.ndarray:
    """Feature vectors a = (c, b) of (aligned) models (paper Section 2.3.1).

    ``block`` = ``"all"`` (the paper: centerline control points and wall coefficients together),
    ``"wall"`` or ``"centerline"`` (beyond the paper): the other block is replaced by its cohort
    mean, so it has no variance and the PCA modes live in the chosen block only, while every
    vector stays a complete, rebuildable feature vector (mean shapes, +- sigma shapes and Fig. 7
    work unchanged). The centerline carries length and arch geometry, the wall the calibre; in a
    joint PCA the first mode mixes them (see tests/vcs/test_atlas.py, phantom cohort).

    Parameters
    ----------
    models : sequence of VesselModel
        n compatible models (same knots and K, R), usually aligned (:func:`vcs.atlas.procrustes.align_models`).
    block : {"all", "wall", "centerline"}

    Returns
    -------
    (n, d) float
        One feature vector per model (control points in mm, then wall coefficients in mm).

    Raises
    ------
    VCSInputError
        ``block`` is not one of :data:`SHAPE_BLOCKS`.
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


@dataclass(frozen=True)
class PCA:
    """Principal components of n samples of dimension d.

    Attributes
    ----------
    mean : (d,) float
    components : (k, d) float
        Orthonormal modes, sign fixed so the largest-magnitude entry of each is positive.
    sigma : (k,) float
        Standard deviation of the scores along each mode (ddof = 1), units of the data.
    explained_variance_ratio : (k,) float
        Fraction of the total variance per mode.
    scores : (n, k) float
        Scores of the training samples, units of the data.
    """

    mean: np.ndarray
    components: np.ndarray
    sigma: np.ndarray
    explained_variance_ratio: np.ndarray
    scores: np.ndarray

    @classmethod
    def from_data(cls, X: ArrayLike, n_modes: int | None = None) -> PCA:
        """PCA by SVD of the centred data.

        Parameters
        ----------
        X : (n, d) float
            n >= 2 samples.
        n_modes : int, optional
            Modes kept; at most (and by default) min(n - 1, d).

        Returns
        -------
        PCA

        Raises
        ------
        VCSInputError
            ``X`` is not 2-D or has fewer than 2 samples.
        """
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
        """Number of modes k."""
        return len(self.sigma)

    def transform(self, X: ArrayLike) -> NDArray[np.float64]:
        """Scores of samples.

        Parameters
        ----------
        X : (n, d) or (d,) float

        Returns
        -------
        (n, k) or (k,) float
        """
        return (np.asarray(X, float) - self.mean) @ self.components.T

    def inverse_transform(self, scores: ArrayLike) -> NDArray[np.float64]:
        """Samples rebuilt from scores: mean + scores @ components.

        Parameters
        ----------
        scores : (n, k) or (k,) float

        Returns
        -------
        (n, d) or (d,) float
        """
        return self.mean + np.asarray(scores, float) @ self.components

    def project(self, x: ArrayLike) -> tuple[np.ndarray, np.ndarray, float]:
        """A new sample's scores, its reconstruction from the modes and the reconstruction error.

        Parameters
        ----------
        x : (d,) float

        Returns
        -------
        scores : (k,) float
        reconstruction : (d,) float
        error : float
            |x - reconstruction| (same units as x).
        """
        s = self.transform(x)
        xh = self.inverse_transform(s)
        return s, xh, float(np.linalg.norm(np.asarray(x, float) - xh))

    def mode_sample(self, mode: int, n_sigma: float) -> NDArray[np.float64]:
        """The sample mean + n_sigma * sigma_m * u_m.

        Parameters
        ----------
        mode : int
            0-based mode index m.
        n_sigma : float
            Signed number of standard deviations.

        Returns
        -------
        (d,) float
        """
        return self.mean + n_sigma * self.sigma[mode] * self.components[mode]

    def arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """The PCA's arrays keyed for ``atlas.npz``.

        Parameters
        ----------
        prefix : str
            E.g. ``"shape"`` or ``"flow_U"``.

        Returns
        -------
        dict
            ``{prefix}_mean`` (d,), ``{prefix}_components`` (k, d), ``{prefix}_sigma`` (k,),
            ``{prefix}_explained_variance_ratio`` (k,), ``{prefix}_scores`` (n, k).
        """
        return {
            f"{prefix}_mean": self.mean,
            f"{prefix}_components": self.components,
            f"{prefix}_sigma": self.sigma,
            f"{prefix}_explained_variance_ratio": self.explained_variance_ratio,
            f"{prefix}_scores": self.scores,
        }


def mode_deformation(
    pca: PCA, template: VesselModel, mode: int, *, n_sigma: float = 2.0, n_tau: int = 101, n_theta: int = 48
) -> dict[str, Any]:
    """Split a shape mode into centerline displacement and radius change (paper Fig. 7).

    Compares the shapes mean + n_sigma sigma_m u_m and the mean (feature vectors rebuilt with
    ``template``'s knots and frame rule): |delta c(tau)| = |c_plus(tau) - c_mean(tau)| on
    ``n_tau`` samples, delta rho_w(tau, theta) = rho_w_plus - rho_w_mean on the wall grid.

    Parameters
    ----------
    pca : PCA
        Shape PCA of feature vectors (:func:`shape_matrix`).
    template : VesselModel
        Supplies knots, K, R and frame rule to rebuild models from feature vectors.
    mode : int
        0-based mode index.
    n_sigma : float
        Signed number of standard deviations.
    n_tau, n_theta : int
        Samples of tau in [0, 1] and of theta = 2 pi j / n_theta.

    Returns
    -------
    dict
        ``tau`` (n_tau,), ``theta`` (n_theta,) rad, ``centerline_displacement`` (n_tau,) mm,
        ``radius_change`` (n_tau, n_theta) mm, ``mean_model`` and ``mode_model`` (VesselModel),
        ``mode`` (int) and ``n_sigma`` (float).
    """
    from vcs.vessel import VesselModel

    m0 = VesselModel.from_feature_vector(pca.mean, template)
    m1 = VesselModel.from_feature_vector(pca.mode_sample(mode, n_sigma), template)
    tau = np.linspace(0.0, 1.0, n_tau)
    theta = TWO_PI * np.arange(n_theta) / n_theta
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    dc = np.linalg.norm(m1.vcs.curve(tau) - m0.vcs.curve(tau), axis=1)
    dr = m1.fitted_wall()(T, TH) - m0.fitted_wall()(T, TH)
    return {
        "tau": tau,
        "theta": theta,
        "centerline_displacement": dc,
        "radius_change": dr,
        "mean_model": m0,
        "mode_model": m1,
        "mode": int(mode),
        "n_sigma": float(n_sigma),
    }


def flow_vector(fields: Mapping[str, ArrayLike], name: str, *, frame: str = "vcs") -> NDArray[np.float64]:
    """Flatten one resampled field of one patient into a measurement vector.

    ``frame="vcs"`` (default) uses the vector components in the local VCS frame
    (``U_vcs``/``WSS_vcs``: along t, e_theta, e_rho), which are invariant to the rigid alignment
    and comparable across patients; ``"cartesian"`` uses ``U``/``WSS`` as sampled. Pressures are
    taken in Pa (``p``).

    Parameters
    ----------
    fields : mapping of str to array
        One patient's resampled arrays (``fields.npz``): e.g. ``U_vcs`` (n_tau, n_theta, n_rho, 3)
        m/s, ``p`` (n_tau, n_theta, n_rho) Pa, ``WSS_vcs`` (n_tau, n_theta, 3) Pa.
    name : str
        ``"U"``, ``"p"`` or ``"WSS"``.
    frame : {"vcs", "cartesian"}

    Returns
    -------
    (size of the field,) float
        The field raveled in C order.

    Raises
    ------
    VCSInputError
        ``fields`` lacks the array.
    """
    key = f"{name}_vcs" if frame == "vcs" and name in ("U", "WSS") else name
    if key not in fields:
        raise VCSInputError(
            f"the resampled fields have no '{key}'; resample the case with vcs.cfd.resample.sample_case"
        )
    return np.asarray(fields[key], float).ravel()


def top_variation_mask(
    pca: PCA, mode: int, field_shape: tuple[int, ...], *, vector: bool, fraction: float = 0.2
) -> NDArray[np.bool_]:
    """Grid cells in the top ``fraction`` of a flow mode's variation sigma_m |u_m|.

    Parameters
    ----------
    pca : PCA
        Flow PCA of one field (:func:`flow_vector`).
    mode : int
        0-based mode index m.
    field_shape : tuple of int
        Shape of the field on the grid, e.g. (n_tau, n_theta, n_rho, 3) for U.
    vector : bool
        The trailing axis of ``field_shape`` holds 3 components; the norm is taken over it.
    fraction : float
        Fraction of the cells marked, in (0, 1].

    Returns
    -------
    bool array
        ``field_shape`` without the trailing 3 of vector fields.
    """
    u = np.abs(pca.components[mode] * pca.sigma[mode]).reshape(field_shape)
    if vector:
        u = np.linalg.norm(u, axis=-1)
    return u >= np.quantile(u, 1.0 - fraction)
