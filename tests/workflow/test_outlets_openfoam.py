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
        kind = {"type": "rcr_fixed_share", "rcr": RCR}
        st = render_case(tmp_path / f"r_{flavour}", split_tube, tube_cfd(kind), flavour=flavour)
        p = (tmp_path / f"r_{flavour}" / "0/p").read_text()
        want = "exprFixedValue" if flavour == "esi" else "codedFixedValue"
        assert want in _block(p, "outlet") and "zeroGradient" in _block(p, "branch_1")  # its Windkessel's share
        u = (tmp_path / f"r_{flavour}" / "0/U").read_text()
        assert "flowRateOutletVelocity" in _block(u, "branch_1") and "inletOutlet" in _block(u, "outlet")
        total = sum(1 / (o["r_p"] + o["r_d"]) for o in st["outlets"])
        assert 1 / total == pytest.approx(RCR["resistance"])
        # rcr: the implicit Windkessel on every outlet, the compiled library loaded by the solver
        st = render_case(tmp_path / f"w_{flavour}", split_tube, tube_cfd({"type": "rcr", "rcr": RCR}), flavour=flavour)
        p = (tmp_path / f"w_{flavour}" / "0/p").read_text()
        u = (tmp_path / f"w_{flavour}" / "0/U").read_text()
        ctl = (tmp_path / f"w_{flavour}" / "system/controlDict").read_text()
        for o in st["outlets"]:
            block = _block(p, o["name"])
            assert "type            vcsWindkesselPressure;" in block and "inletOutlet" in _block(u, o["name"])
            r_sum = float(re.search(r"Rp +(\S+);", block).group(1)) + float(re.search(r"Rd +(\S+);", block).group(1))
            assert r_sum * RHO == pytest.approx(o["r_p"] + o["r_d"], rel=1e-9)  # kinematic: SI / rho
            assert re.search(r"\bC +0;", block)  # steady inflow: the resistances only
        assert re.search(r'libs +\("/\S+/libvcsWindkessel\.so"\);', ctl)


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
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4 and state["outlets"][0]["bc_p"] == "windkessel"


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
def test_rcr_fixed_share_branch_takes_its_windkessel_share(split_tube, tmp_path):
    """rcr_fixed_share (the earlier rcr) with a branch next to the main outlet: the branch takes its
    Windkessel's share f_k Q_in, the main outlet's pressure is its own Windkessel's (explicit), and
    the branch's pressure is within 1 % of what its Windkessel would give."""
    case = tmp_path / "rcr_split"
    render_case(case, split_tube, tube_cfd({"type": "rcr_fixed_share", "rcr": RCR}), flavour="esi")
    st = run_case(case, ranks=1)
    assert st["converged"], st["reason"]
    out = {o["name"]: o for o in st["outlets"]}
    for o in out.values():
        assert o["fraction"] == pytest.approx(o["target_fraction"], rel=0.01)
    main, branch = out["outlet"], out["branch_1"]
    assert main["condition"] == "Windkessel pressure, explicit" and branch["condition"] == "flow share"
    assert main["mean_pressure_pa"] == pytest.approx((main["r_p"] + main["r_d"]) * main["flow_rate_m3_s"], rel=1e-3)
    own = (branch["r_p"] + branch["r_d"]) * branch["flow_rate_m3_s"]
    assert branch["mean_pressure_pa"] == pytest.approx(own, rel=0.01)  # measured -0.9 %
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4


# ------------------------------------------------------------------ a Windkessel on every outlet (issue 37)


def write_half_split_tube_stl(path: Path, n_theta: int = 48, n_z: int = 16) -> Path:
    """A straight tube along z whose end (z = LENGTH) is two half discs: ``outlet`` (x > 0) and
    ``branch_1`` (x < 0), fans from the end's centre sharing its diameter: two outlets of one lumen
    with almost no 3-D resistance between them, their centres 2 x 4R/(3 pi) apart."""
    tube = write_closed_tube_stl(path, radius=R, length=LENGTH, n_theta=n_theta, n_z=n_z, axis=(0.0, 0.0, 1.0))
    from vcs.mesh import read_stl_solids

    solids = read_stl_solids(tube)
    th = np.linspace(-np.pi / 2, 3 * np.pi / 2, n_theta, endpoint=False)  # ring[0] and ring[n/2] on the y axis
    ring = np.column_stack([R * np.cos(th), R * np.sin(th), np.full(n_theta, LENGTH)])
    centre = np.array([0.0, 0.0, LENGTH])
    fan = np.stack([np.broadcast_to(centre, ring.shape), ring, np.roll(ring, -1, axis=0)], 1)  # normal +z
    half = n_theta // 2
    write_stl_ascii(
        path, {"wall": solids["wall"], "inlet": solids["inlet"], "outlet": fan[:half], "branch_1": fan[half:]}
    )
    return path


