#!/usr/bin/env python3
"""Check that a code change leaves the numbers alone (refactorings must be bit-identical).

    python scripts/same_results.py fits OUT_DIR         # vcs fit on a fixed corpus -> OUT_DIR/<name>/
    python scripts/same_results.py compare DIR_A DIR_B  # exit 1 unless every result file matches
    python scripts/same_results.py compare --rtol 1e-9 DIR_A DIR_B  # model.json numbers within 1e-9

``fits`` runs ``vcs fit`` (this checkout's code) with default settings on the three CI aorta
phantoms, a tube, a torus and a helix phantom, and on every real mesh of ``../shared/data``
that is present. ``compare`` walks two result trees (e.g. ``results/`` of two CI-cohort runs,
``snakemake --configfile config/ci.yaml`` before and after a change, or two ``fits`` folders)
and compares every ``model.json``, ``fit_report.json`` (timings left out), ``wall.stl`` and
phantom STL byte by byte, and every ``fields.npz`` array by array (dtype, shape and bits; timings ``*_time_s`` left
out; an npz archive also stores its write time, so its bytes differ between runs). With ``--rtol R`` a
``model.json`` or ``fit_report.json`` that differs is compared number by number instead: every number
within R times the largest magnitude of its array (round-off), everything else equal; the largest
relative difference is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data" / "vessels"
PHANTOMS = [("aorta", 0), ("aorta", 1), ("aorta", 2), ("tube", 0), ("torus", 0), ("helix", 0)]
REAL = {
    "simvascular_open": ("simvascular_aorta_segment_open.vtp", []),
    "simvascular_capped": ("simvascular_aorta_segment_capped.vtp", []),
    "vmtk_closed": ("vmtk_aorta_segment_closed.stl", ["--inlet=219.0,290.0,25.0", "--outlet=221.3,146.5,21.7"]),
    "vmtk_bifurcation": ("vmtk_aorta_bifurcation_open.stl", ["--inlet=221,177.8,21.3", "--outlet=210.2,102.9,30.8"]),
    "aortacfd": (
        "aortacfd_patient1/wall_aorta.stl",
        ["--inlet-cap", "aortacfd_patient1/inlet.stl", "--outlet-cap", "aortacfd_patient1/outlet4.stl"],
    ),
    "vmr0154": (
        "sphinxsys_vmr0154_aorta_capped.stl",
        ["--units=cm", "--inlet=-0.911,4.689,3.648", "--outlet=-1.593,-0.865,0.994"],
    ),
    "tah_coarse": (
        "sphinxsys_tah_aorta_capped_coarse.stl",
        ["--units=mm", "--inlet=-23.0,-202.2,-1177.9", "--outlet=6.6,-123.6,-1246.3"],
    ),
}
BYTE_FILES = ("model.json", "wall.stl")
VOLATILE_REPORT_KEYS = ("timings_s", "mesh")  # wall-clock times; the input path


def _vcs(*args: str) -> None:
    """`vcs ARGS` with THIS checkout's package first on the path (cwd and PYTHONPATH = the checkout:
    an editable install elsewhere must not answer instead)."""
    cmd = [sys.executable, "-m", "vcs.cli", *args]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, env=env)
    if r.returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}\n{r.stderr}")


def run_fits(out: Path) -> None:
    """vcs fit of the fixed corpus into ``out``."""
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    probe = subprocess.run(
        [sys.executable, "-c", "import vcs; print(vcs.__file__)"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    print(f"code: {probe.stdout.strip()}")
    for kind, seed in PHANTOMS:
        name = f"{kind}_seed{seed}"
        stl = out / "phantoms" / f"{name}.stl"
        stl.parent.mkdir(exist_ok=True)
        _vcs("phantom", "--kind", kind, "--seed", str(seed), "--resolution", "1.5", "-o", str(stl), "--overwrite")
        _vcs("fit", str(stl), "-o", str(out / name), "--units", "mm")
        print(f"fitted {name}")
    if not SHARED.is_dir():
        print(f"{SHARED} absent: real meshes skipped")
        return
    for name, (mesh, opts) in REAL.items():
        opts = [str(SHARED / o) if o.endswith(".stl") else o for o in opts]
        _vcs("fit", str(SHARED / mesh), "-o", str(out / name), *opts)
        print(f"fitted {name}")


def _strip_volatile(d):
    if isinstance(d, dict):
        return {k: _strip_volatile(v) for k, v in d.items() if k not in VOLATILE_REPORT_KEYS}
    if isinstance(d, list):
        return [_strip_volatile(v) for v in d]
    return d


def _same_npz(a: Path, b: Path) -> str | None:
    with np.load(a, allow_pickle=False) as za, np.load(b, allow_pickle=False) as zb:
        if sorted(za.files) != sorted(zb.files):
            return f"arrays {sorted(za.files)} vs {sorted(zb.files)}"
        for k in za.files:
            if k.endswith("_time_s"):  # wall-clock timings
                continue
            x, y = za[k], zb[k]
            if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
                return f"array '{k}' differs"
    return None


def _numbers(d, path=""):
    """The numbers of a parsed JSON document as {path: list of floats}, its other values as {path: value}."""
    nums: dict[str, list[float]] = {}
    other: dict[str, object] = {}

    def walk(x, p):
        if isinstance(x, dict):
            for k, v in x.items():
                walk(v, f"{p}/{k}")
        elif isinstance(x, list) and x and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in x):
            nums.setdefault(p, []).extend(float(v) for v in x)
        elif isinstance(x, list):
            for v in x:
                walk(v, p + "[]")
        elif isinstance(x, float):
            nums.setdefault(p, []).append(x)
        else:
            other[p] = x

    walk(d, path)
    return nums, other


def _close_json(da, db, rtol: float) -> tuple[str | None, float]:
    """None when two parsed JSON documents hold the same values, their numbers within ``rtol`` of
    the largest magnitude of their array; and the largest relative difference."""
    (na, oa), (nb, ob) = _numbers(da), _numbers(db)
    if oa != ob or na.keys() != nb.keys():
        return "differs beyond its numbers", float("inf")
    worst = 0.0
    for k in na:
        x, y = np.asarray(na[k]), np.asarray(nb[k])
        if x.shape != y.shape:
            return f"'{k}' has {len(x)} vs {len(y)} numbers", float("inf")
        scale = max(float(np.abs(x).max(initial=0.0)), 1e-300)
        worst = max(worst, float(np.abs(x - y).max(initial=0.0)) / scale)
    return (None if worst <= rtol else f"numbers differ by {worst:.2g} (relative) > {rtol:g}"), worst


def compare(a: Path, b: Path, rtol: float | None = None) -> int:
    """Compare the result files of two trees; print one line per file; 0 when all match."""
    names = ("model.json", "fit_report.json", "wall.stl", "fields.npz")
    files = sorted(
        {p.relative_to(t) for t in (a, b) for p in t.rglob("*") if p.name in names or p.parent.name == "phantoms"}
    )
    if not files:
        print(f"no result files under {a}")
        return 1
    bad = close = 0
    for rel in files:
        pa, pb = a / rel, b / rel
        ja = jb = None
        if not pa.exists() or not pb.exists():
            why = "missing in " + ("A" if not pa.exists() else "B")
        elif rel.name == "fields.npz":
            why = _same_npz(pa, pb)
        elif rel.name == "fit_report.json":
            ja, jb = (_strip_volatile(json.loads(p.read_text())) for p in (pa, pb))
            why = None if ja == jb else "differs (timings and input path ignored)"
        else:
            why = None if pa.read_bytes() == pb.read_bytes() else "bytes differ"
            if rel.name == "model.json":
                ja, jb = (json.loads(p.read_text()) for p in (pa, pb))
        if why and rtol is not None and ja is not None:
            why, worst = _close_json(ja, jb, rtol)
            if why is None:
                close += 1
                print(f"CLOSE {rel}: numbers within {worst:.2g} (relative)")
                continue
        bad += why is not None
        print(f"{'SAME' if why is None else 'DIFF'}  {rel}" + (f": {why}" if why else ""))
    print(
        f"{len(files) - bad - close} of {len(files)} result files identical"
        + (f", {close} within --rtol" if rtol else "")
    )
    return 1 if bad else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    sub = p.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fits", help="fit the fixed corpus into OUT")
    f.add_argument("out", type=Path)
    c = sub.add_parser("compare", help="compare two result trees")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    c.add_argument("--rtol", type=float, help="model.json: numbers within RTOL of their array's largest magnitude")
    args = p.parse_args()
    if args.cmd == "fits":
        run_fits(args.out)
        return 0
    return compare(args.a, args.b, args.rtol)


if __name__ == "__main__":
    sys.exit(main())
