#!/usr/bin/env python3
"""Issue 23, item 2: why SIMPLE stalls on real meshes, and what a mesh setting changes.

    .venv/bin/python bench/simple_stall.py DIR [--patients a,b] [--variant NAME:key=value,...]...

DIR is a finished workflow directory (``bench/real_cohort.py -d DIR`` or any run with fits and
walls under DIR/results/patients/<id>/). For each patient and each variant (``cfd.mesh`` keys,
e.g. ``fl05:final_layer_thickness=0.5``; ``base`` = config/config.yaml as it is) the Eq. 8 wall is
meshed and solved by SIMPLE alone (``fallback: none``) in DIR/simple_stall/<id>_<variant>; then,
from the last state, 10 more SIMPLE iterations write OpenFOAM's residual fields
(``solverInfo writeResidualFields``) and checkMesh writes the cells' non-orthogonality and volume
ratio. Prints per run: cells, criterion, iterations, final residuals, inlet-outlet pressure
difference and mean WSS, layer coverage; and where the p residual sits: the share of its sum in
the 100 largest cells, and how many of those lie within 1.5 own sizes of the wall, have a
neighbour of very different volume (cellVolumeRatio < 0.3) or a face above 40 degrees of
non-orthogonality, against the share of all cells.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
from datetime import date
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial import cKDTree

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from vcs.cfd import render_case, run_case  # noqa: E402
from vcs.cfd.foamfiles import patch_geometry, read_internal_field  # noqa: E402
from vcs.cfd.openfoam import deep_merge, foam_env  # noqa: E402
from vcs.cfd.utilities import _time_dirs  # noqa: E402


def parse_variant(text: str) -> tuple[str, dict]:
    name, _, rest = text.partition(":")
    keys = {}
    for kv in filter(None, rest.split(",")):
        k, v = kv.split("=", 1)
        keys[k] = int(v) if v.isdigit() else float(v)
    return name, keys


def solve(res: Path, pid: str, work: Path, name: str, mesh_keys: dict) -> tuple[Path, dict]:
    """SIMPLE alone on the patient's wall with the variant's mesh keys (a finished run is re-read)."""
    case = work / f"{pid}_{name}"
    if (case / "status.json").exists():
        return case, json.loads((case / "status.json").read_text())
    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["cfd"]
    cfg = deep_merge(cfg, {"mesh": mesh_keys, "solver": {"fallback": "none"}})
    cfg.pop("flavour", None)
    p = res / "patients" / pid
    shutil.rmtree(case, ignore_errors=True)
    render_case(case, p / "wall" / "wall.stl", cfg, model=p / "fit" / "model.json")
    return case, run_case(case, ranks=1)


def residual_location(case: Path) -> dict:
    """10 more SIMPLE iterations writing the residual fields; where the p residual sits."""
    env = foam_env()
    t0 = _time_dirs(case)[-1][1]
    ctrl = case / "system" / "controlDict"
    text = ctrl.read_text()
    text = re.sub(r"endTime\s+[^;]+;", f"endTime         {int(float(t0)) + 10};", text, count=1)
    text = re.sub(r"writeInterval\s+[^;]+;", "writeInterval   10;", text, count=1)
    text = text.replace("stopAt          writeNow;", "stopAt          endTime;")
    text = text.replace("fields          (U p);", "fields          (U p);\n        writeResidualFields yes;", 1)
    ctrl.write_text(text)
    sol = case / "system" / "fvSolution"
    sol.write_text(re.sub(r"residualControl\s*\{[^}]*\}", "", sol.read_text()))
    for cmd in (["simpleFoam"], ["checkMesh", "-writeFields", "(nonOrthoAngle cellVolumeRatio)", "-time", "0"]):
        with open(case / "logs" / f"log.stall.{cmd[0]}", "w") as fh:
            subprocess.run(cmd, cwd=case, env=env, stdout=fh, stderr=subprocess.STDOUT, check=True)
    t1 = _time_dirs(case)[-1][1]
    funcs = "(writeCellCentres writeCellVolumes)"
    subprocess.run(["postProcess", "-funcs", funcs, "-time", t1], cwd=case, env=env, capture_output=True, check=True)
    p = np.abs(read_internal_field(case / t1 / "initialResidual:p"))
    n = len(read_internal_field(case / t1 / "V"))
    p = np.broadcast_to(p, (n,))
    vol, cen = read_internal_field(case / t1 / "V"), read_internal_field(case / t1 / "C")
    cvr, ortho = read_internal_field(case / "0" / "cellVolumeRatio"), read_internal_field(case / "0" / "nonOrthoAngle")
    h = np.cbrt(vol)
    d, _ = cKDTree(patch_geometry(case, "wall")[0]).query(cen)
    top = np.argsort(p)[::-1][:100]
    near, jump, skew = d < 1.5 * h, cvr < 0.3, ortho > 40

    def share(mask: np.ndarray) -> str:
        return f"{100 * mask[top].mean():.0f} % ({100 * mask.mean():.0f} %)"

    return {
        "top100_share": float(p[top].sum() / max(p.sum(), 1e-300)),
        "near_wall": share(near),
        "volume_jump": share(jump),
        "non_ortho_40": share(skew),
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("workdir", type=Path, help="a finished workflow directory")
    ap.add_argument("--patients", help="comma-separated ids (default: every patient with a wall)")
    ap.add_argument("--variant", action="append", help="NAME:key=value,... (cfd.mesh keys)")
    a = ap.parse_args(argv)
    res = a.workdir.resolve() / "results"
    ids = a.patients.split(",") if a.patients else sorted(
        p.name for p in (res / "patients").iterdir() if (p / "wall" / "wall.stl").exists()
    )  # fmt: skip
    work = a.workdir.resolve() / "simple_stall"
    work.mkdir(exist_ok=True)
    print(
        "| patient | variant | cells | criterion (iterations) | final p / U | dp Pa | WSS mean Pa | layer coverage "
        "| p residual in top 100 cells | of which near wall (all cells) | volume jump < 0.3 | non-ortho > 40 |"
    )
    print("|---" * 12 + "|")
    for pid in ids:
        for text in a.variant or ["base:"]:
            name, keys = parse_variant(text)
            case, st = solve(res, pid, work, name, keys)
            loc = residual_location(case)
            fr, cov = st["final_residuals"], (st["mesh"].get("layers") or {}).get("coverage", 0)
            print(
                f"| {pid} | {name} | {st['cells']:,} | {st['criterion_used']} ({st['iterations']}) | "
                f"{fr['p']:.2g} / {fr['U']:.2g} | {st['inlet_minus_outlet_pressure']['Pa']:.4g} | "
                f"{st['wall_shear_stress_Pa']['mean']:.4g} | {cov:.2f} | {100 * loc['top100_share']:.0f} % | "
                f"{loc['near_wall']} | {loc['volume_jump']} | {loc['non_ortho_40']} |",
                flush=True,
            )
    print(f"{date.today()}, {platform.node()} ({os.cpu_count()} cores), load {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
