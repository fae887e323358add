#!/usr/bin/env python3
"""Winding repair: vcs.mesh.consistent_winding vs trimesh.repair.fix_winding on a real aorta.

    .venv/bin/python bench/bench_winding.py [MESH]

30 % of the triangles of the mesh (default: the AortaCFD thoracic aorta of ../shared/data) are
flipped at random (seed 0); both repair it; prints the best of 3 times and checks that both
give a consistently wound mesh. Why the project keeps its own repair (README, dependencies).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import trimesh

from vcs.io import read_surface
from vcs.mesh import consistent_winding

DEFAULT = Path(__file__).resolve().parents[2] / "shared" / "data" / "vessels" / "aortacfd_patient1" / "wall_aorta.stl"


def best_of(fn, n: int = 3) -> float:
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> int:
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT
    if not path.is_file():
        print(f"{path} not found; give a mesh: bench_winding.py MESH", file=sys.stderr)
        return 2
    surf = read_surface(path)
    V, F = surf.vertices, surf.faces.copy()
    flip = np.random.default_rng(0).random(len(F)) < 0.3
    F[flip] = F[flip][:, ::-1]
    own = best_of(lambda: consistent_winding(V, F))
    meshes = []
    tri = best_of(lambda: (meshes.append(m := trimesh.Trimesh(V, F, process=False)), trimesh.repair.fix_winding(m)))
    ok_own = trimesh.Trimesh(V, consistent_winding(V, F)[0], process=False).is_winding_consistent
    print(f"{path.name}: {len(F)} triangles, 30 % flipped")
    print(f"vcs.mesh.consistent_winding     {own:.3f} s  (consistent: {ok_own})")
    print(f"trimesh.repair.fix_winding      {tri:.3f} s  (consistent: {meshes[-1].is_winding_consistent})")
    print(f"ratio {tri / own:.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
