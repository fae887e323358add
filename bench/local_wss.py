#!/usr/bin/env python3
"""Local WSS accuracy on Hagen-Poiseuille flow: the resampled (tau, theta) wall map against
4 mu U_mean / R node by node, with and without wall prism layers.

    .venv/bin/python bench/local_wss.py [-o results/verification] [--workdir DIR] [--json PATH]

The tube of tests/workflow/test_openfoam.py (R = 10 mm, L = 120 mm, axis tilted ~2 degrees,
Q = 2e-5 m3/s, Re = 378, parabolic inflow, 1.25 mm background cells, serial) meshed four ways:
no layers; the default 3 prism layers; 3 layers with the inlet surface refined one level
(`mesh.inlet_level: [1, 1]`); 3 layers on a tube extended by one diameter upstream of tau = 0
(as `wall.extend_inlet: 1` does; the map covers the same 120 mm). For each: cells,
snappyHexMesh and simpleFoam times, iterations, pressure drop between the sections at 0.3 L and
0.75 L and the area-mean |WSS| between them (against Hagen-Poiseuille), percentiles of the local
relative error of |WSS| on the 64 x 32 (tau, theta) map in the developed region
(0.1 <= tau <= 0.9) and on the whole map, where the largest errors sit, and the same on the raw
wall faces. Writes OUT/local_wss.json and OUT/local_wss.png (the error maps); prints a table.
~3-5 min on 2 cores. ``--json PATH`` also writes the table in the docs' format
(docs/data/bench/local_wss.json: of the raw faces, the largest error and where it is).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _table import save  # bench/ is on sys.path when this runs as a script

from vcs.centerline import uniform_knots
from vcs.cfd import render_case, run_case, sample_case
from vcs.cfd.resample import read_case
from vcs.cfd.verification import local_error_stats, poiseuille_pressure_gradient, poiseuille_wall_shear_stress
from vcs.model import VesselCoordinateSystem
from vcs.phantoms import write_closed_tube_stl
from vcs.vessel import VesselModel
from vcs.wall import WallModel

R, L, Q = 0.01, 0.12, 2.0e-5
AXIS = np.array([0.03, 0.02, 1.0]) / np.linalg.norm([0.03, 0.02, 1.0])
NU, RHO = 3.37e-6, 1060.0
BASE = {
    "mesh": {"cell_size": 1.25e-3},
    "inlet": {"type": "parabolic", "flow_rate": Q},
    "solver": {"max_iterations": 800, "startup_iterations": 50, "fallback": "none"},
}
# name: (mesh settings over BASE, straight inlet extension in m before tau = 0)
VARIANTS: dict[str, tuple[dict, float]] = {
    "no layers": ({"layers": 0}, 0.0),
    "3 layers (default)": ({}, 0.0),
    "3 layers, inlet level 1": ({"inlet_level": [1, 1]}, 0.0),
    "3 layers, 1 D inlet extension": ({}, 2 * R),
}
DEVELOPED = (0.1, 0.9)
#: the docs JSON's columns
JSON_COLUMNS = [
    "mesh",
    "cells",
    "snappy s",
    "simpleFoam s",
    "pressure drop",
    "mean WSS",
    "map, developed: p5 / p95 / p95 of |e| / max |e|",
    "whole map: p95 / max |e| (tau, theta)",
    "raw wall faces: max (distance from the inlet cap, theta)",
]


def straight_model() -> VesselModel:
    """The tube as a VesselModel (mm): c(tau) = tau L axis, rho_w = R, v1 = axis x x_hat."""
    from scipy.interpolate import BSpline

    t = uniform_knots(5)
    greville = np.array([t[i + 1 : i + 4].mean() for i in range(9)])
    curve = BSpline(t, greville[:, None] * L * 1e3 * AXIS, 3)
    v1 = np.cross(AXIS, [1.0, 0.0, 0.0])
    vcs = VesselCoordinateSystem(curve, v1 / np.linalg.norm(v1))
    return VesselModel(vcs, WallModel(7, 7, np.full((11, 8), R * 1e3)))


def raw_wall(case: Path) -> dict:
    """Section-mean pressure drop, mean |WSS| and the raw wall faces' error against Hagen-Poiseuille."""
    internal, patches, _ = read_case(case)
    cc = np.asarray(internal.cell_centers().points)
    vol = np.asarray(internal.compute_cell_sizes(length=False, area=False)["Volume"])
    p = np.asarray(internal.cell_data["p"])
    s = cc @ AXIS

    def p_at(x: float) -> float:
        m = np.abs(s - x) < 1.25e-3
        return float((p[m] * vol[m]).sum() / vol[m].sum())

    s1, s2 = 0.3 * L, 0.75 * L
    wall = patches["wall"]
    wc = np.asarray(wall.cell_centers().points)
    ws = wc @ AXIS
    area = np.asarray(wall.compute_cell_sizes(length=False, volume=False)["Area"])
    wss = np.linalg.norm(np.asarray(wall.cell_data["wallShearStress"]), axis=1)
    mid = (ws > s1) & (ws < s2)
    tw = poiseuille_wall_shear_stress(Q, R, NU)
    err = wss / tw - 1
    k = int(np.argmax(np.abs(err)))
    radial = wc[k] - ws[k] * AXIS
    v1 = np.cross(AXIS, [1.0, 0.0, 0.0])
    v1 /= np.linalg.norm(v1)
    theta = np.degrees(np.arctan2(radial @ np.cross(AXIS, v1), radial @ v1)) % 360
    developed = (ws > DEVELOPED[0] * L) & (ws < DEVELOPED[1] * L)
    return {
        "dp_rel_error": (p_at(s1) - p_at(s2)) / (poiseuille_pressure_gradient(Q, R, NU) * (s2 - s1)) - 1,
        "wss_mean_rel_error": float((wss[mid] * area[mid]).sum() / area[mid].sum()) / tw - 1,
        "faces": int(len(err)),
        "faces_developed_p95_abs": float(np.percentile(np.abs(err[developed]), 95)),
        "faces_developed_max": float(np.abs(err[developed]).max()),
        "faces_max": float(err[k]),
        "faces_max_at_mm_deg": [float(ws[k] * 1e3), float(theta)],
    }


