"""vcs.cfd.markers: TAWSS, OSI, RRT, ECAP on wall shear stress signals whose answers are known (steady,
reversing, rotating), and the documented values where a marker is undefined."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vcs.cfd.markers import ecap, osi, osi_from_averages, rrt, tawss

T = np.arange(1000) / 1000  # one period, uniform, the first instant not repeated


def test_steady_shear_has_no_oscillation():
    wss = np.full((len(T), 4), 2.0)
    assert tawss(wss).tolist() == [2.0] * 4
    assert osi(wss).tolist() == [0.0] * 4
    assert rrt(tawss(wss), osi(wss)) == pytest.approx(0.5)
    assert ecap(tawss(wss), osi(wss)) == pytest.approx(0.0)


def test_zero_mean_sinusoid_and_a_rotating_vector_are_fully_oscillatory():
    tau = 3.0 * np.sin(2 * np.pi * T)
    assert tawss(tau) == pytest.approx(6 / math.pi, rel=1e-5)  # mean |sin| = 2 / pi
    assert osi(tau) == pytest.approx(0.5, abs=1e-12)
    assert rrt(tawss(tau), 0.5) == math.inf
    vec = np.stack([np.cos(2 * np.pi * T), np.sin(2 * np.pi * T), 0 * T], axis=1)[:, None, :]  # (n_t, 1, 3)
    assert tawss(vec, vector=True) == pytest.approx([1.0])
    assert osi(vec, vector=True) == pytest.approx([0.5], abs=1e-12)


def test_mean_plus_oscillation():
    """tau = m + a sin, a < m: never reverses, OSI = 0; a > m: OSI from the reversed fraction."""
    assert osi(1.0 + 0.5 * np.sin(2 * np.pi * T)) == pytest.approx(0.0, abs=1e-12)
    m, a = 1.0, 2.0
    tau = m + a * np.sin(2 * np.pi * T)
    # |tau| averages to (2/pi) (a cos(phi0) + m phi0) with sin(phi0) = m / a
    phi0 = math.asin(m / a)
    mean_abs = 2 / math.pi * (a * math.cos(phi0) + m * phi0)
    assert tawss(tau) == pytest.approx(mean_abs, rel=1e-5)
    assert osi(tau) == pytest.approx(0.5 * (1 - m / mean_abs), rel=1e-5)
    assert rrt(tawss(tau), osi(tau)) == pytest.approx(1 / m, rel=1e-5)  # 1 / |mean shear|


def test_times_use_the_trapezoidal_rule():
    t = np.array([0.0, 0.1, 0.4, 1.0])
    tau = np.array([1.0, -1.0, 2.0, 0.0])
    mean = np.trapezoid(tau, t)
    mean_abs = np.trapezoid(np.abs(tau), t)  # the |.| of the samples, as a solver writes them
    assert tawss(tau, t) == pytest.approx(mean_abs)
    assert osi(tau, t) == pytest.approx(0.5 * (1 - abs(mean) / mean_abs))
    with pytest.raises(ValueError, match="strictly increasing"):
        tawss(tau, t[::-1])


def test_from_the_averages_a_solver_accumulates():
    mean_vec = np.array([[3.0, 4.0, 0.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    ta = np.array([10.0, 2.0, 1.0])
    np.testing.assert_allclose(osi_from_averages(mean_vec, ta, vector=True), [0.25, 0.5, 0.0])


def test_undefined_values_are_documented():
    """No shear at all: OSI nan, RRT inf (no mean shear carries anything away), ECAP nan."""
    zero = np.zeros((len(T), 2))
    o, ta = osi(zero), tawss(zero)
    assert np.isnan(o).all() and (ta == 0).all()
    assert np.isinf(rrt(ta, o)).all()
    assert np.isnan(ecap(ta, o)).all()
    assert ecap(0.0, 0.2) == math.inf
    assert np.isnan(rrt(1.0, math.nan))
    np.testing.assert_array_equal(rrt([2.0, 0.0, 4.0], [0.25, 0.1, 0.5]), [1.0, math.inf, math.inf])
