#!/usr/bin/env python3
"""The CI cohort with prism layers off and on: config/config.yaml + config/ci.yaml on
config/ci_patients.tsv (three demo aortas) through the whole workflow twice, ``cfd.mesh.layers: 0``
and then 3 (the default), and one row per patient from both runs' status.json.

    .venv/bin/python bench/ci_layers.py [-d DIR] [--cores 2] [--json PATH]

DIR (default: a temporary folder) holds the two Snakemake working directories, DIR/layers_0 and
DIR/layers_3; a finished one is only re-read. Per patient: cells without layers, cells with them
(and the layer coverage), SIMPLE iterations of both, and each case's seconds (status.json
``timings_s.total``: meshing and solving, wall clock). ``--json PATH`` also writes the table in the
docs' format (docs/data/bench/ci_layers.json). Needs OpenFOAM; minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
import tempfile
from pathlib import Path

import yaml
from _table import emit  # bench/ is on sys.path when this runs as a script
from real_cohort import run_workflow

REPO = Path(__file__).resolve().parents[1]
SHEET = REPO / "config" / "ci_patients.tsv"
LAYERS = (0, 3)  # off, then the default of config/config.yaml
#: the table's columns (as printed and in the docs JSON)
COLUMNS = [
    "patient",
    "cells, `layers: 0`",
    "cells, 3 layers (coverage)",
    "SIMPLE iterations",
    "case s, `layers: 0`",
    "case s, 3 layers",
]


def cells(pid: str, off: dict | None, on: dict | None) -> list[str]:
    """One patient's row of :data:`COLUMNS` from its status.json without and with layers (None:
    the run wrote none; '-' for its figures)."""

    def get(st: dict | None, fmt: str, *keys: str) -> str:
        v = st
        for k in keys:
            v = v.get(k) if isinstance(v, dict) else None
        return "-" if not isinstance(v, (int, float)) else format(v, fmt)

    coverage = get(on, ".2f", "mesh", "layers", "coverage")
    return [
        pid,
        get(off, ",", "cells"),
        f"{get(on, ',', 'cells')} ({coverage})",
        f"{get(off, 'd', 'iterations')} / {get(on, 'd', 'iterations')}",
        get(off, ".1f", "timings_s", "total"),
        get(on, ".1f", "timings_s", "total"),
    ]


def status(wd: Path, pid: str) -> dict | None:
    f = wd / "results" / "patients" / pid / "status.json"
    return json.loads(f.read_text()) if f.exists() else None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-d", "--workdir", type=Path, help="folder of the two runs (default: temporary)")
    ap.add_argument("--cores", type=int, default=2, help="cores for Snakemake (default 2)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    ids = [r["id"] for r in csv.DictReader((ln for ln in open(SHEET) if not ln.startswith("#")), delimiter="\t")]
    codes = []
    with tempfile.TemporaryDirectory() as tmp:
        root = (a.workdir or Path(tmp)).resolve()
        runs = {}
        for n in LAYERS:
            wd = root / f"layers_{n}"
            wd.mkdir(parents=True, exist_ok=True)
            override = wd / "layers.yaml"
            override.write_text(yaml.safe_dump({"cfd": {"mesh": {"layers": n}}}))
            configs = ["config.yaml", "ci.yaml", str(override)]  # an absolute path: REPO / "config" / it is itself
            r = run_workflow(wd, configs, str(SHEET), a.cores, f"CI cohort, layers {n}")
            codes.append(r.returncode)
            runs[n] = wd
        emit(
            COLUMNS,
            (cells(pid, *(status(runs[n], pid) for n in LAYERS)) for pid in ids),
            a.json,
            f"two runs, config/config.yaml + config/ci.yaml, cfd.mesh.layers 0 then 3, {a.cores} cores for Snakemake",
        )
    return 0 if not any(codes) else 1


if __name__ == "__main__":
    sys.exit(main())
