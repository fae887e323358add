"""Seeded synthetic thoracic aorta (lengths in mm).

Aortic root (three sinuses of Valsalva) -> ascending aorta (optional fusiform aneurysm) ->
non-planar arch -> tapering descending aorta. ``_aorta_sample`` draws the free parameters from a
seeded random stream, ``_AortaGeometry`` turns them into an exact unit-speed centreline, its
rotation-minimising frame and the wall radius, and ``_aorta`` redraws until the geometry passes
the anatomical and self-intersection checks, then meshes it with the shared sweep
(:mod:`vcs.phantoms.sweep`). Build one with ``vcs.phantoms.make_phantom("aorta", seed=...)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError
from vcs.phantoms.sweep import SweptSurface, _grid_mesh, _n_around, _reach_ok, _ring_s

_Arr = NDArray[np.floating]

__all__ = ["AORTA_EDGE_SCALE"]

#: The aorta's target edge is ``AORTA_EDGE_SCALE * resolution`` mm: at resolution = 1 its quad
#: sides are ~1.3 mm (diagonals ~1.8 mm), which keeps every aorta below 60k triangles. The analytic
#: kinds use ``resolution`` mm directly.
AORTA_EDGE_SCALE = 1.3

# Gauss-Legendre nodes on [0, 1] for the quadratures that define the aorta's centreline.
_GL_X, _GL_W = np.polynomial.legendre.leggauss(8)
_GL_X = 0.5 * (_GL_X + 1.0)
_GL_W = 0.5 * _GL_W


# ----------------------------------------------------------------------------------------------
# smooth primitives


def _ss(x: ArrayLike) -> _Arr:
    """C2 smooth step (quintic 'smootherstep'): 0 for x <= 0, 1 for x >= 1."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6 * x - 15) + 10)


def _dss(x: ArrayLike) -> _Arr:
    """Derivative of :func:`_ss` (0 outside [0, 1])."""
    x = np.clip(x, 0.0, 1.0)
    return 30 * x * x * (1 - x) ** 2


def _bump(x: ArrayLike) -> _Arr:
    """C2 bump with support (-1, 1), 1 at 0."""
    return _ss(1.0 - np.abs(x))


def _ramp_integral(x: ArrayLike, e: float) -> _Arr:
    """int_0^x ss(v / e) dv."""
    x = np.asarray(x, float)
    u = np.clip(x / e, 0.0, 1.0)
    inside = e * u**4 * (u * (u - 3) + 2.5)
    return np.where(x >= e, 0.5 * e + (x - e), inside)


class _PlateauStep:
    """Monotone C2 step 0 -> 1 on [0, 1] whose slope is a plateau with smooth ramps e1, e2."""

    def __init__(self, e1: float, e2: float) -> None:
        self.e1, self.e2 = e1, e2
        self.area = 1.0 - 0.5 * (e1 + e2)

    def __call__(self, t: ArrayLike) -> _Arr:
        """Step value at ``t`` (clipped to [0, 1])."""
        t = np.clip(t, 0.0, 1.0)
        a = _ramp_integral(t, self.e1) + _ramp_integral(1.0, self.e2) - _ramp_integral(1.0 - t, self.e2) - t
        return a / self.area

    def deriv(self, t: _Arr) -> _Arr:
        """Slope d step / dt (0 outside (0, 1))."""
        inside = (t > 0) & (t < 1)
        w = _ss(t / self.e1) + _ss((1.0 - t) / self.e2) - 1.0
        return np.where(inside, w, 0.0) / self.area


def _b16(t: _Arr) -> tuple[_Arr, _Arr]:
    """C1 bump 16 t^2 (1 - t)^2 on [0, 1] (0 outside) and its derivative."""
    inside = (t > 0) & (t < 1)
    tt = np.clip(t, 0.0, 1.0)
    return np.where(inside, 16 * tt**2 * (1 - tt) ** 2, 0.0), np.where(inside, 32 * tt * (1 - tt) * (1 - 2 * tt), 0.0)


