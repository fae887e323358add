#!/usr/bin/env python
"""Benchmark the OpenFOAM pipeline (vcs.cfd) on STL files.

    python bench/bench_cfd.py vessel1.stl vessel2.stl [--ranks 2] [--cell-size 1e-3]
                              [--inlet jet|uniform|parabolic] [--max-iterations 2000] [--set solver.relax_U=0.7]
    python bench/bench_cfd.py --demo-tube      # synthetic 20 mm x 0.2 m tube (jet inlet, paper defaults)

Prints one row per STL: cells, snappyHexMesh time, SIMPLE iterations, solver time (simpleFoam and
the transient fallback's pimpleFoam), converged (+ reason); for a transient fallback also its time
steps, window and half-window differences.
Cases are kept in --workdir (default: a temporary directory) with their status.json and logs/.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import yaml

from vcs.cfd import render_case, run_case


def _set(cfg: dict, dotted: str) -> None:
    key, _, raw = dotted.partition("=")
    *path, last = key.split(".")
    d = cfg
    for p in path:
        d = d.setdefault(p, {})
    d[last] = yaml.safe_load(raw)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stl", nargs="*", type=Path)
    ap.add_argument("--demo-tube", action="store_true", help="add a synthetic straight tube (R 10 mm, L 0.2 m)")
    ap.add_argument("--ranks", type=int, default=1)
    ap.add_argument("--cell-size", type=float)
    ap.add_argument("--inlet", choices=["jet", "uniform", "parabolic"])
    ap.add_argument("--max-iterations", type=int)
    ap.add_argument("--flavour", choices=["esi", "org10"])
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="any DEFAULTS entry, e.g. solver.startup_iterations=200",
    )
    ap.add_argument("--workdir", type=Path)
    ap.add_argument("--json", type=Path, help="also write all status dicts to this file")
    a = ap.parse_args(argv)

    cfg: dict = {}
    if a.cell_size:
        _set(cfg, f"mesh.cell_size={a.cell_size}")
    if a.inlet:
        _set(cfg, f"inlet.type={a.inlet}")
    if a.max_iterations:
        _set(cfg, f"solver.max_iterations={a.max_iterations}")
    for s in a.set:
        _set(cfg, s)
    work = a.workdir or Path(tempfile.mkdtemp(prefix="bench_cfd_"))
    work.mkdir(parents=True, exist_ok=True)
    stls = list(a.stl)
    if a.demo_tube:
        from vcs.phantoms.analytic import write_closed_tube_stl

        stls.append(
            write_closed_tube_stl(work / "demo_tube.stl", radius=0.01, length=0.2, n_z=100, axis=(0.03, 0.02, 1.0))
        )
    if not stls:
        ap.error("give STL files or --demo-tube")

    hdr = (
        f"{'case':<24} {'cells':>9} {'snappy_s':>9} {'iters':>6} {'solver_s':>9} {'ranks':>5} {'converged':>9}  reason"
    )
    print(f"# workdir {work}", flush=True)
    print(hdr)
    print("-" * len(hdr), flush=True)
    out = []
    for stl in stls:
        case = work / Path(stl).stem
        render_case(case, stl, cfg, flavour=a.flavour)
        st = run_case(case, ranks=a.ranks)
        t = st.get("timings_s", {})
        solver_s = sum(v for k, v in t.items() if k.startswith(("simpleFoam", "pimpleFoam")))
        cells = st.get("cells")
        print(
            f"{Path(stl).stem[:24]:<24} {cells if cells is not None else '-':>9} {t.get('snappyHexMesh', 0):>9.1f} "
            f"{st.get('iterations', 0):>6} {solver_s:>9.1f} {st.get('ranks', a.ranks):>5} "
            f"{str(st.get('converged')):>9}  {st.get('reason') or ''}",
            flush=True,
        )
        tr = st.get("transient")
        if tr and tr.get("evaluated"):  # the transient fallback ran: its window and verdict
            d = tr["relative_errors"]
            print(
                f"{'':<24} transient: {sum(tr['time_steps'].values())} steps (Co max {tr['courant_max']:.3g}), "
                f"window {tr['window_s']:.4g} s = {tr['window_flow_throughs']:.3g} flow-throughs after "
                f"{tr['washout_s']:.3g} s wash-out; {100 * tr['confidence']:g} % half-widths "
                f"dp {100 * d['inlet_minus_outlet_pressure']:.2g} %, "
                f"TAWSS {100 * d['tawss_mean']:.2g} %, U {100 * d.get('U', float('nan')):.2g} %; "
                f"stationary {tr['stationary']}",
                flush=True,
            )
        out.append(st)
    if a.json:
        a.json.write_text(json.dumps(out, indent=2, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
