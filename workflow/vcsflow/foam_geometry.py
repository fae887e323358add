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


def write_tube_stl(path, radius: float = 0.01, length: float = 0.2, n_theta: int = 96, n_z: int = 80,
                   origin=(0.0, 0.0, 0.0)) -> Path:
    """Tube along +z from ``origin``; inlet disc at z=0, outlet disc at z=length, outward normals.
    Solids: ``wall``, ``inlet``, ``outlet`` (metres)."""
    path = Path(path)
    o = np.asarray(origin, float)
    th = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)
    zs = np.linspace(0.0, length, n_z + 1)
    ring = np.stack([radius * np.cos(th), radius * np.sin(th), np.zeros_like(th)], 1)
    with open(path, "w") as fh:
        fh.write("solid wall\n")
        for k in range(n_z):
            lo = ring + [0, 0, zs[k]] + o
            hi = ring + [0, 0, zs[k + 1]] + o
            for i in range(n_theta):
                j = (i + 1) % n_theta
                _facet(fh, lo[i], lo[j], hi[j])
                _facet(fh, lo[i], hi[j], hi[i])
        fh.write("endsolid wall\n")
        for name, z, sign in (("inlet", 0.0, -1), ("outlet", length, 1)):
            fh.write(f"solid {name}\n")
            c = o + [0, 0, z]
            rr = ring + c
            for i in range(n_theta):
                j = (i + 1) % n_theta
                if sign > 0:
                    _facet(fh, c, rr[i], rr[j])
                else:
                    _facet(fh, c, rr[j], rr[i])
            fh.write(f"endsolid {name}\n")
    return path