def run_variant(work: Path, name: str, mesh: dict, extension: float) -> dict:
    """Mesh, solve (or reuse a finished case) and measure one variant."""
    case = work / name.replace(" ", "_").replace(",", "").replace("(", "").replace(")", "")
    case.parent.mkdir(parents=True, exist_ok=True)
    stl = write_closed_tube_stl(
        work / f"tube_{extension * 1e3:.0f}mm.stl",
        radius=R,
        length=L + extension,
        n_theta=96,
        n_z=60 + int(round(extension / (L / 60))),
        origin=-extension * AXIS,
        axis=AXIS,
    )
    cfg = json.loads(json.dumps(BASE))
    cfg["mesh"].update(mesh)
    status_file = case / "status.json"
    if status_file.exists() and json.loads(status_file.read_text()).get("converged"):
        status = json.loads(status_file.read_text())
    else:
        render_case(case, stl, cfg, flavour="esi")
        status = run_case(case, ranks=1)
    if not status.get("converged"):
        sys.exit(f"{name}: did not converge: {status.get('reason')} (case kept in {case})")
    f = sample_case(case, straight_model(), n_tau=64, n_theta=32, n_rho=3)
    wss_map = np.linalg.norm(f["WSS"], axis=-1)
    exact = poiseuille_wall_shear_stress(Q, R, NU * RHO)
    t = status["timings_s"]
    return {
        "cells": int(status["cells"]),
        "iterations": int(status["iterations"]),
        "layer_coverage": status["mesh"]["layers"].get("coverage"),
        "snappyHexMesh_s": t["snappyHexMesh"],
        "simpleFoam_s": t.get("simpleFoam.startup", 0.0) + t["simpleFoam"],
        "total_s": t["total"],
        "developed": local_error_stats(wss_map, exact, f["tau"], DEVELOPED),
        "whole": local_error_stats(wss_map, exact, f["tau"]),
        "error_map": wss_map / exact - 1,
        **raw_wall(case),
    }


