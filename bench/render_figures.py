#!/usr/bin/env python3
"""Render time of every 3-D atlas figure (vcs.atlas.plots3d) on a demo atlas, and the machine.

    .venv/bin/python bench/render_figures.py [--cohort aorta|tubes] [-n 6] [-o DIR]

The atlas: ``aorta`` (default) fits n seeded aorta phantoms (vcs.phantoms, ~3 s each) and gives
them synthetic flow fields on a 40 x 32 x 8 (tau, theta, rho_n) grid (a Poiseuille profile whose
flow rate grows with the radius, a linear pressure drop, a WSS pattern with random amplitudes
along and around the vessel); ``tubes`` uses bent tubes instead (no fit, seconds). Prints one line
per figure (seconds, size in kB) and the total; the figures go to DIR (default a temporary folder).
(The figures the docs show come from a real demo run: scripts/docs_figures.py.)
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def aorta_models(n: int) -> list:
    """n seeded aorta phantoms fitted with the default L, K, R, one L for all."""
    import vcs.phantoms as phantom
    from vcs.io import Surface
    from vcs.vessel import fit_vessel

    models = []
    for seed in range(n):
        ph = phantom.make_phantom("aorta", seed=seed, resolution=3.0, aneurysm=False)
        models.append(fit_vessel(Surface(ph.vertices, ph.faces, {}, "mm", "given", f"aorta{seed}"))[0])
    n_knots = max(m.n_knots for m in models)
    return [m.with_n_knots(n_knots) for m in models]


def tube_models(n: int) -> list:
    """n bent tubes of random radius (the atlas tests' synthetic_model)."""
    sys.path.insert(0, str(REPO / "tests" / "vcs"))
    from test_atlas import synthetic_model

    rng = np.random.default_rng(0)
    return [synthetic_model(radius=8.0 + 4.0 * rng.random(), bend=50 + 3 * i) for i in range(n)]


def demo_fields(radius: float, rng: np.random.Generator, grid: tuple[int, int, int] = (40, 32, 8)) -> dict:
    """Synthetic fields of one patient on the VCS grid, as vcs.cfd.sample_case writes them."""
    nt, nth, nr = grid
    tau, theta, rho_n = np.linspace(0, 1, nt), 2 * np.pi * np.arange(nth) / nth, np.linspace(0, 1, nr)
    T, TH, RN = np.meshgrid(tau, theta, rho_n, indexing="ij")
    q = 0.2 + 0.002 * radius**2 + 0.02 * rng.normal()
    u = np.zeros((nt, nth, nr, 3))
    u[..., 0] = 2 * q * (1 - RN**2) * (1 + 0.3 * RN * np.cos(TH) * np.sin(np.pi * T))
    u[..., 1] = 0.1 * q * np.sin(TH) * RN
    p = 100 * q * (1 - T) + 5 * RN * np.cos(TH) * np.sin(np.pi * T)
    f = {"tau": tau, "theta": theta, "rho_n": rho_n, "U_vcs": u, "U": u, "p": p, "p_kinematic": p / 1060}
    f["WSS_vcs"] = f["WSS"] = _wss(f, rng)
    return f


def machine() -> str:
    """One line: CPU, cores, Python, VTK and its render window (EGL, OSMesa, X)."""
    import pyvista as pv
    import vtk

    pl = pv.Plotter(off_screen=True, window_size=[8, 8])
    window = pl.ren_win.GetClassName()
    pl.close()
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "?")
    return (
        f"{platform.node()}: {cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"VTK {vtk.vtkVersion.GetVTKVersion()} ({window}), pyvista {pv.__version__}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cohort", choices=("aorta", "tubes"), default="aorta")
    ap.add_argument("-n", type=int, default=6, help="patients (default 6)")
    ap.add_argument("-o", "--out", type=Path, help="figure folder (default: a temporary one)")
    args = ap.parse_args()
    from vcs.atlas import compute_atlas
    from vcs.atlas.plots3d import write_3d_figures
    from vcs.vessel import VesselModel

    t0 = time.perf_counter()
    models = aorta_models(args.n) if args.cohort == "aorta" else tube_models(args.n)
    rng = np.random.default_rng(1)
    theta = np.linspace(0.0, 2 * np.pi, 32, endpoint=False)
    fields = {
        f"P{i}": demo_fields(float(np.mean(m.fitted_wall()(np.full(32, 0.5), theta))), rng)
        for i, m in enumerate(models)
    }
    atlas = compute_atlas({f"P{i}": m for i, m in enumerate(models)}, fields, {}, n_modes=2)
    mean = VesselModel.from_feature_vector(atlas.shape.mean, atlas.aligned_models[0])
    print(f"atlas of {len(models)} {args.cohort}: {time.perf_counter() - t0:.1f} s")
    out = args.out or Path(tempfile.mkdtemp(prefix="render_figures_"))
    out.mkdir(parents=True, exist_ok=True)
    written = write_3d_figures(atlas, mean, out)
    print(machine())
    for key, s in written["seconds"].items():
        print(f"{s:7.2f} s  {Path(written['files'][key]).stat().st_size / 1e3:6.0f} kB  {key}")
    total = sum(written["seconds"].values())
    print(f"{total:7.2f} s  total, {total / len(written['seconds']):.2f} s per figure ({out})")
    if args.out is None:
        shutil.rmtree(out)


def _wss(f: dict, rng: np.random.Generator) -> np.ndarray:
    """A WSS map (n_tau, n_theta, 3): 4 q (q the patient's mean velocity) modulated along and
    around the vessel, with two random-amplitude patterns."""
    T, TH = np.meshgrid(f["tau"], f["theta"], indexing="ij")
    q = float(f["U_vcs"][..., 0].mean())
    a, b = rng.normal(size=2)
    w = np.zeros((*T.shape, 3))
    w[..., 0] = 4 * q * (1 + 0.4 * np.sin(np.pi * T) * np.cos(TH)) + 0.3 * a * q * np.sin(2 * np.pi * T) * np.cos(TH)
    w[..., 1] = 0.5 * b * q * np.sin(TH)
    return w


if __name__ == "__main__":
    main()
