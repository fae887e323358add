"""Outlet conditions with the real OpenFOAM (ESI), issue 25: a resistance outlet (p = R Q), an RCR
outlet under a pulsatile inflow against the Windkessel ODE integrated by scipy for the simulated
flow, and Murray splits on a tube whose end is split into a main outlet (a disc) and a branch (the
annulus around it). CI-sized (about 1,000-2,000 cells, a few seconds each); finer sizes are
bench/outlets_rcr.py's. The rendered dictionaries of both flavours are checked without OpenFOAM.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from vcs.cfd import detect_openfoam, render_case, run_case
from vcs.cfd.foamfiles import function_series
from vcs.cfd.outlets import murray_fractions, rcr_pressure
from vcs.errors import VCSInputError
from vcs.mesh import write_stl_ascii
from vcs.phantoms.analytic import write_closed_tube_stl

HAVE_FOAM = shutil.which("pimpleFoam") is not None and detect_openfoam()[0] == "esi"
needs_foam = pytest.mark.skipif(not HAVE_FOAM, reason="Debian's ESI OpenFOAM (pimpleFoam) not installed")

R = 0.004  # tube radius [m]
LENGTH = 0.024
PERIOD = 0.4  # [s]
Q0 = 2.0e-6  # mean flow [m3/s]
RHO = 1060.0
# total R and C of the RCR tube: R_d C = 0.91 x 1.33e8 x 3e-9 = 0.36 s, comparable to the period
RCR = {"resistance": 1.33e8, "compliance": 3.0e-9}


def write_waveform(path: Path, mean: float, amplitude: float, n: int = 200) -> Path:
    """One cycle of Q(t) = mean + amplitude sin(2 pi t / T) (closed: the last row repeats the first)."""
    t = np.linspace(0.0, PERIOD, n + 1)
    q = (mean + amplitude * np.sin(2 * np.pi * t / PERIOD)) * 6e4
    q[-1] = q[0]
    rows = "\n".join(f"{a:.8g},{b:.10g}" for a, b in zip(t, q))
    path.write_text(f"time_s,flow_rate_l_min\n{rows}\n")
    return path


def write_split_end_tube_stl(path: Path, r_inner: float, n_theta: int = 48, n_z: int = 16) -> Path:
    """A straight tube along z whose end (z = LENGTH) is two solids: ``outlet`` (the disc r < r_inner)
    and ``branch_1`` (the annulus r_inner < r < R): two outlets of a vessel in the cheapest form."""
    tube = write_closed_tube_stl(path, radius=R, length=LENGTH, n_theta=n_theta, n_z=n_z, axis=(0.0, 0.0, 1.0))
    from vcs.mesh import read_stl_solids

    solids = read_stl_solids(tube)
    th = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)

    def ring(r: float) -> np.ndarray:
        return np.column_stack([r * np.cos(th), r * np.sin(th), np.full(n_theta, LENGTH)])

    inner, outer = ring(r_inner), ring(R)
    nxt = np.roll(np.arange(n_theta), -1)
    centre = np.array([0.0, 0.0, LENGTH])
    disc = np.stack([np.broadcast_to(centre, inner.shape), inner, inner[nxt]], 1)  # normal +z: out of the lumen
    annulus = np.concatenate([np.stack([inner, outer, outer[nxt]], 1), np.stack([inner, outer[nxt], inner[nxt]], 1)])
    # the tube's own end ring is the same polygon as ``outer`` (same angles): the surface stays closed
    write_stl_ascii(path, {"wall": solids["wall"], "inlet": solids["inlet"], "outlet": disc, "branch_1": annulus})
    return path


def tube_cfd(outlets: dict, **extra) -> dict:
    cfd = {
        "mesh": {"cell_size": 8.0e-4, "layers": 0, "min_patch_faces": 10},
        "physics": {"nu": 3.37e-6, "rho": RHO},
        "inlet": {"type": "parabolic", "flow_rate": Q0},
        "outlets": outlets,
        "solver": {"max_iterations": 600, "startup_iterations": 10},
    }
    for k, v in extra.items():
        cfd[k] = v
    return cfd


def pulsatile_extra(wf: Path) -> dict:
    return {
        "inlet": {"type": "parabolic", "waveform": str(wf), "scaling": "fixed"},
        "pulsatile": {
            "profile": "parabolic",
            "cycles": 2,
            "discard_cycles": 1,
            "max_cycles": 2,
            "periodicity_tolerance": 1.0,
            "tawss_tolerance": 1.0,
            "samples_per_cycle": 40,
            "min_steps_per_cycle": 100,
        },
    }


@pytest.fixture(scope="module")
def tube(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("outlets")
    return write_closed_tube_stl(tmp / "tube.stl", radius=R, length=LENGTH, n_theta=48, n_z=16, axis=(0, 0, 1))


@pytest.fixture(scope="module")
def split_tube(tmp_path_factory) -> Path:
    return write_split_end_tube_stl(tmp_path_factory.mktemp("split") / "split.stl", r_inner=0.6 * R)


# ------------------------------------------------------------------ rendered dictionaries (no OpenFOAM)


def _block(text: str, name: str) -> str:
    m = re.search(rf"^    {name}\n    \{{\n(.*?)^    \}}", text, re.M | re.S)
    assert m, name
    return m.group(1)


def test_rendered_outlet_conditions_both_flavours(split_tube, tmp_path):
    for flavour in ("esi", "org10"):
        st = render_case(tmp_path / f"m_{flavour}", split_tube, tube_cfd({"type": "murray"}), flavour=flavour)
        plan = {o["name"]: o for o in st["outlets"]}
        f = murray_fractions([plan["outlet"]["area_m2"], plan["branch_1"]["area_m2"]])
        assert plan["branch_1"]["target_fraction"] == pytest.approx(f[1]) and plan["outlet"]["role"] == "main"
        u = (tmp_path / f"m_{flavour}" / "0/U").read_text()
        p = (tmp_path / f"m_{flavour}" / "0/p").read_text()
        assert "type            flowRateOutletVelocity;" in _block(u, "branch_1")
        q = float(re.search(r"volumetricFlowRate constant (\S+);", _block(u, "branch_1")).group(1))
        assert q == pytest.approx(f[1] * Q0, rel=1e-9)
        assert "zeroGradient" in _block(p, "branch_1") and "fixedValue" in _block(p, "outlet")
        assert "inletOutlet" in _block(u, "outlet")
        st = render_case(tmp_path / f"r_{flavour}", split_tube, tube_cfd({"type": "rcr", "rcr": RCR}), flavour=flavour)
        p = (tmp_path / f"r_{flavour}" / "0/p").read_text()
        want = "exprFixedValue" if flavour == "esi" else "codedFixedValue"
        assert want in _block(p, "outlet") and "zeroGradient" in _block(p, "branch_1")  # its Windkessel's share
        u = (tmp_path / f"r_{flavour}" / "0/U").read_text()
        assert "flowRateOutletVelocity" in _block(u, "branch_1") and "inletOutlet" in _block(u, "outlet")
        total = sum(1 / (o["r_p"] + o["r_d"]) for o in st["outlets"])
        assert 1 / total == pytest.approx(RCR["resistance"])


def test_patient_outlets_override_and_bad_values(tube, tmp_path):
    st = render_case(tmp_path / "a", tube, tube_cfd({"type": "free"}), patient={"outlets": {"type": "rcr"}})
    assert st["outlets"][0]["type"] == "rcr" and st["cfd"]["outlets"]["type"] == "rcr"
    st = render_case(tmp_path / "b", tube, tube_cfd({"type": "rcr"}), patient={"outlets": {"rcr": {"resistance": 2e8}}})
    assert st["outlets"][0]["r_p"] + st["outlets"][0]["r_d"] == pytest.approx(2e8)
    for bad in ({"type": "windkessel"}, {"rcr": {"resistance": -1.0}}, {"rcr": {"tau": 1.0}}, "rcr", {"foo": 1}):
        with pytest.raises(VCSInputError) as e:
            render_case(tmp_path / "c", tube, tube_cfd({"type": "free"}), patient={"outlets": bad})
        assert "\n" not in str(e.value) and "outlet" in str(e.value)


def test_murray_needs_a_main_outlet(tmp_path):
    from vcs.cfd.outlets import outlet_plan

    with pytest.raises(VCSInputError, match="main outlet"):
        outlet_plan(["branch_1", "branch_2"], [1e-4, 2e-4], {"type": "murray"}, flow_rate=1e-6, rho=RHO)


# ------------------------------------------------------------------ real runs


@pytest.mark.openfoam
@needs_foam
def test_resistance_outlet_steady(tube, tmp_path):
    """(a) A steady run with an rcr outlet sees its resistance: p_outlet = (R_p + R_d) Q."""
    case = tmp_path / "res"
    state = render_case(case, tube, tube_cfd({"type": "rcr", "rcr": RCR}), flavour="esi")
    st = run_case(case, ranks=1)
    assert st["converged"], st["reason"]
    (o,) = st["outlets"]
    q = o["flow_rate_m3_s"]
    assert q == pytest.approx(Q0, rel=1e-4)
    assert o["mean_pressure_pa"] == pytest.approx(RCR["resistance"] * q, rel=0.01)
    assert abs(o["mean_pressure_pa"] / (RCR["resistance"] * q) - 1) < 1e-3  # measured: < 1e-6
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4 and state["outlets"][0]["bc_p"] == "rcr"


@pytest.mark.openfoam
@needs_foam
def test_rcr_outlet_pulsatile_against_the_ode(tube, tmp_path):
    """(b) An RCR outlet under a pulsatile inflow: the simulated outlet pressure against the
    Windkessel ODE integrated by scipy (LSODA) for the simulated outlet flow, after the first
    cycle; and against the backward-Euler recurrence the boundary condition is meant to compute
    (once per time step, across the restarts at the phase cuts)."""
    wf = write_waveform(tmp_path / "w.csv", Q0, 1.5 * Q0)  # reverses: Q from -1e-6 to 5e-6 m3/s
    case = tmp_path / "rcr"
    state = render_case(case, tube, tube_cfd({"type": "rcr", "rcr": RCR}, **pulsatile_extra(wf)), flavour="esi")
    st = run_case(case, ranks=1)
    assert st["pulsatile"]["evaluated"], st["reason"]
    o = state["outlets"][0]
    q, p = function_series(case, "flowRate_outlet"), function_series(case, "pressure_outlet")
    t = q[:, 0]
    p_sim = np.interp(t, p[:, 0], p[:, 1]) * RHO
    tt, qq = np.concatenate([[0.0], t]), np.concatenate([[0.0], q[:, 1]])  # from rest, P_c(0) = P_c0
    p0 = o["kinematic"]["p_c0"] * RHO
    after = t > PERIOD
    ref = rcr_pressure(tt, qq, o["r_p"], o["c"], o["r_d"], p0=p0, method="scipy")[1:]
    err = np.abs(p_sim - ref)[after].max()
    assert err < 0.01 * np.abs(ref[after]).max()  # measured 0.32 % (1.0 Pa of 311)
    assert err < 0.03 * np.ptp(ref[after])  # measured 1.2 % of the cycle's pressure swing (80 Pa)
    be = rcr_pressure(tt, qq, o["r_p"], o["c"], o["r_d"], p0=p0, method="backward_euler")[1:]
    assert np.abs(p_sim - be).max() < 1e-4 * np.abs(be).max()  # measured 2.6e-7
    (so,) = st["outlets"]
    assert so["type"] == "rcr" and len(so["last_cycle"]["pressure_pa"]) == 200
    assert min(so["last_cycle"]["flow_rate_m3_s"]) < 0  # backflow through the RCR outlet, bounded run
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4


@pytest.mark.openfoam
@needs_foam
def test_murray_split_steady_and_pulsatile(split_tube, tmp_path):
    """(c) Murray outlets on the split-end tube: the branch (annulus) carries its Murray share of
    the inflow (70 %, where the free parabolic flow would put 41 % through it), the main outlet the
    rest; steady, and at every instant of a pulsatile inflow (the waveform's share as a table)."""
    case = tmp_path / "murray"
    state = render_case(case, split_tube, tube_cfd({"type": "murray"}), flavour="esi")
    st = run_case(case, ranks=1)
    assert st["converged"], st["reason"]
    out = {o["name"]: o for o in st["outlets"]}
    target = out["branch_1"]["target_fraction"]
    assert target == pytest.approx(0.703, abs=0.01)
    assert out["branch_1"]["fraction"] == pytest.approx(target, rel=0.01)
    assert out["outlet"]["fraction"] == pytest.approx(1 - target, rel=0.01)
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4
    assert "main outlets" in st["inlet_minus_outlet_pressure"]["definition"] and state["outlets"][1]["role"] == "branch"

    wf = write_waveform(tmp_path / "w.csv", Q0, 1.5 * Q0)
    case = tmp_path / "murray_pulsatile"
    render_case(case, split_tube, tube_cfd({"type": "murray"}, **pulsatile_extra(wf)), flavour="esi")
    st = run_case(case, ranks=1)
    assert st["pulsatile"]["evaluated"], st["reason"]
    qb = function_series(case, "flowRate_branch_1")
    qi = function_series(case, "flowRate_inlet")
    q_in = -np.interp(qb[:, 0], qi[:, 0], qi[:, 1])
    assert np.abs(qb[:, 1] - target * q_in).max() < 0.01 * np.abs(q_in).max()
    out = {o["name"]: o for o in st["outlets"]}
    assert out["branch_1"]["fraction"] == pytest.approx(target, rel=0.01)
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4


@pytest.mark.openfoam
@needs_foam
def test_rcr_branch_takes_its_windkessel_share(split_tube, tmp_path):
    """rcr with a branch next to the main outlet (regression: a pressure condition on both, fed by
    their own flows, diverged in SIMPLE and circulated -128 % / +228 % of the inflow in pimpleFoam):
    the branch takes its Windkessel's share f_k Q_in, the main outlet's pressure is its own
    Windkessel's, and the branch's pressure is within 1 % of what its Windkessel would give."""
    case = tmp_path / "rcr_split"
    render_case(case, split_tube, tube_cfd({"type": "rcr", "rcr": RCR}), flavour="esi")
    st = run_case(case, ranks=1)
    assert st["converged"], st["reason"]
    out = {o["name"]: o for o in st["outlets"]}
    for o in out.values():
        assert o["fraction"] == pytest.approx(o["target_fraction"], rel=0.01)
    main, branch = out["outlet"], out["branch_1"]
    assert main["condition"] == "pressure" and branch["condition"] == "flow share"
    assert main["mean_pressure_pa"] == pytest.approx((main["r_p"] + main["r_d"]) * main["flow_rate_m3_s"], rel=1e-3)
    own = (branch["r_p"] + branch["r_d"]) * branch["flow_rate_m3_s"]
    assert branch["mean_pressure_pa"] == pytest.approx(own, rel=0.01)  # measured -0.9 %
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4
