"""Outlet conditions at finer sizes than the CI tests (tests/workflow/test_outlets_openfoam.py):
a straight tube (R 4 mm, L 24 mm) with (1) a resistance outlet in a steady run, p against R Q, and
(2) an RCR outlet (R_d C = 0.36 s, period 0.4 s) under a reversing pulsatile inflow, the simulated
outlet pressure against the Windkessel ODE integrated by scipy (LSODA) for the simulated outlet
flow, and against the backward-Euler recurrence the boundary condition computes, after the first
cycle, for several time steps (period / steps). Prints one line per run.

    python bench/outlets_rcr.py [--cell 5e-4] [--steps 100 200 400] [--cycles 3]
                                [--bifurcation [--workdir DIR]] [--json PATH]

``--json PATH`` also runs the CI tests' cases (the tube at their 0.8 mm cells without layers: (1)
and (2) at 100 steps per cycle; the split-end tube with ``murray`` outlets, steady and pulsatile)
and writes the verification table of the outlets in the docs' format
(docs/data/bench/outlets_verification.json). ``--bifurcation`` adds the shared vmtk aorta
bifurcation (``cfd_geometry: surface``, ``murray``; the sheet row of
tests/workflow/test_surface_geometry.py without its cell size and flow rate) through the workflow
in DIR (default: temporary), needing ../shared/data:

    .venv/bin/python bench/outlets_rcr.py --steps 100 200 --bifurcation \\
        --json docs/data/bench/outlets_verification.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _table import save, sig  # bench/ is on sys.path when this runs as a script

from vcs.cfd import render_case, run_case
from vcs.cfd.foamfiles import function_series
from vcs.cfd.outlets import rcr_pressure
from vcs.phantoms.analytic import write_closed_tube_stl

REPO = Path(__file__).resolve().parents[1]
BIFURCATION = REPO.parent / "shared" / "data" / "vessels" / "vmtk_aorta_bifurcation_open.stl"
#: the docs table's columns (docs/data/bench/outlets_verification.json)
JSON_COLUMNS = ["check", "result"]


def ci_cases():
    """tests/workflow/test_outlets_openfoam.py: the CI cases' tube (R, LENGTH), outlets (RCR),
    settings and helpers. Imported when the cases run, not with this module (importing it asks
    OpenFOAM for its version)."""
    sys.path.insert(0, str(REPO / "tests" / "workflow"))
    import test_outlets_openfoam

    return test_outlets_openfoam


def steady_resistance(case: Path, stl: Path, mesh: dict) -> dict:
    """(1): a steady run with an rcr outlet; p / (R Q) - 1 at the outlet."""
    T = ci_cases()
    cfd = T.tube_cfd({"type": "rcr", "rcr": T.RCR})
    cfd["mesh"] = mesh
    render_case(case, stl, cfd, flavour="esi")
    st = run_case(case, ranks=1)
    (o,) = st["outlets"]
    rq = T.RCR["resistance"] * o["flow_rate_m3_s"]
    return {
        "cells": st["cells"],
        "converged": st["converged"],
        "p": o["mean_pressure_pa"],
        "rq": rq,
        "rel": o["mean_pressure_pa"] / rq - 1,
    }


def rcr_pulsatile(case: Path, stl: Path, cfd: dict) -> dict:
    """(2): the simulated outlet pressure against scipy's ODE and the backward-Euler recurrence for
    the simulated outlet flow, after the first cycle."""
    T = ci_cases()
    state = render_case(case, stl, cfd, flavour="esi")
    st = run_case(case, ranks=1)
    k = state["outlets"][0]
    q, p = function_series(case, "flowRate_outlet"), function_series(case, "pressure_outlet")
    t = q[:, 0]
    p_sim = np.interp(t, p[:, 0], p[:, 1]) * T.RHO
    tt, qq = np.concatenate([[0.0], t]), np.concatenate([[0.0], q[:, 1]])  # from rest, P_c(0) = P_c0
    p0 = k["kinematic"]["p_c0"] * T.RHO
    after = t > T.PERIOD
    ref = rcr_pressure(tt, qq, k["r_p"], k["c"], k["r_d"], p0=p0, method="scipy")[1:]
    be = rcr_pressure(tt, qq, k["r_p"], k["c"], k["r_d"], p0=p0, method="backward_euler")[1:]
    err = float(np.abs(p_sim - ref)[after].max())
    return {
        "cells": st["cells"],
        "time_steps": len(t),
        "error_pa": err,
        "of_max": err / float(np.abs(ref[after]).max()),
        "of_swing": err / float(np.ptp(ref[after])),
        "swing_pa": float(np.ptp(ref[after])),
        "backward_euler": float(np.abs(p_sim - be).max() / np.abs(be).max()),
    }


def murray_split(work: Path) -> dict:
    """The split-end tube of the CI test with murray outlets, steady and pulsatile: the largest
    relative difference of the branch's share from its target (the pulsatile run: at every
    instant) and the largest outlet mass balance."""
    T = ci_cases()
    stl = T.write_split_end_tube_stl(work / "split.stl", r_inner=0.6 * T.R)
    render_case(work / "murray", stl, T.tube_cfd({"type": "murray"}), flavour="esi")
    st = run_case(work / "murray", ranks=1)
    out = {o["name"]: o for o in st["outlets"]}
    target = out["branch_1"]["target_fraction"]
    errs = [abs(o["fraction"] / o["target_fraction"] - 1) for o in out.values()]
    balance = [abs(st["outlet_mass_balance"]["relative"])]
    case = work / "murray_pulsatile"
    wf = T.write_waveform(work / "w_split.csv", T.Q0, 1.5 * T.Q0)
    render_case(case, stl, T.tube_cfd({"type": "murray"}, **T.pulsatile_extra(wf)), flavour="esi")
    st = run_case(case, ranks=1)
    qb, qi = function_series(case, "flowRate_branch_1"), function_series(case, "flowRate_inlet")
    q_in = -np.interp(qb[:, 0], qi[:, 0], qi[:, 1])
    errs.append(float(np.abs(qb[:, 1] - target * q_in).max() / np.abs(q_in).max()))
    balance.append(abs(st["outlet_mass_balance"]["relative"]))
    return {"target": target, "error": max(errs), "mass_balance": max(balance)}


def bifurcation(wd: Path, cores: int) -> dict:
    """The vmtk aorta bifurcation through the workflow (its status.json)."""
    from real_cohort import run_workflow, write_rows

    pid = "bif_murray"
    row = {"id": pid, "mesh": str(BIFURCATION), "units": "mm", "inlet": "end:0", "outlet": "end:1"}
    row |= {"cfd_geometry": "surface", "outlets": "murray"}
    wd.mkdir(parents=True, exist_ok=True)
    write_rows(wd / "patients.tsv", [row])
    target = f"results/patients/{pid}/status.json"
    run_workflow(wd, ["config.yaml"], "patients.tsv", cores, "vmtk bifurcation, murray", targets=[target])
    return json.loads((wd / target).read_text())


def table_rows(ci: dict, bench: dict, murray: dict, bif: dict | None = None) -> list[list[str]]:
    """The rows of :data:`JSON_COLUMNS`: ``ci`` and ``bench`` hold ``steady`` (of
    :func:`steady_resistance`) and ``rcr`` ({steps per cycle: :func:`rcr_pulsatile`}), ``murray``
    is :func:`murray_split`'s, ``bif`` the bifurcation's status.json (None: no such row)."""
    steps = sorted(bench["rcr"])
    errs = [bench["rcr"][n]["of_max"] for n in steps]
    order = ""
    if len(steps) >= 2 and errs[-1] > 0:
        order = f", observed order {math.log(errs[0] / errs[-1]) / math.log(steps[-1] / steps[0]):.1f}"
    (ci_rcr,) = ci["rcr"].values()
    rows = [
        [
            "resistance outlet, steady tube: p = R Q",
            f"{sig(abs(ci['steady']['rel']))} (CI), {sig(abs(bench['steady']['rel']))} "
            f"(bench, {bench['steady']['cells']:,} cells)",
        ],
        [
            "RCR outlet, pulsatile reversing inflow (R_d C = 0.36 s, T = 0.4 s), against scipy's ODE for the "
            "simulated flow, after cycle 1",
            f"{100 * ci_rcr['of_max']:.2f} % of the largest pressure (CI); "
            + " / ".join(f"{100 * e:.2f} %" for e in errs)
            + f" at {' / '.join(str(n) for n in steps)} steps per cycle (bench{order})",
        ],
        [
            "same, against the backward-Euler recurrence (once per step, across restarts)",
            f"{sig(ci_rcr['backward_euler'])} (CI), "
            f"{sig(max(r['backward_euler'] for r in bench['rcr'].values()))} (bench)",
        ],
        [
            f"murray, split-end tube (target {murray['target']:.3f}), steady and every instant of a pulsatile inflow",
            f"within {100 * murray['error']:.2g} %, mass balance {sig(murray['mass_balance'])}",
        ],
    ]
    if bif is not None:
        out = {o["name"]: o for o in bif.get("outlets") or []}
        b, m = out.get("branch_1", {}), out.get("outlet", {})
        inflow = (bif.get("inflow") or {}).get("flow_rate_l_min")
        verdict = "converged" if bif.get("converged") else f"NOT converged: {bif.get('reason')}"
        wall = (bif.get("timings_s") or {}).get("total")
        rows.append(
            [
                f"murray, vmtk aorta bifurcation (`cfd_geometry surface`, {bif.get('cells') or 0:,} cells at auto "
                f"size, {inflow:.3g} L/min; the workflow with the sheet of `tests/workflow/test_surface_geometry.py` "
                "without its cell size and flow rate; status.json `outlets`)",
                f"branch {b.get('fraction', float('nan')):.6f} vs {b.get('target_fraction', float('nan')):.6f} "
                f"target, main {m.get('fraction', float('nan')):.6f} vs {m.get('target_fraction', float('nan')):.6f}; "
                f"mass balance {sig(abs((bif.get('outlet_mass_balance') or {}).get('relative', float('nan'))))}; "
                f"{verdict} ({bif.get('criterion_used')}, {bif.get('iterations')} it., {wall or 0:.0f} s wall)",
            ]
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cell", type=float, default=5e-4, help="lumen cell size [m]")
    ap.add_argument("--steps", type=int, nargs="+", default=[100, 200, 400], help="min time steps per cycle")
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--bifurcation", action="store_true", help="with --json: also the vmtk bifurcation (workflow)")
    ap.add_argument("--workdir", type=Path, help="the bifurcation's Snakemake working directory (default: temporary)")
    ap.add_argument("--cores", type=int, default=2, help="cores for Snakemake (default 2)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also run the CI cases and write the table as docs JSON")
    a = ap.parse_args(argv)
    T = ci_cases()
    if a.bifurcation and not a.json:
        ap.error("--bifurcation adds a row to the --json table")
    if a.bifurcation and not BIFURCATION.is_file():
        ap.error(f"--bifurcation needs {BIFURCATION}")
    t_start = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix="outlets_rcr_"))
    stl = write_closed_tube_stl(tmp / "tube.stl", radius=T.R, length=T.LENGTH, n_theta=96, n_z=32, axis=(0, 0, 1))
    mesh = {"cell_size": a.cell, "layers": 2}
    t0 = time.perf_counter()
    steady = steady_resistance(tmp / "steady", stl, mesh)
    print(
        f"steady resistance: cells {steady['cells']}, converged {steady['converged']}, p {steady['p']:.6g} Pa, "
        f"R Q {steady['rq']:.6g} Pa, relative {steady['rel']:+.2e}, "
        f"{time.perf_counter() - t0:.0f} s"
    )
    wf = T.write_waveform(tmp / "w.csv", T.Q0, 1.5 * T.Q0)
    rcr = {}
    for steps in a.steps:
        c = T.tube_cfd({"type": "rcr", "rcr": T.RCR})
        c["mesh"] = mesh
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
        t0 = time.perf_counter()
        r = rcr[steps] = rcr_pulsatile(tmp / f"rcr{steps}", stl, c)
        print(
            f"rcr, {steps} steps/cycle: cells {r['cells']}, {r['time_steps']} steps, max |p - scipy| "
            f"{r['error_pa']:.3g} Pa = {100 * r['of_max']:.3f} % of max p, {100 * r['of_swing']:.2f} % of the swing "
            f"{r['swing_pa']:.3g} Pa; vs backward Euler {r['backward_euler']:.2e}; "
            f"{time.perf_counter() - t0:.0f} s"
        )
    if not a.json:
        return 0
    # the CI tests' cases: their tube, mesh and pulsatile settings
    ci_stl = write_closed_tube_stl(tmp / "ci_tube.stl", radius=T.R, length=T.LENGTH, n_theta=48, n_z=16, axis=(0, 0, 1))
    ci_steady = steady_resistance(tmp / "ci_steady", ci_stl, T.tube_cfd({})["mesh"])
    ci_wf = T.write_waveform(tmp / "ci_w.csv", T.Q0, 1.5 * T.Q0)
    ci_cfd = T.tube_cfd({"type": "rcr", "rcr": T.RCR}, **T.pulsatile_extra(ci_wf))
    ci_rcr = rcr_pulsatile(tmp / "ci_rcr", ci_stl, ci_cfd)
    murray = murray_split(tmp)
    print(
        f"CI cases: steady relative {ci_steady['rel']:+.2e}; rcr {100 * ci_rcr['of_max']:.3f} % of max p, vs backward "
        f"Euler {ci_rcr['backward_euler']:.2e}; murray split tube within {100 * murray['error']:.2g} % of "
        f"{murray['target']:.3f}, mass balance {murray['mass_balance']:.1e}"
    )
    bif = None
    if a.bifurcation:
        with tempfile.TemporaryDirectory() as wd:
            bif = bifurcation((a.workdir or Path(wd)).resolve(), a.cores)
    ci = {"steady": ci_steady, "rcr": {ci_cfd["pulsatile"]["min_steps_per_cycle"]: ci_rcr}}
    save(
        a.json,
        measured=f"one run, serial cases one after the other, {time.perf_counter() - t_start:.0f} s; bench tube "
        f"{a.cell * 1e3:g} mm cells with 2 layers, {a.cycles} cycles; CI cases as "
        "tests/workflow/test_outlets_openfoam.py",
        columns=JSON_COLUMNS,
        rows=table_rows(ci, {"steady": steady, "rcr": rcr}, murray, bif),
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
