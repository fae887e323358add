#!/usr/bin/env python3
"""The README's real-cohort table: config/real_patients.tsv (the five shared real vessels) through
the whole workflow with the default config/config.yaml, then one row per patient from its
status.json and the workflow's own benchmark files.

    .venv/bin/python bench/real_cohort.py [-d DIR] [--cores 2] [--json PATH]

Needs ../shared/data beside the repository and OpenFOAM. DIR (default: a temporary folder) is the
Snakemake working directory; a finished DIR is only re-read. Prints, per patient: cell size (and
what set it), cells, wall / inlet / outlet faces, layer coverage, SIMPLE iterations and the
convergence criterion, final residuals, inlet - outlet pressure, WSS mean / max, inflow, time per
patient (the five workflow jobs, wall clock) and OpenFOAM solver seconds; then the whole run's wall
time and the machine. ``--json PATH`` also writes the table without its "converged" column in the
docs' format (docs/data/bench/real_cohort.json).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

from _table import emit  # bench/ is on sys.path when this runs as a script

REPO = Path(__file__).resolve().parents[1]
JOBS = ("vcs_fit", "vcs_wall", "openfoam_case", "openfoam_solve", "fields_sample")


def real_rows() -> list[dict[str, str]]:
    """The rows of config/real_patients.tsv with its ../shared paths made absolute."""
    lines = [ln for ln in (REPO / "config" / "real_patients.tsv").read_text().splitlines() if not ln.startswith("#")]
    rows = list(csv.DictReader(lines, delimiter="\t"))
    for r in rows:
        for k in ("mesh", "inlet_cap", "outlet_cap"):
            if r[k]:
                r[k] = str((REPO / r[k]).resolve())
    return rows


def write_rows(dst: Path, rows: list[dict[str, str]]) -> list[str]:
    """``rows`` as a patients sheet (TSV, the union of their columns, empty cells for the rest)."""
    cols = list(dict.fromkeys(k for r in rows for k in r))
    with open(dst, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=cols, delimiter="\t", lineterminator="\n", restval="")
        w.writeheader()
        w.writerows(rows)
    return [r["id"] for r in rows]


def sheet(dst: Path) -> list[str]:
    """config/real_patients.tsv with its ../shared paths made absolute, written to ``dst``."""
    return write_rows(dst, real_rows())


def run_workflow(
    wd: Path, configs: list[str], patients: str, cores: int, title: str, targets: list[str] | None = None
) -> subprocess.CompletedProcess:
    """Run the workflow in ``wd`` (config/<configs> merged in order, the patients sheet
    ``patients``, the local profile; ``targets``, default: all) and print one line: title, date,
    machine, load, exit, wall."""
    cmd = [
        str(Path(sys.executable).parent / "snakemake"),
        *(targets or []),
        *("-s", str(REPO / "Snakefile"), "-d", str(wd), "--configfile"),
        *(str(REPO / "config" / c) for c in configs),
        *("--config", f"patients={patients}", "--profile", str(REPO / "profiles" / "local")),
        *("--cores", str(cores), "--rerun-incomplete"),
    ]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=wd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    print(
        f"{title}, {date.today()}, {platform.node()} ({os.cpu_count()} cores), "
        f"load {os.getloadavg()[0]:.1f}: snakemake exit {r.returncode}, {wall:.0f} s wall"
    )
    if r.returncode:  # say why (a stale lock, a failed job) before the table of what exists
        errors = [ln for ln in r.stderr.splitlines() if ln.strip()][-6:]
        print("snakemake's last lines:\n  " + "\n  ".join(errors), file=sys.stderr)
    return r


def job_seconds(res: Path, pid: str) -> float:
    """Wall seconds of one patient's workflow jobs (:data:`JOBS`), from Snakemake's benchmark files."""
    return sum(
        float(next(csv.DictReader(open(res / "benchmarks" / j / f"{pid}.tsv"), delimiter="\t"))["s"]) for j in JOBS
    )


#: the table's columns as printed; the docs JSON has all but the last
COLUMNS = [
    "vessel",
    "cell mm (set by)",
    "cells",
    "wall / inlet / outlet faces",
    "layer coverage",
    "SIMPLE iterations (criterion)",
    "final residuals p / U",
    "inlet - outlet pressure Pa",
    "WSS mean / max Pa",
    "inflow L/min",
    "time per patient s (solver s)",
    "converged",
]


def cells(res: Path, pid: str) -> list[str]:
    """One row's cells, in the order of :data:`COLUMNS`."""
    st = json.loads((res / "patients" / pid / "status.json").read_text())
    m, t = st["mesh"], st["timings_s"]
    size = m["sizing"]["cell_size"]
    job_s = job_seconds(res, pid)
    solver_s = sum(v for k, v in t.items() if k.startswith(("simpleFoam", "pimpleFoam")))
    fr, wss = st["final_residuals"], st["wall_shear_stress_Pa"]
    faces = " / ".join(f"{m['patches'][k]['faces']:,}" for k in ("wall", "inlet", "outlet"))
    return [
        pid,
        f"{size['cell_size_m'] * 1e3:.3g} ({size['governed_by']})",
        f"{st['cells']:,}",
        faces,
        f"{m['layers'].get('coverage', 0):.2f}",
        f"{st['iterations']:,} ({st['criterion_used']})",
        f"{fr['p']:.2g} / {fr['U']:.2g}",
        f"{st['inlet_minus_outlet_pressure']['Pa']:.1f}",
        f"{wss['mean']:.3g} / {wss['max']:.3g}",
        f"{st['inflow']['flow_rate_l_min']:.3g}",
        f"{job_s:.0f} ({solver_s:.0f})",
        "yes" if st["converged"] else "NO: " + str(st["reason"]),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-d", "--workdir", type=Path, help="Snakemake working directory (default: temporary)")
    ap.add_argument("--cores", type=int, default=2, help="cores for Snakemake (default 2)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    if not (REPO.parent / "shared" / "data").is_dir():
        print(f"real_cohort: error: {REPO.parent / 'shared' / 'data'} is absent", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory() as tmp:
        wd = (a.workdir or Path(tmp)).resolve()
        wd.mkdir(parents=True, exist_ok=True)
        ids = sheet(wd / "patients.tsv")
        r = run_workflow(wd, ["config.yaml"], "patients.tsv", a.cores, "real cohort, default config")
        res = wd / "results"
        emit(
            COLUMNS,
            (cells(res, pid) for pid in ids),
            a.json,
            f"one run, default config/config.yaml, {a.cores} cores for Snakemake",
            json_columns=COLUMNS[:-1],
            json_row=lambda c: c[:-1],
        )
        atlas = json.loads((res / "atlas" / "atlas.json").read_text())
        print(f"atlas: {len(atlas['patients_included'])} included, {len(atlas['patients_excluded'])} excluded")
    return 0 if r.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
