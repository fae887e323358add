"""vcs.cfd.verification: the reference values and statistics against hand-computed numbers."""

from __future__ import annotations

import numpy as np
import pytest

from vcs.cfd.verification import (
    dean_number,
    developed_gradient,
    ito_friction_ratio,
    local_error_stats,
    poiseuille_pressure_gradient,
    poiseuille_wall_shear_stress,
    section_mean,
    white_friction_ratio,
)


def test_poiseuille_by_hand():
    # mu 3.5721e-3 Pa s, Q 2e-5 m3/s, a 1 cm: 8 mu Q / (pi a^4) = 5.7154e-7 / 3.1416e-8 = 18.193 Pa/m,
    # 4 mu Q / (pi a^3) = 2.8577e-7 / 3.1416e-6 = 0.090963 Pa
    assert poiseuille_pressure_gradient(2e-5, 0.01, 3.5721e-3) == pytest.approx(18.193, rel=1e-4)
    assert poiseuille_wall_shear_stress(2e-5, 0.01, 3.5721e-3) == pytest.approx(0.090963, rel=1e-4)


def test_dean_and_curved_pipe_correlations_by_hand():
    assert dean_number(500.0, 5.0, 20.0) == pytest.approx(250.0)
    # Ito (1959): 21.5 x 100 / (1.56 + 2)^5.73 = 2150 / 1444.8 = 1.4881
    assert ito_friction_ratio(100.0) == pytest.approx(1.48809, rel=1e-4)
    # White (1929): (11.6 / 100)^0.45 = 0.37932; 1 - that = 0.62068; ^(1 / 0.45) = 0.34650
    # -> 1 / (1 - 0.34650) = 1.5302
    assert white_friction_ratio(100.0) == pytest.approx(1.53023, rel=1e-4)
    # the two correlations agree within 4 % at the curved-pipe test's De ~ 194
    assert ito_friction_ratio(193.75) == pytest.approx(1.8483, rel=1e-4)
    assert white_friction_ratio(193.75) == pytest.approx(1.9209, rel=1e-4)
    for f, bad in ((ito_friction_ratio, 10.0), (ito_friction_ratio, 3000.0), (white_friction_ratio, 11.0)):
        with pytest.raises(ValueError, match="holds for"):
            f(bad)


def test_section_mean_polar_areas():
    rho_n = np.linspace(0.0, 1.0, 201)
    theta = 2 * np.pi * np.arange(64) / 64
    n_tau = 3
    # constant per section -> that constant; rho_n^2 over the disc: int r^2 2r dr = 1/2
    v = np.broadcast_to(np.array([1.0, 2.0, -3.0])[:, None, None], (n_tau, 64, 201))
    np.testing.assert_allclose(section_mean(v, rho_n), [1.0, 2.0, -3.0])
    v2 = np.broadcast_to(rho_n**2, (n_tau, 64, 201))
    np.testing.assert_allclose(section_mean(v2, rho_n), 0.5, rtol=1e-4)
    # a non-circular section rho_w = 1 + 0.5 cos theta, field cos theta (constant along rho):
    # int cos (1 + 0.5 cos)^2 / int (1 + 0.5 cos)^2 = pi / (2 pi + pi / 4) = 4 / 9
    rho_w = np.broadcast_to(1 + 0.5 * np.cos(theta), (n_tau, 64))
    v3 = np.broadcast_to(np.cos(theta)[None, :, None], (n_tau, 64, 201))
    np.testing.assert_allclose(section_mean(v3, rho_n, rho_w), 4 / 9, rtol=1e-9)


def test_developed_gradient_and_local_error_stats():
    s = np.linspace(0.0, 0.2, 41)
    p = 3.0 - 12.5 * s + np.where(s < 0.05, 40 * (0.05 - s) ** 2, 0.0)  # an inlet bump, then linear
    assert developed_gradient(s, p, (0.05, 0.18)) == pytest.approx(-12.5)
    with pytest.raises(ValueError, match="stations"):
        developed_gradient(s, p, (0.1, 0.101))
    tau = np.linspace(0, 1, 11)
    err = np.zeros((11, 4))
    err[0, 2] = 0.4  # an inlet-edge outlier
    err[5] = [0.01, -0.02, 0.03, -0.04]
    whole = local_error_stats(2.0 * (1 + err), 2.0, tau)
    assert whole["n"] == 44 and whole["max_abs"] == pytest.approx(0.4) and whole["argmax"] == [0.0, 2]
    dev = local_error_stats(2.0 * (1 + err), 2.0, tau, (0.1, 0.9))
    assert dev["n"] == 36 and dev["max_abs"] == pytest.approx(0.04) and dev["argmax"] == [0.5, 3]
    assert dev["mean"] == pytest.approx(-0.02 / 36)
