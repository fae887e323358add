"""Sensitivity of the wall-model residuals to the knot numbers L, K, R (paper Section 3.1, Fig. 5)."""

from __future__ import annotations

import itertools
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vcs.ends import find_ends
from vcs.errors import VCSInputError
from vcs.io import Surface
from vcs.model import VesselCoordinateSystem
from vcs.wall import fit_wall

log = logging.getLogger(__name__)


def parse_range(text: str, name: str) -> list[int]:
    """Parse a knot-number range ``'a:b:s'`` (b inclusive) or a single ``'a'`` into a list of ints.

    Parameters
    ----------
    text : str
        ``a:b:s`` with 1 <= a <= b and s >= 1, or ``a`` (>= 1).
    name : str
        Option name for the error message (``K`` -> ``--K``).

    Returns
    -------
    list of int
        a, a + s, ... up to b.

    Raises
    ------
    VCSInputError
        When ``text`` is not such a range.
    """
    try:
        parts = [int(p) for p in str(text).split(":")]
    except ValueError:
        parts = []
    if len(parts) == 1:
        parts = [parts[0], parts[0], 1]
    if len(parts) != 3 or parts[2] < 1 or parts[0] < 1 or parts[1] < parts[0]:
        raise VCSInputError(f"--{name} '{text}' is not a range; write a:b:s with 1 <= a <= b and s >= 1")
    return list(range(parts[0], parts[1] + 1, parts[2]))


def residual_sweep(
    surfaces: list[Surface], Ls: Sequence[int], Ks: Sequence[int], Rs: Sequence[int]
) -> list[dict[str, Any]]:
    """Cohort-averaged mean and 75th-percentile residuals (Eq. 11) for every (L, K, R) (Section 3.1).

    The centerline is fitted once per (mesh, L); the wall model once per (mesh, L, K, R).

    Parameters
    ----------
    surfaces : list of Surface
        The cohort (mm); each must have its ends decidable without points (open loops or labelled
        caps).
    Ls, Ks, Rs : sequences of int
        Interior knots of the centerline, and of the wall model in tau and theta.

    Returns
    -------
    list of dict
        One row per (L, K, R), sorted: ``L``, ``K``, ``R``, ``residual_mean_mm`` and
        ``residual_p75_mm`` (cohort means, mm), ``n_meshes``.
    """
    rows: dict[tuple[int, int, int], list[tuple[float, float]]] = {}
    for surf in surfaces:
        ends = find_ends(surf.vertices, surf.faces, surf.cell_data)
        wall_faces = surf.faces[ends.wall_mask]
        for L in Ls:
            vcs = VesselCoordinateSystem.from_surface(surf.vertices, surf.faces, ends, n_knots=L)
            for K, R in itertools.product(Ks, Rs):
                rep = fit_wall(vcs, surf.vertices, wall_faces, K=K, R=R).report
                rows.setdefault((L, K, R), []).append((rep["residual_mean_mm"], rep["residual_p75_mm"]))
    out = []
    for (L, K, R), vals in sorted(rows.items()):
        v = np.array(vals)
        out.append(
            {
                "L": L,
                "K": K,
                "R": R,
                "residual_mean_mm": float(v[:, 0].mean()),
                "residual_p75_mm": float(v[:, 1].mean()),
                "n_meshes": len(v),
            }
        )
    return out


def plot_sweep(rows: list[dict[str, Any]], path: Path | str) -> None:
    """Plot the mean residual over the (K, R) grid, one panel per L (paper Fig. 5 style).

    Parameters
    ----------
    rows : list of dict
        Output of :func:`residual_sweep`.
    path : Path or str
        Image file (format from the extension, e.g. ``.png``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    Ls = sorted({r["L"] for r in rows})
    Ks = sorted({r["K"] for r in rows})
    Rs = sorted({r["R"] for r in rows})
    fig, axes = plt.subplots(1, len(Ls), figsize=(4 * len(Ls), 3.5), dpi=110, squeeze=False)
    vmax = max(r["residual_mean_mm"] for r in rows)
    for ax, L in zip(axes[0], Ls):
        grid = np.full((len(Rs), len(Ks)), np.nan)
        for r in rows:
            if r["L"] == L:
                grid[Rs.index(r["R"]), Ks.index(r["K"])] = r["residual_mean_mm"]
        im = ax.imshow(
            grid,
            origin="lower",
            aspect="auto",
            vmin=0,
            vmax=vmax,
            extent=(Ks[0] - 0.5, Ks[-1] + 0.5, Rs[0] - 0.5, Rs[-1] + 0.5),
        )
        ax.set_xlabel("K (tau knots)")
        ax.set_ylabel("R (theta knots)")
        ax.set_title(f"L = {L}")
    fig.colorbar(im, ax=axes[0].tolist(), label="mean residual (mm)")
    fig.savefig(path)
    plt.close(fig)
