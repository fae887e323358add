"""Curved-pipe verification (marker ``openfoam``): developed laminar Dean flow in a torus arc
against the friction-factor correlation of White (1929), through the normal pipeline (phantom ->
fit -> Eq. 8 wall -> case -> simpleFoam on 2 ranks -> resampling on the VCS grid).

The finer meshes of the same case are bench/curved_pipe.py (README, "Curved pipe")."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from vcs.cfd import detect_openfoam, render_case, run_case, sample_case
from vcs.cfd.verification import (
    dean_number,
    developed_gradient,
    ito_friction_ratio,
    poiseuille_pressure_gradient,
    section_mean,
    white_friction_ratio,
)
from vcs.phantoms import make_phantom, write_stl
from vcs.surface import wall_mesh, write_multisolid_stl
from vcs.vessel import fit_vessel

HAVE_FOAM = shutil.which("simpleFoam") is not None and detect_openfoam()[0] == "esi"
needs_foam = pytest.mark.skipif(not HAVE_FOAM, reason="Debian's ESI OpenFOAM (simpleFoam) not installed")

A, R, ARC = 5.0, 33.3, 300.0  # tube radius, centreline radius (mm; a / R = 0.15), arc (deg)
RE, NU = 500.0, 3.37e-6  # Re on the diameter; blood's nu (m2/s)
Q = RE * NU / (2 * A * 1e-3) * np.pi * (A * 1e-3) ** 2  # 1.323e-5 m3/s, U_mean 0.1685 m/s
# developed part: after 90 deg of development from the straight-pipe (parabolic) inflow, and
# 30 deg before the outlet, whose uniform p = 0 distorts the last section
WINDOW = (90.0, 270.0)


@pytest.mark.openfoam
@needs_foam
def test_curved_pipe_dean_friction_factor(tmp_path):
    """f_c / f_s of the developed flow within 4 % of White's 1 / {1 - [1 - (11.6 / De)^0.45]^(1 / 0.45)}
    at De = 194 (measured -1.0 % on this mesh; -1.3 % to +2.7 % on the bench's finer meshes). Ito's
    1959 correlation is 3.9 % below White's here (+2.9 % on this mesh): the spread of the published
    correlations, which come from less curved pipes than a / R = 0.15. A case run with a 10 %
    higher viscosity than assumed gives +5.0 % and fails."""
    ph = make_phantom("torus", resolution=0.5, major_radius_mm=R, tube_radius_mm=A, arc_angle_deg=ARC)
    write_stl(ph, tmp_path / "torus.stl")
    model, _, _ = fit_vessel(tmp_path / "torus.stl", units="mm")
    assert model.vcs.length == pytest.approx(R * np.radians(ARC), rel=1e-4)
    write_multisolid_stl(wall_mesh(model, n_theta=64), tmp_path / "wall.stl", scale=1e-3)
    cfg = {
        "mesh": {"cell_size": 1.0e-3},  # 5 background cells per radius + 3 prism layers
        "physics": {"nu": NU},
        "inlet": {"type": "parabolic", "flow_rate": Q},
        "solver": {"max_iterations": 1000, "startup_iterations": 50, "fallback": "none"},
        "ranks": 2,
    }
    render_case(tmp_path / "case", tmp_path / "wall.stl", cfg, flavour="esi")
    st = run_case(tmp_path / "case", ranks=2)
    assert st["mesh_ok"] and st["ranks"] == 2, st["reason"]
    assert st["converged"], st["reason"]
    assert st["cells"] < 40000 and st["mesh"]["layers"]["coverage"] > 0.95
    assert st["mass_imbalance"] < 1e-5
    # Pappus: pi a^2 x R x arc; the snapped mesh of the 64-gon wall is 1.1 % smaller at this size
    assert st["lumen_volume_m3"] == pytest.approx(np.pi * A**2 * R * np.radians(ARC) * 1e-9, rel=0.02)

    # the area-mean pressure of each cross-section of the VCS grid against arc length
    f = sample_case(tmp_path / "case", model, n_tau=121, n_theta=32, n_rho=11)
    p_mean = section_mean(f["p_kinematic"], f["rho_n"], f["rho_w_mm"])  # m2/s2
    s = f["tau"] * model.vcs.length * 1e-3  # m along the centreline
    per_deg = model.vcs.length * 1e-3 / ARC
    g_hp = poiseuille_pressure_gradient(Q, A * 1e-3, NU)  # straight pipe, same Q: 64 / Re

    def ratio(lo: float, hi: float) -> float:
        return -developed_gradient(s, p_mean, (lo * per_deg, hi * per_deg)) / g_hp

    developed = ratio(*WINDOW)
    de = dean_number(RE, A, R)
    white = white_friction_ratio(de)
    print(
        f"De {de:.1f}: f_c/f_s {developed:.4f} over {WINDOW} deg; "
        f"White {white:.4f} ({100 * (developed / white - 1):+.2f} %), "
        f"Ito {ito_friction_ratio(de):.4f}; halves {ratio(90, 180):.4f} {ratio(180, 270):.4f}; "
        f"first 30 deg {ratio(0, 30):.4f}; cells {st['cells']}, {st['iterations']} iterations"
    )
    assert de == pytest.approx(193.7, abs=0.1)
    # developed: the two halves of the window agree (measured 1.902, 1.884)
    assert ratio(90, 180) == pytest.approx(ratio(180, 270), rel=0.03)
    # the developed gradient (straight-line fit) and the pressure drop between the window's end
    # sections (Pa) against White's correlation
    assert developed == pytest.approx(white, rel=0.04)
    s0, s1 = WINDOW[0] * per_deg, WINDOW[1] * per_deg
    dp = 1060.0 * (np.interp(s0, s, p_mean) - np.interp(s1, s, p_mean))
    assert dp == pytest.approx(1060.0 * white * g_hp * (s1 - s0), rel=0.04)
    # and the inflow is a straight pipe's developed flow: the first 30 degrees are far below
    # the curved pipe's friction (measured 1.22), the curvature is what raises it
    assert ratio(0, 30) < 0.75 * developed
