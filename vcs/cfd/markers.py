"""Haemodynamic wall markers from wall shear stress over one cycle (pure numpy): TAWSS, OSI, RRT,
ECAP. One function per marker, the formula in its docstring, arrays in and out.

Wall shear stress ``tau`` (a vector on the wall, or its signed component along a known direction)
sampled over one period T:

* TAWSS = (1/T) int_0^T |tau| dt                                   (time-averaged magnitude)
* OSI   = 1/2 (1 - |(1/T) int_0^T tau dt| / TAWSS)                 (Ku et al. 1985; He & Ku 1996)
* RRT   = 1 / ((1 - 2 OSI) TAWSS) = 1 / |(1/T) int_0^T tau dt|     (Himburg et al. 2004;
  Lee, Antiga & Steinman 2009)
* ECAP  = OSI / TAWSS                                              (Di Achille et al. 2014)

Undefined values, by rule (never an exception, so that a whole wall is computed at once):

* OSI is ``nan`` where TAWSS = 0 (no shear: no direction that could oscillate);
* RRT is ``inf`` where the mean shear vector vanishes, ``(1 - 2 OSI) TAWSS = 0``: OSI = 1/2, or
  TAWSS = 0 whatever OSI (then ``nan``). RRT is the reciprocal of the mean shear, a particle at
  such a wall is never carried away: the limit is +inf, and it sorts as the longest residence.
  Average RRT over a wall only where it is finite (``np.isfinite``);
* ECAP is ``nan`` where TAWSS = 0 (OSI is undefined there), ``inf`` where a finite OSI > 0 is
  given with TAWSS = 0.

References: Ku DN, Giddens DP, Zarins CK, Glagov S (1985) Arteriosclerosis 5:293-302; He X,
Ku DN (1996) J Biomech Eng 118:74-82; Himburg HA et al. (2004) Am J Physiol Heart Circ Physiol
286:H1916-H1922; Lee SW, Antiga L, Steinman DA (2009) J Biomech Eng 131:061013; Di Achille P,
Tellides G, Figueroa CA, Humphrey JD (2014) Proc R Soc A 470:20140163.

Units: whatever ``tau`` is in (Pa, or m^2/s^2 for OpenFOAM's kinematic incompressible wall shear
stress); RRT and ECAP in its reciprocal.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError


def _time_mean(x: NDArray[np.floating], times: ArrayLike | None) -> NDArray[np.floating]:
    """Mean over axis 0: uniform samples of one period (``times`` None) or the trapezoidal rule."""
    if times is None:
        return np.asarray(x.mean(axis=0))
    t = np.asarray(times, dtype=float)
    if t.shape != (x.shape[0],) or len(t) < 2 or np.any(np.diff(t) <= 0):
        raise VCSInputError(f"times must be ({x.shape[0]},) and strictly increasing, got shape {t.shape}")
    return np.asarray(np.trapezoid(x, t, axis=0) / (t[-1] - t[0]))


def _magnitude(wss: ArrayLike, vector: bool) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """(signal, |signal|): ``vector`` takes the last axis as the components."""
    w = np.asarray(wss, dtype=float)
    return w, (np.linalg.norm(w, axis=-1) if vector else np.abs(w))


def tawss(wss: ArrayLike, times: ArrayLike | None = None, *, vector: bool = False) -> NDArray[np.floating]:
    """Time-averaged wall shear stress magnitude, TAWSS = (1/T) int_0^T |tau| dt.

    Parameters
    ----------
    wss : (n_t, ...) float, or (n_t, ..., 3) with ``vector``
        Wall shear stress at ``n_t`` instants of one cycle, for any number of wall points.
    times : (n_t,) float, optional
        Times of the samples (trapezoidal rule from the first to the last). Without it the samples
        are uniformly spaced over one period, the first instant not repeated at the end (their
        plain mean: the exact rule for periodic signals).
    vector : bool
        The last axis of ``wss`` holds the components of the vector.

    Returns
    -------
    (...) float
        TAWSS, in the unit of ``wss``.

    Examples
    --------
    A shear of 1 Pa reversing to -1 Pa for half the cycle has TAWSS 1 Pa:

    >>> import numpy as np
    >>> from vcs.cfd.markers import tawss
    >>> tawss(np.array([1.0, 1.0, -1.0, -1.0]))
    array(1.)
    """
    _, mag = _magnitude(wss, vector)
    return _time_mean(mag, times)


def osi_from_averages(mean_wss: ArrayLike, tawss: ArrayLike, *, vector: bool = False) -> NDArray[np.floating]:
    """Oscillatory shear index from the two time averages a solver accumulates.

    OSI = 1/2 (1 - |mean tau| / TAWSS), in [0, 1/2]: 0 for shear of constant direction, 1/2 for
    shear whose mean vanishes. ``nan`` where TAWSS = 0 (no shear, see the module docstring).

    Parameters
    ----------
    mean_wss : (...) float, or (..., 3) with ``vector``
        Time average of the wall shear stress (vector or signed component).
    tawss : (...) float
        Time average of its magnitude.
    vector : bool
        The last axis of ``mean_wss`` holds the components.

    Returns
    -------
    (...) float
        OSI (rounding clipped to [0, 1/2]).
    """
    _, mean_mag = _magnitude(mean_wss, vector)
    ta = np.asarray(tawss, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(ta > 0, mean_mag / np.where(ta > 0, ta, 1.0), np.nan)
    return np.asarray(np.clip(0.5 * (1.0 - ratio), 0.0, 0.5))


def osi(wss: ArrayLike, times: ArrayLike | None = None, *, vector: bool = False) -> NDArray[np.floating]:
    """Oscillatory shear index, OSI = 1/2 (1 - |int_0^T tau dt| / int_0^T |tau| dt).

    Parameters
    ----------
    wss, times, vector
        As for :func:`tawss`.

    Returns
    -------
    (...) float
        OSI in [0, 1/2]; ``nan`` where the shear is zero throughout.

    Examples
    --------
    A steady shear has OSI 0, a zero-mean oscillating one 1/2:

    >>> import numpy as np
    >>> from vcs.cfd.markers import osi
    >>> osi(np.array([[2.0, 1.0], [2.0, -1.0], [2.0, 1.0], [2.0, -1.0]]))
    array([0. , 0.5])
    """
    w, mag = _magnitude(wss, vector)
    return osi_from_averages(_time_mean(w, times), _time_mean(mag, times), vector=vector)


def rrt(tawss: ArrayLike, osi: ArrayLike) -> NDArray[np.floating]:
    """Relative residence time, RRT = 1 / ((1 - 2 OSI) TAWSS), the reciprocal of the mean shear.

    Parameters
    ----------
    tawss, osi : array
        Broadcastable TAWSS and OSI.

    Returns
    -------
    array
        RRT; ``inf`` where the mean shear vanishes (OSI = 1/2, or TAWSS = 0 whatever OSI),
        ``nan`` only where an input is ``nan`` with TAWSS > 0.
    """
    ta = np.asarray(tawss, dtype=float)
    o = np.asarray(osi, dtype=float)
    mean_shear = np.where(ta == 0, 0.0, (1.0 - 2.0 * o) * ta)
    with np.errstate(divide="ignore"):
        return np.asarray(np.where(mean_shear == 0, np.inf, 1.0 / mean_shear))


def ecap(tawss: ArrayLike, osi: ArrayLike) -> NDArray[np.floating]:
    """Endothelial cell activation potential, ECAP = OSI / TAWSS.

    Parameters
    ----------
    tawss, osi : array
        Broadcastable TAWSS and OSI.

    Returns
    -------
    array
        ECAP; ``nan`` where TAWSS = 0 and OSI is ``nan`` or 0, ``inf`` where OSI > 0 and TAWSS = 0.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.asarray(osi, dtype=float) / np.asarray(tawss, dtype=float))
