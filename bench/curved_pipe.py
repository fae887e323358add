#!/usr/bin/env python3
"""Developed laminar flow in a curved pipe (torus arc) against the Dean-flow friction factor of
Ito (1959) and White (1929), on systematically refined meshes.

    .venv/bin/python bench/curved_pipe.py [-o results/verification] [--sizes 1.0,0.77,0.59]
                                          [--layers 3] [--also LAYERS:SIZES] [--ranks 2] [--workdir DIR]
                                          [--json PATH]

The torus-arc phantom (`vcs phantom --kind torus`: tube radius a = 5 mm, centreline radius
R = 33.3 mm, a / R = 0.15, 300 degrees) goes through the normal pipeline: phantom STL -> `vcs fit`
(fit_vessel) -> Eq. 8 wall STL (64 around, no extensions) -> OpenFOAM case with the default mesh
settings (3 prism layers) at each background cell size -> simpleFoam (parabolic inflow, Re = 500
on the diameter, nu = 3.37e-6 m2/s: De = Re sqrt(a / R) = 194) -> p resampled on the (tau, theta,
rho_n) grid. The area-mean pressure of each cross-section against arc length gives the pressure
gradient along the centreline; its developed value is a straight-line fit over 90-270 degrees
(the first 90 degrees are the development from the straight-pipe inflow profile, the last 30 are
next to the uniform outlet pressure), divided by the Hagen-Poiseuille gradient of the same flow
rate: f_c / f_s, compared with Ito's and White's correlations (vcs.cfd.verification), with the
observed order, Richardson extrapolation and GCI of Celik et al. 2008 (bench/grid_convergence.py).
Writes OUT/curved_pipe.json and OUT/curved_pipe.png (local f_c / f_s along the arc); prints a
table. The coarsest mesh is the one of tests/workflow/test_curved_pipe.py. ``--also 6:0.77,0.59``
(repeatable) adds meshes at another prism-layer count after the series (not in its GCI);
``--json PATH`` also writes the table of every mesh in the docs' format
(docs/data/bench/curved_pipe.json):

    .venv/bin/python bench/curved_pipe.py --sizes 1.0,0.77,0.59,0.45 --also 6:0.77,0.59 \
        --json docs/data/bench/curved_pipe.json
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
from grid_convergence import gci

from vcs.cfd import render_case, run_case, sample_case
from vcs.cfd.verification import (
    dean_number,
    developed_gradient,
    ito_friction_ratio,
    poiseuille_pressure_gradient,
    section_mean,
    white_friction_ratio,
)
from vcs.phantoms import make_phantom, write_stl
from vcs.surface import wall_mesh, write_multisolid_stl
from vcs.vessel import fit_vessel

A_MM, R_MM, ARC_DEG = 5.0, 33.3, 300.0  # tube radius, centreline radius, arc
RE, NU = 500.0, 3.37e-6
WINDOW_DEG = (90.0, 270.0)  # developed part: away from the inlet (development) and the outlet
LAYERS = 3  # the default mesh's prism layers
CI_CELL_MM = 1.0  # tests/workflow/test_curved_pipe.py's mesh (with LAYERS)
#: the docs table's columns (docs/data/bench/curved_pipe.json)
JSON_COLUMNS = [
    "background cell",
    "layers",
    "cells",
    "SIMPLE iterations",
    "case s",
    "f_c / f_s",
    "vs White",
    "vs Ito",
    "mesh volume vs torus",
    "f_c / f_s at the mesh's mean radius",
]


def flow_rate() -> float:
    """Q (m3/s) giving Re = U_mean 2a / nu = RE."""
    a = A_MM * 1e-3
    return RE * NU / (2 * a) * np.pi * a**2


def friction_ratio(fields: dict, length_mm: float, window_deg: tuple[float, float]) -> tuple[float, dict]:
    """Developed f_c / f_s from a resampled case, and the local ratio per 15-degree window."""
    pm = section_mean(fields["p_kinematic"], fields["rho_n"], fields["rho_w_mm"])
    s = fields["tau"] * length_mm * 1e-3
    g_hp = poiseuille_pressure_gradient(flow_rate(), A_MM * 1e-3, NU)
    s_of = length_mm * 1e-3 / ARC_DEG
    ratio = -developed_gradient(s, pm, (window_deg[0] * s_of, window_deg[1] * s_of)) / g_hp
    local = {
        float(lo + 7.5): -developed_gradient(s, pm, (lo * s_of, (lo + 15) * s_of)) / g_hp
        for lo in np.arange(0.0, ARC_DEG, 15.0)
    }
    return ratio, local


def run_mesh(work: Path, stl: Path, model, h_bg: float, ranks: int, layers: int) -> dict:
    """Render, mesh, solve and measure one mesh (a finished case in ``work`` is reused)."""
    case = work / (f"case_{h_bg * 1e3:.3f}mm" + ("" if layers == LAYERS else f"_{layers}layers"))
    cfg = {
        "mesh": {"cell_size": h_bg, "layers": layers},
        "physics": {"nu": NU},
        "inlet": {"type": "parabolic", "flow_rate": flow_rate()},
        "solver": {"max_iterations": 3000, "startup_iterations": 50, "fallback": "none"},
        "ranks": ranks,
    }
    t0 = time.perf_counter()
    status_file = case / "status.json"
    if status_file.exists() and json.loads(status_file.read_text()).get("converged"):
        status = json.loads(status_file.read_text())
    else:
        render_case(case, stl, cfg, flavour="esi")
        status = run_case(case, ranks=ranks)
    if not status.get("converged"):
        sys.exit(f"mesh {h_bg * 1e3:.3f} mm did not converge: {status.get('reason')} (case kept in {case})")
    fields = sample_case(case, model, n_tau=121, n_theta=32, n_rho=11)
    ratio, local = friction_ratio(fields, model.vcs.length, WINDOW_DEG)
    # the snapped mesh is slightly thinner than the wall; at a fixed flow rate the gradient goes as
    # 1 / area^2, so (V_mesh / V_torus)^2 x f_c / f_s is the ratio against the mesh's own mean radius
    volume_ratio = status["lumen_volume_m3"] / (np.pi * (A_MM * 1e-3) ** 2 * R_MM * 1e-3 * np.radians(ARC_DEG))
    return {
        "background_cell_mm": h_bg * 1e3,
        "layers": layers,
        "cells": int(status["cells"]),
        "h": (status["lumen_volume_m3"] / status["cells"]) ** (1.0 / 3.0),
        "iterations": int(status["iterations"]),
        "layer_coverage": status["mesh"]["layers"].get("coverage"),
        "solver_time_s": float(status["timings_s"]["total"]),
        "time_s": time.perf_counter() - t0,
        "friction_ratio": ratio,
        "volume_ratio": volume_ratio,
        "friction_ratio_mesh_radius": ratio * volume_ratio**2,
        "local_friction_ratio": local,
    }


def json_cells(g: dict, ito: float, white: float) -> list[str]:
    """One mesh of :func:`run_mesh` as a row of :data:`JSON_COLUMNS`."""
    r = g["friction_ratio"]
    ci = g["layers"] == LAYERS and round(g["background_cell_mm"], 6) == CI_CELL_MM
    return [
        f"{g['background_cell_mm']:.2f} mm" + (" (the CI test)" if ci else ""),
        str(g["layers"]),
        f"{g['cells']:,}",
        str(g["iterations"]),
        f"{g['solver_time_s']:.0f}",
        f"{r:.3f}",
        f"{100 * (r / white - 1):+.1f} %",
        f"{100 * (r / ito - 1):+.1f} %",
        f"{100 * (g['volume_ratio'] - 1):+.2f} %",
        f"{g['friction_ratio_mesh_radius']:.3f}",
    ]


def parse_also(text: str) -> tuple[int, list[float]]:
    """``LAYERS:SIZES`` (``6:0.77,0.59``, mm) as (layers, cell sizes in m, coarse to fine)."""
    layers, _, sizes = text.partition(":")
    return int(layers), sorted((float(x) * 1e-3 for x in sizes.split(",")), reverse=True)


def plot(out: Path, grids: list[dict], ito: float, white: float) -> None:
    """Local f_c / f_s along the arc for each mesh, the correlations and the developed window."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4.5))
    for g in grids:
        phi = list(g["local_friction_ratio"])
        ax.plot(phi, list(g["local_friction_ratio"].values()), "o-", ms=3, label=f"{g['cells']:,} cells")
    ax.axhline(ito, color="k", ls="--", label=f"Ito 1959 ({ito:.3f})")
    ax.axhline(white, color="grey", ls=":", label=f"White 1929 ({white:.3f})")
    ax.axvspan(*WINDOW_DEG, color="0.9", label="developed window")
    ax.set_xlabel("angle along the arc (deg)")
    ax.set_ylabel("local f_c / f_s (15-degree windows)")
    ax.set_title(f"torus arc a/R = {A_MM / R_MM:.2f}, Re = {RE:g}, De = {dean_number(RE, A_MM, R_MM):.0f}")
    ax.set_ylim(0.8, 2.6)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "curved_pipe.png", dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-o", "--output", type=Path, default=Path("results/verification"), help="output folder")
    ap.add_argument("--sizes", default="1.0,0.77,0.59", help="background cell sizes [mm], coarse to fine")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks per case")
    ap.add_argument("--layers", type=int, default=LAYERS, help="wall prism layers (the default mesh has 3)")
    ap.add_argument(
        "--also",
        action="append",
        default=[],
        metavar="LAYERS:SIZES",
        help="more meshes after the series at another layer count, e.g. 6:0.77,0.59 (not in the GCI)",
    )
    ap.add_argument("--workdir", type=Path, help="keep the cases here and reuse finished ones (default: temporary)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    try:
        sizes = sorted((float(x) * 1e-3 for x in a.sizes.split(",")), reverse=True)
    except ValueError:
        print(f"curved_pipe: error: --sizes {a.sizes!r} is not a comma-separated list of mm", file=sys.stderr)
        return 2
    try:
        also = [parse_also(x) for x in a.also]
    except ValueError:
        print(f"curved_pipe: error: --also {a.also!r}: each is LAYERS:SIZES, e.g. 6:0.77,0.59", file=sys.stderr)
        return 2
    a.output.mkdir(parents=True, exist_ok=True)
    de = dean_number(RE, A_MM, R_MM)
    ito, white = ito_friction_ratio(de), white_friction_ratio(de)
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = a.workdir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        ph = make_phantom("torus", resolution=0.5, major_radius_mm=R_MM, tube_radius_mm=A_MM, arc_angle_deg=ARC_DEG)
        write_stl(ph, work / "torus.stl")
        model, _, _ = fit_vessel(work / "torus.stl", units="mm")
        stl = work / "wall.stl"
        write_multisolid_stl(wall_mesh(model, n_theta=64), stl, scale=1e-3)
        grids, more = [], []
        for layers, h_bg in [(a.layers, h) for h in sizes] + [(n, h) for n, hs in also for h in hs]:
            g = run_mesh(work, stl, model, h_bg, a.ranks, layers)
            print(
                f"background {g['background_cell_mm']:.3f} mm: {g['cells']:,} cells, {g['iterations']} iterations, "
                f"f_c/f_s {g['friction_ratio']:.4f} (Ito {100 * (g['friction_ratio'] / ito - 1):+.2f} %), "
                f"{g['time_s']:.0f} s" + ("" if layers == a.layers else f" ({layers} layers)"),
                flush=True,
            )
            (grids if len(grids) < len(sizes) else more).append(g)
    result: dict = {
        "geometry": {
            "tube_radius_mm": A_MM,
            "centreline_radius_mm": R_MM,
            "curvature_ratio": A_MM / R_MM,
            "arc_deg": ARC_DEG,
            "fitted_length_mm": model.vcs.length,
        },
        "layers": a.layers,
        "reynolds": RE,
        "dean": de,
        "ito_1959": ito,
        "white_1929": white,
        "developed_window_deg": list(WINDOW_DEG),
        "order": "coarse to fine",
        "meshes": grids,
        **({"more_meshes": more} if more else {}),
        "total_time_s": round(time.perf_counter() - t_start, 1),
    }
    if len(grids) >= 3:  # the three finest
        fine, medium, coarse = grids[-1], grids[-2], grids[-3]
        result["gci"] = gci(
            fine["friction_ratio"],
            medium["friction_ratio"],
            coarse["friction_ratio"],
            fine["h"],
            medium["h"],
            coarse["h"],
        )
        p = result["gci"]["observed_order"]
        result["gci"]["asymptotic"] = bool(np.isfinite(p) and 0.5 <= p <= 4.0)
    (a.output / "curved_pipe.json").write_text(json.dumps(result, indent=1) + "\n")
    plot(a.output, grids, ito, white)
    print(f"De = {de:.1f}: Ito 1959 f_c/f_s = {ito:.4f}, White 1929 {white:.4f}")
    print(
        "| background cell | cells | iterations | solver s | f_c/f_s | vs Ito | vs White "
        "| mesh volume / torus | f_c/f_s at the mesh's radius |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for g in grids + more:
        r = g["friction_ratio"]
        layers = "" if g["layers"] == a.layers else f", {g['layers']} layers"
        print(
            f"| {g['background_cell_mm']:.2f} mm{layers} | {g['cells']:,} | {g['iterations']} | "
            f"{g['solver_time_s']:.0f} | "
            f"{r:.4f} | {100 * (r / ito - 1):+.2f} % | {100 * (r / white - 1):+.2f} % | "
            f"{100 * (g['volume_ratio'] - 1):+.2f} % | {g['friction_ratio_mesh_radius']:.4f} |"
        )
    if "gci" in result:
        x = result["gci"]
        if x["asymptotic"]:
            print(
                f"observed order {x['observed_order']:.2f}, extrapolated {x['extrapolated']:.4f} "
                f"(White {100 * (x['extrapolated'] / white - 1):+.2f} %), GCI fine {100 * x['gci_fine']:.2f} %"
            )
        else:  # Celik et al. 2008: no extrapolation outside the asymptotic range
            print(
                f"apparent order {x['observed_order']:.2f} outside 0.5-4: the meshes are not in the asymptotic "
                "range, no Richardson value; the spread of the finest meshes is the uncertainty"
            )
    print(f"total {result['total_time_s']:.0f} s -> {a.output / 'curved_pipe.json'}")
    save(
        a.json,
        measured=f"one run, {result['total_time_s']:.0f} s wall, {a.ranks} MPI ranks per case; "
        f"also in {a.output / 'curved_pipe.json'}",
        columns=JSON_COLUMNS,
        rows=[json_cells(g, ito, white) for g in grids + more],
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
