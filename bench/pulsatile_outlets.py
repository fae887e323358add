"""What a pulsatile run with a Windkessel on every outlet cost and gave, per patient of a results
folder: cells, cycles run and whether periodic, CPU per cycle, each outlet's realised mean split and
its systolic / diastolic / mean pressure; prints the table.

Usage (after a workflow run, e.g. the real vessels pulsatile with ``outlets: rcr``)::

    .venv/bin/python bench/pulsatile_outlets.py RESULTS_DIR [--json PATH]

``RESULTS_DIR`` is the folder holding ``patients/<id>/status.json`` (the workflow's ``results/``).
``--json PATH`` writes the table as docs data (docs/data/bench/pulsatile_outlets.json).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from _table import emit, sig  # bench/ is on sys.path when this runs as a script

COLUMNS = [
    "patient",
    "cells",
    "cycles (periodic)",
    "CPU min per cycle",
    "last change: outlet p / Q, TAWSS",
    "outlets: mean split, sys/dia (mean) mmHg",
]


def patient_row(pid: str, st: dict) -> list[str] | None:
    """One patient's row from its status.json (None: not a pulsatile run)."""
    pu = st.get("pulsatile") or {}
    cycles = pu.get("cycles") if isinstance(pu.get("cycles"), list) else None
    if not pu.get("evaluated") or not cycles:
        return None
    cpu = [float(c.get("cpu_s", 0.0)) for c in cycles]
    last = (pu.get("changes") or [{}])[-1]
    outs = []
    for o in st.get("outlets") or []:
        pm = {k: float("nan") for k in ("systolic", "diastolic", "mean")} | (o.get("pressure_mmhg") or {})
        outs.append(
            f"{o['name']} {100 * (o.get('fraction') or 0):.1f} %, "
            f"{pm['systolic']:.0f}/{pm['diastolic']:.0f} ({pm['mean']:.0f})"
        )
    change = (
        f"{sig(100 * last.get('pressure', float('nan')))} / {sig(100 * last.get('flow', float('nan')))} %, "
        f"{sig(100 * last.get('tawss', float('nan')))} %"
    )
    return [
        pid,
        f"{int(st.get('cells') or 0):,}",
        f"{len(cycles)} ({'yes' if pu.get('periodic') else 'no'})",
        f"{sig(sum(cpu) / len(cpu) / 60)} (max {sig(max(cpu) / 60)})",
        change,
        "; ".join(outs),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, help="the workflow's results folder")
    ap.add_argument("--json", type=Path, metavar="PATH", help="write the table as docs JSON")
    a = ap.parse_args(argv)
    rows = []
    for status in sorted(a.results.glob("patients/*/status.json")):
        row = patient_row(status.parent.name, json.loads(status.read_text()))
        if row is not None:
            rows.append(row)
    if not rows:
        ap.error(f"no pulsatile patient in {a.results}/patients/*/status.json")
    emit(COLUMNS, rows, a.json, measured="from the runs' status.json (CPU: OpenFOAM's, per cycle)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
