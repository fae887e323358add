#!/usr/bin/env python3
"""Grid convergence of the CFD on a demo aorta phantom: observed order, Richardson extrapolation
and the grid convergence index (GCI) of Celik et al. 2008, J. Fluids Eng. 130:078001.

    .venv/bin/python bench/grid_convergence.py [-o results/verification] [--fine 1.0e-3]
                                               [--ratio 1.5] [--ranks 2] [--seed 0] [--layers 0]
                                               [--json PATH]

Three meshes of the same Eq. 8 wall (demo aorta phantom, seed 0, fitted with the default VCS
settings), refined systematically: the background cell size is h_fine * ratio^k (k = 2, 1, 0) and
every other setting (snappy refinement levels, which are relative to the background cell) is the
same, so all cells shrink by the same ratio. Physics and solver are those of config/config.yaml
(the default steady 5 L/min parabolic inflow), without the averaging fallback, and without wall
prism layers by default (``--layers``): snappyHexMesh's layer addition is not geometrically
similar from grid to grid (coverage and collapse at edges vary), and with the default 3 layers
the measured triplets were not in the asymptotic range (pressure difference oscillating, apparent
orders 0.2-7: README, "CFD verification"), so the layered default mesh is judged against the
extrapolated value of this layer-free study instead.

For each mesh: cells, representative size h = (V / N)^(1/3), pressure difference inlet - outlet
(Pa), area-weighted mean and 95th percentile of |WSS| on the wall patch (Pa), and the WSS map on
the (tau, theta) grid. Then, per quantity, the observed order p (fixed-point iteration of Celik's
Eqs. 4-6), the extrapolated value (Eq. 7), the approximate and extrapolated relative errors and
GCI_fine = 1.25 e_a / (r^p - 1) (Eqs. 8-10). Writes OUT/grid_convergence.json (keys ``cells``,
``h``, ``pressure_drop_Pa``, ``wss_mean_Pa``, ``wss_p95_Pa``, ``observed_order``, ``gci_fine``, ...)
and OUT/grid_convergence.png; prints a table. ~10-20 min on 2 cores at the defaults. ``--json PATH``
also writes the table in the docs' format (docs/data/bench/grid_convergence.json).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from _table import save  # bench/ is on sys.path when this runs as a script

from vcs.cfd import render_case, run_case, sample_case
from vcs.cfd.resample import read_case
from vcs.io import Surface
from vcs.phantoms import make_phantom
from vcs.surface import wall_mesh, write_multisolid_stl
from vcs.vessel import fit_vessel

REPO = Path(__file__).resolve().parents[1]
QUANTITIES = ("pressure_drop_Pa", "wss_mean_Pa", "wss_p95_Pa")
#: each quantity's row label in the docs JSON
LABELS = {
    "pressure_drop_Pa": "pressure difference inlet - outlet (Pa)",
    "wss_mean_Pa": "mean WSS (Pa)",
    "wss_p95_Pa": "p95 WSS (Pa)",
}


def observed_order(f1: float, f2: float, f3: float, r21: float, r32: float) -> tuple[float, float]:
    """Observed order p and the sign s of Celik et al. 2008, Eqs. 4-6 (fine 1, medium 2, coarse 3).

    p = |ln|e32 / e21| + q(p)| / ln r21, q(p) = ln((r21^p - s) / (r32^p - s)), s = sign(e32 / e21),
    solved by fixed-point iteration from q = 0. Returns (nan, s) when e21 or e32 vanishes.
    """
    e21, e32 = f2 - f1, f3 - f2
    if e21 == 0 or e32 == 0:
        return float("nan"), 1.0
    s = float(np.sign(e32 / e21))
    p = abs(np.log(abs(e32 / e21))) / np.log(r21)
    for _ in range(200):
        q = np.log((r21**p - s) / (r32**p - s))
        p_new = abs(np.log(abs(e32 / e21)) + q) / np.log(r21)
        if abs(p_new - p) < 1e-10:
            p = p_new
            break
        p = p_new
    return float(p), s


def gci(f1: float, f2: float, f3: float, h1: float, h2: float, h3: float) -> dict:
    """Celik et al. 2008 Eqs. 4-10 for one quantity on three grids (h1 < h2 < h3)."""
    r21, r32 = h2 / h1, h3 / h2
    p, s = observed_order(f1, f2, f3, r21, r32)
    out = {"r21": r21, "r32": r32, "observed_order": p, "oscillatory": bool(s < 0)}
    if not np.isfinite(p):
        return out | {"extrapolated": None, "e_a21": None, "e_ext21": None, "gci_fine": None}
    ext = (r21**p * f1 - f2) / (r21**p - 1)
    e_a = abs((f1 - f2) / f1)
    return out | {
        "extrapolated": float(ext),
        "e_a21": float(e_a),
        "e_ext21": float(abs((ext - f1) / ext)),
        "gci_fine": float(1.25 * e_a / (r21**p - 1)),
    }


def wall_wss(case: Path, rho: float) -> tuple[float, float, float]:
    """Area-weighted mean and 95th percentile of |WSS| (Pa) on the wall patch, and the fluid
    volume (m3), from the finished case."""
    internal, patches, _ = read_case(case)
    wall = patches["wall"]
    wss = np.linalg.norm(np.asarray(wall.cell_data["wallShearStress"], float), axis=1) * rho
    area = np.asarray(wall.compute_cell_sizes(length=False, volume=False)["Area"], float)
    order = np.argsort(wss)
    cum = np.cumsum(area[order]) / area.sum()
    p95 = float(wss[order][np.searchsorted(cum, 0.95)])
    volume = float(np.asarray(internal.compute_cell_sizes(length=False, area=False)["Volume"]).sum())
    return float((wss * area).sum() / area.sum()), p95, volume


def case_stamp(cfg: dict, stl: Path) -> str:
    """What a solved case depends on: the CFD settings and the wall STL (sha256)."""
    return json.dumps({"cfd": cfg, "stl_sha256": hashlib.sha256(stl.read_bytes()).hexdigest()}, sort_keys=True)


def run_mesh(work: Path, stl: Path, cfd: dict, h_bg: float, model, ranks: int) -> dict:
    """Render, mesh, solve and measure one grid."""
    case = work / f"case_{h_bg * 1e3:.3f}mm"
    cfg = yaml.safe_load(yaml.safe_dump(cfd))
    cfg["mesh"]["cell_size"] = h_bg
    cfg["ranks"] = ranks
    cfg["solver"].update(fallback="none", max_iterations=3000, timeout_s=None)
    t0 = time.perf_counter()
    stamp = case_stamp(cfg, stl)
    done = case / "status.json"
    if done.is_file() and (case / "bench_config.json").is_file() and (case / "bench_config.json").read_text() == stamp:
        status = json.loads(done.read_text())  # a --workdir of an earlier run: reuse the solved case
    else:
        render_case(case, stl, cfg, flavour="esi")
        status = run_case(case, ranks=ranks)
        (case / "bench_config.json").write_text(stamp)
    if not status.get("converged"):
        sys.exit(f"grid {h_bg * 1e3:.3f} mm did not converge: {status.get('reason')} (case kept in {case})")
    rho = float(cfg["physics"]["rho"])
    wss_mean, wss_p95, volume = wall_wss(case, rho)
    fields = sample_case(case, model, n_tau=64, n_theta=32, n_rho=11)
    return {
        "background_cell_mm": h_bg * 1e3,
        "cells": int(status["cells"]),
        "h": (volume / status["cells"]) ** (1.0 / 3.0),
        "iterations": int(status["iterations"]),
        "pressure_drop_Pa": float(status["inlet_minus_outlet_pressure"]["Pa"]),  # a drop: parabolic inflow
        "wss_mean_Pa": wss_mean,
        "wss_p95_Pa": wss_p95,
        "wss_map": np.linalg.norm(fields["WSS"], axis=-1),
        "time_s": time.perf_counter() - t0,
    }


def plot(out: Path, grids: list[dict], result: dict) -> None:
    """Convergence of the three quantities against h (with the extrapolated value) and the WSS maps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    h = np.array([g["h"] for g in grids]) * 1e3
    for ax, q in zip(axes[0], QUANTITIES):
        ax.plot(h, [g[q] for g in grids], "o-", label="grids")
        ext = result["quantities"][q]["extrapolated"]
        if ext is not None:
            ax.plot([0], [ext], "r*", ms=10, label=f"Richardson ({ext:.4g})")
        gci_f = result["quantities"][q]["gci_fine"]
        ax.set_title(
            f"{q}: p = {result['quantities'][q]['observed_order']:.2f}, GCI = "
            + (f"{100 * gci_f:.2f} %" if gci_f is not None else "n/a")
        )
        ax.set_xlabel("h = (V/N)^(1/3) (mm)")
        ax.set_xlim(left=0)
        ax.legend(fontsize=8)
    vmax = float(np.percentile(grids[0]["wss_map"], 99))
    for ax, g in zip(axes[1][:2], (grids[0], grids[2])):
        im = ax.imshow(g["wss_map"].T, origin="lower", aspect="auto", extent=(0, 1, 0, 360), vmin=0, vmax=vmax)
        ax.set_title(f"|WSS| (Pa), {g['cells']:,} cells")
        ax.set_xlabel("tau")
        ax.set_ylabel("theta (deg)")
        fig.colorbar(im, ax=ax)
    rel = (grids[1]["wss_map"] - grids[0]["wss_map"]) / np.maximum(grids[0]["wss_map"].mean(), 1e-12)
    im = axes[1][2].imshow(
        rel.T, origin="lower", aspect="auto", extent=(0, 1, 0, 360), cmap="coolwarm", vmin=-0.2, vmax=0.2
    )
    axes[1][2].set_title("(medium - fine) / mean fine |WSS|")
    axes[1][2].set_xlabel("tau")
    fig.colorbar(im, ax=axes[1][2])
    fig.tight_layout()
    fig.savefig(out / "grid_convergence.png", dpi=100)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("-o", "--output", type=Path, default=Path("results/verification"), help="output folder")
    ap.add_argument("--fine", type=float, default=1.0e-3, help="background cell of the fine grid [m]")
    ap.add_argument("--ratio", type=float, default=1.5, help="refinement ratio between grids (>= 1.3)")
    ap.add_argument("--ranks", type=int, default=2, help="MPI ranks per case")
    ap.add_argument("--seed", type=int, default=0, help="demo aorta phantom seed")
    ap.add_argument(
        "--layers",
        type=int,
        default=0,
        help="wall prism layers on every grid (default 0: snappy's layers are not geometrically similar "
        "between grids; with the default 3 the triplets were not in the asymptotic range, README)",
    )
    ap.add_argument(
        "--workdir",
        type=Path,
        help="keep the cases here (default: a temporary folder); solved cases found there are reused",
    )
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    if a.ratio < 1.3:
        print(f"grid_convergence: error: --ratio {a.ratio} is below 1.3 (Celik et al. 2008)", file=sys.stderr)
        return 2
    a.output.mkdir(parents=True, exist_ok=True)
    cfd = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["cfd"]
    cfd["flavour"] = "esi"
    cfd["mesh"]["layers"] = a.layers
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = a.workdir or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        ph = make_phantom("aorta", seed=a.seed, resolution=1.5)
        model, _, _ = fit_vessel(Surface(ph.vertices, ph.faces, {}, "mm", "given", f"aorta_seed{a.seed}"))
        stl = work / "wall.stl"
        write_multisolid_stl(wall_mesh(model, n_theta=64, extend_outlet=1.0), stl, scale=1e-3)
        sizes = [a.fine * a.ratio**k for k in (0, 1, 2)]  # fine, medium, coarse
        grids = []
        for h_bg in sizes:
            g = run_mesh(work, stl, cfd, h_bg, model, a.ranks)
            print(
                f"background {g['background_cell_mm']:.3f} mm: {g['cells']:,} cells, {g['iterations']} iterations, "
                f"dp {g['pressure_drop_Pa']:.3f} Pa, WSS mean {g['wss_mean_Pa']:.4f} Pa, p95 {g['wss_p95_Pa']:.4f} Pa, "
                f"{g['time_s']:.0f} s",
                flush=True,
            )
            grids.append(g)
    h = [g["h"] for g in grids]
    quantities = {q: gci(*(g[q] for g in grids), *h) for q in QUANTITIES}
    maps = np.stack([g["wss_map"] for g in grids])
    result = {
        "reference": "Celik et al. 2008, J. Fluids Eng. 130:078001 (Eqs. 1-10)",
        "vessel": f"demo aorta phantom seed {a.seed} (Eq. 8 wall, 64 around, outlet extension 1 diameter)",
        "inflow": cfd["inlet"],
        "layers": a.layers,
        "order": "fine, medium, coarse",
        "background_cell_mm": [g["background_cell_mm"] for g in grids],
        "cells": [g["cells"] for g in grids],
        "h": h,
        "h_units": "m, (fluid volume / cells)^(1/3)",
        "iterations": [g["iterations"] for g in grids],
        "time_s": [round(g["time_s"], 1) for g in grids],
        **{q: [g[q] for g in grids] for q in QUANTITIES},
        "observed_order": {q: quantities[q]["observed_order"] for q in QUANTITIES},
        "gci_fine": {q: quantities[q]["gci_fine"] for q in QUANTITIES},
        "extrapolated": {q: quantities[q]["extrapolated"] for q in QUANTITIES},
        "quantities": quantities,
        "wss_map_relative_change_medium_to_fine": {
            "p50": float(np.percentile(np.abs(maps[1] - maps[0]) / maps[0].mean(), 50)),
            "p95": float(np.percentile(np.abs(maps[1] - maps[0]) / maps[0].mean(), 95)),
        },
        "total_time_s": round(time.perf_counter() - t_start, 1),
    }
    np.savez_compressed(a.output / "grid_convergence_wss_maps.npz", fine=maps[0], medium=maps[1], coarse=maps[2])
    (a.output / "grid_convergence.json").write_text(json.dumps(result, indent=1) + "\n")
    plot(a.output, grids, result)
    print("| quantity | fine | medium | coarse | observed order | extrapolated | GCI fine |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for q in QUANTITIES:
        r = quantities[q]
        gci_text = f"{100 * r['gci_fine']:.2f} %" if r["gci_fine"] is not None else "n/a"
        ext = f"{r['extrapolated']:.4g}" if r["extrapolated"] is not None else "n/a"
        print(
            f"| {q} | {grids[0][q]:.4g} | {grids[1][q]:.4g} | {grids[2][q]:.4g} | {r['observed_order']:.2f} | "
            f"{ext} | {gci_text} |"
        )
        rows.append([LABELS[q], *(f"{g[q]:.4g}" for g in grids), f"{r['observed_order']:.2f}", ext, gci_text])
    heads = [f"{g['background_cell_mm']:.3g} mm ({g['cells']:,})" for g in grids]
    save(
        a.json,
        measured=f"one run, {result['total_time_s']:.0f} s wall; also in {a.output / 'grid_convergence.json'}",
        columns=["quantity", heads[0][:-1] + " cells)", *heads[1:], "observed order", "Richardson", "GCI fine"],
        rows=rows,
    )
    print(f"cells {result['cells']}; total {result['total_time_s']:.0f} s -> {a.output / 'grid_convergence.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
