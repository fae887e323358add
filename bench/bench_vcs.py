"""Benchmark: VCS build time (centerline + frame) and its lumen path search, wall fit time, whole `vcs fit`,
to_vcs throughput; and the `vcs fit` command itself on every shared real mesh: wall time, CPU time,
peak memory and its stages.

Prints Markdown tables; run with `.venv/bin/python bench/bench_vcs.py` (``--fit-only``: only the
command's table; ``--repeat N``: runs per mesh, default 3; ``--json PATH``: also write the first
table in the docs' format, e.g. docs/data/bench/bench_vcs.json). Meshes from ../shared/data are used when
present; an aorta phantom is always used. Each figure is given as wall-clock time / CPU time of this
process (`time.process_time`): on a machine shared with other jobs the wall time grows with the load,
the CPU time does not (set OPENBLAS_NUM_THREADS=1 so that CPU time is not spread over BLAS threads).

The command's table runs `vcs fit` as its own process, as a user does (interpreter start-up and
imports included), and reads the child's resource usage (``os.wait4``): wall time (median of the
runs, and the fastest), CPU time (user + system, median) and peak resident memory (largest of the
runs), then the stages from its fit_report.json ``timings_s`` (median). The load average is printed
before and after: with other jobs on the machine the wall time grows, the CPU time hardly does.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _table import save  # bench/ is on sys.path when this runs as a script

from vcs.ends import find_ends
from vcs.io import Surface, read_surface
from vcs.model import VesselCoordinateSystem
from vcs.vessel import fit_vessel
from vcs.wall import fit_wall

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "vessels"

#: `vcs fit` options of every shared real mesh (as in tests/vcs/test_real_vessels.py); cap files relative to DATA
FIT_CASES = {
    "aortacfd_patient1": (
        "aortacfd_patient1/wall_aorta.stl",
        [
            "--units",
            "mm",
            "--inlet-cap",
            "aortacfd_patient1/inlet.stl",
            "--outlet-cap",
            "aortacfd_patient1/outlet4.stl",
        ],
    ),
    "simvascular_open": ("simvascular_aorta_segment_open.vtp", []),
    "simvascular_capped": ("simvascular_aorta_segment_capped.vtp", []),
    "vmtk_closed": ("vmtk_aorta_segment_closed.stl", ["--inlet=219.0,290.0,25.0", "--outlet=221.3,146.5,21.7"]),
    "vmtk_bifurcation": ("vmtk_aorta_bifurcation_open.stl", ["--inlet=221,177.8,21.3", "--outlet=210.2,102.9,30.8"]),
    "vmr0154": (
        "sphinxsys_vmr0154_aorta_capped.stl",
        ["--units=cm", "--inlet=-0.911,4.689,3.648", "--outlet=-1.593,-0.865,0.994"],
    ),
    "tah_coarse": (
        "sphinxsys_tah_aorta_capped_coarse.stl",
        ["--units=mm", "--inlet=-23.0,-202.2,-1177.9", "--outlet=6.6,-123.6,-1246.3"],
    ),
}
STAGES = ("startup", "read_and_ends", "vcs_build", "wall_fit", "self_intersection", "outputs", "command")


def vcs_fit_command(mesh: Path, opts: list[str], out: Path) -> tuple[float, float, float, dict]:
    """Run `vcs fit MESH -o OUT OPTS` as a child process (the venv's ``vcs`` beside this Python).

    Returns
    -------
    wall : float, s
    cpu : float, s
        User + system time of the child.
    peak_mb : float, MB
        Its peak resident memory (``ru_maxrss``).
    timings : dict
        ``timings_s`` of its fit_report.json.
    """
    exe = Path(sys.executable).with_name("vcs")
    cmd = [str(exe) if exe.exists() else sys.executable, *([] if exe.exists() else ["-m", "vcs.cli"])]
    cmd += ["fit", str(mesh), "-o", str(out), *opts]
    # started by a small launcher, not by this process: Linux keeps a child's peak memory from its
    # parent's at fork across exec, so a child of this bench (~550 MB after the in-process
    # benchmarks) would report at least that much
    launched = subprocess.run([sys.executable, "-S", "-c", _LAUNCH, *cmd], capture_output=True, text=True, check=True)
    r = json.loads(launched.stdout)
    if r["returncode"] != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({r['returncode']}): {r['stderr']}")
    timings = json.loads((out / "fit_report.json").read_text())["timings_s"]
    return r["wall"], r["cpu"], r["peak_kb"] / 1024.0, timings  # ru_maxrss: kilobytes on Linux


#: runs argv[1:], waits for it (os.wait4) and prints its wall time, CPU time, peak memory and exit
_LAUNCH = """
import json, os, subprocess, sys, time
t0 = time.perf_counter()
p = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
err = p.stderr.read().decode()
_, status, u = os.wait4(p.pid, 0)
wall = time.perf_counter() - t0
print(json.dumps({"wall": wall, "cpu": u.ru_utime + u.ru_stime, "peak_kb": u.ru_maxrss,
                  "returncode": os.waitstatus_to_exitcode(status), "stderr": err}))
"""


def fit_command_table(repeat: int = 3) -> None:
    """Markdown table of `vcs fit` (its own process) on every shared real mesh: wall, CPU, peak memory, stages."""
    if not DATA.is_dir():
        print(f"{DATA} absent: no real meshes for the `vcs fit` table")
        return
    cache = (
        "off (PYTHONDONTWRITEBYTECODE: vcs's modules compiled at every start)"
        if os.environ.get("PYTHONDONTWRITEBYTECODE")
        else "on"
    )
    print(f"\n`vcs fit` as a command, {repeat} runs per mesh; bytecode cache {cache}; load before: {load()}")
    print("| mesh | triangles | wall s (median / fastest) | CPU s | peak MB | " + " | ".join(STAGES) + " |")
    print("|---|---|---|---|---|" + "---|" * len(STAGES))
    tmp = Path(tempfile.mkdtemp(prefix="bench_vcs_fit_"))
    try:
        for name, (mesh, opts) in FIT_CASES.items():
            opts = [str(DATA / o) if o.endswith(".stl") and not o.startswith("-") else o for o in opts]
            runs = [vcs_fit_command(DATA / mesh, opts, tmp / name) for _ in range(repeat)]
            n_tri = json.loads((tmp / name / "fit_report.json").read_text())["n_triangles"]
            walls = sorted(r[0] for r in runs)
            stages = [float(np.median([r[3].get(k) or np.nan for r in runs])) for k in STAGES]
            print(
                f"| {name} | {n_tri} | {np.median(walls):.2f} / {walls[0]:.2f} | {np.median([r[1] for r in runs]):.2f} "
                f"| {max(r[2] for r in runs):.0f} | " + " | ".join(f"{v:.2f}" for v in stages) + " |"
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"load after: {load()}")


def load() -> str:
    """The 1, 5 and 15 minute load averages and the number of cores."""
    one, five, fifteen = os.getloadavg()
    return f"{one:.2f}, {five:.2f}, {fifteen:.2f} on {os.cpu_count()} cores"


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
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument("--fit-only", action="store_true", help="only the `vcs fit` command's table")
    p.add_argument("--repeat", type=int, default=3, help="runs of `vcs fit` per mesh (default 3)")
    p.add_argument("--json", type=Path, metavar="PATH", help="also write the library table as docs JSON")
    args = p.parse_args()
    if args.json and args.fit_only:
        p.error("--json writes the library table, which --fit-only leaves out")
    print(f"machine: {machine()}; {time.strftime('%Y-%m-%d %H:%M %Z')}")
    if not args.fit_only:
        load_before = os.getloadavg()[0]
        rows, note = library_table()
        save(
            args.json,
            measured=f"load {load_before:.1f} at the start; best of 3, wall / CPU seconds",
            columns=LIBRARY_COLUMNS,
            rows=rows,
            notes=[note],
        )
    fit_command_table(args.repeat)


#: the library table's columns (as printed and in the docs JSON)
LIBRARY_COLUMNS = [
    "mesh",
    "triangles",
    "L",
    "VCS build (centerline + frame) s",
    "of which lumen path search s (wall)",
    "wall fit K=19 R=15 s",
    "whole `vcs fit` s",
]


def library_table() -> tuple[list[list[str]], str]:
    """Print the library table (and the to_vcs throughput); return its rows and the throughput line."""
    print("best of 3; times are wall / CPU seconds")
    print("| " + " | ".join(LIBRARY_COLUMNS) + " |")
    print("|---|---|---|---|---|---|---|")
    last = None
    rows = []
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
        rows.append([name, f"{len(surf.faces):,}", str(vcs.report["L"]), fmt(t_vcs), f"{t_path:.3f}"])
        rows[-1] += [fmt(t_wall, 3), fmt(t_all)]
        print("| " + " | ".join(rows[-1]) + " |")
        last = vcs
    rng = np.random.default_rng(0)
    c = last.curve(rng.uniform(0, 1, 10**6))
    pts = c + rng.normal(0, 5.0, c.shape)
    t, *_ = best_of(lambda: last.to_vcs(pts))
    note = f"`to_vcs` on 10^6 points: {fmt(t)} s = {1e6 / t[0]:,.0f} points/s (wall), {1e6 / t[1]:,.0f} (CPU)"
    print(f"\n{note.replace('`', '')}")
    return rows, note


if __name__ == "__main__":
    main()
