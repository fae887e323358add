"""``make_phantom``: build a phantom of any kind (analytic tube/torus/helix or seeded aorta)."""
from __future__ import annotations

import numpy as np

from vcs.errors import VCSInputError
from vcs.phantoms.analytic import _helix, _torus, _tube
from vcs.phantoms.aorta import AORTA_EDGE_SCALE, _aorta
from vcs.phantoms.sweep import Phantom, _finish, _reach_ok

__all__ = ["KINDS", "make_phantom"]

KINDS = ("tube", "torus", "helix", "aorta")


def make_phantom(kind: str, *, seed: int = 0, resolution: float = 1.0, **overrides) -> Phantom:
    """Build a phantom of ``kind`` (tube, torus, helix, aorta); see the module docstring.

    ``resolution`` is the target triangle edge (mm; quad sides, diagonals are sqrt(2) longer) for
    the analytic kinds and ``AORTA_EDGE_SCALE * resolution`` for the aorta. ``seed`` only affects
    the aorta. ``overrides`` set generator parameters by name (unknown names are an error); all
    parameters, drawn or derived, are returned in ``Phantom.params``.
    """
    if kind not in KINDS:
        raise VCSInputError(f"unknown phantom kind '{kind}'; choose one of {', '.join(KINDS)}")
    resolution = float(resolution)
    if not np.isfinite(resolution) or resolution <= 0:
        raise VCSInputError(f"phantom resolution must be a positive edge length in mm, got {resolution}")
    if kind == "aorta":
        h = AORTA_EDGE_SCALE * resolution
        V, F, p, centerline, radius, frame, ring = _aorta(h, int(seed), **overrides)
    else:
        h = resolution
        V, F, p, centerline, radius, frame, ring = {"tube": _tube, "torus": _torus, "helix": _helix}[kind](h, **overrides)
        if kind != "tube" and not _reach_ok(V, ring, p["n_phi"], centerline, p["length_mm"]):
            raise VCSInputError(f"{kind} phantom self-intersects with parameters {overrides}; change them")
    params = {"kind": kind, "seed": int(seed), "resolution": resolution, "edge_mm": h, **p}
    return _finish(kind, V, F, params, centerline, radius, frame)
