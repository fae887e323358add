#!/usr/bin/env python3
"""The pulsatile runs of a results folder as a table: cells, time step, CPU per cycle, cycles to
periodicity, the last cycle-to-cycle changes and the TAWSS / OSI ranges on the VCS grid.

    .venv/bin/python bench/bench_cohort.py --n 2 --configfile config/pulsatile.yaml --workdir W
    .venv/bin/python bench/pulsatile_table.py W/results [--rows-json out.json] [--json PATH]

Reads results/patients/<id>/status.json (``pulsatile``, ``cells``) and fields.npz (TAWSS, OSI,
RRT, ECAP on the grid: 5th-95th percentiles). CPU per cycle is pimpleFoam's ExecutionTime summed
over the cycle's runs (x ranks); the README's pulsatile table is this script's output.
``--rows-json`` writes the rows read, ``--json PATH`` the table in the docs' format
(docs/data/bench/pulsatile_cost.json).
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

#: the table's columns (as printed and in the docs JSON)
COLUMNS = [
    "patient",
    "cells",
    "dt (ms)",
    "steps/cycle",
    "CPU s/cycle",
    "cycles",
    "last change dp/flow/TAWSS %",
    "TAWSS 5-95% (Pa)",
    "OSI 5-95%",
]


def patient_row(pid: str, folder: Path) -> dict | None:
    st_file = folder / "status.json"
    if not st_file.exists():
        return None
    st = json.loads(st_file.read_text())
    pu = st.get("pulsatile")
    if not pu:
        return None
    cycles = pu.get("cycles") or []
    row = {
        "id": pid,
        "converged": st.get("converged"),
        "reason": st.get("reason"),
        "cells": st.get("cells"),
        "period_s": pu.get("period_s"),
        "cycles_run": pu.get("cycles_run"),
        "dt_min_s": min((c["delta_t_s"]["min"] for c in cycles if c["delta_t_s"]["min"]), default=None),
        "dt_max_s": max((c["delta_t_s"]["max"] for c in cycles if c["delta_t_s"]["max"]), default=None),
        "steps_per_cycle": float(np.mean([c["time_steps"] for c in cycles])) if cycles else None,
        "cpu_s_per_cycle": float(np.mean([c["cpu_s"] for c in cycles])) if cycles else None,
        "last_change": (pu.get("changes") or [None])[-1],
        "inflow_l_min": (st.get("inflow") or {}).get("flow_rate_l_min"),
        "womersley_number": (st.get("inlet") or {}).get("womersley_number"),
    }
    npz = folder / "fields.npz"
    if npz.exists():
        with np.load(npz) as f:
            for key in ("TAWSS", "OSI", "RRT", "ECAP"):
                if key in f.files:
                    v = f[key][np.isfinite(f[key])]
                    row[key] = [float(np.percentile(v, 5)), float(np.percentile(v, 95))] if v.size else None
    return row


def cells(r: dict) -> list[str]:
    """One row of :func:`patient_row` as cells of :data:`COLUMNS`."""
    ch = r["last_change"]
    ch_txt = "-" if not ch else f"{100 * ch['dp']:.2g} / {100 * ch['flow']:.2g} / {100 * ch['tawss']:.2g}"
    dt = f"{1e3 * r['dt_min_s']:.3g}-{1e3 * r['dt_max_s']:.3g}" if r["dt_min_s"] else "-"
    ta = "-" if not r.get("TAWSS") else f"{r['TAWSS'][0]:.2g}-{r['TAWSS'][1]:.2g}"
    osi = "-" if not r.get("OSI") else f"{r['OSI'][0]:.2g}-{r['OSI'][1]:.2g}"
    return [
        r["id"],
        f"{r['cells']}",
        dt,
        f"{r['steps_per_cycle']:.0f}",
        f"{r['cpu_s_per_cycle']:.0f}",
        f"{r['cycles_run']}{'' if r['converged'] else ' (not periodic)'}",
        ch_txt,
        ta,
        osi,
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", help="a results folder (results/patients/<id>/...)")
    ap.add_argument("--rows-json", help="also write the rows read here")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    args = ap.parse_args(argv)
    patients = Path(args.results) / "patients"
    rows = [r for d in sorted(patients.iterdir()) if (r := patient_row(d.name, d))]
    if not rows:
        print(f"no pulsatile status.json under {patients}", file=sys.stderr)
        return 1
    emit(
        COLUMNS,
        (cells(r) for r in rows),
        args.json,
        f"read from {args.results} after its run (the date and load: the reading's)",
    )
    print(f"machine: {platform.node()} {os.cpu_count()} cores, {platform.processor() or platform.machine()}")
    if args.rows_json:
        Path(args.rows_json).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