def plot(out: Path, results: dict) -> None:
    """The relative error maps of |WSS| on (tau, theta)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(5 * len(results), 3.8), squeeze=False)
    for ax, (name, r) in zip(axes[0], results.items()):
        err = 100 * r["error_map"].T
        im = ax.imshow(err, origin="lower", aspect="auto", extent=(0, 1, 0, 360), cmap="coolwarm", vmin=-20, vmax=20)
        d = r["developed"]
        ax.set_title(
            f"{name}: {r['cells']:,} cells\n"
            f"developed p95 |e| {100 * d['p95_abs']:.1f} %, max {100 * d['max_abs']:.1f} %"
        )
        ax.axvline(DEVELOPED[0], color="k", lw=0.8)
        ax.axvline(DEVELOPED[1], color="k", lw=0.8)
        ax.set_xlabel("tau")
        ax.set_ylabel("theta (deg)")
        fig.colorbar(im, ax=ax, label="|WSS| / Hagen-Poiseuille - 1 (%)")
    fig.tight_layout()
    fig.savefig(out / "local_wss.png", dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-o", "--output", type=Path, default=Path("results/verification"), help="output folder")
    ap.add_argument("--workdir", type=Path, help="keep the cases here and reuse finished ones (default: temporary)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    a.output.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = a.workdir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for name, (mesh, extension) in VARIANTS.items():
            results[name] = run_variant(work, name, mesh, extension)
            print(f"{name}: {results[name]['cells']:,} cells", flush=True)
    plot(a.output, results)
    table = {k: {kk: vv for kk, vv in v.items() if kk != "error_map"} for k, v in results.items()}
    (a.output / "local_wss.json").write_text(
        json.dumps({"developed_tau": list(DEVELOPED), "variants": table, "total_s": time.perf_counter() - t0}, indent=1)
        + "\n"
    )
    print(
        "| mesh | cells | snappy s | simpleFoam s | dp | mean WSS | map, developed: p5 / p95 / p95 abs / max "
        "| whole map: p95 abs / max (at tau, theta) | raw faces: developed max / max (at s, theta) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for name, r in results.items():
        d, w = r["developed"], r["whole"]
        th = w["argmax"][1] * 360 / 32
        print(
            f"| {name} | {r['cells']:,} | {r['snappyHexMesh_s']:.1f} | {r['simpleFoam_s']:.1f} | "
            f"{100 * r['dp_rel_error']:+.2f} % | {100 * r['wss_mean_rel_error']:+.2f} % | "
            f"{100 * d['p5']:+.1f} / {100 * d['p95']:+.1f} / {100 * d['p95_abs']:.1f} / {100 * d['max_abs']:.1f} % | "
            f"{100 * w['p95_abs']:.1f} / {100 * w['max_abs']:.1f} % ({w['argmax'][0]:.3f}, {th:.0f} deg) | "
            f"{100 * r['faces_developed_max']:.1f} / {100 * r['faces_max']:+.1f} % "
            f"({r['faces_max_at_mm_deg'][0]:.1f} mm, {r['faces_max_at_mm_deg'][1]:.0f} deg) |"
        )
        rows.append(
            [
                name,
                f"{r['cells']:,}",
                f"{r['snappyHexMesh_s']:.1f}",
                f"{r['simpleFoam_s']:.1f}",
                f"{100 * r['dp_rel_error']:+.2f} %",
                f"{100 * r['wss_mean_rel_error']:+.2f} %",
                f"{100 * d['p5']:+.1f} / {100 * d['p95']:+.1f} / {100 * d['p95_abs']:.1f} / {100 * d['max_abs']:.1f} %",
                f"{100 * w['p95_abs']:.1f} / {100 * w['max_abs']:.1f} % ({w['argmax'][0]:.3f}, {th:.0f} deg)",
                f"{100 * r['faces_max']:+.1f} % ({r['faces_max_at_mm_deg'][0]:.1f} mm, "
                f"{r['faces_max_at_mm_deg'][1]:.0f} deg)",
            ]
        )
    save(
        a.json,
        measured=f"one run, variants one after the other, serial; also in {a.output / 'local_wss.json'}",
        columns=JSON_COLUMNS,
        rows=rows,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
