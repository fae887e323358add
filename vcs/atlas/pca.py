"""Principal component analysis of shapes and flows (paper Section 2.3.3) and what is built on it.

:class:`PCA` of feature vectors (shape, :func:`shape_matrix`) or of resampled flow fields (flow,
:func:`flow_vector`); :func:`mode_deformation` splits a shape mode into centerline displacement
|delta c(tau)| and radius change delta rho_w(tau, theta) (paper Fig. 7);
:func:`top_variation_mask` marks where a flow mode varies most.

The flow fields an atlas can have a PCA of (the names used in atlas.json, :func:`field_key` gives
the array of ``fields.npz`` each one is made of):

* every cohort: :data:`FLOW_FIELDS` ``U``, ``p``, ``WSS`` (a pulsatile cohort's are the time
  averages over the kept cardiac cycles);
* a pulsatile cohort, in addition: the wall markers :data:`WALL_MARKERS` ``TAWSS``, ``OSI``,
  ``log10_RRT`` and ``ECAP`` (scalar (n_tau, n_theta) wall maps; the relative residence time is
  analysed as its decimal logarithm, see :func:`flow_vector`), and per phase of its
  ``phase_names`` the fields ``phase/<name>/U``, ``phase/<name>/p``, ``phase/<name>/WSS``
  (:func:`phase_field`; vectors in the frame of the unprefixed ones).

Only the wall fields (:func:`is_wall_field`: WSS, the wall markers, a phase's WSS) may hold
non-finite values: NaN where the resampling found a side branch's ostium (no wall of the section:
:data:`vcs.cfd.resample.OSTIUM_CRITERION`), inf/NaN where RRT diverges (OSI -> 0.5 or TAWSS -> 0).
Their PCA leaves those cells out (:meth:`PCA.from_data` with ``drop_non_finite``: NaN in the mean
and the modes there, never a number standing in; :data:`vcs.atlas.cohort.NON_FINITE_RULE`).

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
#: Wall markers of a pulsatile cohort, one PCA each of its (n_tau, n_theta) wall map.
WALL_MARKERS = ("TAWSS", "OSI", "log10_RRT", "ECAP")
#: The quantities of each phase of a pulsatile cohort (``phase/<name>/<quantity>``).
PHASE_QUANTITIES = ("U", "p", "WSS")
#: Units of the fields' values as the PCAs see them (vector fields: of their components).
FIELD_UNITS = {
    "U": "m/s",
    "p": "Pa",
    "WSS": "Pa",
    "TAWSS": "Pa",
    "OSI": "1",
    "log10_RRT": "log10(1/Pa)",
    "ECAP": "1/Pa",
}
#: What the PCA of a wall marker analyses when it is not the ``fields.npz`` array as is.
MARKER_TRANSFORMS = {
    "log10_RRT": "log10 of RRT (1/Pa): RRT = 1 / ((1 - 2 OSI) TAWSS) spans decades and diverges as "
    "OSI -> 0.5, so its raw values would let a few near-divergent cells carry the whole variance"
}


def phase_field(phase: str, quantity: str) -> str:
    """Name of a phase field, ``phase/<phase>/<quantity>`` (as in ``fields.npz``)."""
    return f"phase/{phase}/{quantity}"


def field_quantity(name: str) -> str:
    """The quantity of a flow field name: ``U`` of ``U`` and of ``phase/peak_systole/U``."""
    return name.rsplit("/", 1)[-1]


def field_phase(name: str) -> str | None:
    """The phase of a phase field (``peak_systole`` of ``phase/peak_systole/U``), else None."""
    parts = name.split("/")
    return parts[1] if len(parts) == 3 and parts[0] == "phase" else None


def is_wall_field(name: str) -> bool:
    """Whether a flow field lives on the wall grid (n_tau, n_theta[, 3]) and may miss cells: WSS,
    the :data:`WALL_MARKERS` and a phase's WSS (U and p are volume fields and never may)."""
    return field_quantity(name) in ("WSS", *WALL_MARKERS)