def _aorta_sample(rng: np.random.Generator) -> dict:
    """Draw the aorta's free parameters (fixed order: the stream never depends on overrides)."""
    u = rng.uniform
    q = {}
    q["ascending_diameter_mm"] = u(28.0, 48.0)
    q["annulus_diameter_ratio"] = u(0.82, 0.95)
    q["arch_end_diameter_ratio"] = u(0.75, 0.90)
    q["outlet_diameter_ratio"] = u(0.80, 0.95)
    q["root_tilt_deg"] = u(0.0, 15.0)
    q["ascending_bend_deg"] = u(-5.0, 15.0)
    q["ascending_length_mm"] = u(80.0, 105.0)
    q["arch_curvature_radius_mm"] = u(28.0, 45.0)
    q["arch_ramp_proximal"] = u(0.15, 0.30)
    q["arch_ramp_distal"] = u(0.15, 0.30)
    q["arch_out_of_plane_deg"] = (1.0 if rng.random() < 0.5 else -1.0) * u(5.0, 22.0)
    q["target_length_mm"] = u(280.0, 340.0)
    q["descending_wobble_deg"] = u(0.0, 8.0)
    q["descending_wobble_wavelength_mm"] = u(80.0, 160.0)
    q["descending_twist_deg"] = u(0.0, 8.0)
    q["descending_twist_wavelength_mm"] = u(80.0, 160.0)
    q["descending_twist_phase_deg"] = u(0.0, 360.0)
    q["sinus_tau_start"] = u(0.025, 0.035)
    q["sinus_tau_end"] = u(0.11, 0.13)
    q["sinus_bulge"] = u(0.18, 0.35)
    q["sinus_lobe_power"] = u(1.0, 2.0)
    q["sinus_orientation_deg"] = u(0.0, 120.0)
    q["aneurysm"] = bool(rng.random() < 0.5)
    q["aneurysm_diameter_ratio"] = u(1.2, 1.6)
    q["aneurysm_position"] = u(0.0, 1.0)
    q["aneurysm_length_fraction"] = u(0.6, 1.0)
    q["aneurysm_eccentricity"] = u(0.0, 0.1)
    q["aneurysm_direction_deg"] = 180.0 + u(-30.0, 30.0)
    # allometry: larger aortas are longer, with wider arches (body size, age-related dilation and
    # elongation); 75 % of each length's position in its range follows the diameter's, so the
    # diameter is the generator's dominant parameter (ranges and the random stream unchanged)
    z = (q["ascending_diameter_mm"] - 28.0) / 20.0
    for key, lo, hi in (
        ("ascending_length_mm", 80.0, 105.0),
        ("arch_curvature_radius_mm", 28.0, 45.0),
        ("target_length_mm", 280.0, 340.0),
    ):
        q[key] = lo + (hi - lo) * (0.75 * z + 0.25 * (q[key] - lo) / (hi - lo))
    return q


# ----------------------------------------------------------------------------------------------
# geometry


