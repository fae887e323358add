"""Figures (matplotlib, Agg backend: headless)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from vcs.surface import WallMesh
    from vcs.wall import WallFit


def residual_map(wall_fit: WallFit, path: Path | str, title: str | None = None) -> None:
    """Plot the wall residual r(p) (Eq. 11) over the (tau, theta) plane, like the paper's Fig. 4.

    Parameters
    ----------
    wall_fit : WallFit
        Result of :func:`vcs.wall.fit_wall`; residuals in mm, theta in rad.
    path : Path or str
        Image file (format from the extension, e.g. ``.png``).
    title : str or None
        Figure title; None: the mean residual of the used vertices (mm).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 3.2), dpi=120)
    u = wall_fit.used
    sc = ax.scatter(wall_fit.tau[u], wall_fit.theta[u], c=wall_fit.residual[u], s=2, cmap="viridis")
    ax.scatter(wall_fit.tau[~u], wall_fit.theta[~u], c="lightgrey", s=1, label="not used")
    ax.set_xlabel("tau")
    ax.set_ylabel("theta (rad)")
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 2 * np.pi)
    fig.colorbar(sc, ax=ax, label="residual (mm)")
    ax.set_title(title or f"wall residuals (mean {np.nanmean(wall_fit.residual[u]):.3f} mm)")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def render_wall(mesh: WallMesh, path: Path | str, reference: tuple[ArrayLike, Any] | None = None) -> None:
    """Render a wall mesh off screen (grey, two views) with optional reference points (red dots).

    Parameters
    ----------
    mesh : WallMesh
        Vertices in mm.
    path : Path or str
        Image file (e.g. ``.png``); its folder is created.
    reference : tuple or None
        ``(points, ...)``: only the first item is used, (P, 3) float points in mm (e.g. the
        input mesh's vertices, or ``(wall_fit.points, None)``).
    """
    import pyvista as pv

    pv.OFF_SCREEN = True

    Path(path).parent.mkdir(parents=True, exist_ok=True)
    faces = np.hstack([np.full((len(mesh.faces), 1), 3), mesh.faces]).ravel()
    poly = pv.PolyData(mesh.vertices, faces)
    p = pv.Plotter(off_screen=True, window_size=[1000, 500], shape=(1, 2))
    for col, view in enumerate(("view_yz", "view_xz")):
        p.subplot(0, col)
        p.add_mesh(poly, color="lightgray", smooth_shading=True)
        if reference is not None:
            p.add_points(np.asarray(reference[0]), color="red", point_size=1, opacity=0.15)
        getattr(p, view)()
    p.screenshot(str(path))
    p.close()
