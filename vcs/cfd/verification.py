"""Reference solutions the CFD is verified against, and the statistics of a comparison.

Not equations of Romero et al. (2024): these are the analytic and published values that
``tests/workflow/test_openfoam.py`` and ``bench/`` compare the OpenFOAM results with.

* Hagen-Poiseuille flow in a straight circular pipe of radius a carrying Q (exact):
  -dp/ds = 8 mu Q / (pi a^4), wall shear stress 4 mu Q / (pi a^3).
* Developed laminar flow in a curved pipe (a torus arc of centreline radius R): Dean number
  De = Re sqrt(a / R) with Re = U_mean 2a / nu; the ratio of the curved-pipe friction factor to
  the straight-pipe one at the same Re (= ratio of the pressure gradients along the centreline)
  from the correlations of Ito (1959) and White (1929).
* Womersley flow in a straight rigid pipe (:mod:`vcs.cfd.womersley`): a periodic record against
  the analytic one by its mean and first harmonic (:func:`harmonic_errors`).
* On the (tau, theta, rho_n) grid of :mod:`vcs.cfd.resample`: the area-weighted mean of a field
  over each cross-section, the developed pressure gradient along the centreline (a straight-line
  fit over a tau window), and percentiles of a local relative error over a tau window.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "dean_number",
    "harmonic_errors",
    "developed_gradient",
    "ito_friction_ratio",
    "local_error_stats",
    "poiseuille_pressure_gradient",
    "poiseuille_wall_shear_stress",
    "section_mean",
    "white_friction_ratio",
]


def poiseuille_pressure_gradient(flow_rate: float, radius: float, viscosity: float) -> float:
    """Hagen-Poiseuille pressure gradient -dp/ds = 8 mu Q / (pi a^4) of a straight circular pipe.

    Parameters
    ----------
    flow_rate : float
        Q, m^3/s.
    radius : float
        Pipe radius a, m.
    viscosity : float
        Dynamic viscosity mu (Pa s) for a gradient in Pa/m, or kinematic nu (m^2/s) for a
        kinematic gradient (m/s^2, OpenFOAM's p / rho).

    Returns
    -------
    float
        -dp/ds (positive for flow towards +s).

    Examples
    --------
    5 L/min of blood (mu = 3.57e-3 Pa s) through a 12.5 mm radius pipe, in Pa/m:

    >>> from vcs.cfd.verification import poiseuille_pressure_gradient
    >>> round(poiseuille_pressure_gradient(5 / 60000, 12.5e-3, 3.57e-3), 3)
    31.03
    """
    return 8.0 * viscosity * flow_rate / (np.pi * radius**4)


def poiseuille_wall_shear_stress(flow_rate: float, radius: float, viscosity: float) -> float:
    """Hagen-Poiseuille wall shear stress 4 mu Q / (pi a^3) = 4 mu U_mean / a.

    Parameters
    ----------
    flow_rate : float
        Q, m^3/s.
    radius : float
        Pipe radius a, m.
    viscosity : float
        Dynamic viscosity (Pa s) for Pa, or kinematic (m^2/s) for m^2/s^2.

    Returns
    -------
    float
        |tau_w|, in the unit chosen by ``viscosity``.

    Examples
    --------
    >>> from vcs.cfd.verification import poiseuille_wall_shear_stress
    >>> round(poiseuille_wall_shear_stress(5 / 60000, 12.5e-3, 3.57e-3), 4)
    0.1939
    """
    return 4.0 * viscosity * flow_rate / (np.pi * radius**3)


def dean_number(reynolds: float, radius: float, curvature_radius: float) -> float:
    """Dean number De = Re sqrt(a / R) (Re on the diameter 2a; Ito 1959, White 1929).

    Parameters
    ----------
    reynolds : float
        Re = U_mean 2a / nu.
    radius : float
        Pipe radius a (any length unit).
    curvature_radius : float
        Radius R of the pipe's centreline (same unit as ``radius``).

    Returns
    -------
    float
        De.

    Examples
    --------
    The curved pipe of the CFD verification: Re 500, a / R = 0.15:

    >>> from vcs.cfd.verification import dean_number
    >>> round(dean_number(500, 5.0, 33.3), 1)
    193.7
    """
    return float(reynolds * np.sqrt(radius / curvature_radius))


def ito_friction_ratio(dean: float) -> float:
    """Curved- to straight-pipe laminar friction factor f_c / f_s of Ito (1959).

    f_c / f_s = 21.5 De / (1.56 + log10 De)^5.73, for 13.5 < De < 2000: H. Ito, "Friction
    factors for turbulent flow in curved pipes", Trans. ASME J. Basic Engineering 81 (1959)
    123-134 (its laminar-flow correlation; fully developed flow, small a / R). f_s = 64 / Re.

    Parameters
    ----------
    dean : float
        De = Re sqrt(a / R), see :func:`dean_number`.

    Returns
    -------
    float
        f_c / f_s (= the ratio of the developed pressure gradients at the same flow rate).

    Raises
    ------
    ValueError
        Outside 13.5 < De < 2000, where the correlation was not fitted.
    """
    if not 13.5 < dean < 2000.0:
        raise ValueError(f"Ito's laminar correlation holds for 13.5 < De < 2000, not De = {dean:g}")
    return float(21.5 * dean / (1.56 + np.log10(dean)) ** 5.73)


def white_friction_ratio(dean: float) -> float:
    """Curved- to straight-pipe laminar friction factor f_c / f_s of White (1929).

    f_c / f_s = 1 / {1 - [1 - (11.6 / De)^0.45]^(1 / 0.45)}, for 11.6 < De < 2000: C. M. White,
    "Streamline flow through curved pipes", Proc. R. Soc. Lond. A 123 (1929) 645-663.

    Parameters
    ----------
    dean : float
        De = Re sqrt(a / R).

    Returns
    -------
    float
        f_c / f_s.

    Raises
    ------
    ValueError
        Outside 11.6 < De < 2000.
    """
    if not 11.6 < dean < 2000.0:
        raise ValueError(f"White's correlation holds for 11.6 < De < 2000, not De = {dean:g}")
    return float(1.0 / (1.0 - (1.0 - (11.6 / dean) ** 0.45) ** (1.0 / 0.45)))


def section_mean(values: ArrayLike, rho_n: ArrayLike, rho_w: ArrayLike | None = None) -> NDArray[np.floating]:
    """Area-weighted mean of a field over each cross-section of the (tau, theta, rho_n) grid.

    The section at tau is the polar grid x = c + rho_n rho_w(theta) e_rho(theta); its area element
    is rho_w(theta)^2 rho_n d rho_n d theta, integrated by the trapezoidal rule in rho_n (second
    order in the rho_n spacing) and the periodic rectangle rule in theta (spectrally accurate).

    Parameters
    ----------
    values : (n_tau, n_theta, n_rho) float
        A scalar field on the grid (e.g. ``fields["p"]``).
    rho_n : (n_rho,) float
        Normalised radii, increasing from 0 to 1.
    rho_w : (n_tau, n_theta) float or None
        Wall radius per (tau, theta) (``fields["rho_w_mm"]``); None: a circular section.

    Returns
    -------
    (n_tau,) float
        Mean over each section, in the unit of ``values``.
    """
    v = np.asarray(values, float)
    r = np.asarray(rho_n, float)
    dr = np.diff(r)
    trap = np.zeros_like(r)
    trap[:-1] += dr / 2
    trap[1:] += dr / 2
    w = r * trap  # (n_rho,)
    ww = np.ones(v.shape[:2]) if rho_w is None else np.asarray(rho_w, float) ** 2
    weights = ww[..., None] * w
    return (v * weights).sum(axis=(1, 2)) / weights.sum(axis=(1, 2))


def developed_gradient(s: ArrayLike, values: ArrayLike, window: tuple[float, float]) -> float:
    """Slope of a least-squares straight line through ``values`` over ``window`` of s.

    Parameters
    ----------
    s : (n,) float
        Position along the centreline (e.g. arc length tau x length).
    values : (n,) float
        A section mean at each s (e.g. from :func:`section_mean`).
    window : (float, float)
        [s_lo, s_hi] (same unit as ``s``), away from both ends.

    Returns
    -------
    float
        d values / d s (negative for a pressure falling along the flow).

    Raises
    ------
    ValueError
        When fewer than 3 stations lie in the window.
    """
    s = np.asarray(s, float)
    m = (s >= window[0]) & (s <= window[1])
    if m.sum() < 3:
        raise ValueError(f"only {int(m.sum())} stations in the window {window}; need at least 3")
    return float(np.polyfit(s[m], np.asarray(values, float)[m], 1)[0])


def local_error_stats(
    values: ArrayLike, exact: ArrayLike | float, tau: ArrayLike, window: tuple[float, float] = (0.0, 1.0)
) -> dict[str, Any]:
    """Percentiles of the local relative error of a wall map over a tau window.

    Parameters
    ----------
    values : (n_tau, n_theta) float
        Computed map (e.g. |WSS| on the wall grid).
    exact : float or (n_tau, n_theta) float
        The reference, same unit.
    tau : (n_tau,) float
        Grid tau.
    window : (float, float)
        Rows with window[0] <= tau <= window[1] are used.

    Returns
    -------
    dict
        ``window``, ``n`` (nodes used), ``mean``, ``p5``, ``p95`` (signed, of values / exact - 1),
        ``p95_abs``, ``p99_abs``, ``max_abs``, and ``argmax`` = (tau, theta index) of the largest
        |error| in the window.
    """
    v = np.asarray(values, float)
    e = v / np.broadcast_to(np.asarray(exact, float), v.shape) - 1.0
    t = np.asarray(tau, float)
    rows = np.flatnonzero((t >= window[0]) & (t <= window[1]))
    sub = e[rows]
    a = np.abs(sub)
    i, j = np.unravel_index(int(np.argmax(a)), a.shape)
    return {
        "window": [float(window[0]), float(window[1])],
        "n": int(sub.size),
        "mean": float(sub.mean()),
        "p5": float(np.percentile(sub, 5)),
        "p95": float(np.percentile(sub, 95)),
        "p95_abs": float(np.percentile(a, 95)),
        "p99_abs": float(np.percentile(a, 99)),
        "max_abs": float(a.max()),
        "argmax": [float(t[rows[i]]), int(j)],
    }


def harmonic_errors(t: ArrayLike, simulated: ArrayLike, exact: ArrayLike, period: float) -> dict[str, float]:
    """Mean and first-harmonic errors of a record over one period against the exact one.

    With c_k = (2 / T) int_0^T y(t) exp(-i k omega t) dt (trapezoid on the record's own times,
    omega = 2 pi / T) and the mean m = (1/T) int y dt:

        mean_rel = m_sim / m_exact - 1,  amplitude_rel = |c_1,sim| / |c_1,exact| - 1,
        phase_deg = arg(c_1,sim / c_1,exact) in degrees (positive: the simulation leads),
        max_rel = max_t |y_sim - y_exact| / max_t |y_exact|.

    Parameters
    ----------
    t : (n,) float
        Times within one period (s), increasing.
    simulated, exact : (n,) float
        The record and the exact values at ``t``.
    period : float
        T (s).

    Returns
    -------
    dict
        ``mean_rel``, ``amplitude_rel``, ``phase_deg``, ``max_rel`` and the exact ``mean`` and
        ``amplitude``.
    """
    tt = np.asarray(t, dtype=float)
    y, e = np.asarray(simulated, dtype=float), np.asarray(exact, dtype=float)
    span = float(tt[-1] - tt[0])
    w = np.exp(-2j * np.pi * tt / period)

    def mean_c1(v: NDArray[np.floating]) -> tuple[float, complex]:
        return float(np.trapezoid(v, tt) / span), complex(2 * np.trapezoid(v * w, tt) / span)

    m_s, c_s = mean_c1(y)
    m_e, c_e = mean_c1(e)
    return {
        "mean": m_e,
        "amplitude": abs(c_e),
        "mean_rel": m_s / m_e - 1 if m_e else float("nan"),
        "amplitude_rel": abs(c_s) / abs(c_e) - 1,
        "phase_deg": float(np.angle(c_s / c_e, deg=True)),
        "max_rel": float(np.abs(y - e).max() / np.abs(e).max()),
    }
