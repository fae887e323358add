#!/usr/bin/env python3
"""What the side branches change in what the atlas measures: the same patients with
``cfd_geometry: model`` (the Eq. 8 model wall, one outlet) and ``surface`` (their own lumen, every
branch an outlet), side by side on the VCS grid.

    .venv/bin/snakemake --profile profiles/local --config patients=config/real_surface_patients.tsv
    .venv/bin/python bench/surface_vs_model.py results [--rows-json out.json] [--json PATH]

Pairs ``<name>_model`` / ``<name>_surface`` of results/patients/. Per pair: cells, convergence,
the inlet-main outlet pressure difference (status.json), the branches' share of the inflow, and
per tau band (ascending 0-0.25, arch 0.25-0.5, proximal descending 0.5-0.75, distal descending
0.75-1) the mean WSS magnitude on the wall grid (fields.npz ``WSS``; for a steady run that settled
in time, its time average), over the wall points that both runs have (the ostia of the surface run
are left out of both: fields.npz ``ostium``), and its relative change. The README's model / surface
table is this script's output. ``--rows-json`` writes the comparisons, ``--json PATH`` the table in
the docs' format (docs/data/bench/surface_vs_model.json).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

import numpy as np
from _table import save  # bench/ is on sys.path when this runs as a script

BANDS = {"ascending": (0.0, 0.25), "arch": (0.25, 0.5), "desc. prox.": (0.5, 0.75), "desc. dist.": (0.75, 1.0)}
#: the docs table's columns (docs/data/bench/surface_vs_model.json): the bands by their tau
JSON_COLUMNS = [
    "patient",
    "cells model / surface",
    "outlets (branches, their share)",
    "dp Pa model / surface",
    "WSS tau 0-0.25 Pa model / surface",
    "tau 0.25-0.5",
    "tau 0.5-0.75",
    "tau 0.75-1",
]
#: the patients of config/real_surface_patients.tsv by name in the docs table
LABELS = {
    "aortacfd_patient1": "AortaCFD patient1 (coarctation)",
    "vmr0154": "VMR 0154",
    "simvascular_capped": "SimVascular segment (no branches)",
}


def _load(folder: Path) -> tuple[dict, dict] | None:
    """(status.json, fields.npz) of a patient, or None when either is missing."""
    st, npz = folder / "status.json", folder / "fields.npz"
    if not st.exists() or not npz.exists():
        return None
    with np.load(npz) as f:
        fields = {k: f[k] for k in ("tau", "WSS", "ostium") if k in f.files}
    if "WSS" not in fields:  # a failed patient's placeholder (excluded, stage)
        return None
    return json.loads(st.read_text()), fields


def pair_row(name: str, model: tuple[dict, dict], surface: tuple[dict, dict]) -> dict:
    """The comparison of one patient's model and surface runs (see the module doc)."""
    (sm, fm), (ss, fs) = model, surface
    wss_m = np.linalg.norm(fm["WSS"], axis=-1)
    wss_s = np.linalg.norm(fs["WSS"], axis=-1)
    keep = np.isfinite(wss_m) & np.isfinite(wss_s)
    if "ostium" in fs:
        keep &= ~fs["ostium"]
    tau = fm["tau"]
    bands = {}
    for band, (lo, hi) in BANDS.items():
        rows = (tau >= lo) & ((tau < hi) if hi < 1.0 else (tau <= hi))  # half-open bands, the last closed
        k = keep & rows[:, None]
        a, b = float(wss_m[k].mean()), float(wss_s[k].mean())
        bands[band] = {"model_pa": a, "surface_pa": b, "change": (b - a) / a}
    branches = [o for o in ss.get("outlets") or [] if o.get("role") == "branch"]

    def dp(st: dict) -> float | None:
        return (st.get("inlet_minus_outlet_pressure") or {}).get("Pa")

    return {
        "patient": name,
        "cells": {"model": sm.get("cells"), "surface": ss.get("cells")},
        "converged": {"model": sm.get("converged"), "surface": ss.get("converged")},
        "criterion": {"model": sm.get("criterion_used"), "surface": ss.get("criterion_used")},
        "dp_pa": {"model": dp(sm), "surface": dp(ss)},
        "branches": len(branches),
        "branch_fraction": float(sum(o.get("fraction") or 0.0 for o in branches)),
        "outlet_type": (ss.get("outlets") or [{}])[0].get("type"),
        "mass_balance": (ss.get("outlet_mass_balance") or {}).get("relative"),
        "ostium_fraction": float(fs["ostium"].mean()) if "ostium" in fs else None,
        "wall_points_compared": int(keep.sum()),
        "bands": bands,
    }