# unequal RCRs (SI): the x > 0 half 1/3 of the resistance of the x < 0 half; tau 0.15 s and 0.10 s
RCR_A = {"R_p": 5.0e7, "C": 0.15 / 4.5e8, "R_d": 4.5e8}
RCR_B = {"R_p": 1.5e8, "C": 0.10 / 1.35e9, "R_d": 1.35e9}


def write_rcr_table(path: Path) -> Path:
    """The per-outlet table of the half-split tube, ends given as points (m) near each half's centre."""
    lines = ["end,R_p,C,R_d,P_d,units"]
    for x, r in ((0.4 * R, RCR_A), (-0.4 * R, RCR_B)):
        lines.append(f'"{x:.6g},0,{LENGTH:.6g}",{r["R_p"]:.6g},{r["C"]:.6g},{r["R_d"]:.6g},0,SI')
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def half_tube(tmp_path_factory) -> Path:
    return write_half_split_tube_stl(tmp_path_factory.mktemp("half") / "half.stl")


@pytest.mark.openfoam
@needs_foam
def test_rcr_every_outlet_split_emerges_steady(half_tube, tmp_path):
    """rcr on both halves of a split end (regression: two Windkessel pressures fed by their own
    flows, coupled explicitly, diverged in SIMPLE and circulated -128 % / +228 % of the inflow in
    pimpleFoam): with the implicit coupling the steady split is that of the resistances in parallel
    (3/4 : 1/4, a lumen of negligible resistance between them), each outlet's pressure its own
    (R_p + R_d) Q, from the patient's own per-outlet table."""
    table = write_rcr_table(tmp_path / "outlets.csv")
    case = tmp_path / "rcr_every"
    state = render_case(case, half_tube, tube_cfd({"type": "free"}), flavour="esi", patient={"outlet_bc": str(table)})
    assert {o["bc_p"] for o in state["outlets"]} == {"windkessel"} and state["cfd"]["outlets"]["type"] == "rcr"
    st = run_case(case, ranks=1)
    assert st["converged"], st["reason"]
    out = {o["name"]: o for o in st["outlets"]}
    assert out["outlet"]["r_d"] == pytest.approx(RCR_A["R_d"]) and out["branch_1"]["r_d"] == pytest.approx(RCR_B["R_d"])
    assert out["outlet"]["target_fraction"] == pytest.approx(0.75, rel=1e-12)
    for o in out.values():
        assert o["fraction"] == pytest.approx(o["target_fraction"], rel=0.005)
        assert o["mean_pressure_pa"] == pytest.approx((o["r_p"] + o["r_d"]) * o["flow_rate_m3_s"], rel=1e-3)
        assert o["condition"] == "Windkessel pressure, implicit" and o["source"] == "table"
    assert abs(st["outlet_mass_balance"]["relative"]) < 1e-4


