#!/usr/bin/env python3
"""Issue 23's targets: what an honest result costs per patient with the default configuration.

Every shared real vessel (../shared/data/vessels: the five of config/real_patients.tsv, AortaCFD
patient1 at its default ``auto`` cell size, not the sheet's 1.0 mm, plus the SimVascular open
segment and the vmtk bifurcation) and, with ``--demo N``, the first N demo aortas, through the
whole workflow with config/config.yaml; then one row per patient.

    .venv/bin/python bench/cfd_cost.py [-d DIR] [--cores 2] [--demo 8] [--skip id,id] [--json PATH]

DIR (default: a temporary folder) is the Snakemake working directory; a finished DIR is only
re-read. Per patient: cells, the CFD verdict (criterion; for a time average its window in
flow-through times and the 95 % half-widths of dp / mean TAWSS / U), SIMPLE iterations and
pimpleFoam time steps, the time step, OpenFOAM CPU s (the solvers' ExecutionTime plus the other
utilities' wall time), the patient's CPU s and wall s over all its workflow jobs (Snakemake's
benchmark files: ``cpu_time``, ``s``; ``cpu_time`` is sampled every 30 s over the job's process
tree, so it misses the shorter processes and is a lower bound); then the run's wall time, the machine and its load.
``--json PATH`` also writes the table in the docs' format (docs/data/bench/cfd_cost.json: SIMPLE
iterations without the time steps, no time step column).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
from jet_atlas import solver_cpu_s  # noqa: E402
from real_cohort import real_rows, run_workflow, write_rows  # noqa: E402
from stage_survey import EXTRA  # noqa: E402


def sheet_rows(n_demo: int) -> list[dict[str, str]]:
    """The shared real vessels at the default cell size, then ``n_demo`` demo aortas."""
    rows = real_rows() + [dict(r) for r in EXTRA]
    for r in rows:
        r["cell_size_mm"] = ""  # patient1 too: the default auto size (0.59 mm), not the CI sheet's 1.0 mm
    rows += [{"id": f"demo_aorta_{s}", "mesh": f"results/demo/aorta_seed{s}.stl", "units": "mm"} for s in range(n_demo)]
    return rows


def job_totals(res: Path, pid: str) -> tuple[float, float]:
    """(CPU s, wall s) of every workflow job of the patient (its benchmark files, any rule)."""
    cpu = wall = 0.0
    for f in res.glob(f"benchmarks/*/{pid}.tsv"):
        rec = next(csv.DictReader(open(f), delimiter="\t"))
        cpu += float(rec.get("cpu_time") or 0.0)
        wall += float(rec["s"])
    return cpu, wall


def verdict(st: dict) -> str:
    if not st.get("converged"):
        return f"NOT converged: {(st.get('reason') or '')[:120]}"
    tr = st.get("transient") or {}
    if st.get("criterion_used") != "time_average_stationary":
        return str(st.get("criterion_used"))
    e = tr["relative_errors"]
    bars = " / ".join(f"{100 * e[k]:.2g}" for k in ("inlet_minus_outlet_pressure", "tawss_mean", "U") if k in e)
    return f"time average, {tr['window_flow_throughs']:.2g} FT window (+- {bars} %)"


#: the table's columns as printed
COLUMNS = [
    "patient",
    "cells",
    "verdict (95 % half-widths dp / TAWSS / U)",
    "SIMPLE iterations / time steps",
    "dt ms",
    "OpenFOAM CPU s",
    "jobs CPU s (sampled)",
    "patient wall s",
]
#: the docs JSON's columns
JSON_COLUMNS = [
    "patient",
    "cells",
    "verdict",
    "SIMPLE iterations",
    "OpenFOAM CPU s",
    "jobs CPU s (sampled)",
    "patient wall s",
]


def json_cells(c: list[str]) -> list[str]:
    """A row of :data:`COLUMNS` as one of :data:`JSON_COLUMNS`."""
    if len(c) < len(COLUMNS):  # no status.json
        return c + ["-"] * (len(JSON_COLUMNS) - len(c))
    return [c[0], c[1], c[2], c[3].split(" / ")[0], c[5], c[6], c[7]]


def cells(res: Path, pid: str) -> list[str]:
    """One row's cells, in the order of :data:`COLUMNS` (a patient without status.json: two)."""
    p = res / "patients" / pid
    f = p / "status.json"
    if not f.exists():
        return [pid, "no status.json"]
    st = json.loads(f.read_text())
    tr = st.get("transient") or {}
    steps = sum((tr.get("time_steps") or {}).values())
    dt = tr.get("delta_t_s") or {}
    dts = "-" if not dt.get("min") else f"{1e3 * dt['min']:.2g}-{1e3 * dt['max']:.2g}"
    t = st.get("timings_s") or {}
    foam = solver_cpu_s(p / "case") + sum(
        v for k, v in t.items() if k != "total" and not k.startswith(("simpleFoam", "pimpleFoam", "inletProfile"))
    )
    cpu, wall = job_totals(res, pid)
    return [
        pid,
        f"{st.get('cells') or 0:,}",
        verdict(st),
        f"{st.get('iterations', 0):,} / {steps:,}",
        dts,
        f"{foam:.0f}",
        f"{cpu:.0f}",
        f"{wall:.0f}",
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-d", "--workdir", type=Path, help="Snakemake working directory (default: temporary)")
    ap.add_argument("--cores", type=int, default=2, help="cores for Snakemake (default 2)")
    ap.add_argument("--demo", type=int, default=0, help="also the first N demo aortas (default 0)")
    ap.add_argument("--skip", default="", help="comma-separated patient ids to leave out")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    if not (REPO.parent / "shared" / "data").is_dir():
        print(f"cfd_cost: error: {REPO.parent / 'shared' / 'data'} is absent", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        wd = (a.workdir or Path(tmp)).resolve()
        wd.mkdir(parents=True, exist_ok=True)
        skip = set(filter(None, a.skip.split(",")))
        ids = write_rows(wd / "patients.tsv", [r for r in sheet_rows(a.demo) if r["id"] not in skip])
        run_workflow(wd, ["config.yaml"], "patients.tsv", a.cores, "shared real vessels, default config")
        res = wd / "results"
        from _table import emit

        emit(
            COLUMNS,
            (cells(res, pid) for pid in ids),
            a.json,
            f"one run, default config/config.yaml, {a.cores} cores for Snakemake",
            json_columns=JSON_COLUMNS,
            json_row=json_cells,
        )
        atlas = res / "atlas" / "atlas.json"
        if atlas.exists():
            at = json.loads(atlas.read_text())
            print(f"atlas: {len(at['patients_included'])} included, {len(at['patients_excluded'])} excluded")
    return 0


if __name__ == "__main__":
    sys.exit(main())
