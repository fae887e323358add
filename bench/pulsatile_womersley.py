#!/usr/bin/env python3
"""Womersley flow in a straight rigid tube, pimpleFoam against the analytic solution, at several
mesh sizes: the amplitude and phase errors of the centreline velocity and of the wall shear stress
over the cycle, TAWSS and OSI (a waveform with flow reversal), and the cost per cycle.

    .venv/bin/python bench/pulsatile_womersley.py -d DIR [--cells 0.75 0.5] [--steps 200 800]
                                                  [--also CELL:STEPS] [--rows-json out.json] [--json PATH]

The case of tests/workflow/test_pulsatile.py (radius 5 mm, length 50 mm, Q(t) = Q0 (1 + 1.5 sin
wt), Q0 = 2 mL/s, period 0.4 s: Womersley number 10.8, nu 3.37e-6 m2/s, Womersley inlet profile,
3 cycles of which 1 is discarded) at the given cell sizes (mm), one after the other; the test
runs the first. Errors of the last cycle: mean, first-harmonic amplitude (relative) and phase
(degrees, positive = leads) against :mod:`vcs.cfd.womersley`
(:func:`vcs.cfd.verification.harmonic_errors`); the centreline velocity is a probe at mid-length,
the wall shear stress the area-mean WSS vector along the axis (the developed flow's is uniform).
A finished DIR/<cell> is re-read. ``--also 0.75:800`` (repeatable) adds one more run after the
cells x steps; ``--rows-json`` writes the measured rows, ``--json PATH`` the table in the docs'
format (docs/data/bench/pulsatile_womersley.json):

    .venv/bin/python bench/pulsatile_womersley.py -d /tmp/wom --cells 0.75 0.5 --also 0.75:800 \
        --json docs/data/bench/pulsatile_womersley.json
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np
from _table import emit  # bench/ is on sys.path when this runs as a script

from vcs.cfd import render_case, run_case
from vcs.cfd.foamfiles import function_table
from vcs.cfd.verification import harmonic_errors
from vcs.cfd.waveform import load_waveform
from vcs.cfd.womersley import centreline_velocity, tawss_osi, wall_shear_stress
from vcs.phantoms.analytic import write_closed_tube_stl

R, LENGTH, NU, PERIOD, Q0 = 0.005, 0.05, 3.37e-6, 0.4, 2.0e-6
AXIS = np.array([0.0, 0.0, 1.0])
STEPS = 200  # the default time step: T / 200
#: the table's columns (as printed and in the docs JSON)
COLUMNS = [
    "cell (mm)",
    "cells",
    "steps/cycle",
    "CPU s/cycle",
    "u_c mean / amp (%) / phase (deg)",
    "WSS mean / amp (%) / phase (deg)",
    "TAWSS (%)",
    "OSI (exact)",
]


def waveform_csv(path: Path, n: int = 200) -> Path:
    t = np.linspace(0.0, PERIOD, n + 1)
    q = Q0 * (1 + 1.5 * np.sin(2 * np.pi * t / PERIOD)) * 6e4
    q[-1] = q[0]
    path.write_text("time_s,flow_rate_l_min\n" + "\n".join(f"{a:.8g},{b:.10g}" for a, b in zip(t, q)) + "\n")
    return path


def run(root: Path, cell_mm: float, steps: int) -> dict:
    case = root / f"cell_{cell_mm:g}mm" if steps == STEPS else root / f"cell_{cell_mm:g}mm_{steps}steps"
    status = case / "status.json"
    if not status.exists():
        root.mkdir(parents=True, exist_ok=True)
        stl = write_closed_tube_stl(root / "tube.stl", radius=R, length=LENGTH, n_theta=96, n_z=40, axis=AXIS)
        cfd = {
            "mesh": {"cell_size": cell_mm * 1e-3, "layers": 2},
            "physics": {"nu": NU},
            "inlet": {"type": "parabolic", "waveform": str(waveform_csv(root / "waveform.csv")), "scaling": "fixed"},
            "pulsatile": {
                "cycles": 3,
                "discard_cycles": 1,
                "max_cycles": 4,
                "samples_per_cycle": 80,
                "min_steps_per_cycle": steps,
                "probes": [[0.0, 0.0, LENGTH / 2]],
            },
        }
        render_case(case, stl, cfd, flavour="esi")
        run_case(case, ranks=1)
    st = json.loads(status.read_text())
    wf = load_waveform(root / "waveform.csv")
    coeffs = wf.fourier(10)
    t1 = st["pulsatile"]["window"][1]

    def last(record: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        m = (record[:, 0] > t1 - PERIOD + 1e-9) & (record[:, 0] <= t1 + 1e-9)
        return record[m, 0] - (t1 - PERIOD), record[m, 1:]

    t, u = last(function_table(case, "probes", "U"))
    e_u = harmonic_errors(t, u @ AXIS, centreline_velocity(t, coeffs, PERIOD, R, NU), PERIOD)
    t, w = last(function_table(case, "wss_wall"))
    e_w = harmonic_errors(t, -(w[:, 1:4] @ AXIS), wall_shear_stress(t, coeffs, PERIOD, R, NU), PERIOD)
    tawss, osi = tawss_osi(coeffs, PERIOD, R, NU)
    cycles = st["pulsatile"]["cycles"]
    return {
        "cell_mm": cell_mm,
        "min_steps_per_cycle": steps,
        "cells": st["cells"],
        "converged": st["converged"],
        "cycles_run": st["pulsatile"]["cycles_run"],
        "steps_per_cycle": float(np.mean([c["time_steps"] for c in cycles])),
        "cpu_s_per_cycle": float(np.mean([c["cpu_s"] for c in cycles])),
        "centreline": e_u,
        "wss": e_w,
        "tawss_rel": st["tawss_Pa"]["mean"] / st["rho"] / tawss - 1,
        "osi": st["osi"]["mean"],
        "osi_exact": osi,
    }


def cells(r: dict) -> list[str]:
    """One run of :func:`run` as a row of :data:`COLUMNS` (another time step than T / 200: its
    ratio, ``0.75, dt / 4``)."""
    u, w = r["centreline"], r["wss"]
    steps = r["min_steps_per_cycle"]
    return [
        f"{r['cell_mm']:g}" + ("" if steps == STEPS else f", dt / {steps / STEPS:g}"),
        f"{r['cells']}",
        f"{r['steps_per_cycle']:.0f}",
        f"{r['cpu_s_per_cycle']:.0f}",
        f"{100 * u['mean_rel']:+.2f} / {100 * u['amplitude_rel']:+.2f} / {u['phase_deg']:+.2f}",
        f"{100 * w['mean_rel']:+.2f} / {100 * w['amplitude_rel']:+.2f} / {w['phase_deg']:+.2f}",
        f"{100 * r['tawss_rel']:+.2f}",
        f"{r['osi']:.4f} ({r['osi_exact']:.4f})",
    ]


def parse_also(text: str) -> tuple[float, int]:
    """``CELL:STEPS`` (``0.75:800``) as (cell mm, steps per cycle)."""
    cell, _, steps = text.partition(":")
    return float(cell), int(steps)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-d", "--dir", required=True, help="working folder (a finished case is re-read)")
    ap.add_argument("--cells", type=float, nargs="+", default=[0.75, 0.5], help="cell sizes, mm")
    ap.add_argument(
        "--steps", type=int, nargs="+", default=[200], help="cfd.pulsatile.min_steps_per_cycle (time step T / steps)"
    )
    ap.add_argument("--also", action="append", default=[], metavar="CELL:STEPS", help="one more run, e.g. 0.75:800")
    ap.add_argument("--rows-json", help="also write the measured rows here")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    args = ap.parse_args(argv)
    try:
        also = [parse_also(x) for x in args.also]
    except ValueError:
        ap.error(f"--also {args.also!r}: each is CELL:STEPS, e.g. 0.75:800")
    os.environ.setdefault("WM_PROJECT_DIR", "/usr/share/openfoam")
    runs = [(c, n) for c in args.cells for n in args.steps] + also
    rows = [run(Path(args.dir).resolve(), c, n) for c, n in runs]
    alpha = R * np.sqrt(2 * np.pi / PERIOD / NU)
    emit(
        COLUMNS,
        (cells(r) for r in rows),
        args.json,
        f"one run, serial, one case after the other; 2 prism layers, Womersley number {alpha:.1f}, "
        "time step T / steps per cycle (cfd.pulsatile.min_steps_per_cycle)",
    )
    print(f"machine: {platform.node()} {os.cpu_count()} cores; Womersley number {alpha:.1f}")
    if args.rows_json:
        Path(args.rows_json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
