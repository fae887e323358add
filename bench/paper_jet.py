#!/usr/bin/env python3
"""The paper's jet on one demo aorta, stage by stage: demo aorta seed 3 through the workflow with
config/config.yaml + config/paper.yaml (the jet inlet, steady SIMPLE then the transient time
average) at a fixed 2 mm cell (the sheet's ``cell_size_mm``), serial, then what each stage cost
and gave, from its status.json and the solvers' logs (CPU seconds: their ExecutionTime).

    .venv/bin/python bench/paper_jet.py [-d DIR] [--cores 2] [--cell-mm 2.0] [--json PATH]

DIR (default: a temporary folder) is the Snakemake working directory; a finished DIR is only
re-read. Rows: the mesh (cells, the jet refinement, prism layers, snappyHexMesh), SIMPLE, the
flow-through time, the wash-out, the averaging window (ended when its means are known to the
tolerances, ``cfd.solver.transient``), the 95 % half-widths of the window means, the verdict and
the window means. ``--json PATH`` also writes the table in the docs' format
(docs/data/bench/paper_jet.json). Needs OpenFOAM; ~1-3 CPU hours.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

from _table import emit, sig  # bench/ is on sys.path when this runs as a script
from jet_atlas import execution_time
from real_cohort import run_workflow, write_rows

PID = "demo_aorta_3"
CONFIGS = ("config.yaml", "paper.yaml")
#: the table's columns (as printed and in the docs JSON)
COLUMNS = ["stage", "figures"]
WORDS = {
    "inlet_minus_outlet_pressure": "inlet - outlet pressure",
    "tawss_mean": "area-mean TAWSS",
    "U": "U (volume L2)",
}


def stage_cpu(case: Path) -> dict[str, float]:
    """CPU seconds of SIMPLE, the wash-out and the averaging window (their logs in case/logs)."""
    logs = case / "logs"
    return {
        "simple": execution_time(sorted(logs.glob("log.simpleFoam*"))),
        "washout": execution_time(sorted(logs.glob("log.pimpleFoam.washout*"))),
        "average": execution_time(sorted(logs.glob("log.pimpleFoam.average*"))),
    }


def rows(st: dict, cpu: dict[str, float]) -> list[list[str]]:
    """The stage / figures rows of one patient's status.json and :func:`stage_cpu`."""
    m, tr = st.get("mesh") or {}, st.get("transient") or {}
    jet, layers = m.get("jet_refinement") or {}, m.get("layers") or {}
    t = st.get("timings_s") or {}
    out = [
        [
            "mesh",
            f"{st.get('cells') or 0:,} cells ({jet.get('cells_across', float('nan')):.1f} cells across the jet); "
            f"{layers.get('requested', 0)} prism layers: mean {layers.get('mean_layers', 0):.2f}, coverage "
            f"{layers.get('coverage', 0):.2f}; snappyHexMesh {t.get('snappyHexMesh', 0):.1f} s",
        ],
    ]
    simple = f"{st.get('iterations', 0):,} iterations, {cpu['simple']:.0f} s CPU"
    if not tr:  # no transient fallback: SIMPLE's verdict is the result
        verdict = f"`{st.get('criterion_used')}`" if st.get("converged") else f"not converged: {st.get('reason')}"
        return out + [["SIMPLE", f"{simple}; {verdict}"]]
    fr = st.get("final_residuals") or {}
    last = ", ".join(f"{k} {v:.2g}" for k, v in fr.items() if isinstance(v, (int, float)))
    out.append(["SIMPLE", f"{simple}; not converged (last initial residuals {last})"])
    t_ft = tr.get("flow_through_time_s")
    vol, q = st.get("lumen_volume_m3"), (st.get("inflow") or {}).get("flow_rate_m3_s")
    if vol and q:
        out.append(["flow-through time", f"lumen {vol * 1e6:.1f} cm3 / {sig(q)} m3/s = {t_ft:.3g} s"])
    steps = tr.get("time_steps") or {}
    washout_steps = int(steps.get("washout", 0))
    average_steps = sum(steps.values()) - washout_steps
    out.append(
        [
            "wash-out",
            f"{tr.get('washout_s', 0):.3g} s ({tr.get('washout_flow_throughs', 0):.2g} flow-throughs), "
            f"{washout_steps:,} time steps, {cpu['washout']:.0f} s CPU",
        ]
    )
    dt = tr.get("delta_t_s") or {}
    total = sum(cpu.values())
    if "window_s" in tr:
        out.append(
            [
                "averaging window (ended when its means are known)",
                f"{tr['window_s']:.4g} s ({tr['window_flow_throughs']:.3g} flow-throughs), {average_steps:,} time "
                f"steps of {1e3 * (dt.get('min') or 0):.2g}-{1e3 * (dt.get('max') or 0):.2g} ms (Courant number "
                f"max {tr.get('courant_max') or 0:.3g}), {cpu['average']:.0f} s CPU; total {total:,.0f} s CPU = "
                f"{total / 3600:.2g} CPU hours",
            ]
        )
        rel, tol = tr.get("relative_errors") or {}, tr.get("tolerances") or {}
        conf = 100 * float(tr.get("confidence") or 0.95)
        out.append(
            [
                f"{conf:g} % half-widths of the window means",
                "; ".join(
                    f"{WORDS.get(k, k)} {100 * v:.2g} %" + (f" (tolerance {100 * tol[k]:g} %)" if k in tol else "")
                    for k, v in rel.items()
                ),
            ]
        )
    verdict = f"`converged: {str(bool(st.get('converged'))).lower()}`"
    verdict += f" (`{st.get('criterion_used')}`)" if st.get("converged") else f', "{st.get("reason")}"'
    out.append(["verdict", verdict])
    dp = (st.get("inlet_minus_outlet_pressure") or {}).get("Pa")
    wss, tawss, osi = st.get("wall_shear_stress_Pa") or {}, st.get("tawss_Pa") or {}, st.get("osi") or {}
    means = [f"mass imbalance {sig(st.get('mass_imbalance') or 0)}"]
    if dp is not None:
        means.append(f"inlet - outlet pressure {dp:.1f} Pa")
    if "mean" in wss:
        means.append(f"magnitude of the mean WSS {wss['mean']:.3g} Pa (max {wss['max']:.3g})")
    if "mean" in tawss:
        means.append(f"TAWSS {tawss['mean']:.3g} Pa (max {tawss['max']:.3g})")
    if "mean" in osi:
        means.append(f"OSI mean {osi['mean']:.2g} (max {osi['max']:.2g})")
    out.append(["window means", "; ".join(means)])
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-d", "--workdir", type=Path, help="Snakemake working directory (default: temporary)")
    ap.add_argument("--cores", type=int, default=2, help="cores for Snakemake (default 2)")
    ap.add_argument("--cell-mm", type=float, default=2.0, help="the lumen cell size, mm (default 2.0)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        wd = (a.workdir or Path(tmp)).resolve()
        wd.mkdir(parents=True, exist_ok=True)
        row = {"id": PID, "mesh": "results/demo/aorta_seed3.stl", "units": "mm", "cell_size_mm": f"{a.cell_mm:g}"}
        write_rows(wd / "patients.tsv", [row])
        target = f"results/patients/{PID}/status.json"
        title = f"paper's jet, {' + '.join(CONFIGS)}"
        r = run_workflow(wd, list(CONFIGS), "patients.tsv", a.cores, title, targets=[target])
        if not (wd / target).exists():
            print(f"paper_jet: error: no {target} (see the lines above)", file=sys.stderr)
            return 1
        st = json.loads((wd / target).read_text())
        emit(
            COLUMNS,
            rows(st, stage_cpu(wd / "results" / "patients" / PID / "case")),
            a.json,
            f"one run, config/{' + config/'.join(CONFIGS)}, demo aorta seed 3 at {a.cell_mm:g} mm cells, serial",
        )
    return 0 if r.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