class _AortaGeometry:
    """Unit-speed centreline from a heading (theta in the arch plane, beta out of it) and the wall.

    c'(s) = (cos b sin th, sin b, cos b cos th), so s is arc length exactly; the root is at the
    origin, the ascending aorta rises along +z (tilted towards -x), the arch turns over towards
    +x and the descending aorta runs down (-z). The rotation-minimising frame is
    v1 = cos psi E_th + sin psi E_b with psi' = -th' sin b (E_th = d c'/d th / cos b,
    E_b = d c'/d b); v1(0) = (cos alpha, 0, sin alpha), v2(0) = +y. c and psi are integrated with
    8-point Gauss-Legendre from a 1 mm table, i.e. exact to round-off.
    """

    def __init__(self, q: dict, widen: float = 1.0) -> None:
        self.q = q
        d2r = np.deg2rad
        self.alpha = d2r(q["root_tilt_deg"])
        self.delta = d2r(q["ascending_bend_deg"])
        self.La = q["ascending_length_mm"]
        self.step = _PlateauStep(q["arch_ramp_proximal"], q["arch_ramp_distal"])
        self.turn = np.pi + self.alpha - self.delta
        self.beta_a = d2r(q["arch_out_of_plane_deg"])
        # diameters (mm)
        D = q["ascending_diameter_mm"]
        self.D_ann = max(28.0, q["annulus_diameter_ratio"] * D)
        self.D_d0 = max(26.0, q["arch_end_diameter_ratio"] * D)
        self.D_out = float(np.clip(q["outlet_diameter_ratio"] * self.D_d0, 25.0, self.D_ann - 2.0))
        self.R_asc, self.R_ann, self.R_d0, self.R_out = D / 2, self.D_ann / 2, self.D_d0 / 2, self.D_out / 2
        # arch: curvature radius floored so that r * kappa <= 0.7 in the arch
        self.Rc = widen * max(q["arch_curvature_radius_mm"], self.R_asc / (0.7 * self.step.area))
        self.ell = self.turn * self.Rc
        self.sd = self.La + self.ell
        self.Ld = max(50.0, q["target_length_mm"] - self.sd)
        self.L = self.sd + self.Ld
        self.wob = (d2r(q["descending_wobble_deg"]), q["descending_wobble_wavelength_mm"])
        self.twi = (
            d2r(q["descending_twist_deg"]),
            q["descending_twist_wavelength_mm"],
            d2r(q["descending_twist_phase_deg"]),
        )
        # root, sinuses, aneurysm
        L = self.L
        self.s1, self.s2 = q["sinus_tau_start"] * L, q["sinus_tau_end"] * L
        self.s_mid, self.s_half = 0.5 * (self.s1 + self.s2), 0.5 * (self.s2 - self.s1)
        base_mid = float(self._base(np.array([self.s_mid]))[0])
        self.sinus_bulge = min(q["sinus_bulge"], 29.5 / base_mid - 1.0)
        self.lobe_p = q["sinus_lobe_power"]
        self.phi_sin = d2r(q["sinus_orientation_deg"])
        # fusiform aneurysm between the sinus crest and the arch: the nearly straight ascending aorta
        lo, hi = self.s_mid, self.La
        self.an_half = 0.5 * q["aneurysm_length_fraction"] * (hi - lo)
        self.an_c = lo + self.an_half + q["aneurysm_position"] * (hi - lo - 2 * self.an_half)
        self.an_ecc = q["aneurysm_eccentricity"]
        self.an_phi = d2r(q["aneurysm_direction_deg"])
        D_an = min(58.0, q["aneurysm_diameter_ratio"] * D)
        amp = max(0.0, D_an / 2 - self.R_asc)
        self.an_amp = 0.0
        if q["aneurysm"]:  # cap so that the widest point (with the sinuses) stays <= 59 mm across
            sp = np.linspace(self.an_c - self.an_half, self.an_c + self.an_half, 201)[1:-1]
            ph = np.linspace(0, 2 * np.pi, 120, endpoint=False)
            room = 29.5 - self.radius_mm(sp[:, None], ph[None, :]).max(axis=1)
            cap = np.min(room / ((1 + self.an_ecc) * _bump((sp - self.an_c) / self.an_half)))
            self.an_amp = float(np.clip(amp, 0.0, cap))
        self._table()

    def angles(self, s: ArrayLike) -> tuple[_Arr, _Arr, _Arr, _Arr]:
        """Heading angles theta, beta (rad) at arc length ``s`` (mm) and their s-derivatives (rad/mm)."""
        s = np.asarray(s, float)
        t_arch = (s - self.La) / self.ell
        th = -self.alpha + self.delta * _ss(s / self.La) + self.turn * self.step(t_arch)
        dth = self.delta * _dss(s / self.La) / self.La + self.turn * self.step.deriv(t_arch) / self.ell
        bb, dbb = _b16(t_arch)
        be, dbe = self.beta_a * bb, self.beta_a * dbb / self.ell
        x = np.maximum(s - self.sd, 0.0)
        ramp, dramp = _ss(x / 30.0), _dss(x / 30.0) / 30.0
        for amp, lam, ph, which in ((*self.wob, 0.0, "th"), (*self.twi, "be")):
            k = 2 * np.pi / lam
            w = amp * np.sin(k * x + ph) * ramp
            dw = amp * (k * np.cos(k * x + ph) * ramp + np.sin(k * x + ph) * dramp) * (s > self.sd)
            if which == "th":
                th, dth = th + w, dth + dw
            else:
                be, dbe = be + w, dbe + dw
        return th, dth, be, dbe

    def _rates(self, s: ArrayLike) -> tuple[_Arr, _Arr]:
        """Integrands: c'(s) (n, 3) and psi'(s) (n,)."""
        th, dth, be, _ = self.angles(s)
        cb = np.cos(be)
        T = np.stack([cb * np.sin(th), np.sin(be), cb * np.cos(th)], -1)
        return T, -dth * np.sin(be)

    def _table(self) -> None:
        """c and psi at every 1 mm (``self.st``, ``self.ct``, ``self.pt``) by 8-point Gauss-Legendre."""
        n = int(np.ceil(self.L / 1.0))
        self.ht = self.L / n
        self.st = np.linspace(0.0, self.L, n + 1)
        x = self.st[:-1, None] + self.ht * _GL_X[None, :]
        T, dpsi = self._rates(x.ravel())
        dc = self.ht * np.einsum("k,nkd->nd", _GL_W, T.reshape(n, 8, 3))
        dp = self.ht * (dpsi.reshape(n, 8) @ _GL_W)
        self.ct = np.concatenate([np.zeros((1, 3)), np.cumsum(dc, axis=0)])
        self.pt = np.concatenate([[0.0], np.cumsum(dp)])

    def _integrate(self, s: ArrayLike) -> tuple[_Arr, _Arr]:
        """c(s) (..., 3) mm and psi(s) (...) rad at arc length ``s`` (mm, clipped to [0, L])."""
        s = np.clip(np.asarray(s, float), 0.0, self.L)
        j = np.minimum((s / self.ht).astype(int), len(self.st) - 2)
        d = s - self.st[j]
        x = self.st[j][..., None] + d[..., None] * _GL_X
        T, dpsi = self._rates(x.ravel())
        c = self.ct[j] + d[..., None] * np.einsum("k,...kd->...d", _GL_W, T.reshape(x.shape + (3,)))
        psi = self.pt[j] + d * (dpsi.reshape(x.shape) @ _GL_W)
        return c, psi

    def point(self, s: ArrayLike) -> _Arr:
        """Centreline point(s) (..., 3) mm at arc length ``s`` (mm)."""
        return self._integrate(s)[0]

    def frame_mm(self, s: ArrayLike) -> tuple[_Arr, _Arr, _Arr]:
        """Rotation-minimising frame (t, v1, v2), each (..., 3), at arc length ``s`` (mm)."""
        s = np.asarray(s, float)
        _, psi = self._integrate(s)
        th, _, be, _ = self.angles(s)
        cb, sb, ct, st = np.cos(be), np.sin(be), np.cos(th), np.sin(th)
        T = np.stack([cb * st, sb, cb * ct], -1)
        Eth = np.stack([ct, 0 * ct, -st], -1)
        Ebe = np.stack([-sb * st, cb, -sb * ct], -1)
        v1 = np.cos(psi)[..., None] * Eth + np.sin(psi)[..., None] * Ebe
        return T, v1, np.cross(T, v1)

    def curvature(self, s: ArrayLike) -> _Arr:
        """Centreline curvature (1/mm) at arc length ``s`` (mm)."""
        _, dth, be, dbe = self.angles(s)
        return np.hypot(dth * np.cos(be), dbe)

    def _base(self, s: ArrayLike) -> _Arr:
        """Axisymmetric radius (mm) at arc length ``s`` (mm): annulus -> ascending -> arch end -> outlet."""
        L = self.L
        return (
            self.R_ann
            + (self.R_asc - self.R_ann) * _ss((s - self.s1) / (self.s2 - self.s1))
            + (self.R_d0 - self.R_asc) * _ss((s - self.La) / self.ell)
            + (self.R_out - self.R_d0) * _ss((s - self.sd) / (L - self.sd))
        )

    def radius_mm(self, s: ArrayLike, phi: ArrayLike) -> _Arr:
        """Wall radius (mm) at arc length ``s`` (mm) and angle ``phi`` (rad from v1), broadcast."""
        s, phi = np.broadcast_arrays(np.asarray(s, float), np.asarray(phi, float))
        lobes = (0.5 * (1 + np.cos(3 * (phi - self.phi_sin)))) ** self.lobe_p
        r = self._base(s) * (1 + self.sinus_bulge * _bump((s - self.s_mid) / self.s_half) * lobes)
        if self.an_amp > 0:
            r = r + self.an_amp * _bump((s - self.an_c) / self.an_half) * (1 + self.an_ecc * np.cos(phi - self.an_phi))
        return r

    def clearance(self) -> float:
        """min |c_a - c_d| - 2 max(r_a, r_d) (mm) over ascending/descending pairs: positive when
        every wall point of either is nearer its own centreline than the other's."""
        s = np.arange(0.0, self.L, 2.0)
        ph = np.linspace(0, 2 * np.pi, 72, endpoint=False)
        rmax = self.radius_mm(s[:, None], ph[None, :]).max(axis=1)
        c = self.point(s)
        a, d = s < self.La, s > self.sd
        gap = np.linalg.norm(c[a][:, None] - c[d][None], axis=-1) - 2 * np.maximum(rmax[a][:, None], rmax[d][None])
        return float(gap.min()) if gap.size else np.inf

    def arch_measures(self) -> tuple[float, float]:
        """Arch width (mm, ascending end to where the descending aorta is back at its height) and
        height (mm, top of the arch above the end of the ascending aorta)."""
        s = np.linspace(0.0, self.L, int(self.L / 0.25) + 1)
        c = self.point(s)
        zA = float(c[np.searchsorted(s, self.La), 2])
        k_top = int(np.argmax(c[:, 2]))
        below = np.nonzero(c[k_top:, 2] <= zA)[0]
        B = c[k_top + below[0]] if len(below) else c[-1]
        A = c[np.searchsorted(s, self.La)]
        return float(np.linalg.norm(B - A)), float(c[k_top, 2] - zA)


