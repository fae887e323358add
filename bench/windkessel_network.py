"""A Windkessel on every outlet (``cfd.outlets.type: rcr``, the implicit vcsWindkesselPressure)
against the 0-D network it stands for, with the real OpenFOAM; prints the table.

The case is the CI tests' tube whose end is split into two half discs (two outlets of one lumen,
almost no 3-D resistance between them: tests/workflow/test_outlets_openfoam.py), with unequal RCRs
from a per-outlet table (the x > 0 half 1/3 of the other's resistance, R_d C = 0.15 s and 0.10 s):

1. steady: the split and each outlet's pressure against the resistances in parallel;
2. pulsatile (a reversing sine inflow, T = 0.4 s, 3 cycles): each outlet's pressure and flow over
   the last cycle against the exact periodic solution of the parallel RCRs fed by the waveform
   (:func:`vcs.cfd.outlets.parallel_rcr_periodic`), at ``--steps`` time steps per cycle (the RCR's
   backward-Euler step errs by ~dt / (2 R_d C));
3. the steady and the pulsatile case on 2 MPI ranks against serial (``--ranks``).

Usage::

    .venv/bin/python bench/windkessel_network.py [--steps 400 800] [--json PATH]

``--json PATH`` writes the table as docs data (docs/data/bench/windkessel_verification.json).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _table import save, sig  # bench/ is on sys.path when this runs as a script

from vcs.cfd import render_case, run_case
from vcs.cfd.foamfiles import function_series, read_internal_field
from vcs.cfd.outlets import parallel_rcr_periodic
from vcs.cfd.waveform import load_waveform

REPO = Path(__file__).resolve().parents[1]
JSON_COLUMNS = ["check", "result"]
OUTLETS = ("outlet", "branch_1")


def ci_cases():
    """tests/workflow/test_outlets_openfoam.py: the half-split tube, its RCR table, the waveform and
    the CI settings (imported when the cases run: importing it asks OpenFOAM for its version)."""
    sys.path.insert(0, str(REPO / "tests" / "workflow"))
    import test_outlets_openfoam

    return test_outlets_openfoam


def _rcrs(T) -> list[dict[str, float]]:
    return [{"r_p": r["R_p"], "c": r["C"], "r_d": r["R_d"], "p_distal_pa": 0.0} for r in (T.RCR_A, T.RCR_B)]


def _last_fields(case: Path) -> tuple[np.ndarray, np.ndarray]:
    """U and p of a case's latest time folder (reconstructed)."""
    times = sorted((d for d in case.iterdir() if d.name.replace(".", "").isdigit()), key=lambda d: float(d.name))
    return tuple(np.asarray(read_internal_field(times[-1] / f)) for f in ("U", "p"))  # type: ignore[return-value]


def steady(tmp: Path, stl: Path, table: Path, ranks: int = 1) -> dict:
    """(1): the realised split and each outlet's p / ((R_p + R_d) Q) - 1; the final U and p."""
    T = ci_cases()
    case = tmp / f"steady_{ranks}"
    cfd = T.tube_cfd({"type": "free"}) | {"ranks": ranks, "decomposition": {"method": "simple"}}
    render_case(case, stl, cfd, flavour="esi", patient={"outlet_bc": str(table)})
    st = run_case(case, ranks=ranks)
    out = {o["name"]: o for o in st["outlets"]}
    return {
        "converged": st["converged"],
        "fraction": out["outlet"]["fraction"],
        "target": out["outlet"]["target_fraction"],
        "p_rel": max(
            abs(o["mean_pressure_pa"] / ((o["r_p"] + o["r_d"]) * o["flow_rate_m3_s"]) - 1) for o in out.values()
        ),
        "balance": abs(st["outlet_mass_balance"]["relative"]),
        "iterations": st.get("iterations"),
        "fields": _last_fields(case),
    }


def pulsatile(tmp: Path, stl: Path, table: Path, wf: Path, steps: int, ranks: int = 1) -> dict:
    """(2)/(3): the last cycle's largest error of each outlet's p and Q against the 0-D network,
    relative to its largest magnitude over the cycle; the series themselves (for the ranks check)."""
    T = ci_cases()
    extra = T.pulsatile_extra(wf)
    extra["pulsatile"] |= {"cycles": 3, "discard_cycles": 2, "max_cycles": 3, "min_steps_per_cycle": steps}
    cfd = T.tube_cfd({"type": "free"}, **extra) | {"ranks": ranks, "decomposition": {"method": "simple"}}
    case = tmp / f"pulsatile_{steps}_{ranks}"
    state = render_case(case, stl, cfd, flavour="esi", patient={"outlet_bc": str(table)})
    t0 = time.process_time()
    st = run_case(case, ranks=ranks)
    cpu = sum(c.get("cpu_s", 0.0) for c in st["pulsatile"].get("cycles", [])) or time.process_time() - t0
    waveform = load_waveform(wf)
    t_last = 2 * T.PERIOD
    errors, series = {}, {}
    for k, name in enumerate(OUTLETS):
        q, p = function_series(case, f"flowRate_{name}"), function_series(case, f"pressure_{name}")
        series[name] = (q, p)
        last = q[:, 0] > t_last + 1e-9
        t = q[last, 0]
        p_sim = np.interp(t, p[:, 0], p[:, 1]) * T.RHO
        p_ref, q_ref = parallel_rcr_periodic(t, T.PERIOD, waveform.fourier(400), _rcrs(T))
        errors[name] = {
            "p": float(np.abs(p_sim - p_ref).max() / np.abs(p_ref).max()),
            "q": float(np.abs(q[last, 1] - q_ref[k]).max() / np.abs(q_ref[k]).max()),
        }
    return {
        "errors": errors,
        "series": series,
        "cells": state.get("ncells_final") or st.get("cells"),
        "periodic": st["pulsatile"].get("periodic"),
        "cpu_s": cpu,
    }


