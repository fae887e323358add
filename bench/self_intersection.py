"""Benchmark: the self-intersection test that every `vcs fit` runs (vcs.mesh.self_intersections).

Prints a Markdown table (triangles, crossing triangles found, best-of-5 wall / CPU seconds, peak
extra memory of the test by tracemalloc: numpy's and scipy's allocations, what the test adds to a
fit) on every shared real mesh (../shared/data, when present) and an aorta phantom; then the
machine and load. Run with `OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/self_intersection.py`.
"""

from __future__ import annotations

import os
import platform
import time
import tracemalloc
from datetime import date
from pathlib import Path

from vcs.io import Surface, read_surface
from vcs.mesh import self_intersections
from vcs.phantoms import make_phantom

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "vessels"
MESHES = {
    "AortaCFD thoracic aorta": ("aortacfd_patient1/wall_aorta.stl", "mm"),
    "vmtk closed segment": ("vmtk_aorta_segment_closed.stl", "mm"),
    "vmtk bifurcation": ("vmtk_aorta_bifurcation_open.stl", "mm"),
    "SPHinXsys VMR 0154": ("sphinxsys_vmr0154_aorta_capped.stl", "cm"),
    "SimVascular segment": ("simvascular_aorta_segment_open.vtp", "cm"),
    "SPHinXsys TAH, coarse": ("sphinxsys_tah_aorta_capped_coarse.stl", "mm"),
}


def measure(surf: Surface) -> tuple[int, float, float, float]:
    """(crossing triangles, best wall s, best CPU s, peak extra MB) of 5 runs."""
    walls, cpus = [], []
    for _ in range(5):
        t0, c0 = time.perf_counter(), time.process_time()
        found = self_intersections(surf.vertices, surf.faces)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    tracemalloc.start()
    self_intersections(surf.vertices, surf.faces)
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    return len(found), min(walls), min(cpus), peak


def main() -> None:
    surfaces = []
    for name, (rel, units) in MESHES.items():
        if (DATA / rel).exists():
            surfaces.append((name, read_surface(DATA / rel, units)))
    ph = make_phantom("aorta", seed=0, resolution=1.0)
    surfaces.append(("aorta phantom (seed 0, 1 mm)", Surface(ph.vertices, ph.faces, {}, "mm", "given", "phantom")))
    print("| mesh | triangles | crossing triangles | wall / CPU s | peak extra MB |")
    print("|---|---|---|---|---|")
    for name, surf in surfaces:
        n, wall, cpu, peak = measure(surf)
        print(f"| {name} | {len(surf.faces):,} | {n} | {wall:.3f} / {cpu:.3f} | {peak:.0f} |")
    print(
        f"\n{date.today()}, {platform.node()} ({os.cpu_count()} cores, {platform.processor() or platform.machine()}), "
        f"load {os.getloadavg()[0]:.1f}"
    )


if __name__ == "__main__":
    main()