def json_cells(r: dict) -> list[str]:
    """One comparison of :func:`pair_row` as a row of :data:`JSON_COLUMNS`."""
    c, d = r["cells"], r["dp_pa"]
    share = f"{100 * r['branch_fraction']:.1f} %" if r["branches"] else "0 %"
    return [
        LABELS.get(r["patient"], r["patient"]),
        f"{c['model']:,} / {c['surface']:,}",
        f"{r['outlet_type']} ({r['branches']}, {share})",
        " / ".join("-" if d[k] is None else f"{d[k]:.0f}" for k in ("model", "surface")),
        *(
            f"{x['model_pa']:.2f} / {x['surface_pa']:.2f} ({100 * x['change']:+.0f} %)"
            for x in (r["bands"][band] for band in BANDS)
        ),
    ]


def table(rows: list[dict]) -> str:
    """Markdown: one row per patient."""
    head = "| patient | cells model / surface | outlets (branches, their share) | dp Pa model / surface |"
    head += "".join(f" WSS {b} Pa model / surface (change) |" for b in BANDS)
    lines = [head, "|" + "---|" * (4 + len(BANDS))]
    for r in rows:
        c, d = r["cells"], r["dp_pa"]
        line = f"| {r['patient']} | {c['model']:,} / {c['surface']:,} | {r['outlet_type']} ({r['branches']}, "
        line += f"{100 * r['branch_fraction']:.1f} %) | "
        line += " / ".join("-" if d[k] is None else f"{d[k]:.0f}" for k in ("model", "surface")) + " |"
        for band in BANDS:
            x = r["bands"][band]
            line += f" {x['model_pa']:.2f} / {x['surface_pa']:.2f} ({100 * x['change']:+.0f} %) |"
        lines.append(line)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", type=Path, help="a results folder (results/patients/<name>_model, <name>_surface)")
    ap.add_argument("--rows-json", type=Path, default=None, help="also write the comparisons as JSON")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    pts = a.results / "patients"
    names = sorted(
        {p.name.rsplit("_", 1)[0] for p in pts.glob("*_model")}
        & {p.name.rsplit("_", 1)[0] for p in pts.glob("*_surface")}
    )
    rows = []
    for n in names:
        m, s = _load(pts / f"{n}_model"), _load(pts / f"{n}_surface")
        if m is None or s is None:
            print(f"{n}: a run is missing or failed (status.json / fields.npz with WSS)", file=sys.stderr)
            continue
        rows.append(pair_row(n, m, s))
    print(f"# {platform.node()} ({os.cpu_count()} cores), {a.results}")
    for r in rows:
        print(
            f"{r['patient']}: converged model {r['converged']['model']} ({r['criterion']['model']}), surface "
            f"{r['converged']['surface']} ({r['criterion']['surface']}); mass balance {r['mass_balance']}; ostium "
            f"{100 * (r['ostium_fraction'] or 0):.1f} % of the wall grid; "
            f"{r['wall_points_compared']} wall points compared"
        )
    print(table(rows))
    if a.rows_json:
        a.rows_json.write_text(json.dumps(rows, indent=2) + "\n")
    save(
        a.json if rows else None,
        measured=f"read from {a.results} after its run (the date and load: the reading's)",
        columns=JSON_COLUMNS,
        rows=[json_cells(r) for r in rows],
    )
    return 0 if rows else 1


if __name__ == "__main__":
    sys.exit(main())
