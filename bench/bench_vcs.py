"""Benchmark: VCS build time (centerline + frame) and its lumen path search, wall fit time, whole `vcs fit`,
to_vcs throughput.

Prints a Markdown table; run with `.venv/bin/python bench/bench_vcs.py`. Meshes from
../shared/data are used when present; an aorta phantom is always used. Each figure is given as
wall-clock time / CPU time of this process (`time.process_time`): on a machine shared with other
jobs the wall time grows with the load, the CPU time does not (set OPENBLAS_NUM_THREADS=1 so that
CPU time is not spread over BLAS threads).
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from vcs.ends import find_ends
from vcs.io import Surface, read_surface
from vcs.model import VesselCoordinateSystem
from vcs.vessel import fit_vessel
from vcs.wall import fit_wall

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "vessels"


def best_of(fn, n=3):
    """(best wall time s, best CPU time s), the last result, all results."""
    times, cpus, outs = [], [], []
    for _ in range(n):
        t0, c0 = time.perf_counter(), time.process_time()
        outs.append(fn())
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return (min(times), min(cpus)), outs[-1], outs


def fmt(t: tuple[float, float], digits: int = 2) -> str:
    """``wall / cpu`` seconds."""
    return f"{t[0]:.{digits}f} / {t[1]:.{digits}f}"


def cases():
    if DATA.is_dir():
        d = DATA / "aortacfd_patient1"
        yield (
            "AortaCFD thoracic aorta",
            read_surface(d / "wall_aorta.stl"),
            {"inlet_cap": d / "inlet.stl", "outlet_cap": d / "outlet4.stl"},
        )
        yield "SimVascular segment", read_surface(DATA / "simvascular_aorta_segment_open.vtp"), {}
    try:
        from vcs.phantoms import make_phantom

        ph = make_phantom("aorta", seed=0, resolution=1.0)
        yield "aorta phantom (seed 0)", Surface(ph.vertices, ph.faces, {}, "mm", "given", "phantom"), {}
    except ImportError:
        pass


def machine() -> str:
    """CPU model, cores, memory and load, for the figures' context."""
    import os

    cpu = next(
        (ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), platform.machine()
    )
    mem = next((int(ln.split()[1]) // 1024**2 for ln in open("/proc/meminfo") if ln.startswith("MemTotal")), 0)
    return f"{cpu}, {os.cpu_count()} cores, {mem} GB, load {os.getloadavg()[0]:.1f}, Python {platform.python_version()}"


def main():
    print(f"machine: {machine()}; best of 3; times are wall / CPU seconds")
    print(
        "| mesh | triangles | L | VCS build (centerline+frame) s | of which lumen path search s (wall) "
        "| wall fit K=19 R=15 s | whole `vcs fit` s |"
    )
    print("|---|---|---|---|---|---|---|")
    last = None
    for name, surf, opts in cases():
        caps = {}
        for k in ("inlet_cap", "outlet_cap"):
            if k in opts:
                c = read_surface(opts[k], surf.units)
                caps[k] = (c.vertices, c.faces)
        ends = find_ends(surf.vertices, surf.faces, surf.cell_data, **caps)
        t_vcs, vcs, builds = best_of(lambda: VesselCoordinateSystem.from_surface(surf.vertices, surf.faces, ends))
        t_path = min(b.report["timings_s"]["astar"] for b in builds)  # the "astar" key times the path search
        wf = surf.faces[ends.wall_mask]
        t_wall, *_ = best_of(lambda: fit_wall(vcs, surf.vertices, wf))
        path = Path(surf.path)
        if path.is_file():
            t_all, *_ = best_of(lambda: fit_vessel(path, **{k: str(v) for k, v in opts.items()}), 1)
        else:
            t_all, *_ = best_of(lambda: fit_vessel(surf), 1)
        print(
            f"| {name} | {len(surf.faces)} | {vcs.report['L']} | {fmt(t_vcs)} | {t_path:.3f} | {fmt(t_wall, 3)} "
            f"| {fmt(t_all)} |"
        )
        last = vcs
    rng = np.random.default_rng(0)
    c = last.curve(rng.uniform(0, 1, 10**6))
    pts = c + rng.normal(0, 5.0, c.shape)
    t, *_ = best_of(lambda: last.to_vcs(pts))
    print(f"\nto_vcs on 10^6 points: {fmt(t)} s = {1e6 / t[0]:,.0f} points/s (wall), {1e6 / t[1]:,.0f} (CPU)")


if __name__ == "__main__":
    main()