def ranks_difference(a: dict, b: dict) -> float:
    """(3): the largest difference of any outlet's flow or pressure series between two runs,
    relative to the series' largest magnitude (the same time steps in both, else inf)."""
    worst = 0.0
    for name in OUTLETS:
        for x, y in zip(a["series"][name], b["series"][name]):
            if x.shape != y.shape or not np.array_equal(x[:, 0], y[:, 0]):
                return float("inf")
            worst = max(worst, float(np.abs(x[:, 1] - y[:, 1]).max() / np.abs(x[:, 1]).max()))
    return worst


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, nargs="+", default=[400], help="time steps per cycle (largest dt = T / this)")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks of the parallel run (0: none)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="write the table as docs JSON")
    a = ap.parse_args(argv)
    T = ci_cases()
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        stl = T.write_half_split_tube_stl(tmp / "half.stl")
        table = T.write_rcr_table(tmp / "outlets.csv")
        wf = T.write_waveform(tmp / "w.csv", T.Q0, 1.5 * T.Q0)
        s = steady(tmp, stl, table)
        print(
            f"steady: split {s['fraction']:.5f} (0-D {s['target']:.5f}), |p/(R Q) - 1| <= {s['p_rel']:.1e}, "
            f"mass balance {s['balance']:.1e}, {s['iterations']} iterations"
        )
        puls = {}
        for n in a.steps:
            r = pulsatile(tmp, stl, table, wf, n)
            puls[n] = r
            e = r["errors"]
            print(
                f"pulsatile, {n} steps/cycle: last cycle p {100 * e['outlet']['p']:.2f} / "
                f"{100 * e['branch_1']['p']:.2f} %, "
                f"Q {100 * e['outlet']['q']:.2f} / {100 * e['branch_1']['q']:.2f} % (outlet / branch_1), "
                f"{r['cpu_s']:.0f} CPU s"
            )
        diff = steady_diff = None
        if a.ranks > 1:
            s2 = steady(tmp, stl, table, ranks=a.ranks)
            steady_diff = {
                name: float(np.abs(x - y).max() / np.abs(x).max())
                for name, x, y in zip(("U", "p"), s["fields"], s2["fields"])
            } | {"iterations": (s["iterations"], s2["iterations"])}
            print(f"steady, {a.ranks} ranks against serial: {steady_diff}")
            n0 = a.steps[0]
            par = pulsatile(tmp, stl, table, wf, n0, ranks=a.ranks)
            diff = ranks_difference(puls[n0], par)
            print(f"{a.ranks} ranks against serial ({n0} steps/cycle): largest difference {diff:.1e}")
    rows = [
        [
            "steady, two half-disc outlets with unequal RCR tables (R 5e8 and 1.5e9 Pa s/m3)",
            f"split {s['fraction']:.4f} against the resistances in parallel {s['target']:.4f}; each outlet's "
            f"p = (R_p + R_d) Q within {sig(100 * s['p_rel'])} %; mass balance {sig(s['balance'])}",
        ]
    ]
    for n, r in puls.items():
        e = r["errors"]
        rows.append(
            [
                f"pulsatile reversing inflow (T = 0.4 s, R_d C = 0.15 / 0.10 s), last of 3 cycles, {n} steps per "
                "cycle, against the exact periodic 0-D network (parallel RCRs, harmonic by harmonic)",
                f"pressure {sig(100 * e['outlet']['p'])} % / {sig(100 * e['branch_1']['p'])} %, flow "
                f"{sig(100 * e['outlet']['q'])} % / {sig(100 * e['branch_1']['q'])} % of the cycle's largest "
                "(outlet / branch_1; tolerance 2 %)",
            ]
        )
    if steady_diff is not None:
        rows.append(
            [
                f"steady, {a.ranks} MPI ranks against serial (summation order)",
                f"U within {sig(steady_diff['U'])}, p within {sig(steady_diff['p'])} of their largest values; "
                f"iterations {steady_diff['iterations'][0]} / {steady_diff['iterations'][1]}",
            ]
        )
    if diff is not None:
        rows.append(
            [f"pulsatile, {a.ranks} MPI ranks against serial, same case", f"waveforms within {sig(100 * diff)} %"]
        )
    save(
        a.json,
        measured=f"one run, the cases one after the other, {time.perf_counter() - t_start:.0f} s; the CI tests' "
        "half-split tube (tests/workflow/test_outlets_openfoam.py)",
        columns=JSON_COLUMNS,
        rows=rows,
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
