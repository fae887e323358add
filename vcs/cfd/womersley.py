"""Womersley flow: the exact pulsatile flow in a straight rigid circular pipe driven by a periodic flow
rate, and the inlet velocity profile it gives a (non-circular) inlet section (pure numpy/scipy).

A flow rate given by its Fourier coefficients (:meth:`vcs.cfd.waveform.Waveform.fourier`)::

    Q(t) = Re( sum_{n>=0} Q_n exp(i n omega t) ),      omega = 2 pi / T

drives, in a pipe of radius R and kinematic viscosity nu, the axial velocity (Womersley 1955,
J Physiol 127:553-563, his velocity and flow-rate solutions combined so that each harmonic is given
by its flow rate instead of its pressure gradient)::

    u(r, t) = 2 Q_0 / (pi R^2) (1 - r^2/R^2)
              + Re sum_{n>=1} Q_n / (pi R^2) * (1 - J0(L_n r/R) / J0(L_n)) / (1 - 2 J1(L_n) / (L_n J0(L_n)))
                              * exp(i n omega t)

    L_n = i^{3/2} a_n,   a_n = R sqrt(n omega / nu)   (the Womersley number of harmonic n)

Each harmonic's profile carries exactly its flow rate Q_n (the denominator is the profile's mean over
the disc), tends to Poiseuille's 2 (1 - r^2/R^2) as a_n -> 0 (quasi-steady) and to a plug with a
wall layer of thickness ~R / a_n as a_n -> infinity. The wall shear stress, positive along the
direction in which Q counts positive (the mean flow's for a waveform of positive mean)::

    tau_w(t) = -mu du/dr|_R = mu / (pi R^3) Re sum_n Q_n g_n exp(i n omega t),
    g_0 = 4,   g_n = -L_n J1(L_n) / (J0(L_n) - 2 J1(L_n) / L_n)

(g_n -> 4 as a_n -> 0: Poiseuille's 4 mu Q / (pi R^3); g_n -> a_n exp(i pi/4) as a_n -> infinity:
the wall shear leads the flow rate by 45 degrees). The Bessel functions of complex argument are
scipy's exponentially scaled ``jve`` (no overflow at large a_n); below a_n = :data:`SERIES_ALPHA`
the ratios are summed from their power series instead (no 0/0 as a_n -> 0).

For an inlet that is not a circle, :func:`section_radius` maps each face to a normalised radius
s in [0, 1] and :func:`inlet_velocities` evaluates each harmonic's profile at s, scaled so that the
discrete flux over the faces is exactly that harmonic's flow rate.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import jve

from vcs.cfd import markers
from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

if TYPE_CHECKING:
    from vcs.cfd.waveform import Waveform

SERIES_ALPHA = 2.0
"""Below this Womersley number the profile ratios are summed from their power series."""

_SERIES_TERMS = 24  # |y| = a^2 / 4 < 1: the k-th term is below 1 / (k!)^2, 24 terms reach 1e-46

_I32 = np.exp(0.75j * np.pi)  # i^{3/2}

DEFAULT_HARMONICS = 30
"""Harmonics of an inlet profile (the shipped waveform's series is within 0.5 % of its peak)."""

INLET_KINDS = ("womersley", "parabolic", "plug")
"""Inlet profiles of :func:`inlet_velocities`."""


def womersley_number(radius: ArrayLike, omega: ArrayLike, nu: float) -> float | NDArray[np.floating]:
    """Womersley number a = R sqrt(omega / nu).

    Parameters
    ----------
    radius : float or array
        Pipe radius, m.
    omega : float or array
        Angular frequency, rad/s (``n * 2 pi / T`` for harmonic n).
    nu : float
        Kinematic viscosity, m^2/s.

    Returns
    -------
    float or array
        Dimensionless a: a float for scalar ``radius`` and ``omega`` (JSON-ready), else their broadcast.
    """
    a = np.asarray(radius, dtype=float) * np.sqrt(np.asarray(omega, dtype=float) / nu)
    return float(a) if a.ndim == 0 else a


def _profile(alpha: float, s: NDArray[np.floating]) -> tuple[NDArray[np.complexfloating], complex]:
    """A harmonic's profile, normalised to a mean of 1 over the unit disc, and its wall gradient.

    Parameters
    ----------
    alpha : float
        Womersley number of the harmonic (0: steady, Poiseuille).
    s : array
        r / R in [0, 1].

    Returns
    -------
    array complex, complex
        ``phi(s) = (1 - J0(L s)/J0(L)) / (1 - 2 J1(L)/(L J0(L)))`` (so that u = Q phi / (pi R^2)) and
        ``g = -dphi/ds`` at s = 1 (so that tau = mu Q g / (pi R^3)), L = i^{3/2} alpha.
    """
    s = np.asarray(s, dtype=float)
    if alpha == 0.0:
        return (2.0 * (1.0 - s**2)).astype(complex), complex(4.0)
    if alpha < SERIES_ALPHA:
        # J0(L) - J0(L s) = sum_{k>=1} (-1)^k y^k (1 - s^{2k}) / (k!)^2,  y = (L/2)^2 = -i alpha^2/4
        # J0(L) - 2 J1(L)/L = sum_{k>=1} (-1)^k y^k k / ((k+1) (k!)^2)
        y = -0.25j * alpha**2
        term = complex(1.0)
        num = np.zeros(s.shape, dtype=complex)
        den = complex(0.0)
        grad = complex(0.0)
        for k in range(1, _SERIES_TERMS + 1):
            term *= -y / k**2
            num += term * (1.0 - s ** (2 * k))
            den += term * k / (k + 1)
            grad += term * 2 * k
        return num / den, grad / den
    lam = _I32 * alpha
    decay = alpha / math.sqrt(2.0)  # |Im L|: jve(v, z) = jv(v, z) exp(-|Im z|)
    j0, j1 = complex(jve(0, lam)), complex(jve(1, lam))
    den = j0 - 2.0 * j1 / lam
    phi = (j0 - jve(0, lam * s) * np.exp(-(1.0 - s) * decay)) / den
    return np.asarray(phi), complex(-lam * j1 / den)


def _harmonics(coeffs: ArrayLike, period: float) -> tuple[NDArray[np.complexfloating], float]:
    c = np.atleast_1d(np.asarray(coeffs, dtype=complex))
    if c.ndim != 1:
        raise VCSInputError(f"Fourier coefficients must be 1-D (Q_0, Q_1, ...), got shape {c.shape}")
    if not period > 0:
        raise VCSInputError(f"period {period!r} s is not positive; give the cycle's period")
    return c, 2.0 * math.pi / period


def flow_rate(t: ArrayLike, coeffs: ArrayLike, period: float) -> NDArray[np.floating]:
    """The truncated Fourier series Q(t) = Re sum_n Q_n exp(i n omega t), m^3/s.

    Parameters
    ----------
    t : array
        Times, s.
    coeffs : (N + 1,) complex
        ``Q_0 .. Q_N`` (:meth:`Waveform.fourier`).
    period : float
        T, s.

    Returns
    -------
    array
        Shaped like ``t``.
    """
    c, omega = _harmonics(coeffs, period)
    t = np.asarray(t, dtype=float)
    q = np.zeros(t.shape)
    for n, qn in enumerate(c):
        q += np.real(qn * np.exp(1j * n * omega * t))
    return q


def velocity(
    r: ArrayLike, t: ArrayLike, coeffs: ArrayLike, period: float, radius: float, nu: float
) -> NDArray[np.floating]:
    """Axial velocity u(r, t) of Womersley flow (the formula in the module docstring).

    Parameters
    ----------
    r : array
        Distance from the axis, m, in [0, R].
    t : array
        Times, s (broadcast against ``r``).
    coeffs : (N + 1,) complex
        Flow-rate Fourier coefficients ``Q_0 .. Q_N``, m^3/s.
    period : float
        T, s.
    radius : float
        Pipe radius R, m.
    nu : float
        Kinematic viscosity, m^2/s.

    Returns
    -------
    array
        u, m/s, positive along the direction in which Q counts positive; shape of ``r`` and ``t``
        broadcast.
    """
    c, omega = _harmonics(coeffs, period)
    r, t = np.broadcast_arrays(np.asarray(r, dtype=float), np.asarray(t, dtype=float))
    s = r / radius
    if np.any(s < 0) or np.any(s > 1 + 1e-12):
        raise VCSInputError(f"r must lie in [0, R = {radius:g} m]; got {r.min():g} to {r.max():g} m")
    u = np.zeros(r.shape)
    for n, qn in enumerate(c):
        if qn != 0:
            phi, _ = _profile(float(womersley_number(radius, n * omega, nu)), s)
            u += np.real(qn * phi * np.exp(1j * n * omega * t))
    return u / (math.pi * radius**2)


def centreline_velocity(
    t: ArrayLike, coeffs: ArrayLike, period: float, radius: float, nu: float
) -> NDArray[np.floating]:
    """Axial velocity on the axis, u(0, t), m/s (:func:`velocity` at r = 0)."""
    return velocity(0.0, t, coeffs, period, radius, nu)


def wall_shear_stress(
    t: ArrayLike, coeffs: ArrayLike, period: float, radius: float, nu: float, *, rho: float = 1.0
) -> NDArray[np.floating]:
    """Wall shear stress tau_w(t) = -rho nu du/dr at r = R (the formula in the module docstring).

    Parameters
    ----------
    t : array
        Times, s.
    coeffs, period, radius, nu
        As for :func:`velocity`.
    rho : float
        Density. The default 1 gives the kinematic wall shear stress (m^2/s^2) that OpenFOAM's
        incompressible solvers write; the blood density (kg/m^3) gives Pa.

    Returns
    -------
    array
        tau_w, shaped like ``t``; positive along the direction in which Q counts positive. Uniform
        around the wall.
    """
    c, omega = _harmonics(coeffs, period)
    t = np.asarray(t, dtype=float)
    tau = np.zeros(t.shape)
    for n, qn in enumerate(c):
        if qn != 0:
            _, g = _profile(float(womersley_number(radius, n * omega, nu)), np.zeros(0))
            tau += np.real(qn * g * np.exp(1j * n * omega * t))
    return rho * nu * tau / (math.pi * radius**3)


def tawss_osi(
    coeffs: ArrayLike, period: float, radius: float, nu: float, *, rho: float = 1.0, n_t: int = 4096
) -> tuple[float, float]:
    """TAWSS and OSI of Womersley flow (uniform over the pipe wall).

    The analytic wall shear stress sampled at ``n_t`` uniform instants of one period, reduced by
    :func:`vcs.cfd.markers.tawss` and :func:`vcs.cfd.markers.osi` (error O(1/n_t^2) where tau_w
    changes sign, spectral elsewhere).

    Parameters
    ----------
    coeffs, period, radius, nu, rho
        As for :func:`wall_shear_stress`.
    n_t : int
        Instants per period.

    Returns
    -------
    (float, float)
        TAWSS (unit of ``rho nu`` m/s / m) and OSI.
    """
    t = np.arange(n_t) * (period / n_t)
    tau = wall_shear_stress(t, coeffs, period, radius, nu, rho=rho)
    return float(markers.tawss(tau)), float(markers.osi(tau))


# --------------------------------------------------------------------------- inlet sections


def _segment_distance(
    p: NDArray[np.floating], a: NDArray[np.floating], b: NDArray[np.floating]
) -> NDArray[np.floating]:
    """Distance of each 2-D point ``p`` (n, 2) to the nearest of the segments ``a``-``b`` (m, 2)."""
    ab = b - a
    len2 = np.maximum((ab**2).sum(1), 1e-300)
    out = np.empty(len(p))
    chunk = max(1, 2_000_000 // max(len(a), 1))
    for i in range(0, len(p), chunk):
        q = p[i : i + chunk, None, :] - a[None]  # (c, m, 2)
        w = np.clip((q * ab[None]).sum(-1) / len2[None], 0.0, 1.0)
        out[i : i + chunk] = np.sqrt(((q - w[..., None] * ab[None]) ** 2).sum(-1).min(1))
    return out


def section_radius(
    points: ArrayLike, centre: ArrayLike, normal: ArrayLike, boundary: ArrayLike
) -> NDArray[np.floating]:
    """Normalised radius s in [0, 1] of points of a plane section: 0 at its centre, 1 on its edge.

    ``s = r / (r + d)``, with r the distance to ``centre`` and d the distance to the section's edge,
    both in the plane through ``centre`` normal to ``normal`` (points are projected onto it). For a
    circle about its centre, s = r / R exactly; for any shape, the level sets of s interpolate
    between the centre and the edge, so a circular profile f(r/R) becomes f(s) "mapped to the shape".

    Parameters
    ----------
    points : (n, 3) float
        Points of the section (e.g. inlet face centres).
    centre : (3,) float
        Section centre (e.g. its area-weighted centroid).
    normal : (3,) float
        Section normal (any length, either sense).
    boundary : (m, 3) or (m, 2, 3) float
        The section's edge: an ordered closed loop of points (consecutive points joined, the last to
        the first) or ``m`` edge segments in any order.

    Returns
    -------
    (n,) float
        s in [0, 1] (0 where a point is both the centre and on the edge).
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    c = np.asarray(centre, dtype=float)
    n = np.asarray(normal, dtype=float)
    norm = float(np.linalg.norm(n))
    if not norm > 0:
        raise VCSInputError("section normal is zero; give the inlet's normal vector")
    n = n / norm
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    basis = np.stack([e1, e2], axis=1)  # (3, 2): in-plane coordinates
    b = np.asarray(boundary, dtype=float)
    if b.ndim == 2 and b.shape[1] == 3 and len(b) >= 3:
        seg = np.stack([b, np.roll(b, -1, axis=0)], axis=1)
    elif b.ndim == 3 and b.shape[1:] == (2, 3) and len(b) >= 1:
        seg = b
    else:
        raise VCSInputError(
            f"section boundary of shape {b.shape}: give an (m, 3) closed loop of points or (m, 2, 3) edges"
        )
    q2 = (p - c) @ basis
    s2 = (seg - c) @ basis  # (m, 2, 2)
    r = np.linalg.norm(q2, axis=1)
    d = _segment_distance(q2, s2[:, 0], s2[:, 1])
    total = r + d
    return np.where(total > 0, r / np.where(total > 0, total, 1.0), 0.0)


def inlet_velocities(
    s: ArrayLike,
    face_areas: ArrayLike,
    times: ArrayLike,
    waveform: Waveform,
    kind: str = "womersley",
    radius: float | None = None,
    nu: float | None = None,
    *,
    n_harmonics: int = DEFAULT_HARMONICS,
) -> NDArray[np.floating]:
    """Axial inlet speeds on the faces of an inlet section, with the exact flux at every instant.

    Each face gets ``u_f(t)``, normal to the section, positive into the domain:

    * ``womersley``: ``u_f(t) = Re sum_{n=0}^{N} c_n phi_n(s_f) exp(i n omega t) + r(t)``, phi_n the
      Womersley profile of harmonic n (module docstring) for a pipe of radius ``radius``, evaluated
      at the mapped radius s_f, and ``c_n = Q_n / sum_f A_f phi_n(s_f)``: the discrete flux of
      harmonic n is exactly ``Q_n``. The remainder ``Q(t) - Q_N(t)`` (harmonics above N, whose
      profiles are plug-like: wall layers of thickness R / a_N) is added as a uniform speed
      ``r(t) = (Q(t) - Q_N(t)) / sum_f A_f``, so the flux is the waveform's own Q(t);
    * ``parabolic``: ``u_f(t) = Q(t) (1 - s_f^2) / sum_f A_f (1 - s_f^2)`` (quasi-steady Poiseuille);
    * ``plug``: ``u_f(t) = Q(t) / sum_f A_f``.

    In every case ``sum_f A_f u_f(t) = Q(t)`` to rounding.

    Parameters
    ----------
    s : (F,) float
        Normalised radius of each face in [0, 1] (:func:`section_radius`).
    face_areas : (F,) float
        Face areas projected on the section normal (``|S_f|`` for a flat inlet), m^2.
    times : (n_t,) float
        Times, s (the waveform's cycle repeats).
    waveform : Waveform
        The inflow Q(t), m^3/s.
    kind : {"womersley", "parabolic", "plug"}
        Profile.
    radius : float, optional
        Radius of the pipe whose Womersley numbers are used (``womersley`` only), m; default the
        equivalent radius ``sqrt(sum A_f / pi)``.
    nu : float
        Kinematic viscosity, m^2/s (``womersley`` only).
    n_harmonics : int
        Highest harmonic N of the ``womersley`` series.

    Returns
    -------
    (n_t, F) float
        Speeds, m/s, positive into the domain.
    """
    s = np.asarray(s, dtype=float).ravel()
    area = np.asarray(face_areas, dtype=float).ravel()
    t = np.atleast_1d(np.asarray(times, dtype=float))
    if s.shape != area.shape or len(s) == 0:
        raise VCSInputError(f"inlet: {len(s)} radii for {len(area)} face areas; give one of each per face")
    if np.any(~np.isfinite(s)) or s.min() < 0 or s.max() > 1:
        raise VCSInputError("inlet: normalised radii must lie in [0, 1]; compute them with section_radius")
    if np.any(~(area > 0)):
        raise VCSInputError("inlet: face areas must be positive; give |S_f| (m^2) of each inlet face")
    total = float(area.sum())
    q = waveform(t)
    if kind == "plug":
        return np.outer(q, np.full_like(s, 1.0 / total))
    if kind == "parabolic":
        shape = 1.0 - s**2
        return np.outer(q, shape / float(area @ shape))
    if kind != "womersley":
        raise VCSInputError(f"inlet profile {kind!r} is unknown; use one of {', '.join(INLET_KINDS)}")
    if nu is None or not nu > 0:
        raise VCSInputError(f"inlet: a Womersley profile needs the kinematic viscosity nu > 0 (m^2/s), got {nu!r}")
    r_pipe = math.sqrt(total / math.pi) if radius is None else float(radius)
    coeffs = waveform.fourier(n_harmonics)
    omega = waveform.omega
    u = np.zeros((len(t), len(s)))
    for n, qn in enumerate(coeffs):
        phi, _ = _profile(float(womersley_number(r_pipe, n * omega, nu)), s)
        cn = qn / complex(area @ phi)
        u += np.real(np.outer(np.exp(1j * n * omega * t), cn * phi))
    u += ((q - flow_rate(t, coeffs, waveform.period_s)) / total)[:, None]
    return u


def profile_on_section(
    points: ArrayLike,
    centre: ArrayLike,
    normal: ArrayLike,
    boundary: ArrayLike,
    face_areas: ArrayLike,
    times: ArrayLike,
    waveform: Waveform,
    *,
    kind: str = "womersley",
    radius: float | None = None,
    nu: float | None = None,
    n_harmonics: int = DEFAULT_HARMONICS,
) -> NDArray[np.floating]:
    """Inlet speeds of a section's faces: :func:`section_radius` then :func:`inlet_velocities`.

    Parameters
    ----------
    points, centre, normal, boundary
        As for :func:`section_radius` (``points``: the face centres).
    face_areas, times, waveform, kind, radius, nu, n_harmonics
        As for :func:`inlet_velocities`.

    Returns
    -------
    (n_t, F) float
        Speeds, m/s, positive into the domain (multiply by the inward unit normal for vectors).
    """
    s = section_radius(points, centre, normal, boundary)
    return inlet_velocities(s, face_areas, times, waveform, kind=kind, radius=radius, nu=nu, n_harmonics=n_harmonics)
