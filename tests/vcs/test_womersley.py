"""vcs.cfd.womersley against what can be derived without it: the profile's flux is the flow rate
(quadrature over the disc), its wall shear stress is its wall gradient (finite differences), small
Womersley numbers give Poiseuille's quasi-steady flow, large ones a plug core with a Stokes layer
whose shear leads the flow by 45 degrees, TAWSS/OSI of steady and zero-mean flows are known in
closed form, and the inlet profile mapped onto an elliptical section carries the waveform's flow
exactly."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.spatial import Delaunay

from vcs.cfd import womersley as W
from vcs.cfd.waveform import Waveform, default_waveform_path, load_waveform
from vcs.cfd.womersley import (
    centreline_velocity,
    flow_rate,
    inlet_velocities,
    profile_on_section,
    section_radius,
    tawss_osi,
    velocity,
    wall_shear_stress,
    womersley_number,
)
from vcs.errors import VCSInputError

NU = 3.5e-6  # blood, m^2/s
RHO = 1060.0
R = 0.012  # ascending aorta, m


@pytest.fixture(scope="module")
def aorta():
    w = load_waveform(default_waveform_path())
    return w, w.fourier(30)


def _pipe(alpha: float, period: float = 1.0, radius: float = R) -> float:
    """The viscosity that gives the first harmonic the Womersley number ``alpha``."""
    return radius**2 * (2 * math.pi / period) / alpha**2


def test_womersley_number():
    assert womersley_number(0.01, 2 * math.pi, 4e-6) == pytest.approx(0.01 * math.sqrt(2 * math.pi / 4e-6))
    assert isinstance(womersley_number(0.01, 1.0, 1e-6), float)  # JSON-ready
    assert womersley_number(np.array([1.0, 2.0]), 4.0, 1.0).tolist() == [2.0, 4.0]


def test_profile_carries_the_flow_rate(aorta):
    """int_0^R u 2 pi r dr = Q(t) to 1e-6 of the peak: the Bessel branch (a_1 = 18 .. a_30 = 100)."""
    w, c = aorta
    t = np.linspace(0, w.period_s, 17)
    flux, _ = quad_vec(lambda r: velocity(r, t, c, w.period_s, R, NU) * 2 * math.pi * r, 0, R, epsrel=1e-11, limit=500)
    np.testing.assert_allclose(flux, flow_rate(t, c, w.period_s), rtol=0, atol=1e-6 * w.peak_m3_s)
    # and the 30-harmonic series is the waveform within 0.5 % of its peak
    np.testing.assert_allclose(flux, w(t), rtol=0, atol=5e-3 * w.peak_m3_s)
    assert womersley_number(R, w.omega, NU) == pytest.approx(18.0, abs=0.1)


@pytest.mark.parametrize("alpha", [0.3, 1.0, 1.9, 2.1, 5.0])
def test_flux_of_each_branch(alpha):
    """Series (a < 2) and Bessel (a >= 2) branches each carry exactly their harmonic."""
    nu = _pipe(alpha)
    c = np.array([0.0, 2e-5 * np.exp(0.3j)])
    t = np.linspace(0, 1, 9)
    flux, _ = quad_vec(lambda r: velocity(r, t, c, 1.0, R, nu) * 2 * math.pi * r, 0, R, epsrel=1e-12)
    np.testing.assert_allclose(flux, flow_rate(t, c, 1.0), rtol=0, atol=1e-12 * 2e-5)


@pytest.mark.parametrize("alpha", [0.5, 1.5, 1.999, 2.001, 3.0])
def test_series_and_bessel_agree(monkeypatch, alpha):
    s = np.linspace(0, 1, 21)
    monkeypatch.setattr(W, "SERIES_ALPHA", 10.0)
    phi_s, g_s = W._profile(alpha, s)
    monkeypatch.setattr(W, "SERIES_ALPHA", 0.0)
    phi_b, g_b = W._profile(alpha, s)
    np.testing.assert_allclose(phi_s, phi_b, rtol=0, atol=1e-12)
    assert g_s == pytest.approx(g_b, rel=1e-12)


@pytest.mark.parametrize("alpha", [1e-4, 1e-2])
def test_small_alpha_is_quasi_steady_poiseuille(alpha):
    """u -> 2 Q(t) / (pi R^2) (1 - r^2/R^2) and tau -> 4 mu Q(t) / (pi R^3), errors O(alpha^2)."""
    nu = _pipe(alpha)
    c = np.array([1e-5, 3e-5 * np.exp(0.7j)])
    r = np.linspace(0, R, 13)[:, None]
    t = np.linspace(0, 1, 11)[None, :]
    q = flow_rate(t, c, 1.0)
    poiseuille = 2 * q / (math.pi * R**2) * (1 - (r / R) ** 2)
    u = velocity(r, t, c, 1.0, R, nu)
    assert u.shape == (13, 11)
    scale = np.abs(poiseuille).max()
    assert np.abs(u - poiseuille).max() < 0.1 * alpha**2 * scale
    tau = wall_shear_stress(t[0], c, 1.0, R, nu, rho=RHO)
    np.testing.assert_allclose(
        tau, 4 * RHO * nu * q[0] / (math.pi * R**3), rtol=0, atol=0.1 * alpha**2 * scale * RHO * nu / R
    )


def test_wall_shear_is_minus_mu_du_dr_at_the_wall(aorta):
    w, c = aorta
    t = np.linspace(0, w.period_s, 13)
    h = R * 2e-5
    u0, u1, u2 = (velocity(R - k * h, t, c, w.period_s, R, NU) for k in range(3))
    dudr = (3 * u0 - 4 * u1 + u2) / (2 * h)  # one-sided, second order
    tau = wall_shear_stress(t, c, w.period_s, R, NU, rho=RHO)
    np.testing.assert_allclose(tau, -RHO * NU * dudr, rtol=0, atol=1e-4 * np.abs(tau).max())
    assert np.abs(velocity(R, t, c, w.period_s, R, NU)).max() < 1e-12  # no slip


def _lead_deg(signal: np.ndarray, reference: np.ndarray) -> float:
    """Phase lead (degrees) of the first harmonic of ``signal`` over ``reference`` (one period sampled)."""
    a, b = np.fft.rfft(signal)[1], np.fft.rfft(reference)[1]
    return float(np.degrees(np.angle(a / b)))


def test_wall_shear_leads_an_oscillating_flow_by_0_to_45_degrees():
    """Pure oscillation Q = cos(omega t): quasi-steady (a -> 0) shear in phase with the flow; a
    Stokes layer (a -> infinity) leads it by 45 degrees with amplitude mu a |Q| / (pi R^3)."""
    t = np.arange(256) / 256
    c = np.array([0.0, 1e-5])
    leads = []
    for alpha in (0.1, 1.0, 3.0, 10.0, 30.0, 300.0):
        nu = _pipe(alpha)
        tau = wall_shear_stress(t, c, 1.0, R, nu)
        leads.append(_lead_deg(tau, flow_rate(t, c, 1.0)))
    assert leads[0] < 0.1 and all(np.diff(leads) > 0) and 44.0 < leads[-1] < 45.0, leads
    alpha = 1000.0
    nu = _pipe(alpha)
    amp = np.abs(wall_shear_stress(t, c, 1.0, R, nu)).max()
    assert amp == pytest.approx(nu * alpha * 1e-5 / (math.pi * R**3), rel=2e-3)


def test_large_alpha_gives_a_plug_core_in_phase_with_the_flow():
    """Centreline speed: twice the mean speed (Poiseuille) as a -> 0, the mean speed (plug core,
    in phase with Q) as a -> infinity."""
    t = np.arange(256) / 256
    c = np.array([0.0, 1e-5])
    mean_speed = 1e-5 / (math.pi * R**2)
    q = flow_rate(t, c, 1.0)
    slow = centreline_velocity(t, c, 1.0, R, _pipe(0.01))
    fast = centreline_velocity(t, c, 1.0, R, _pipe(200.0))
    assert np.abs(slow).max() == pytest.approx(2 * mean_speed, rel=1e-4)
    # the core's excess over the mean speed is the wall layer's deficit: ~ sqrt(2) / a
    assert 0 < np.abs(fast).max() / mean_speed - 1 < 1.5 / 200
    faster = centreline_velocity(t, c, 1.0, R, _pipe(2000.0))
    assert 0 < np.abs(faster).max() / mean_speed - 1 < 1.5 / 2000
    assert abs(_lead_deg(fast, q)) < 0.5


def test_tawss_of_steady_poiseuille_and_osi():
    q0 = 5.25 / 60000
    tawss, osi = tawss_osi(np.array([q0]), 0.8, R, NU, rho=RHO)
    assert tawss == pytest.approx(4 * RHO * NU * q0 / (math.pi * R**3), rel=1e-12)
    assert osi == 0.0


def test_osi_of_a_zero_mean_sinusoid_is_one_half():
    c = np.array([0.0, 4e-5 * np.exp(1.1j)])
    nu = _pipe(7.0)
    tawss, osi = tawss_osi(c, 1.0, R, nu)
    assert osi == pytest.approx(0.5, abs=1e-12)
    amp = np.abs(wall_shear_stress(np.arange(4096) / 4096, c, 1.0, R, nu)).max()
    assert tawss == pytest.approx(2 / math.pi * amp, rel=1e-6)  # mean |sin| = 2 / pi


def test_osi_of_the_aortic_waveform_in_a_pipe(aorta):
    """Positive mean flow, short reversal: 0 < OSI < 1/2; TAWSS above the steady value."""
    w, c = aorta
    tawss, osi = tawss_osi(c, w.period_s, R, NU, rho=RHO)
    assert 0.0 < osi < 0.5
    assert tawss > 4 * RHO * NU * w.mean_m3_s / (math.pi * R**3)


# --------------------------------------------------------------------------- inlet sections


def _section(a: float, b: float, n_rings: int = 24, n_theta: int = 96):
    """An elliptical section (semi-axes a, b) triangulated, in a tilted plane about a centre off the
    origin: (face centres, face areas, centre, unit normal, boundary loop)."""
    rho = np.linspace(0, 1, n_rings + 1)[1:]
    th = np.linspace(0, 2 * np.pi, n_theta, endpoint=False)
    pts2 = np.vstack(
        [[0.0, 0.0], np.stack([np.outer(rho, a * np.cos(th)).ravel(), np.outer(rho, b * np.sin(th)).ravel()], 1)]
    )
    tri = Delaunay(pts2).simplices
    p = pts2[tri]
    cen2 = p.mean(1)
    e, f = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0])
    normal = np.array([1.0, 2.0, 3.0]) / math.sqrt(14)
    e1 = np.cross(normal, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    centre = np.array([0.01, -0.02, 0.3])

    def lift(x2):
        return centre + x2[:, :1] * e1 + x2[:, 1:] * e2

    rim = lift(np.stack([a * np.cos(th), b * np.sin(th)], 1))
    return lift(cen2), area, centre, normal, rim


def test_section_radius_on_a_circle_is_r_over_r():
    centres, area, centre, normal, rim = _section(R, R, n_theta=360)
    s = section_radius(centres, centre, -2 * normal, rim)  # any length, either sense
    r = np.linalg.norm(centres - centre, axis=1)
    np.testing.assert_allclose(s, r / R, rtol=0, atol=1e-4)
    # edges given as (m, 2, 3) segments in any order: the same
    seg = np.stack([rim, np.roll(rim, -1, 0)], 1)[np.random.default_rng(0).permutation(len(rim))]
    np.testing.assert_allclose(section_radius(centres, centre, normal, seg), s, rtol=0, atol=1e-14)


def test_section_radius_of_an_ellipse():
    """On the minor axis the nearest edge point is the minor vertex (the edge's curvature radius
    there, a^2/b, exceeds b): s = r / b; on the major axis beyond the evolute's cusp (r > a - b^2/a)
    it is the major vertex: s = r / a."""
    a, b = 0.012, 0.007
    centres, area, centre, normal, rim = _section(a, b, n_theta=400)
    s = section_radius(centres, centre, normal, rim)
    assert s.min() >= 0 and s.max() <= 1
    assert s[np.argmin(np.linalg.norm(centres - centre, axis=1))] < 0.05
    major, minor = (rim[0] - centre) / a, (rim[100] - centre) / b
    f = np.linspace(0, 1, 11)
    np.testing.assert_allclose(section_radius(centre + np.outer(f * b, minor), centre, normal, rim), f, atol=1e-5)
    far = np.linspace(a - b**2 / a, a, 5) / a
    # (at the evolute's cusp the edge's osculating circle is centred on the point: the polygon's
    # chords beside the vertex are closer by their sagitta, ~4e-7 m here)
    np.testing.assert_allclose(section_radius(centre + np.outer(far * a, major), centre, normal, rim), far, atol=1e-4)


@pytest.mark.parametrize("kind", ["womersley", "parabolic", "plug"])
def test_inlet_flux_is_exact_on_an_elliptical_section(aorta, kind):
    w, _ = aorta
    centres, area, centre, normal, rim = _section(0.012, 0.007)
    t = np.linspace(-0.3, 2.0, 47)
    u = profile_on_section(centres, centre, normal, rim, area, t, w, kind=kind, nu=NU)
    assert u.shape == (len(t), len(area))
    np.testing.assert_allclose(u @ area, w(t), rtol=0, atol=1e-12 * w.peak_m3_s)
    if kind == "plug":
        np.testing.assert_allclose(u, np.outer(w(t), np.ones(len(area))) / area.sum(), rtol=1e-12)
    if kind == "parabolic":  # u_f proportional to 1 - s_f^2 at every instant
        s = section_radius(centres, centre, normal, rim)
        np.testing.assert_allclose(u, np.outer(u[:, 0] / (1 - s[0] ** 2), 1 - s**2), rtol=1e-10, atol=1e-14)


def test_each_harmonic_carries_its_own_flow_rate(aorta):
    """With the series exactly the waveform (a pure two-harmonic cycle), no remainder is added and
    the discrete flux of each harmonic is Q_n: the flux is exact with any radius given."""
    t = np.linspace(0, 1, 401)
    q = 5e-5 + 3e-5 * np.cos(2 * np.pi * t) + 1e-5 * np.sin(4 * np.pi * t)
    w = Waveform(t, q, 1.0, "two harmonics")
    centres, area, centre, normal, rim = _section(0.012, 0.007)
    s = section_radius(centres, centre, normal, rim)
    times = np.linspace(0, 1, 33)
    for radius in (0.005, 0.01, 0.05):
        u = inlet_velocities(s, area, times, w, "womersley", radius, NU, n_harmonics=2)
        np.testing.assert_allclose(u @ area, w(times), rtol=0, atol=1e-12 * q.max())


def test_mapped_profile_on_a_disc_is_womersleys(aorta):
    w, c = aorta
    centres, area, centre, normal, rim = _section(R, R, n_rings=40, n_theta=160)
    t = np.linspace(0, w.period_s, 6)
    u = profile_on_section(centres, centre, normal, rim, area, t, w, kind="womersley", nu=NU, radius=R)
    r = np.linalg.norm(centres - centre, axis=1)
    exact = velocity(np.minimum(r, R)[None, :], t[:, None], c, w.period_s, R, NU)
    assert np.abs(u - exact).max() < 0.02 * np.abs(exact).max()


def test_bad_inlet_arguments():
    t = np.linspace(0, 1, 30)
    w = Waveform(t, 1e-5 * (1 + np.sin(2 * np.pi * t) ** 2), 1.0, "w")
    s, a = np.array([0.0, 0.5, 1.0]), np.ones(3)
    with pytest.raises(VCSInputError, match="unknown"):
        inlet_velocities(s, a, t, w, "cone")
    with pytest.raises(VCSInputError, match="viscosity"):
        inlet_velocities(s, a, t, w, "womersley")
    with pytest.raises(VCSInputError, match=r"\[0, 1\]"):
        inlet_velocities(s + 0.5, a, t, w, "plug")
    with pytest.raises(VCSInputError, match="positive"):
        inlet_velocities(s, -a, t, w, "plug")
    with pytest.raises(VCSInputError, match="boundary"):
        section_radius(np.zeros((3, 3)), np.zeros(3), [0, 0, 1], np.zeros((2, 3)))
    with pytest.raises(VCSInputError, match=r"r must lie"):
        velocity(2 * R, 0.0, [1e-5], 1.0, R, NU)