@pytest.mark.openfoam
@needs_foam
def test_rcr_every_outlet_pulsatile_against_the_0d_network(half_tube, tmp_path):
    """Unequal RCRs on the two halves under a reversing pulsatile inflow: each outlet's pressure and
    flow over the last cycle within 2 % (of its cycle's largest magnitude) of the exact periodic
    solution of the 0-D network, the RCRs in parallel fed by the waveform, harmonic by harmonic
    (:func:`vcs.cfd.outlets.parallel_rcr_periodic`)."""
    from vcs.cfd.outlets import parallel_rcr_periodic
    from vcs.cfd.waveform import load_waveform

    wf_path = write_waveform(tmp_path / "w.csv", Q0, 1.5 * Q0)  # reverses: Q from -1e-6 to 5e-6 m3/s
    table = write_rcr_table(tmp_path / "outlets.csv")
    extra = pulsatile_extra(wf_path)
    # 3 cycles from the mean-flow state (the transients decay as exp(-t / 0.15 s)); the RCR's
    # backward-Euler step at T/400 = 1 ms errs by ~dt / (2 tau) = 0.3-0.5 % of the swing
    extra["pulsatile"] |= {"cycles": 3, "discard_cycles": 2, "max_cycles": 3, "min_steps_per_cycle": 400}
    case = tmp_path / "rcr_pulsatile"
    render_case(case, half_tube, tube_cfd({"type": "free"}, **extra), flavour="esi", patient={"outlet_bc": str(table)})
    st = run_case(case, ranks=1)
    assert st["pulsatile"]["evaluated"], st["reason"]
    wf = load_waveform(wf_path)
    rcrs = [{"r_p": r["R_p"], "c": r["C"], "r_d": r["R_d"], "p_distal_pa": 0.0} for r in (RCR_A, RCR_B)]
    t0 = 2 * PERIOD
    for k, name in enumerate(("outlet", "branch_1")):
        q, p = function_series(case, f"flowRate_{name}"), function_series(case, f"pressure_{name}")
        last = q[:, 0] > t0 + 1e-9
        t = q[last, 0]
        p_sim = np.interp(t, p[:, 0], p[:, 1]) * RHO
        p_ref, q_ref = parallel_rcr_periodic(t, PERIOD, wf.fourier(400), rcrs)
        err_p = np.abs(p_sim - p_ref).max() / np.abs(p_ref).max()
        err_q = np.abs(q[last, 1] - q_ref[k]).max() / np.abs(q_ref[k]).max()
        assert err_p < 0.02 and err_q < 0.02, (name, err_p, err_q)  # measured 0.2-1.1 %
    # what each outlet did, as status.json and the case's CSV report it: the last cycle's pressures
    # in mmHg against the 0-D network's, the realised mean split against the resistances'
    out = {o["name"]: o for o in st["outlets"]}
    phase = np.asarray(out["outlet"]["last_cycle"]["phase"])
    p_ref, _ = parallel_rcr_periodic(2 * PERIOD + phase * PERIOD, PERIOD, wf.fourier(400), rcrs)
    mmhg = 133.322387415
    for name in ("outlet", "branch_1"):
        pm = out[name]["pressure_mmhg"]
        assert pm["systolic"] == pytest.approx(p_ref.max() / mmhg, rel=0.02)
        assert pm["diastolic"] == pytest.approx(p_ref.min() / mmhg, rel=0.05)
        assert pm["mean"] == pytest.approx(p_ref.mean() / mmhg, rel=0.02)
    assert out["outlet"]["fraction"] == pytest.approx(0.75, rel=0.01)  # the mean split: resistances
    table = np.genfromtxt(case / "outlets_last_cycle.csv", delimiter=",", names=True)
    assert table.dtype.names == (
        "phase",
        "outlet_flow_ml_s",
        "outlet_pressure_mmhg",
        "branch_1_flow_ml_s",
        "branch_1_pressure_mmhg",
    )
    assert np.allclose(table["branch_1_pressure_mmhg"], np.asarray(out["branch_1"]["last_cycle"]["pressure_pa"]) / mmhg)
    assert (case / "outlets_last_cycle.png").stat().st_size > 10_000


@pytest.mark.openfoam
@needs_foam
def test_rcr_every_outlet_serial_against_two_ranks(half_tube, tmp_path):
    """The same Windkessel case serial and on 2 MPI ranks (the coupling's sums over a patch are
    global, gSum): each outlet's flow and pressure waveforms agree within 0.1 % of their largest
    magnitude (summation order differs between the two, nothing else)."""
    wf_path = write_waveform(tmp_path / "w.csv", Q0, 1.5 * Q0)
    table = write_rcr_table(tmp_path / "outlets.csv")
    series = {}
    for ranks in (1, 2):
        extra = pulsatile_extra(wf_path)
        case = tmp_path / f"ranks{ranks}"
        cfd = tube_cfd({"type": "free"}, **extra) | {"ranks": ranks, "decomposition": {"method": "simple"}}
        render_case(case, half_tube, cfd, flavour="esi", patient={"outlet_bc": str(table)})
        st = run_case(case, ranks=ranks)
        assert st["pulsatile"]["evaluated"], st["reason"]
        series[ranks] = {
            f"{kind}_{n}": function_series(case, f"{kind}_{n}")
            for kind in ("flowRate", "pressure")
            for n in ("outlet", "branch_1")
        }
    for key, a in series[1].items():
        b = series[2][key]
        assert a.shape == b.shape and np.array_equal(a[:, 0], b[:, 0]), key  # the same time steps
        assert np.abs(a[:, 1] - b[:, 1]).max() < 1e-3 * np.abs(a[:, 1]).max(), key
