"""The README's per-mesh table of default fits (`vcs fit` defaults: --L auto, K = 19, R = 15).

For every shared real mesh (the ends of tests/vcs/test_real_vessels.py), the eight demo aorta
phantoms and the synthetic long vessels of tests/vcs/test_fit_quality.py (the same inputs the
tests check), one `fit_vessel` each: L chosen, residual mean / p75 / max, % of the wall points
between the end planes used, % of the vessel's points used (without side branches and points
not star-convex), arc-length speed deviation, quality, and the time of the whole fit (reading
the mesh to the wall model) as wall-clock / CPU seconds (`time.process_time`; on a machine
shared with other jobs the wall time grows with the load, the CPU time does not). All rows come
from one run; the header says when and where.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/fit_table.py [--only NAME ...] [--json PATH]

``--json PATH`` also writes the table in the docs' format (docs/data/bench/fit_table.json).
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import sys
import tempfile
import time
from datetime import date
from pathlib import Path

from _table import save  # bench/ is on sys.path when this runs as a script

from vcs.io import Surface
from vcs.mesh import write_stl_binary
from vcs.phantoms import make_phantom
from vcs.vessel import fit_vessel

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "vessels"

#: row names of the shared real meshes (tests/vcs/test_real_vessels.py's case names)
LABELS = {
    "simvascular_open": "SimVascular open",
    "simvascular_capped": "SimVascular capped",
    "vmtk_closed": "vmtk closed segment",
    "vmtk_bifurcation": "vmtk bifurcation (inlet -> one iliac)",
    "aortacfd": "AortaCFD thoracic (3 branches)",
    "vmr0154": "SPHinXsys VMR 0154 (4 stubs)",
    "tah_coarse": "SPHinXsys TAH coarse",
}
COLUMNS = [
    "mesh",
    "units",
    "L chosen",
    "residual mean / p75 / max mm",
    "used",
    "of vessel",
    "speed deviation",
    "quality",
    "whole fit s (wall / CPU)",
]


def _load(name: str):
    """A test module of tests/vcs by file name (its case tables and vessel builders)."""
    path = REPO / "tests" / "vcs" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def cases(tmp: Path):
    """(name, mesh or path, fit options) of every row."""
    if DATA.is_dir():
        real = _load("test_real_vessels")
        for name, (mesh, opts) in real.CASES.items():
            opts = {k: (str(DATA / v) if k.endswith("cap") else v) for k, v in opts.items()}
            yield LABELS.get(name, name), DATA / mesh, opts
    for seed in range(8):
        ph = make_phantom("aorta", seed=seed)
        yield f"aorta phantom {seed}", Surface(ph.vertices, ph.faces, {}, "mm", "given", "phantom"), {}
    fq = _load("test_fit_quality")
    yield "tortuous phantom 434 mm", fq.tortuous_vessel(), {}
    for seed, length, unit in ((3, 450.0, "mm"), (4, 400.0, "cm")):
        V, F, _ = fq.long_aorta(seed, length)
        path = tmp / f"long_aorta_{seed}.stl"
        write_stl_binary(path, V / {"mm": 1.0, "cm": 10.0}[unit], F)
        yield f"long bumpy aorta {length:.0f} mm, file in {unit}", path, {}
    V, F, _ = fq.segmented_aorta(0, 420.0)
    path = tmp / "segmented_aorta.stl"
    write_stl_binary(path, V / 10.0, F)
    yield "marching-cubes aorta 420 mm, 3 branches, file in cm", path, {}


def machine() -> str:
    """CPU model, cores, memory, load and Python version."""
    cpu = next(
        (ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), platform.machine()
    )
    mem = next((int(ln.split()[1]) // 1024**2 for ln in open("/proc/meminfo") if ln.startswith("MemTotal")), 0)
    return f"{cpu}, {os.cpu_count()} cores, {mem} GB, Python {platform.python_version()}"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="rows whose name contains one of these")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    args = ap.parse_args(argv)
    print(f"{date.today().isoformat()}, {machine()}, load at start {os.getloadavg()[0]:.1f}")
    print("| " + " | ".join(COLUMNS) + " |")
    print("|---|---|---|---|---|---|---|---|---|")
    loads, rows = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name, mesh, opts in cases(Path(tmp)):
            if args.only and not any(k in name for k in args.only):
                continue
            t0, c0 = time.perf_counter(), time.process_time()
            _, r, _ = fit_vessel(mesh, **opts)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            loads.append(os.getloadavg()[0])
            quality = r["quality"] if r["quality"] == "ok" else f"poor ({'; '.join(r['quality_reasons'])})"
            rows.append(
                [
                    name,
                    r["units"],
                    str(r["L"]),
                    f"{r['residual_mean_mm']:.4f} / {r['residual_p75_mm']:.4f} / {r['residual_max_mm']:.3f}",
                    f"{100 * r['fraction_points_used']:.1f} %",
                    f"{100 * r['fraction_points_used_of_vessel']:.1f} %",
                    f"{r['arc_length_speed_deviation']:.4f}",
                    quality,
                    f"{wall:.1f} / {cpu:.1f}",
                ]
            )
            print("| " + " | ".join(rows[-1]) + " |", flush=True)
    print(f"\nload (1 min average) during the run: {min(loads):.1f}-{max(loads):.1f}" if loads else "")
    sys.stdout.flush()
    if loads:  # a row was measured
        save(
            args.json,
            measured=f"load {min(loads):.1f}-{max(loads):.1f} during the run (1 min average); one run",
            columns=COLUMNS,
            rows=rows,
        )


if __name__ == "__main__":
    main()
