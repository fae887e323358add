"""Outlet conditions of a vessel with several ends (pure numpy/scipy): Murray's law flow fractions
and the three-element Windkessel (RCR), its parameters per outlet, its integration in time and its
periodic solution.

Murray's law (Murray 1926) splits the flow among the outlets in proportion to the cube of their
radii, the radius of an end being that of the circle of the same area::

    fraction_k = r_k^3 / sum_j r_j^3,      r_k = sqrt(A_k / pi)

An RCR outlet (proximal resistance R_p, compliance C, distal resistance R_d, distal pressure P_d)
relates the outlet's pressure P to its flow rate Q (positive out of the domain) through the
capacitor's pressure P_c::

    P = R_p Q + P_c,      C dP_c/dt = Q - (P_c - P_d) / R_d

Its impedance at angular frequency omega is ``Z(omega) = R_p + R_d / (1 + i omega R_d C)``: a steady
flow sees ``R_p + R_d``, a fast one only ``R_p``; the capacitor relaxes with the time constant
``R_d C``.

Functions: :func:`murray_fractions` (the split), :func:`split_rcr` (an RCR per outlet from a total
resistance and compliance), :func:`rcr_pressure` (the pressure of a flow record, integrated by scipy
or by the boundary condition's own step), :func:`rcr_step` (the backward-Euler step the OpenFOAM
boundary condition takes at every time step), :func:`rcr_impedance` and
:func:`rcr_periodic_pressure` (the exact periodic solution of a Fourier series of the flow).

Units SI throughout: areas m^2, flow rates m^3/s, pressures Pa, resistances Pa s/m^3, compliances
m^3/Pa, times s. OpenFOAM's incompressible solvers carry the kinematic pressure p/rho (m^2/s^2): give
the resistances divided by rho (m^-1 s^-1) and the compliance times rho (m s^2), the formulas are
the same.

References: Murray CD (1926) The physiological principle of minimum work: I. The vascular system and
the cost of blood volume. PNAS 12:207-214. Westerhof N, Lankhaar JW, Westerhof BE (2009) The arterial
Windkessel. Med Biol Eng Comput 47:131-141. Vignon-Clementel IE, Figueroa CA, Jansen KE, Taylor CA
(2006) Outflow boundary conditions for three-dimensional finite element modeling of blood flow and
pressure in arteries. Comput Methods Appl Mech Eng 195:3776-3796; (2010) ... of non-periodic blood
flow and pressure fields in deformable arteries. Comput Methods Biomech Biomed Eng 13:625-640.
Xiao N, Alastruey J, Figueroa CA (2014) A systematic comparison between 1-D and 3-D hemodynamics in
compliant arterial models. Int J Numer Method Biomed Eng 30:204-231.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.integrate import solve_ivp

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

DEFAULT_PROXIMAL_FRACTION = 0.09
"""R_p / (R_p + R_d) of :func:`split_rcr`: see its docstring for where the value comes from."""

RCR_METHODS = ("scipy", "backward_euler")
"""Integrators of :func:`rcr_pressure`."""

ODE_RTOL = 1e-10
"""Relative tolerance of the scipy integration (absolute: this times the record's pressure scale)."""


def _positive(name: str, value: float, unit: str) -> float:
    """``value`` as a float, or a one-line error if it is not a finite positive number."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise VCSInputError(f"{name} must be a positive number ({unit}), not {value!r}") from None
    if not (math.isfinite(v) and v > 0.0):
        raise VCSInputError(f"{name} must be a positive number ({unit}), not {value!r}")
    return v


def _non_negative(name: str, value: float, unit: str) -> float:
    """``value`` as a float, or a one-line error if it is not a finite number >= 0."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise VCSInputError(f"{name} must be a number >= 0 ({unit}), not {value!r}") from None
    if not (math.isfinite(v) and v >= 0.0):
        raise VCSInputError(f"{name} must be a number >= 0 ({unit}), not {value!r}")
    return v


def _finite(name: str, value: float, unit: str) -> float:
    """``value`` as a float, or a one-line error if it is not finite."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise VCSInputError(f"{name} must be a number ({unit}), not {value!r}") from None
    if not math.isfinite(v):
        raise VCSInputError(f"{name} must be a finite number ({unit}), not {value!r}")
    return v


def _rcr(r_p: float, c: float, r_d: float) -> tuple[float, float, float]:
    """Checked RCR parameters: R_p >= 0 (0: a two-element Windkessel), C > 0, R_d > 0."""
    return (
        _non_negative("the proximal resistance r_p", r_p, "Pa s/m^3"),
        _positive("the compliance c", c, "m^3/Pa"),
        _positive("the distal resistance r_d", r_d, "Pa s/m^3"),
    )


def murray_fractions(areas: ArrayLike, exponent: float = 3.0) -> NDArray[np.floating]:
    """Flow fraction of each outlet by Murray's law (``exponent`` n: r^n instead of r^3).

    Murray (1926, PNAS 12:207-214) found that the flow a vessel carries at least cost (viscous
    dissipation plus the metabolic upkeep of its blood volume) grows as the cube of its radius, so
    that the outlets of a tree share the flow as::

        fraction_k = r_k^3 / sum_j r_j^3 = A_k^{3/2} / sum_j A_j^{3/2},      r_k = sqrt(A_k / pi)

    (r_k: the radius of the circle with the end's area A_k). Another exponent n splits as
    ``fraction_k = r_k^n / sum_j r_j^n`` (n = 2: in proportion to the area), for a cohort whose
    branches are known to take less than Murray's share.

    Parameters
    ----------
    areas : (n,) float
        Area of each outlet, m^2 (any consistent unit: only ratios matter); n >= 1, all positive.
    exponent : float
        n > 0 (default 3, Murray's law).

    Returns
    -------
    (n,) float
        Fractions in (0, 1], summing to 1.
    """
    a = np.asarray(areas, dtype=float)
    if a.ndim != 1 or a.size == 0:
        raise VCSInputError(f"outlet areas must be a non-empty 1-D list (m^2), got shape {a.shape}")
    bad = ~(np.isfinite(a) & (a > 0.0))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise VCSInputError(f"outlet area {k} is {a[k]!r}; every outlet area must be a positive number (m^2)")
    n = _positive("the Murray exponent", exponent, "r^n")
    rn = np.sqrt(a / math.pi) ** n
    return np.asarray(rn / rn.sum())


def split_rcr(
    total_resistance: float,
    total_compliance: float,
    areas: ArrayLike,
    *,
    proximal_fraction: float = DEFAULT_PROXIMAL_FRACTION,
    exponent: float = 3.0,
) -> list[dict[str, float]]:
    """An RCR Windkessel per outlet from the total resistance and compliance, split by Murray's law.

    With f_k = :func:`murray_fractions` (areas, exponent: r^n, n = 3 by default, 2 = by area), the
    outlets are resistances in parallel, each taking
    its Murray share of the flow at a common pressure, and the compliance is shared in proportion::

        R_k = R_total / f_k,      C_k = C_total f_k,
        R_p,k = beta R_k,         R_d,k = (1 - beta) R_k          (beta = proximal_fraction)

    so that sum_k 1/R_k = 1/R_total, sum_k C_k = C_total, every outlet has the same time constant
    R_d,k C_k = (1 - beta) R_total C_total, and the outlets in parallel have, at every frequency, the
    impedance of the single RCR (beta R_total, C_total, (1 - beta) R_total): Z_k = Z_total / f_k.

    The proximal resistance stands for the characteristic impedance of the arteries downstream of the
    outlet, a small part of the whole resistance (the three-element Windkessel: Westerhof et al. 2009,
    Med Biol Eng Comput 47:131-141); RCR outlets of a 3-D model as in Vignon-Clementel et al. 2006
    (Comput Methods Appl Mech Eng 195:3776-3796) and 2010 (Comput Methods Biomech Biomed Eng
    13:625-640) and Xiao et al. 2014 (Int J Numer Method Biomed Eng 30:204-231). The default
    beta = 0.09 is a modelling convention (R_p about a tenth of the outlet's resistance), not a value
    measured in or taken from a table of these papers: give the patient's own
    ``cfd.outlets.rcr.proximal_fraction`` when it is known, or the measured values of every outlet
    (the patients sheet's ``outlet_bc`` table, :mod:`vcs.cfd.bc_tables`) instead of this split.

    Parameters
    ----------
    total_resistance : float
        R_total > 0, Pa s/m^3 (e.g. mean arterial pressure / cardiac output ~ 1.6e8).
    total_compliance : float
        C_total > 0, m^3/Pa (total arterial compliance, ~1-2 mL/mmHg = 0.75-1.5e-8 m^3/Pa).
    areas : (n,) float
        Outlet areas, m^2.
    proximal_fraction : float, keyword-only
        beta = R_p / (R_p + R_d), in [0, 1) (0: a two-element Windkessel).
    exponent : float, keyword-only
        n of the split r^n / sum r^n (3: Murray's law; 2: by area).

    Returns
    -------
    list of dict
        One per outlet, in the order of ``areas``: ``fraction`` (f_k), ``r_p`` and ``r_d`` (Pa s/m^3),
        ``c`` (m^3/Pa); plain floats (JSON-ready).
    """
    r_total = _positive("the total resistance", total_resistance, "Pa s/m^3")
    c_total = _positive("the total compliance", total_compliance, "m^3/Pa")
    beta = _finite("the proximal fraction", proximal_fraction, "R_p / (R_p + R_d)")
    if not 0.0 <= beta < 1.0:
        raise VCSInputError(f"the proximal fraction {proximal_fraction!r} must be in [0, 1) (R_p / (R_p + R_d))")
    fractions = murray_fractions(areas, exponent)
    outlets = []
    for f in fractions:
        r_k = r_total / float(f)
        outlets.append({"fraction": float(f), "r_p": beta * r_k, "c": c_total * float(f), "r_d": (1.0 - beta) * r_k})
    return outlets


def rcr_step(
    p_c: ArrayLike,
    q_new: ArrayLike,
    dt: float,
    r_p: ArrayLike,
    c: ArrayLike,
    r_d: ArrayLike,
    p_distal: ArrayLike = 0.0,
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """One implicit (backward-Euler) step of the RCR: the update the OpenFOAM boundary condition makes
    at every time step from the outlet's new flow rate.

    Backward Euler on ``C dP_c/dt = Q - (P_c - P_d) / R_d`` with the flow at the end of the step::

        P_c^{n+1} = (P_c^n + dt/C (Q^{n+1} + P_d/R_d)) / (1 + dt/(R_d C))
                  = (R_d C P_c^n + dt (R_d Q^{n+1} + P_d)) / (R_d C + dt)      (the form computed)
        P^{n+1}   = R_p Q^{n+1} + P_c^{n+1}

    Unconditionally stable, first order in dt; as C -> 0 it gives the resistance
    ``P = (R_p + R_d) Q + P_d`` exactly (the second form has no dt/C to overflow).

    Parameters
    ----------
    p_c : float or array
        Capacitor pressure P_c^n at the start of the step, Pa.
    q_new : float or array
        Flow rate out of the domain at the end of the step, Q^{n+1}, m^3/s.
    dt : float
        Time step, s (> 0).
    r_p, c, r_d : float or array
        Proximal resistance (>= 0, Pa s/m^3), compliance (> 0, m^3/Pa), distal resistance
        (> 0, Pa s/m^3); arrays broadcast with ``p_c`` and ``q_new`` (several outlets at once).
    p_distal : float or array
        Distal (venous) pressure P_d, Pa.

    Returns
    -------
    p, p_c_new : float arrays
        Outlet pressure P^{n+1} and capacitor pressure P_c^{n+1}, Pa, broadcast shape of the inputs.
    """
    h = _positive("the time step dt", dt, "s")
    rp, cc, rd = (np.asarray(x, dtype=float) for x in (r_p, c, r_d))
    for name, x, ok, rule in (
        ("proximal resistance r_p", rp, rp >= 0.0, ">= 0 (Pa s/m^3)"),
        ("compliance c", cc, cc > 0.0, "positive (m^3/Pa)"),
        ("distal resistance r_d", rd, rd > 0.0, "positive (Pa s/m^3)"),
    ):
        bad = ~(np.isfinite(x) & ok)
        if bad.any():
            raise VCSInputError(f"the {name} must be {rule}, not {float(x[bad].flat[0])!r}")
    q = np.asarray(q_new, dtype=float)
    tau = rd * cc
    p_c_new = (tau * np.asarray(p_c, dtype=float) + h * (rd * q + np.asarray(p_distal, dtype=float))) / (tau + h)
    return np.asarray(rp * q + p_c_new), np.asarray(p_c_new)


def _record(t: ArrayLike, q: ArrayLike) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Checked flow record: 1-D, same length >= 2, finite, strictly increasing times."""
    tt = np.asarray(t, dtype=float)
    qq = np.asarray(q, dtype=float)
    if tt.ndim != 1 or tt.shape != qq.shape or tt.size < 2:
        raise VCSInputError(
            f"the flow record needs 1-D times and flow rates of the same length >= 2, got {tt.shape} and {qq.shape}"
        )
    if not (np.all(np.isfinite(tt)) and np.all(np.isfinite(qq))):
        raise VCSInputError("the flow record has a nan or inf time or flow rate; give finite numbers")
    if not np.all(np.diff(tt) > 0.0):
        raise VCSInputError("the flow record's times must increase strictly (s)")
    return tt, qq


def rcr_pressure(
    t: ArrayLike,
    q: ArrayLike,
    r_p: float,
    c: float,
    r_d: float,
    *,
    p_distal: float = 0.0,
    p0: float | None = None,
    method: str = "scipy",
) -> NDArray[np.floating]:
    """Outlet pressure of an RCR Windkessel driven by a flow record.

    Integrates::

        P = R_p Q + P_c,      C dP_c/dt = Q - (P_c - P_d) / R_d

    with Q(t) linear between the samples of the record, from P_c(t_0) = ``p0``, by default the state
    the mean flow would hold, ``P_d + R_d mean(Q)`` (mean: the record's time average); the start-up
    transient then decays as exp(-(t - t_0) / (R_d C)).

    * ``"scipy"``: :func:`scipy.integrate.solve_ivp` with LSODA (it switches to an implicit method
      where R_d C is much shorter than the record's steps: stiff), relative tolerance
      :data:`ODE_RTOL`, absolute tolerance ``ODE_RTOL`` times the record's pressure scale, evaluated
      at the samples; its steps are capped at the record's smallest spacing so that no sample's flow
      is stepped over (a stiff solver otherwise takes steps across a whole systole). About 1e-8 of
      the pressure scale from the exact solution; the reference a simulated outlet is checked against.
    * ``"backward_euler"``: the recurrence of :func:`rcr_step` from sample to sample, what the
      OpenFOAM boundary condition computes with the record's times as its time steps (first order
      in the step).

    Parameters
    ----------
    t : (n,) float
        Times, s, strictly increasing, n >= 2.
    q : (n,) float
        Flow rate out of the domain at those times, m^3/s (negative: backflow).
    r_p, c, r_d : float
        Proximal resistance (>= 0, Pa s/m^3), compliance (> 0, m^3/Pa), distal resistance
        (> 0, Pa s/m^3).
    p_distal : float, keyword-only
        Distal (venous) pressure P_d, Pa.
    p0 : float or None, keyword-only
        Capacitor pressure P_c at ``t[0]``, Pa; None: ``P_d + R_d mean(Q)``.
    method : {"scipy", "backward_euler"}, keyword-only
        Integrator.

    Returns
    -------
    (n,) float
        Outlet pressure P at the times ``t``, Pa.
    """
    tt, qq = _record(t, q)
    rp, cc, rd = _rcr(r_p, c, r_d)
    pd = _finite("the distal pressure p_distal", p_distal, "Pa")
    if method not in RCR_METHODS:
        raise VCSInputError(f"unknown RCR integration method {method!r}; known: {', '.join(RCR_METHODS)}")
    if p0 is None:
        mean_q = float(np.sum(0.5 * (qq[1:] + qq[:-1]) * np.diff(tt)) / (tt[-1] - tt[0]))
        pc0 = pd + rd * mean_q
    else:
        pc0 = _finite("the initial capacitor pressure p0", p0, "Pa")
    tau = rd * cc

    if method == "backward_euler":
        pc = np.empty_like(qq)
        pc[0] = pc0
        dts = np.diff(tt)
        for n in range(tt.size - 1):
            h = float(dts[n])
            pc[n + 1] = (tau * pc[n] + h * (rd * qq[n + 1] + pd)) / (tau + h)
        return np.asarray(rp * qq + pc)

    def rhs(time: float, y: NDArray[np.floating]) -> NDArray[np.floating]:
        return (rd * np.interp(time, tt, qq) + pd - y) / tau

    scale = max(abs(pd) + rd * float(np.max(np.abs(qq))), abs(pc0), 1e-300)
    sol = solve_ivp(
        rhs,
        (float(tt[0]), float(tt[-1])),
        [pc0],
        method="LSODA",
        t_eval=tt,
        rtol=ODE_RTOL,
        atol=ODE_RTOL * scale,
        max_step=float(np.min(np.diff(tt))),
    )
    if not sol.success:  # pragma: no cover - a linear scalar ODE; kept for an honest message
        raise RuntimeError(f"the RCR integration failed: {sol.message}")
    return np.asarray(rp * qq + sol.y[0])


def rcr_impedance(omega: ArrayLike, r_p: float, c: float, r_d: float) -> NDArray[np.complexfloating]:
    """Input impedance of the RCR Windkessel, Pa s/m^3.

    ::

        Z(omega) = R_p + R_d / (1 + i omega R_d C)

    (``Z(0) = R_p + R_d``; ``Z -> R_p`` as omega -> infinity), the ratio of the pressure harmonic to
    the flow harmonic ``exp(i omega t)``.

    Parameters
    ----------
    omega : float or array
        Angular frequency, rad/s.
    r_p, c, r_d : float
        Proximal resistance (>= 0, Pa s/m^3), compliance (> 0, m^3/Pa), distal resistance
        (> 0, Pa s/m^3).

    Returns
    -------
    complex array
        Shaped like ``omega``.
    """
    rp, cc, rd = _rcr(r_p, c, r_d)
    w = np.asarray(omega, dtype=float)
    return np.asarray(rp + rd / (1.0 + 1j * w * rd * cc))


def rcr_periodic_pressure(
    t: ArrayLike,
    period: float,
    coeffs: ArrayLike,
    r_p: float,
    c: float,
    r_d: float,
    *,
    p_distal: float = 0.0,
) -> NDArray[np.floating]:
    """The periodic (after-transient) pressure of an RCR outlet driven by a Fourier series of the flow.

    The ODE is linear, so each harmonic of the flow, ``Q(t) = Re sum_{n>=0} Q_n exp(i n omega t)``
    (omega = 2 pi / T; the coefficients of :meth:`vcs.cfd.waveform.Waveform.fourier`), gives its own
    pressure harmonic through the impedance (:func:`rcr_impedance`)::

        P(t) = P_d + Re sum_{n>=0} Z(n omega) Q_n exp(i n omega t)

    Its mean over a period is ``P_d + (R_p + R_d) Q_0``.

    Parameters
    ----------
    t : float or array
        Times, s.
    period : float
        T > 0, s.
    coeffs : (N + 1,) complex
        Flow harmonics Q_0 .. Q_N, m^3/s (e.g. ``Q_0 + Q_1 sin(omega t)``: ``[Q_0, -1j * Q_1]``).
    r_p, c, r_d : float
        Proximal resistance (>= 0, Pa s/m^3), compliance (> 0, m^3/Pa), distal resistance
        (> 0, Pa s/m^3).
    p_distal : float, keyword-only
        Distal (venous) pressure P_d, Pa.

    Returns
    -------
    float array
        P at the times ``t``, Pa, shaped like ``t``.
    """
    T = _positive("the period", period, "s")
    qn = np.atleast_1d(np.asarray(coeffs, dtype=complex))
    if qn.ndim != 1 or qn.size == 0 or not np.all(np.isfinite(qn)):
        raise VCSInputError(
            f"the flow harmonics must be a non-empty 1-D list of finite numbers (m^3/s), got {coeffs!r}"
        )
    pd = _finite("the distal pressure p_distal", p_distal, "Pa")
    omega = 2.0 * math.pi / T
    n = np.arange(qn.size)
    zq = rcr_impedance(n * omega, r_p, c, r_d) * qn  # pressure harmonics, Pa
    tt = np.asarray(t, dtype=float)
    phase = np.exp(1j * omega * np.multiply.outer(tt, n))  # (..., N + 1)
    return np.asarray(pd + np.real(phase @ zq))


def parallel_rcr_periodic(
    t: ArrayLike,
    period: float,
    coeffs: ArrayLike,
    rcrs: list[dict[str, float]],
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """The exact periodic state of RCR outlets in parallel fed by one flow (a lumen with no
    resistance of its own): the common pressure and every outlet's flow.

    Each harmonic n of the inflow, ``Q_in(t) = Re sum_n Q_n exp(i n omega t)`` (the coefficients of
    :meth:`vcs.cfd.waveform.Waveform.fourier`), divides among the outlets by their impedances
    ``Z_k(omega) = R_p,k + R_d,k / (1 + i omega R_d,k C_k)`` (:func:`rcr_impedance`), all at one
    pressure (the outlets' distal pressures P_d equal)::

        P_n = Q_n / sum_k 1/Z_k(n omega),      Q_k,n = P_n / Z_k(n omega)

        P(t) = P_d + Re sum_n P_n exp(i n omega t),   Q_k(t) = Re sum_n Q_k,n exp(i n omega t)

    Parameters
    ----------
    t : (m,) float
        Times, s.
    period : float
        T > 0, s.
    coeffs : (N + 1,) complex
        Inflow harmonics Q_0 .. Q_N, m^3/s.
    rcrs : list of dict
        Per outlet ``r_p``, ``c``, ``r_d`` (SI) and ``p_distal_pa`` (the same for every outlet).

    Returns
    -------
    pressure : (m,) float
        P(t), Pa.
    flows : (n_outlets, m) float
        Q_k(t), m^3/s (their sum is the inflow).
    """
    T = _positive("the period", period, "s")
    qn = np.atleast_1d(np.asarray(coeffs, dtype=complex))
    pds = {float(k.get("p_distal_pa", 0.0)) for k in rcrs}
    if len(pds) != 1:
        raise VCSInputError("the outlets in parallel must share one distal pressure P_d for this solution")
    omega = 2.0 * math.pi / T
    w = np.arange(qn.size) * omega
    z = np.array([rcr_impedance(w, k["r_p"], k["c"], k["r_d"]) for k in rcrs])  # (n_outlets, N + 1)
    pn = qn / (1.0 / z).sum(axis=0)
    phase = np.exp(1j * np.multiply.outer(np.asarray(t, dtype=float), w))  # (m, N + 1)
    return pds.pop() + np.real(phase @ pn), np.real((pn / z) @ phase.T)


# --------------------------------------------------------------------------- the outlet plan of a case

OUTLET_TYPES = ("free", "murray", "rcr", "rcr_fixed_share")
"""``cfd.outlets.type`` (also :data:`vcs.cfd.openfoam.OUTLET_TYPES`)."""

STEADY_RELAXATION = 0.3
"""Under-relaxation of an explicit resistance outlet (``rcr_fixed_share``'s main outlet) in a steady
(SIMPLE) run and its transient fallback: ``p <- p + a (R Q - p)`` at every evaluation. The explicit
coupling ``p = R Q`` (Q of the last iteration) amplifies a change of the flow split between outlets
by about R over the lumen's own resistance, which can exceed 1 for SIMPLE's pressure correction;
relaxed, a single outlet converges as (1 - a)^n to p = R Q."""

WINDKESSEL_BC = "vcsWindkesselPressure"
"""The OpenFOAM boundary condition of an ``rcr`` outlet (``templates/openfoam/lib/vcsWindkessel``,
compiled at install): the RCR coupled implicitly with the pressure equation."""


def outlet_role(name: str) -> str:
    """``"main"`` for an ``outlet*`` end (the section's tau = 1 end), ``"branch"`` for ``branch*``."""
    return "branch" if name.lower().startswith("branch") else "main"


def common_pressure_split(
    r_total: ArrayLike, p_distal: ArrayLike, flow_rate: float
) -> tuple[float, NDArray[np.floating]]:
    """The pressure and the flows of resistances in parallel fed by one flow (steady 0-D network).

    Outlets k of resistance R_k = R_p,k + R_d,k to their distal pressures P_d,k, joined at one node
    (a lumen whose own resistance is negligible) and fed by Q::

        sum_k (P - P_d,k) / R_k = Q   ->   P = (Q + sum_k P_d,k / R_k) / sum_k 1/R_k,
        Q_k = (P - P_d,k) / R_k

    Parameters
    ----------
    r_total : (n,) float
        R_p + R_d of each outlet, Pa s/m^3 (> 0).
    p_distal : (n,) float
        P_d of each outlet, Pa.
    flow_rate : float
        Q, m^3/s.

    Returns
    -------
    pressure : float
        P, Pa.
    flows : (n,) float
        Q_k, m^3/s (summing to Q).
    """
    r = np.asarray(r_total, dtype=float)
    pd = np.asarray(p_distal, dtype=float)
    g = 1.0 / r
    p = (float(flow_rate) + float((pd * g).sum())) / float(g.sum())
    return p, (p - pd) * g


def rcr_values(
    names: list[str],
    areas: ArrayLike,
    outlets: dict[str, Any],
    table: dict[str, dict[str, float]] | None = None,
) -> list[dict[str, Any]]:
    """Every outlet's RCR (SI): the user's per-outlet values when ``table`` is given, else the totals
    of ``cfd.outlets.rcr`` split by r^n (:func:`split_rcr`, n = ``split_exponent``, 3: Murray).

    Parameters
    ----------
    names : list of str
        The outlet patches.
    areas : (n,) float
        Their areas, m^2.
    outlets : dict
        ``cfd.outlets`` (``rcr``: ``resistance``, ``compliance``, ``proximal_fraction``,
        ``distal_pressure``, ``split_exponent``).
    table : dict, optional
        Patch name -> ``r_p``, ``c``, ``r_d``, ``p_d`` (SI), one entry for every name
        (:func:`vcs.cfd.bc_tables.outlet_rcrs`).

    Returns
    -------
    list of dict
        Per outlet: ``r_p``, ``c``, ``r_d`` (Pa s/m^3, m^3/Pa), ``p_distal_pa``, ``source``
        (``table`` or ``split r^n``).
    """
    r = outlets.get("rcr") or {}
    if table is not None:
        missing = [n for n in names if n not in table]
        if missing:
            raise VCSInputError(
                f"the outlet table has no row for {', '.join(missing)}: give every outlet its R_p, C, R_d"
            )
        out = []
        for n in names:
            r_p, c, r_d = _rcr(table[n]["r_p"], table[n]["c"], table[n]["r_d"])
            p_d = _finite("the distal pressure P_d", table[n].get("p_d", 0.0), "Pa")
            out.append({"r_p": r_p, "c": c, "r_d": r_d, "p_distal_pa": p_d, "source": "table"})
        return out
    n_exp = float(r.get("split_exponent", 3.0))
    split = split_rcr(
        r["resistance"],
        r["compliance"],
        areas,
        proximal_fraction=r.get("proximal_fraction", DEFAULT_PROXIMAL_FRACTION),
        exponent=n_exp,
    )
    p_d = _finite("the distal pressure", r.get("distal_pressure", 0.0), "Pa")
    return [
        {"r_p": k["r_p"], "c": k["c"], "r_d": k["r_d"], "p_distal_pa": p_d, "source": f"split r^{n_exp:g}"}
        for k in split
    ]


def outlet_plan(
    names: list[str],
    areas: ArrayLike,
    outlets: dict[str, Any],
    *,
    flow_rate: float,
    rho: float,
    table: dict[str, dict[str, float]] | None = None,
) -> list[dict[str, Any]]:
    """The boundary condition of every outlet of a case, from ``cfd.outlets`` (plain JSON dicts).

    * ``free``: every outlet at p = 0 (U ``inletOutlet``).
    * ``murray``: every branch prescribes its Murray share (Murray 1926) of the inflow,
      ``Q_k = f_k Q_in`` with ``f_k = r_k^n / sum_j r_j^n`` over **all** outlets (the main ones
      included; :func:`murray_fractions`, n = ``rcr.split_exponent``, 3 by default), through
      ``flowRateOutletVelocity`` (p zero gradient); the main outlet(s) at p = 0 take the rest.
    * ``rcr``: a three-element Windkessel (Westerhof et al. 2009) on **every** outlet, the user's
      per-outlet values (``table``) or the totals split by r^n (:func:`rcr_values`)::

          P = R_p Q + P_c,      C dP_c/dt = Q - (P_c - P_d)/R_d

      coupled implicitly with the 3-D flow (:data:`WINDKESSEL_BC`: a Robin condition built from the
      pressure equation's own coefficients, so the RCR holds within every pressure solve); the flow
      split between the outlets is part of the solution. A steady run sees ``R_p + R_d``. U is
      ``inletOutlet`` (backflow enters with no momentum: the stabilisation of the outlets).
      ``target_fraction`` is the split of resistances in parallel at one pressure
      (:func:`common_pressure_split`), what a lumen with no resistance of its own would give; the
      capacitors start at that state (``p_c0``), the mean-flow state of the cycle.
    * ``rcr_fixed_share``: the branches take a fixed share of the inflow (their Windkessel's share,
      ``Q_k = f_k Q_in(t)``, as murray) and only the main outlet(s) carry a Windkessel pressure,
      coupled explicitly (an OpenFOAM expression): the split cannot respond to the lumen (kept for
      comparison with earlier runs; with branches only, every outlet keeps that explicit pressure).

    Parameters
    ----------
    names : list of str
        The outlet patches (``outlet*`` main, ``branch*`` branches).
    areas : (n,) float
        Their areas, m^2.
    outlets : dict
        ``cfd.outlets`` (``type``, ``rcr``: ``resistance``, ``compliance``, ``proximal_fraction``,
        ``distal_pressure``, ``split_exponent``), checked.
    flow_rate : float
        The (mean) inflow, m^3/s.
    rho : float
        Density, kg/m^3: OpenFOAM's kinematic values are the SI ones over rho (pressures,
        resistances) or times rho (compliance).
    table : dict, optional
        ``rcr``: the patient's per-outlet values (patch name -> ``r_p``, ``c``, ``r_d``, ``p_d``, SI).

    Returns
    -------
    list of dict
        Per outlet, in the order of ``names``: ``name``, ``role`` (main | branch), ``type``,
        ``area_m2``, ``target_fraction`` (murray, rcr: the planned mean split; free: None), ``bc_u``
        (``inletOutlet`` | ``flowRateOutletVelocity``), ``bc_p`` (``fixedValue`` | ``zeroGradient``
        | ``windkessel`` | ``rcr``); murray branches ``flow_rate_m3_s`` (the mean target); rcr and
        rcr_fixed_share ``r_p``, ``c``, ``r_d`` (SI), ``p_distal_pa``, ``source``, ``kinematic``
        (``r_p``, ``r_d``, ``c`` (C rho), ``tau`` = R_d C (s), ``p_distal``, ``p_c0``: the capacitor's
        mean-flow state, its initial value).
    """
    a = np.asarray(areas, dtype=float)
    kind = str(outlets.get("type", "free"))
    if kind not in OUTLET_TYPES:
        raise VCSInputError(f"outlet type {kind!r} is not one of {', '.join(OUTLET_TYPES)}")
    if table is not None and kind != "rcr":
        raise VCSInputError(f"a per-outlet RCR table needs outlets type rcr, not {kind!r}")
    roles = [outlet_role(n) for n in names]
    if kind == "murray" and "main" not in roles:
        raise VCSInputError(
            "murray outlets need a main outlet (an 'outlet' solid at p = 0 taking the rest of the flow); "
            f"found only {', '.join(names)}"
        )
    n_exp = float((outlets.get("rcr") or {}).get("split_exponent", 3.0))
    fractions = murray_fractions(a, n_exp) if kind != "free" else np.full(len(names), np.nan)
    rcr = rcr_values(names, a, outlets, table) if kind in ("rcr", "rcr_fixed_share") else None
    q_k = None
    if rcr is not None:
        _, q_k = common_pressure_split([k["r_p"] + k["r_d"] for k in rcr], [k["p_distal_pa"] for k in rcr], flow_rate)
        if kind == "rcr":
            fractions = q_k / flow_rate
    plan: list[dict[str, Any]] = []
    for i, (name, role) in enumerate(zip(names, roles)):
        o: dict[str, Any] = {
            "name": name,
            "role": role,
            "type": kind,
            "area_m2": float(a[i]),
            "target_fraction": None if kind == "free" else float(fractions[i]),
            "bc_u": "inletOutlet",
            "bc_p": "fixedValue",
        }
        if kind == "murray" and role == "branch":
            o.update(bc_u="flowRateOutletVelocity", bc_p="zeroGradient", flow_rate_m3_s=float(fractions[i]) * flow_rate)
        elif rcr is not None and q_k is not None:
            o.update(_rcr_entry(rcr[i], float(q_k[i]), rho))
            if kind == "rcr":
                o["bc_p"] = "windkessel"
            elif role == "branch" and "main" in roles:  # rcr_fixed_share: its Windkessel's share of the flow
                o.update(
                    bc_u="flowRateOutletVelocity", bc_p="zeroGradient", flow_rate_m3_s=float(fractions[i]) * flow_rate
                )
        plan.append(o)
    return plan


def _rcr_entry(k: dict[str, Any], q_mean: float, rho: float) -> dict[str, object]:
    """The rcr fields of one outlet of :func:`outlet_plan` (SI and kinematic); the capacitor starts
    at P_d + R_d Q_k (``q_mean``: the outlet's planned mean flow)."""
    p_d = float(k["p_distal_pa"])
    p_c0 = p_d + k["r_d"] * q_mean
    return {
        "bc_p": "rcr",
        "r_p": k["r_p"],
        "c": k["c"],
        "r_d": k["r_d"],
        "p_distal_pa": p_d,
        "source": k["source"],
        "kinematic": {
            "r_p": k["r_p"] / rho,
            "r_d": k["r_d"] / rho,
            "c": k["c"] * rho,
            "tau": k["r_d"] * k["c"],
            "p_distal": p_d / rho,
            "p_c0": p_c0 / rho,
            "relaxation": STEADY_RELAXATION,
        },
    }


def flow_table(
    time_s: ArrayLike, flow_m3_s: ArrayLike, period: float, fraction: float, cycles: int
) -> list[list[float]]:
    """A branch's prescribed flow over ``cycles`` cycles as (t, Q) rows: ``fraction`` times the
    waveform at its own knots, repeated (linear interpolation between the rows is then the
    fraction of the periodic piecewise-linear waveform at every instant, as OpenFOAM's Function1
    ``table`` interpolates). An exact zero is nudged to 1e-12 of the largest |Q| (the sign kept):
    ``flowRateOutletVelocity`` divides by the target flow."""
    t = np.asarray(time_s, dtype=float)
    q = fraction * np.asarray(flow_m3_s, dtype=float)
    tiny = 1e-12 * max(float(np.abs(q).max()), 1e-300)
    q = np.where(np.abs(q) < tiny, np.where(q < 0, -tiny, tiny), q)
    one_t, one_q = t[:-1], q[:-1]  # the last knot is the next cycle's first
    times = np.concatenate([one_t + k * period for k in range(cycles)] + [[cycles * period]])
    flows = np.concatenate([one_q] * cycles + [[q[0]]])
    return [[float(a), float(b)] for a, b in zip(times, flows)]


def pressure_outlets(patches: list[dict[str, Any]]) -> list[str]:
    """The outlets whose pressure the inlet-outlet pressure difference takes: the main outlet(s)
    (``outlet*``) when there are any, else every outlet. With branches, dp is the inlet's
    area-mean pressure minus the main outlet's: a branch's pressure (prescribed flow, or its own
    Windkessel) is not the pressure at the end of the section the atlas measures."""
    outs = [str(p["name"]) for p in patches if p["role"] == "outlet"]
    main = [n for n in outs if outlet_role(n) == "main"]
    return main or outs


def outlet_summary(
    plan: list[dict[str, Any]],
    flows: dict[str, float | None],
    pressures: dict[str, float | None],
    inflow: float | None,
    rho: float,
) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """status.json ``outlets`` (one entry per outlet of ``plan``) and the outlet mass balance.

    Parameters
    ----------
    plan : list of dict
        :func:`outlet_plan` of the case.
    flows : dict
        Achieved flow rate per patch (m^3/s, out of the domain positive; mean over the window).
    pressures : dict
        Area-mean kinematic pressure per patch (m^2/s^2; mean over the window).
    inflow : float or None
        Flow rate into the domain through the inlet(s), m^3/s (> 0).
    rho : float
        Density, kg/m^3.

    Returns
    -------
    outlets : list of dict
        ``name``, ``role``, ``type``, ``area_m2``, ``flow_rate_m3_s``, ``fraction`` (of the inflow),
        ``target_fraction``, ``mean_pressure_pa``; rcr: ``r_p``, ``c``, ``r_d`` (SI).
    balance : dict
        ``inflow_m3_s``, ``outflow_m3_s`` (sum over the outlets), ``relative`` ((out - in) / in).
    """
    out = []
    for o in plan:
        q, p = flows.get(o["name"]), pressures.get(o["name"])
        entry = {k: o.get(k) for k in ("name", "role", "type", "area_m2", "target_fraction")}
        entry |= {
            "flow_rate_m3_s": q,
            "fraction": q / inflow if q is not None and inflow else None,
            "mean_pressure_pa": p * rho if p is not None else None,
        }
        if o.get("type") in ("rcr", "rcr_fixed_share"):
            entry |= {k: o[k] for k in ("r_p", "c", "r_d", "p_distal_pa")}
            entry["source"] = o.get("source")
            entry["condition"] = {
                "windkessel": "Windkessel pressure, implicit",
                "rcr": "Windkessel pressure, explicit",
            }.get(str(o.get("bc_p")), "flow share")
        out.append(entry)
    q_out = [e["flow_rate_m3_s"] for e in out]
    total = float(sum(float(q) for q in q_out if q is not None)) if q_out and None not in q_out else None
    balance = {
        "inflow_m3_s": inflow,
        "outflow_m3_s": total,
        "relative": (total - inflow) / inflow if total is not None and inflow else None,
    }
    return out, balance
