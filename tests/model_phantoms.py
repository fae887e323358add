"""Vessel models with hand-computable sections, built directly from B-spline coefficients (no fit).

``narrowed_model`` is a straight vessel whose wall radius is the quadratic rho(tau) through
(0, r_in), (1/2, r_mid), (1, r_out), the same at every theta. A cubic B-spline reproduces a
quadratic exactly when its coefficients are the polar form (blossom) of the quadratic at the
knots t_{i+1}, t_{i+2}, t_{i+3}: f[t1, t2, t3] = a + b (t1 + t2 + t3) / 3 + c (t1 t2 + t1 t3 + t2 t3) / 3.
So the model's rho_w(tau, theta) equals the quadratic to round-off, and its sections' diameters are
2 rho(tau) exactly: ends 2 r_in and 2 r_out, the narrowest 2 (a - b^2 / (4 c)) at tau = -b / (2 c)
when that lies in (0, 1).
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline

from vcs.centerline import uniform_knots
from vcs.model import VesselCoordinateSystem
from vcs.vessel import VesselModel
from vcs.wall import WallModel


def quadratic(r_in: float, r_mid: float, r_out: float) -> tuple[float, float, float]:
    """(a, b, c) of rho(tau) = a + b tau + c tau^2 through (0, r_in), (1/2, r_mid), (1, r_out)."""
    a = r_in
    # a + b/2 + c/4 = r_mid, a + b + c = r_out
    c = 2.0 * (r_out + r_in - 2.0 * r_mid)
    b = r_out - a - c
    return a, b, c


def blossom_coefficients(abc: tuple[float, float, float], K: int) -> np.ndarray:
    """Cubic B-spline coefficients (K + 4,) on the clamped uniform knots reproducing a + b t + c t^2."""
    a, b, c = abc
    t = uniform_knots(K)
    out = []
    for i in range(K + 4):
        t1, t2, t3 = t[i + 1 : i + 4]
        out.append(a + b * (t1 + t2 + t3) / 3.0 + c * (t1 * t2 + t1 * t3 + t2 * t3) / 3.0)
    return np.array(out)


def narrowed_model(
    r_in: float = 12.0,
    r_mid: float = 4.0,
    r_out: float = 9.0,
    length: float = 100.0,
    axis=(0.3, 0.2, 1.0),
    origin=(0.0, 0.0, 0.0),
    K: int = 7,
    R: int = 7,
    L: int = 3,
) -> VesselModel:
    """Straight vessel (mm) with the quadratic radius through r_in, r_mid (tau 1/2), r_out."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    t = uniform_knots(L)
    greville = np.array([t[i + 1 : i + 4].mean() for i in range(L + 4)])
    curve = BSpline(t, np.asarray(origin, float) + greville[:, None] * length * axis, 3)
    v1 = np.cross(axis, [1.0, 0.0, 0.0])
    vcs = VesselCoordinateSystem(curve, v1 / np.linalg.norm(v1))
    col = blossom_coefficients(quadratic(r_in, r_mid, r_out), K)
    return VesselModel(vcs, WallModel(K, R, np.repeat(col[:, None], R + 1, axis=1)))
