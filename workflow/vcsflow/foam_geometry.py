"""Synthetic test geometry: a closed straight tube as a multi-solid ASCII STL (wall/inlet/outlet)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def _facet(fh, a, b, c):
    n = np.cross(b - a, c - a)
    n = n / (np.linalg.norm(n) or 1.0)
    fh.write(f"  facet normal {n[0]:.9g} {n[1]:.9g} {n[2]:.9g}\n    outer loop\n")
    for p in (a, b, c):
        fh.write(f"      vertex {p[0]:.9g} {p[1]:.9g} {p[2]:.9g}\n")
    fh.write("    endloop\n  endfacet\n")


def _frame(axis) -> np.ndarray:
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    t = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    e1 = np.cross(a, t)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(a, e1), a], 1)   # columns: e1, e2, axis


def write_tube_stl(path, radius: float = 0.01, length: float = 0.2, n_theta: int = 96, n_z: int = 80,
                   origin=(0.0, 0.0, 0.0), axis=(0.0, 0.0, 1.0)) -> Path:
    """Tube of ``radius`` and ``length`` from ``origin`` along ``axis``; inlet disc at the origin,
    outlet disc at the far end, outward normals. Solids: ``wall``, ``inlet``, ``outlet`` (metres).
    A tilted axis avoids axis-aligned flow, whose round-off transverse components keep
    OpenFOAM's normalised Ux/Uy residuals from dropping below ~1e-4."""
    path = Path(path)
    o = np.asarray(origin, float)
    rot = _frame(axis)
    th = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)
    zs = np.linspace(0.0, length, n_z + 1)
    ring = np.stack([radius * np.cos(th), radius * np.sin(th), np.zeros_like(th)], 1)
    tf = lambda p: o + rot @ (np.asarray(p, float) - o)  # noqa: E731
    _f = _facet
    def _facet_t(fh, a, b, c):  # noqa: E306
        _f(fh, tf(a), tf(b), tf(c))
    with open(path, "w") as fh:
        fh.write("solid wall\n")
        for k in range(n_z):
            lo = ring + [0, 0, zs[k]] + o
            hi = ring + [0, 0, zs[k + 1]] + o
            for i in range(n_theta):
                j = (i + 1) % n_theta
                _facet_t(fh, lo[i], lo[j], hi[j])
                _facet_t(fh, lo[i], hi[j], hi[i])
        fh.write("endsolid wall\n")
        for name, z, sign in (("inlet", 0.0, -1), ("outlet", length, 1)):
            fh.write(f"solid {name}\n")
            c = o + [0, 0, z]
            rr = ring + c
            for i in range(n_theta):
                j = (i + 1) % n_theta
                if sign > 0:
                    _facet_t(fh, c, rr[i], rr[j])
                else:
                    _facet_t(fh, c, rr[j], rr[i])
            fh.write(f"endsolid {name}\n")
    return path