def is_vector_field(name: str) -> bool:
    """Whether a flow field holds vectors (U, WSS and their phase fields)."""
    return field_quantity(name) in VECTOR_FIELDS


def field_slug(name: str) -> str:
    """A flow field's name in file and array names: ``/`` -> ``_`` (``phase_peak_systole_U``)."""
    return name.replace("/", "_")


def field_key(name: str, frame: str = "vcs") -> str:
    """The ``fields.npz`` array a flow field's PCA is made of.

    ``U_vcs``/``WSS_vcs`` (and ``phase/<name>/U_vcs``, ...) for vector fields in the VCS frame,
    ``RRT`` for ``log10_RRT``, the name itself otherwise.
    """
    if name == "log10_RRT":
        return "RRT"
    return f"{name}_vcs" if frame == "vcs" and is_vector_field(name) else name


def pulsatile_fields(phase_names: Sequence[str]) -> tuple[str, ...]:
    """The flow fields of a pulsatile cohort's atlas: :data:`FLOW_FIELDS` (time averages), the
    :data:`WALL_MARKERS`, then :data:`PHASE_QUANTITIES` of each phase in order."""
    phases = (phase_field(ph, q) for ph in phase_names for q in PHASE_QUANTITIES)
    return (*FLOW_FIELDS, *WALL_MARKERS, *phases)


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
        NaN outside ``support``.
    components : (k, d) float
        Orthonormal modes (over ``support``), sign fixed so the largest-magnitude entry of each is
        positive; NaN outside ``support``.
    sigma : (k,) float
        Standard deviation of the scores along each mode (ddof = 1), units of the data.
    explained_variance_ratio : (k,) float
        Fraction of the total variance per mode.
    scores : (n, k) float
        Scores of the training samples, units of the data.
    support : (d,) bool or None
        The entries the PCA was fitted on (None: all); see :meth:`from_data` ``drop_non_finite``.
    """

    mean: np.ndarray
    components: np.ndarray
    sigma: np.ndarray
    explained_variance_ratio: np.ndarray
    scores: np.ndarray
    support: np.ndarray | None = None

    @classmethod
    def from_data(cls, X: ArrayLike, n_modes: int | None = None, *, drop_non_finite: bool = False) -> PCA:
        """PCA by SVD of the centred data.

        Parameters
        ----------
        X : (n, d) float
            n >= 2 samples.
        n_modes : int, optional
            Modes kept; at most (and by default) min(n - 1, d') with d' the entries used.
        drop_non_finite : bool
            Leave out the entries (columns) that are not finite in every sample: the PCA is that of
            the other columns, its ``support``; outside it the mean and the modes are NaN (so are
            samples rebuilt from them; scores and projections use the support only). Without it, a
            non-finite value is an error (never replaced by a number).

        Returns
        -------
        PCA

        Raises
        ------
        VCSInputError
            ``X`` is not 2-D, has fewer than 2 samples, or holds non-finite values (all its columns
            do, with ``drop_non_finite``).

        Examples
        --------
        Six samples on a line in 3-D: one mode along it explains all the variance and rebuilds
        every sample.

        >>> import numpy as np
        >>> from vcs.atlas import PCA
        >>> t = np.array([-2.0, -1.0, 0.0, 0.5, 1.0, 1.5])
        >>> X = np.array([10.0, 0.0, -1.0]) + t[:, None] * np.array([1.0, 2.0, 2.0])
        >>> pca = PCA.from_data(X, n_modes=1)
        >>> pca.components.round(6)
        array([[0.333333, 0.666667, 0.666667]])
        >>> round(float(pca.explained_variance_ratio[0]), 9)
        1.0
        >>> bool(np.allclose(pca.inverse_transform(pca.transform(X)), X, atol=1e-12))
        True
        """
        X = np.asarray(X, float)
        if X.ndim != 2 or len(X) < 2:
            raise VCSInputError(f"PCA needs an (n >= 2, d) array, got shape {X.shape}")
        keep = np.isfinite(X).all(axis=0)
        if not keep.all():
            if not drop_non_finite:
                raise VCSInputError(
                    f"PCA data has {int((~np.isfinite(X)).sum())} non-finite values "
                    f"(in {int((~keep).sum())} of {X.shape[1]} columns)"
                )
            if not keep.any():
                raise VCSInputError(f"PCA data has no column finite in all {len(X)} samples")
            part = cls.from_data(X[:, keep], n_modes)
            mean = np.full(X.shape[1], np.nan)
            mean[keep] = part.mean
            comps = np.full((part.n_modes, X.shape[1]), np.nan)
            comps[:, keep] = part.components
            return cls(mean, comps, part.sigma, part.explained_variance_ratio, part.scores, keep)
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
            From the ``support`` entries only (the others have no mean).
        """
        X = np.asarray(X, float)
        if self.support is None:
            return (X - self.mean) @ self.components.T
        s = self.support
        return (X[..., s] - self.mean[s]) @ self.components[:, s].T

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
            |x - reconstruction| (same units as x) over the ``support`` entries.
        """
        s = self.transform(x)
        xh = self.inverse_transform(s)
        r = np.asarray(x, float) - xh
        return s, xh, float(np.linalg.norm(r if self.support is None else r[self.support]))

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
            ``{prefix}_explained_variance_ratio`` (k,), ``{prefix}_scores`` (n, k), and
            ``{prefix}_support`` (d,) bool when the PCA left entries out.
        """
        out = {
            f"{prefix}_mean": self.mean,
            f"{prefix}_components": self.components,
            f"{prefix}_sigma": self.sigma,
            f"{prefix}_explained_variance_ratio": self.explained_variance_ratio,
            f"{prefix}_scores": self.scores,
        }
        if self.support is not None:
            out[f"{prefix}_support"] = self.support
        return out


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
    taken in Pa (``p``). Phase fields (``phase/<name>/U``, ...) are read like the unprefixed ones
    (:func:`field_key`).

    ``log10_RRT`` is the decimal logarithm of ``RRT`` (1/Pa; :data:`MARKER_TRANSFORMS` says why);
    where RRT is not finite or not positive (OSI = 0.5 or TAWSS = 0: no residence time to speak
    of) the value is NaN, never a number standing in for it: the marker's PCA leaves such cells
    out (:meth:`PCA.from_data` ``drop_non_finite``). The other fields are returned as stored.

    Parameters
    ----------
    fields : mapping of str to array
        One patient's resampled arrays (``fields.npz``): e.g. ``U_vcs`` (n_tau, n_theta, n_rho, 3)
        m/s, ``p`` (n_tau, n_theta, n_rho) Pa, ``WSS_vcs`` (n_tau, n_theta, 3) Pa, and of a
        pulsatile case ``TAWSS``, ``OSI``, ``RRT``, ``ECAP`` (n_tau, n_theta) and the phase fields.
    name : str
        ``"U"``, ``"p"``, ``"WSS"``, a wall marker of :data:`WALL_MARKERS` or a phase field.
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
    key = field_key(name, frame)
    if key not in fields:
        raise VCSInputError(
            f"the resampled fields have no '{key}'; resample the case with vcs.cfd.resample.sample_case"
        )
    a = np.asarray(fields[key], float).ravel()
    if name == "log10_RRT":
        ok = np.isfinite(a) & (a > 0)
        a = np.where(ok, np.log10(np.where(ok, a, 1.0)), np.nan)
    return a


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
        Fraction of the cells marked, in (0, 1]; of the cells in the PCA's ``support`` when it left
        some out (those are never marked).

    Returns
    -------
    bool array
        ``field_shape`` without the trailing 3 of vector fields.
    """
    u = np.abs(pca.components[mode] * pca.sigma[mode]).reshape(field_shape)
    if vector:
        u = np.linalg.norm(u, axis=-1)
    if pca.support is None:
        return u >= np.quantile(u, 1.0 - fraction)
    support = pca.support.reshape(field_shape)
    inside = support.all(axis=-1) if vector else support
    return inside & (u >= np.quantile(u[inside], 1.0 - fraction))
