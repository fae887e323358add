"""vcs.cfd.outlets against truths derived without it: Murray fractions of equal and hand-computed
areas, the parallel law of the split resistances and compliances, the RCR integration against the
periodic solution from the impedance and against the closed-form solution for a piecewise-linear
flow, the first-order convergence of the boundary condition's backward-Euler step, the pure
resistance limit C -> 0, and the mean pressure of a periodic state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vcs.cfd.outlets import (
    DEFAULT_PROXIMAL_FRACTION,
    murray_fractions,
    rcr_impedance,
    rcr_periodic_pressure,
    rcr_pressure,
    rcr_step,
    split_rcr,
)
from vcs.cfd.waveform import default_waveform_path, load_waveform
from vcs.errors import VCSInputError

# a systemic RCR: 100 mmHg / 5 L/min ~ 1.6e8 Pa s/m^3; C chosen so that R_d C ~ 0.29 s, about a
# third of the period: the compliance shifts and damps the pressure strongly, and the start-up
# transient dies within a few cycles
R_P, C, R_D = 1.44e7, 2e-9, 1.456e8  # Pa s/m^3, m^3/Pa, Pa s/m^3
P_D = 700.0  # Pa
T = 0.8  # s
OMEGA = 2.0 * math.pi / T
Q0, Q1 = 8e-5, 5e-5  # m^3/s


def exact_piecewise_linear(t: np.ndarray, q: np.ndarray, r_d: float, c: float, p_d: float, pc0: float) -> np.ndarray:
    """P_c of C dP_c/dt = Q - (P_c - P_d)/R_d for Q linear between samples, in closed form.

    On a segment Q = q_k + s u (u = t - t_k), y = P_c solves tau y' = a + b u - y with
    a = R_d q_k + P_d, b = R_d s, tau = R_d C: y = a + b (u - tau) + (y_k - a + b tau) exp(-u / tau).
    """
    tau = r_d * c
    pc = np.empty_like(q)
    pc[0] = pc0
    for k in range(t.size - 1):
        h = t[k + 1] - t[k]
        a = r_d * q[k] + p_d
        b = r_d * (q[k + 1] - q[k]) / h
        pc[k + 1] = a + b * (h - tau) + (pc[k] - a + b * tau) * math.exp(-h / tau)
    return pc


def sine_record(cycles: int, per_cycle: int) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, cycles * T, cycles * per_cycle + 1)
    return t, Q0 + Q1 * np.sin(OMEGA * t)


# --- Murray's law -------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 2, 3, 5])
def test_murray_equal_areas_share_equally(n):
    assert np.allclose(murray_fractions(np.full(n, 3.1e-5)), 1.0 / n, rtol=0, atol=1e-15)


def test_murray_hand_checked_three_outlets():
    # radii 1, 2, 3 mm: r^3 = 1, 8, 27 of 36
    areas = math.pi * (np.array([1.0, 2.0, 3.0]) * 1e-3) ** 2
    f = murray_fractions(areas)
    assert np.allclose(f, np.array([1.0, 8.0, 27.0]) / 36.0, rtol=1e-14, atol=0)
    assert math.isclose(f.sum(), 1.0, rel_tol=1e-15)
    assert np.allclose(murray_fractions(areas * 1e6), f, rtol=1e-14, atol=0)  # units cancel


@pytest.mark.parametrize("areas", [[1e-4, 0.0], [1e-4, -2e-5], [1e-4, float("nan")], [], [[1e-4, 2e-4]]])
def test_murray_bad_areas(areas):
    with pytest.raises(VCSInputError) as e:
        murray_fractions(areas)
    assert "\n" not in str(e.value)


# --- the split ----------------------------------------------------------------------------------


def test_split_rcr_is_the_total_in_parallel():
    r_total, c_total = 1.6e8, 1e-8
    areas = math.pi * np.array([12.0, 5.0, 4.0, 6.0]) ** 2 * 1e-6  # descending aorta + 3 arch branches
    outlets = split_rcr(r_total, c_total, areas)
    f = murray_fractions(areas)
    assert [o["fraction"] for o in outlets] == pytest.approx(f, rel=1e-15)
    r = np.array([o["r_p"] + o["r_d"] for o in outlets])
    assert math.isclose(1.0 / np.sum(1.0 / r), r_total, rel_tol=1e-13)  # resistances in parallel
    assert math.isclose(sum(o["c"] for o in outlets), c_total, rel_tol=1e-13)
    for o in outlets:
        assert math.isclose(o["r_p"] / (o["r_p"] + o["r_d"]), DEFAULT_PROXIMAL_FRACTION, rel_tol=1e-13)
        assert math.isclose(o["r_d"] * o["c"], (1 - DEFAULT_PROXIMAL_FRACTION) * r_total * c_total, rel_tol=1e-13)
        assert all(isinstance(v, float) for v in o.values())
    # at every frequency the outlets in parallel are the single total RCR
    omega = np.array([0.0, 1.0, OMEGA, 10 * OMEGA, 1e4])
    beta = DEFAULT_PROXIMAL_FRACTION
    z_total = rcr_impedance(omega, beta * r_total, c_total, (1 - beta) * r_total)
    z_parallel = 1.0 / sum(1.0 / rcr_impedance(omega, o["r_p"], o["c"], o["r_d"]) for o in outlets)
    assert np.allclose(z_parallel, z_total, rtol=1e-13, atol=0)


def test_split_rcr_proximal_fraction_zero_is_a_two_element_windkessel():
    (o,) = split_rcr(1.6e8, 1e-8, [3e-4], proximal_fraction=0.0)
    assert o == {"fraction": 1.0, "r_p": 0.0, "c": 1e-8, "r_d": 1.6e8}


@pytest.mark.parametrize(
    "args, kwargs",
    [
        ((0.0, 1e-8, [1e-4]), {}),
        ((-1.6e8, 1e-8, [1e-4]), {}),
        ((1.6e8, 0.0, [1e-4]), {}),
        ((1.6e8, float("inf"), [1e-4]), {}),
        ((1.6e8, 1e-8, [1e-4, 0.0]), {}),
        ((1.6e8, 1e-8, [1e-4]), {"proximal_fraction": 1.0}),
        ((1.6e8, 1e-8, [1e-4]), {"proximal_fraction": -0.1}),
        (("a lot", 1e-8, [1e-4]), {}),
    ],
)
def test_split_rcr_bad_input(args, kwargs):
    with pytest.raises(VCSInputError) as e:
        split_rcr(*args, **kwargs)
    assert "\n" not in str(e.value)


# --- the RCR in time ----------------------------------------------------------------------------


def test_impedance_limits():
    assert rcr_impedance(0.0, R_P, C, R_D) == pytest.approx(R_P + R_D, rel=1e-15)
    assert rcr_impedance(1e12, R_P, C, R_D) == pytest.approx(R_P, rel=1e-6)


def test_scipy_integration_matches_the_impedance_solution_after_the_transient():
    t, q = sine_record(cycles=6, per_cycle=1000)
    p = rcr_pressure(t, q, R_P, C, R_D, p_distal=P_D)
    exact = rcr_periodic_pressure(t, T, [Q0, -1j * Q1], R_P, C, R_D, p_distal=P_D)
    last = t >= 5 * T  # 5 cycles = 14 R_d C: the transient is down by exp(-14)
    assert np.max(np.abs(p[last] - exact[last]) / np.abs(exact[last])) < 1e-4
    # and the start is the mean flow's state, not the periodic one: there was a transient to lose
    assert math.isclose(p[0] - R_P * q[0], P_D + R_D * Q0, rel_tol=1e-6)
    assert abs(p[0] - exact[0]) > 1e-3 * exact[0]


def test_scipy_integration_matches_the_closed_form_for_a_piecewise_linear_flow():
    wf = load_waveform(default_waveform_path())  # corners, backflow: a realistic outlet record
    t = np.linspace(0.0, 3 * wf.period_s, 3 * 400 + 1)
    q = wf(t)
    pc0 = 9000.0
    p = rcr_pressure(t, q, R_P, C, R_D, p_distal=P_D, p0=pc0)
    exact = R_P * q + exact_piecewise_linear(t, q, R_D, C, P_D, pc0)
    assert np.max(np.abs(p - exact)) < 1e-7 * np.max(np.abs(exact))


def test_backward_euler_step_converges_at_first_order():
    # start on the periodic solution, so that the only error is the time step's
    p_c0 = float(rcr_periodic_pressure(0.0, T, [Q0, -1j * Q1], R_P, C, R_D, p_distal=P_D)) - R_P * Q0
    errors = []
    for n in (100, 200, 400, 800):
        t = np.linspace(0.0, T, n + 1)
        q = Q0 + Q1 * np.sin(OMEGA * t)
        exact = rcr_periodic_pressure(t, T, [Q0, -1j * Q1], R_P, C, R_D, p_distal=P_D)
        p, p_c = np.empty(n + 1), p_c0
        p[0] = R_P * q[0] + p_c0
        for k in range(n):
            p[k + 1], p_c = rcr_step(p_c, q[k + 1], T / n, R_P, C, R_D, P_D)
        errors.append(np.max(np.abs(p - exact)))
        # the record integrator is the same recurrence
        assert np.allclose(rcr_pressure(t, q, R_P, C, R_D, p_distal=P_D, p0=p_c0, method="backward_euler"), p)
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 1.8) & (ratios < 2.2)), ratios
    assert errors[-1] < 2e-3 * (R_P + R_D) * Q0


@pytest.mark.parametrize("method", ["scipy", "backward_euler"])
def test_vanishing_compliance_is_a_resistance(method):
    c = 1e-16  # R_d C ~ 1.5e-8 s, far below the record's 2e-3 s steps
    t, q = sine_record(cycles=1, per_cycle=400)
    p = rcr_pressure(t, q, R_P, c, R_D, p_distal=P_D, method=method)
    # from the first step on: the start-up state (mean flow) relaxes within R_d C
    assert np.allclose(p[1:], (R_P + R_D) * q[1:] + P_D, rtol=1e-6, atol=0)
    # one step keeps tau / (tau + dt) = 1.5e-5 of the old capacitor pressure
    p_step, _ = rcr_step(5000.0, Q0, 1e-3, R_P, c, R_D, P_D)
    assert math.isclose(float(p_step), (R_P + R_D) * Q0 + P_D, rel_tol=2e-5)


def test_mean_pressure_of_the_periodic_state():
    wf = load_waveform(default_waveform_path())
    period = wf.period_s
    mean = (R_P + R_D) * wf.mean_m3_s + P_D
    # the analytic periodic solution of the waveform's Fourier series (uniform samples: exact mean)
    tau = np.arange(2000) * period / 2000
    p = rcr_periodic_pressure(tau, period, wf.fourier(30), R_P, C, R_D, p_distal=P_D)
    assert math.isclose(p.mean(), mean, rel_tol=1e-12)
    # the ODE after 8 cycles (27 R_d C), over its last cycle
    t = np.linspace(0.0, 8 * period, 8 * 500 + 1)
    q = wf(t)
    p = rcr_pressure(t, q, R_P, C, R_D, p_distal=P_D)
    last = slice(7 * 500, None)
    mean_q = np.trapezoid(q[last], t[last]) / period  # the record's own mean (it cuts the CSV's corners)
    assert math.isclose(mean_q, wf.mean_m3_s, rel_tol=1e-4)
    assert math.isclose(np.trapezoid(p[last], t[last]) / period, (R_P + R_D) * mean_q + P_D, rel_tol=1e-7)


def test_rcr_step_several_outlets_at_once():
    outlets = split_rcr(1.6e8, 1e-8, [3e-4, 5e-5, 4e-5])
    r_p, c, r_d = (np.array([o[k] for o in outlets]) for k in ("r_p", "c", "r_d"))
    q = np.array([6e-5, 8e-6, 6e-6])
    p, p_c = rcr_step(np.full(3, 9000.0), q, 1e-3, r_p, c, r_d, 700.0)
    assert p.shape == p_c.shape == (3,)
    for k in range(3):
        pk, pck = rcr_step(9000.0, q[k], 1e-3, r_p[k], c[k], r_d[k], 700.0)
        assert math.isclose(float(pk), p[k], rel_tol=1e-15) and math.isclose(float(pck), p_c[k], rel_tol=1e-15)
    # the step as written in the OpenFOAM boundary condition
    dt = 1e-3
    pc_bc = (9000.0 + dt / c * (q + 700.0 / r_d)) / (1.0 + dt / (r_d * c))
    assert np.allclose(p_c, pc_bc, rtol=1e-13, atol=0)
    assert np.allclose(p, r_p * q + pc_bc, rtol=1e-13, atol=0)


@pytest.mark.parametrize(
    "call",
    [
        lambda: rcr_pressure([0.0, 1.0], [1e-5, 1e-5], R_P, 0.0, R_D),
        lambda: rcr_pressure([0.0, 1.0], [1e-5, 1e-5], R_P, C, -R_D),
        lambda: rcr_pressure([0.0, 1.0], [1e-5, 1e-5], -R_P, C, R_D),
        lambda: rcr_pressure([0.0, 0.0], [1e-5, 1e-5], R_P, C, R_D),
        lambda: rcr_pressure([0.0, 1.0, 2.0], [1e-5, 1e-5], R_P, C, R_D),
        lambda: rcr_pressure([0.0], [1e-5], R_P, C, R_D),
        lambda: rcr_pressure([0.0, 1.0], [1e-5, float("nan")], R_P, C, R_D),
        lambda: rcr_pressure([0.0, 1.0], [1e-5, 1e-5], R_P, C, R_D, method="rk4"),
        lambda: rcr_step(9000.0, 1e-5, 0.0, R_P, C, R_D),
        lambda: rcr_step(9000.0, 1e-5, 1e-3, R_P, 0.0, R_D),
        lambda: rcr_step(9000.0, 1e-5, 1e-3, R_P, C, [R_D, 0.0]),
        lambda: rcr_periodic_pressure(0.0, 0.0, [Q0], R_P, C, R_D),
        lambda: rcr_impedance(1.0, R_P, -C, R_D),
    ],
)
def test_rcr_bad_input(call):
    with pytest.raises(VCSInputError) as e:
        call()
    assert "\n" not in str(e.value)


def test_parallel_rcr_periodic_against_the_integrated_network():
    """The exact periodic solution of RCRs in parallel (one node pressure, fed by the inflow)
    against the network integrated in time by scipy (LSODA) over 40 periods: with R_p > 0 the node
    pressure is algebraic, P = (Q_in + sum P_c,k / R_p,k) / sum 1/R_p,k, each capacitor
    C_k dP_c,k/dt = (P - P_c,k) / R_p,k - (P_c,k - P_d) / R_d,k."""
    from scipy.integrate import solve_ivp

    from vcs.cfd.outlets import parallel_rcr_periodic

    T = 0.8
    rcrs = [
        {"r_p": 1.0e7, "c": 1.5e-9, "r_d": 9.0e7, "p_distal_pa": 700.0},
        {"r_p": 4.0e7, "c": 0.4e-9, "r_d": 3.6e8, "p_distal_pa": 700.0},
        {"r_p": 2.0e8, "c": 0.1e-9, "r_d": 1.8e9, "p_distal_pa": 700.0},
    ]
    coeffs = np.array([5e-5, -2j * 3e-5, 1.5e-5 + 1e-5j])  # mean, sin, a second harmonic

    def q_in(t):
        n = np.arange(coeffs.size)
        return float(np.real(np.exp(2j * np.pi * n * t / T) @ coeffs))

    rp = np.array([k["r_p"] for k in rcrs])
    rd = np.array([k["r_d"] for k in rcrs])
    c = np.array([k["c"] for k in rcrs])

    def node(t, pc):
        return (q_in(t) + (pc / rp).sum()) / (1.0 / rp).sum()

    def rhs(t, pc):
        p = node(t, pc)
        return ((p - pc) / rp - (pc - 700.0) / rd) / c

    sol = solve_ivp(rhs, (0.0, 40 * T), np.full(3, 700.0), method="LSODA", rtol=1e-10, atol=1e-6, dense_output=True)
    t = np.linspace(39 * T, 40 * T, 101)
    pc = sol.sol(t)
    p_num = np.array([node(ti, pc[:, i]) for i, ti in enumerate(t)])
    q_num = (p_num - pc) / rp[:, None]
    p_ref, q_ref = parallel_rcr_periodic(t, T, coeffs, rcrs)
    assert np.abs(p_num - p_ref).max() < 1e-6 * np.abs(p_ref).max()
    assert np.abs(q_num - q_ref).max() < 1e-6 * np.abs(q_ref).max()
    assert np.allclose(q_ref.sum(axis=0), [q_in(ti) for ti in t], rtol=0, atol=1e-12)
