#!/usr/bin/env python3
"""The README's jet-atlas table: config/paper.yaml + config/paper_atlas.yaml (the paper's jet,
steady SIMPLE then the transient time average over 10 flow-through times, on four demo aortas)
through the whole workflow, then one row per patient from its status.json and the workflow's
benchmark files, and the atlas's field sources and explained variances.

    .venv/bin/python bench/jet_atlas.py [-d DIR] [--cores 2] [--json PATH]

Needs OpenFOAM; ~3 hours on 2 cores (5.4 CPU hours of solver) (README, "An atlas of jet patients"). DIR (default: a
temporary folder) is the Snakemake working directory; a finished DIR is only re-read. Prints, per
patient: cells, jet cells across, layer coverage, SIMPLE iterations, flow-through time, wash-out +
window, pimpleFoam time steps and their size, the relative error bars (95 % half-widths) of the
window means, the window means (inlet - outlet pressure, TAWSS, OSI), CPU hours of the solvers (their
logs' ExecutionTime), the patient's wall time (the five workflow jobs) and the verdict; then the
atlas. A patient that failed gets '-' where it has no figure and its reason. ``--json PATH`` also
writes the table in the docs' format (docs/data/bench/jet_atlas.json).
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

from _table import emit, markdown_row  # bench/ is on sys.path when this runs as a script
from real_cohort import job_seconds, run_workflow

REPO = Path(__file__).resolve().parents[1]
CONFIGS = ("config.yaml", "paper.yaml", "paper_atlas.yaml")
NO_STATUS = "no status.json (the run stopped before the solver)"
#: the table's columns (as printed and in the docs JSON)
COLUMNS = [
    "patient",
    "cells",
    "jet cells across",
    "layer coverage",
    "SIMPLE iterations",
    "flow-through s",
    "wash-out + window s",
    "time steps",
    "dt ms",
    "95 % half-widths % (dp / TAWSS / U)",
    "inlet - outlet pressure Pa",
    "TAWSS mean / max Pa",
    "OSI mean",
    "solver CPU h",
    "patient wall min",
    "converged",
]


def execution_time(logs: list[Path]) -> float:
    """CPU seconds of OpenFOAM runs: the sum of each log's last ExecutionTime (0 without one)."""
    total = 0.0
    for log in logs:
        last = None
        with open(log, errors="replace") as fh:
            for line in fh:
                if line.startswith("ExecutionTime = "):
                    last = line
        total += float(last.split()[2]) if last else 0.0
    return total


def solver_cpu_s(case: Path) -> float:
    """CPU seconds of the case's solvers: the last ExecutionTime of every simpleFoam / pimpleFoam log."""
    logs = sorted((case / "logs").glob("log.*Foam*"))
    return execution_time([log for log in logs if log.name.split(".")[1] in ("simpleFoam", "pimpleFoam")])


def row(res: Path, pid: str) -> str:
    """One table row from the patient's status.json, logs and benchmark files ('-' where absent)."""
    return markdown_row(printed(cells(res, pid)))


def printed(c: list[str]) -> list[str]:
    """The cells of :func:`cells` as printed (a patient without status.json: its id and reason)."""
    return c[:2] if c[1] == NO_STATUS else c


def cells(res: Path, pid: str) -> list[str]:
    """:func:`row`'s cells, in the order of :data:`COLUMNS` (a patient without status.json: its
    reason, then '-')."""
    f = res / "patients" / pid / "status.json"
    if not f.exists():
        return [pid, NO_STATUS] + ["-"] * (len(COLUMNS) - 2)
    st = json.loads(f.read_text())
    m, tr = st.get("mesh") or {}, st.get("transient") or {}
    try:
        wall_min = f"{job_seconds(res, pid) / 60:.0f}"
    except (OSError, StopIteration, KeyError, ValueError):
        wall_min = "-"
    cpu_h = solver_cpu_s(res / "patients" / pid / "case") / 3600
    jet = m.get("jet_refinement") or {}
    d = tr.get("relative_errors") or {}
    halves = " / ".join(f"{100 * d[k]:.2g}" for k in ("inlet_minus_outlet_pressure", "tawss_mean", "U") if k in d)
    steps = tr.get("time_steps") or {}
    dt = tr.get("delta_t_s") or {}
    tawss, osi = st.get("tawss_Pa") or {}, st.get("osi") or {}
    dp = (st.get("inlet_minus_outlet_pressure") or {}).get("Pa")
    window = "-"
    if "window_s" in tr:
        window = f"{tr['washout_s']:.3g} + {tr['window_s']:.3g} ({tr['window_flow_throughs']:.3g} FT)"

    def num(v: object, fmt: str) -> str:
        return "-" if not isinstance(v, (int, float)) else format(v, fmt)

    dts = "-" if dt.get("min") is None else f"{1e3 * dt['min']:.2g}-{1e3 * dt['max']:.2g}"
    return [
        pid,
        num(st.get("cells"), ","),
        num(jet.get("cells_across"), ".1f"),
        num((m.get("layers") or {}).get("coverage"), ".2f"),
        num(st.get("iterations"), ","),
        num(tr.get("flow_through_time_s"), ".3g"),
        window,
        num(sum(steps.values()), ","),
        dts,
        halves or "-",
        num(dp, ".1f"),
        f"{num(tawss.get('mean'), '.3g')} / {num(tawss.get('max'), '.3g')}",
        num(osi.get("mean"), ".2g"),
        f"{cpu_h:.2f}",
        wall_min,
        str(st.get("criterion_used")) if st.get("converged") else "NO: " + str(st.get("reason")),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-d", "--workdir", type=Path, help="Snakemake working directory (default: temporary)")
    ap.add_argument("--cores", type=int, default=2, help="cores for Snakemake (default 2)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        wd = (a.workdir or Path(tmp)).resolve()
        wd.mkdir(parents=True, exist_ok=True)
        sheet = REPO / "config" / "paper_atlas_patients.tsv"
        ids = [r["id"] for r in csv.DictReader((ln for ln in open(sheet) if not ln.startswith("#")), delimiter="\t")]
        r = run_workflow(wd, list(CONFIGS), str(sheet), a.cores, f"jet atlas, {' + '.join(CONFIGS)}")
        res = wd / "results"
        emit(
            COLUMNS,
            (printed(cells(res, pid)) for pid in ids),
            a.json,
            f"one run, config/{' + config/'.join(CONFIGS)}, {a.cores} cores for Snakemake",
            json_row=lambda c: c + ["-"] * (len(COLUMNS) - len(c)),  # the '-' a printed failure leaves out
        )
        if not (res / "atlas" / "atlas.json").exists():
            print("atlas: none (fewer than 3 patients included: see the rows above, results/logs/atlas_build/)")
            return 1
        atlas = json.loads((res / "atlas" / "atlas.json").read_text())
        ev = {f: ", ".join(f"{100 * v:.0f}" for v in x) for f, x in atlas["flow_explained_variance"].items()}
        print(
            f"atlas: {len(atlas['patients_included'])} included, {len(atlas['patients_excluded'])} excluded; "
            f"field sources {atlas.get('field_sources')}; explained variance % shape "
            f"{', '.join(f'{100 * v:.0f}' for v in atlas['shape_explained_variance'])}; "
            + "; ".join(f"{f} {v}" for f, v in ev.items())
        )
    return 0 if r.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
