"""Benchmark: time to resample a finished OpenFOAM case on the VCS grid, next to the solver's time.

    python bench/bench_resample.py CASE_DIR MODEL_JSON [--n-tau 64 --n-theta 32 --n-rho 11]
    python bench/bench_resample.py            # builds and solves the Hagen-Poiseuille tube (needs OpenFOAM)

Prints the read / interpolation / total resampling times, the grid and mesh sizes, the counts of
points outside the CFD mesh, and the solver's wall time from the case's status.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def tube_case(tmp: Path):
    """The tests' straight-tube Hagen-Poiseuille case and its model (tests/vcs/test_resample.py)."""
    sys.path.insert(0, str(ROOT / "tests" / "vcs"))
    from test_resample import AXIS, LENGTH_MM, RADIUS_MM, U_MEAN, straight_model

    from vcs.cfd import render_case, run_case
    from vcs.phantoms.analytic import write_closed_tube_stl

    stl = write_closed_tube_stl(
        tmp / "tube.stl", radius=RADIUS_MM * 1e-3, length=LENGTH_MM * 1e-3, n_theta=96, n_z=60, axis=AXIS
    )
    cfg = {
        "mesh": {"cell_size": 1.25e-3},
        "inlet": {"type": "parabolic", "flow_rate": U_MEAN * np.pi * (RADIUS_MM * 1e-3) ** 2},
        "solver": {"max_iterations": 800, "startup_iterations": 50, "fallback": "none"},
    }
    render_case(tmp / "case", stl, cfg, flavour="esi")
    run_case(tmp / "case", ranks=1)
    return tmp / "case", straight_model()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", nargs="?")
    ap.add_argument("model", nargs="?")
    ap.add_argument("--n-tau", type=int, default=64)
    ap.add_argument("--n-theta", type=int, default=32)
    ap.add_argument("--n-rho", type=int, default=11)
    ap.add_argument("--method", default="mls", choices=("mls", "probe"))
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)

    from vcs.cfd import sample_case
    from vcs.vessel import VesselModel

    with tempfile.TemporaryDirectory() as tmp:
        if a.case:
            case, model = Path(a.case), VesselModel.load(a.model)
        else:
            t0 = time.perf_counter()
            case, model = tube_case(Path(tmp))
            print(f"built and solved the Hagen-Poiseuille tube in {time.perf_counter() - t0:.1f} s")
        times = []
        for _ in range(a.repeat):
            t0 = time.perf_counter()
            f = sample_case(case, model, n_tau=a.n_tau, n_theta=a.n_theta, n_rho=a.n_rho, method=a.method)
            times.append(time.perf_counter() - t0)
        status = json.loads((case / "status.json").read_text()) if (case / "status.json").is_file() else {}
    solver = status.get("timings_s", {}).get("total")
    print(
        f"case: {case}  cells: {int(f['n_cells'])}  "
        f"grid: {a.n_tau} x {a.n_theta} x {a.n_rho} = {int(f['n_points'])} points"
        f"  method: {a.method}"
    )
    print(
        f"resample: best {min(times):.3f} s of {a.repeat} (read {float(f['read_time_s']):.3f} s, "
        f"U/p interpolation {float(f['interpolation_time_s']):.3f} s, total sampling {float(f['sample_time_s']):.3f} s)"
    )
    print(
        f"outside the CFD mesh: {int(f['n_outside_mesh'])} points ({int(f['n_wall_outside_mesh'])} on the wall, "
        f"{int(f['n_interior_nearest'])} interior -> nearest cell)"
    )
    if solver:
        print(
            f"solver (status.json timings_s.total): {solver:.1f} s -> "
            f"resampling is {100 * min(times) / solver:.1f}% of it"
        )
    else:
        print("solver time: not in status.json")
    return 0


if __name__ == "__main__":
    sys.exit(main())
