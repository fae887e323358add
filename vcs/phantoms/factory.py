"""``make_phantom``: build a phantom of any kind (analytic tube/torus/helix or seeded aorta)."""

from __future__ import annotations

import numpy as np

from vcs.errors import VCSInputError
from vcs.phantoms.analytic import _helix, _torus, _tube
from vcs.phantoms.aorta import AORTA_EDGE_SCALE, _aorta
from vcs.phantoms.sweep import Phantom, _finish, _reach_ok

__all__ = ["KINDS", "make_phantom"]

#: Phantom kinds accepted by :func:`make_phantom`.
KINDS = ("tube", "torus", "helix", "aorta")


def make_phantom(kind: str, *, seed: int = 0, resolution: float = 1.0, **overrides: float | bool) -> Phantom:
    """Build a phantom of ``kind``: an open swept tube with its exact generating geometry (mm).

    Parameters
    ----------
    kind : {"tube", "torus", "helix", "aorta"}
        Analytic kinds: :mod:`vcs.phantoms.analytic`; the seeded aorta: :mod:`vcs.phantoms.aorta`.
    seed : int
        Random seed of the aorta (ignored by the analytic kinds, but recorded in ``params``).
    resolution : float
        Target triangle edge (mm; quad sides, diagonals are sqrt(2) longer) for the analytic kinds;
        ``AORTA_EDGE_SCALE * resolution`` mm for the aorta.
    **overrides
        Generator parameters by name (unknown names are an error).

    Returns
    -------
    Phantom
        Vertices (n_s * n_phi, 3) mm, outward faces (2 (n_s - 1) n_phi, 3), the exact centreline,
        frame and radius, and every parameter (given, drawn or derived) in ``params``.

    Raises
    ------
    VCSInputError
        Unknown kind or parameter, non-positive resolution, or parameters giving a
        self-intersecting (or, for the aorta, anatomically out-of-range) surface.

    Examples
    --------
    A straight tube of radius 5 mm: every vertex lies 5 mm from its axis, the z axis.

    >>> import numpy as np
    >>> from vcs import make_phantom
    >>> tube = make_phantom("tube", radius_mm=5.0, length_mm=40.0)
    >>> tube.params["n_triangles"], tube.params["length_mm"]
    (2560, 40.0)
    >>> bool(np.allclose(np.hypot(tube.vertices[:, 0], tube.vertices[:, 1]), 5.0, atol=1e-12))
    True
    >>> tube.outlet_center
    array([ 0.,  0., 40.])
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
        build = {"tube": _tube, "torus": _torus, "helix": _helix}[kind]
        V, F, p, centerline, radius, frame, ring = build(h, **overrides)
        if kind != "tube" and not _reach_ok(V, ring, p["n_phi"], centerline, p["length_mm"]):
            raise VCSInputError(f"{kind} phantom self-intersects with parameters {overrides}; change them")
    params = {"kind": kind, "seed": int(seed), "resolution": resolution, "edge_mm": h, **p}
    return _finish(kind, V, F, params, centerline, radius, frame)