# ----------------------------------------------------------------------------------------------
# generator


def _aorta(h: float, seed: int, **overrides: float | bool) -> SweptSurface:
    """Seeded aorta meshed with edges of about ``h`` mm (up to 25 draws until every check passes).

    ``overrides`` fix drawn parameters by name (see :func:`_aorta_sample`); derived measures
    (diameters, arch size, clearance, ...) are added to the returned parameters.
    """
    rng = np.random.default_rng(seed)
    allowed = set(_aorta_sample(np.random.default_rng(0)))
    unknown = sorted(set(overrides) - allowed)
    if unknown:
        raise VCSInputError(
            f"unknown aorta phantom parameter(s) {', '.join(unknown)}; allowed: {', '.join(sorted(allowed))}"
        )
    for attempt in range(25):  # noqa: B007 (read after the loop: n_rejected)
        q = _aorta_sample(rng)
        for k, v in overrides.items():
            q[k] = bool(v) if isinstance(q[k], bool) else float(v)
        widen = 1.0
        g = _AortaGeometry(q)
        while g.clearance() < 5.0 and widen < 1.6:  # the descending aorta must clear the root
            widen *= 1.05
            g = _AortaGeometry(q, widen)
        L = g.L
        if g.clearance() < 5.0 or L > 350.0:
            continue
        # wall checks on a dense (s, phi) probe: diameters and r * kappa
        sp = np.linspace(0.0, L, int(L / 0.5) + 1)
        ph = np.linspace(0, 2 * np.pi, 180, endpoint=False)
        rr = g.radius_mm(sp[:, None], ph[None, :])
        rk = float(np.max(rr.max(axis=1) * g.curvature(sp)))
        if rk >= 0.75 or rr.max() > 30.0 or rr.min() < 12.5 - 1e-9:
            continue
        mean_r = rr.mean(axis=1)
        n_phi = _n_around(float(mean_r.mean()), h)
        ring = _ring_s(L, lambda u: np.interp(u * L, sp, mean_r), n_phi)  # noqa: B023 (called here)
        _, v1, v2 = g.frame_mm(ring * L)
        phi = 2 * np.pi * np.arange(n_phi) / n_phi
        V, F = _grid_mesh(g.point(ring * L), v1, v2, g.radius_mm(ring[:, None] * L, phi[None, :]), phi)

        def centerline(s: ArrayLike, g: _AortaGeometry = g) -> _Arr:
            return g.point(np.asarray(s, float) * g.L)

        if not _reach_ok(V, ring, n_phi, centerline, L):
            continue
        break
    else:
        raise VCSInputError(
            f"aorta phantom: no valid geometry in 25 draws with overrides {overrides}; relax the overrides"
        )

    def radius(s: ArrayLike, phi: ArrayLike, g: _AortaGeometry = g) -> _Arr:
        return g.radius_mm(np.asarray(s, float) * g.L, phi)

    def frame(s: ArrayLike, g: _AortaGeometry = g) -> tuple[_Arr, _Arr, _Arr]:
        return g.frame_mm(np.asarray(s, float) * g.L)

    width, height = g.arch_measures()
    asc_max = float(2 * rr.max(axis=1)[(sp > g.s2) & (sp < g.La)].max())
    in_an = np.abs(sp - g.an_c) < g.an_half
    an_max = float(2 * rr.mean(axis=1)[in_an].max()) if q["aneurysm"] and in_an.any() else 0.0
    p = dict(q)
    p.update(
        annulus_diameter_mm=g.D_ann,
        arch_end_diameter_mm=g.D_d0,
        outlet_diameter_mm=g.D_out,
        arch_curvature_radius_used_mm=g.Rc,
        arch_widening=widen,
        ascending_descending_clearance_mm=g.clearance(),
        arch_turn_deg=float(np.rad2deg(g.turn)),
        arch_length_mm=g.ell,
        descending_length_mm=g.Ld,
        length_mm=L,
        sinus_bulge_used=g.sinus_bulge,
        sinus_max_diameter_mm=2 * float(g.radius_mm(np.array([g.s_mid]), np.array([g.phi_sin]))[0]),
        ascending_max_diameter_mm=asc_max,
        aneurysm_max_diameter_mm=an_max,
        aneurysm_center_tau=g.an_c / L if q["aneurysm"] else 0.0,
        aneurysm_half_length_mm=g.an_half if q["aneurysm"] else 0.0,
        arch_width_mm=width,
        arch_height_mm=height,
        max_diameter_mm=2 * float(rr.max()),
        min_diameter_mm=2 * float(rr.min()),
        max_radius_times_curvature=rk,
        n_rejected=attempt,
        n_phi=n_phi,
        n_s=len(ring),
    )
    return SweptSurface(V, F, p, centerline, radius, frame, ring)
