"""Outlet conditions at finer sizes than the CI tests (tests/workflow/test_outlets_openfoam.py):
a straight tube (R 4 mm, L 24 mm) with (1) a resistance outlet in a steady run, p against R Q, and
(2) an RCR outlet (R_d C = 0.36 s, period 0.4 s) under a reversing pulsatile inflow, the simulated
outlet pressure against the Windkessel ODE integrated by scipy (LSODA) for the simulated outlet
flow, and against the backward-Euler recurrence the boundary condition computes, after the first
cycle, for several time steps (period / steps). Prints one line per run.

    python bench/outlets_rcr.py [--cell 5e-4] [--steps 100 200 400] [--cycles 3]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "workflow"))

from test_outlets_openfoam import LENGTH, PERIOD, Q0, RCR, RHO, R, tube_cfd, write_waveform  # noqa: E402

from vcs.cfd import render_case, run_case  # noqa: E402
from vcs.cfd.foamfiles import function_series  # noqa: E402
from vcs.cfd.outlets import rcr_pressure  # noqa: E402
from vcs.phantoms.analytic import write_closed_tube_stl  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=5e-4, help="lumen cell size [m]")
    ap.add_argument("--steps", type=int, nargs="+", default=[100, 200, 400], help="min time steps per cycle")
    ap.add_argument("--cycles", type=int, default=3)
    a = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="outlets_rcr_"))
    stl = write_closed_tube_stl(tmp / "tube.stl", radius=R, length=LENGTH, n_theta=96, n_z=32, axis=(0, 0, 1))
    cfd = tube_cfd({"type": "rcr", "rcr": RCR})
    cfd["mesh"] = {"cell_size": a.cell, "layers": 2}
    t0 = time.perf_counter()
    render_case(tmp / "steady", stl, cfd, flavour="esi")
    st = run_case(tmp / "steady", ranks=1)
    (o,) = st["outlets"]
    rel = o["mean_pressure_pa"] / (RCR["resistance"] * o["flow_rate_m3_s"]) - 1
    print(
        f"steady resistance: cells {st['cells']}, converged {st['converged']}, p {o['mean_pressure_pa']:.6g} Pa, "
        f"R Q {RCR['resistance'] * o['flow_rate_m3_s']:.6g} Pa, relative {rel:+.2e}, {time.perf_counter() - t0:.0f} s"
    )
    wf = write_waveform(tmp / "w.csv", Q0, 1.5 * Q0)
    for steps in a.steps:
        c = tube_cfd({"type": "rcr", "rcr": RCR})
        c["mesh"] = cfd["mesh"]
        c["inlet"] = {"type": "parabolic", "waveform": str(wf), "scaling": "fixed"}
        c["pulsatile"] = {
            "profile": "womersley",
            "cycles": a.cycles,
            "discard_cycles": 1,
            "max_cycles": a.cycles,
            "periodicity_tolerance": 1.0,
            "tawss_tolerance": 1.0,
            "min_steps_per_cycle": steps,
        }
        case = tmp / f"rcr{steps}"
        t0 = time.perf_counter()
        state = render_case(case, stl, c, flavour="esi")
        st = run_case(case, ranks=1)
        k = state["outlets"][0]
        q, p = function_series(case, "flowRate_outlet"), function_series(case, "pressure_outlet")
        t = q[:, 0]
        p_sim = np.interp(t, p[:, 0], p[:, 1]) * RHO
        tt, qq = np.concatenate([[0.0], t]), np.concatenate([[0.0], q[:, 1]])
        p0 = k["kinematic"]["p_c0"] * RHO
        after = t > PERIOD
        ref = rcr_pressure(tt, qq, k["r_p"], k["c"], k["r_d"], p0=p0, method="scipy")[1:]
        be = rcr_pressure(tt, qq, k["r_p"], k["c"], k["r_d"], p0=p0, method="backward_euler")[1:]
        err = np.abs(p_sim - ref)[after].max()
        swing = float(np.ptp(ref[after]))
        print(
            f"rcr, {steps} steps/cycle: cells {st['cells']}, {len(t)} steps, max |p - scipy| {err:.3g} Pa = "
            f"{100 * err / np.abs(ref[after]).max():.3f} % of max p, {100 * err / swing:.2f} % of the swing "
            f"{swing:.3g} Pa; vs backward Euler {np.abs(p_sim - be).max() / np.abs(be).max():.2e}; "
            f"{time.perf_counter() - t0:.0f} s"
        )


if __name__ == "__main__":
    main()
