"""Pixel checks of the 3-D atlas figures (issue 26, item 4), as a reader judges a figure: not blank,
its colour range not saturated, coloured where the data is.

Used by the tests (``tests/vcs/test_atlas_figures3d.py`` on a synthetic atlas, the workflow tests on
real runs) and by ``bench/figure_pixels.py``, which prints the table for any finished run's
``results/atlas/figures/``. A figure of :mod:`vcs.atlas.plots3d` is a grid of equal panels
(:data:`vcs.atlas.plots3d.PANEL_3D_PX`); :func:`figure_layout` knows which panels of each carry
the colour map.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

#: A pixel is coloured when its largest and smallest channel differ by more (0-255 scale).
CHROMA = 40
#: Share of the colour map's 256 entries that counts as "at an end of the scale".
END_ENTRIES = 3


@dataclass(frozen=True)
class Layout:
    """Panels of a figure: ``cols`` x ``rows``, the colour map, and the panels drawn with it."""

    cmap: str
    cols: int
    rows: int
    field_panels: tuple[int, ...]


def figure_layout(name: str) -> Layout | None:
    """The layout of a 3-D atlas figure from its file name (without ``.png``); None when the
    name is not one of :func:`vcs.atlas.plots3d.write_3d_figures`' figures."""
    from vcs.atlas.plots3d import field_cmap

    if name == "shape_mean_3d":
        return Layout("viridis", 2, 1, (0, 1))
    if re.fullmatch(r"shape_mode\d+_3d", name):
        return Layout("RdBu_r", 3, 2, (0, 1, 3, 4))  # the walls, not the centerlines
    m = re.fullmatch(r"flow_(.+)_(mean|mode\d+)_3d", name)
    if not m:
        return None
    field, what = m.groups()
    cmap = field_cmap(field)
    volume = field in ("U", "p")
    if what == "mean":
        return Layout(cmap, 1, 1, (0,)) if field == "U" else Layout(cmap, 2, 1, (0, 1))
    return Layout(cmap, 4, 1, (0, 1, 2)) if volume else Layout(cmap, 4, 2, (0, 1, 2, 4, 5, 6))


def panel(img: np.ndarray, i: int, n_cols: int, n_rows: int = 1) -> np.ndarray:
    """Panel i (row-major) of a figure of n_rows x n_cols equal panels."""
    h, w = img.shape[0] // n_rows, img.shape[1] // n_cols
    r, c = divmod(i, n_cols)
    return img[r * h : (r + 1) * h, c * w : (c + 1) * w]


def foreground(img: np.ndarray) -> np.ndarray:
    """Pixels that are not the white background."""
    return np.any(img < 250, axis=-1)


def coloured(img: np.ndarray) -> np.ndarray:
    """Pixels of a colour (not white, grey, black: background, text, NaN, ghost)."""
    i = img.astype(int)
    return i.max(axis=-1) - i.min(axis=-1) > CHROMA


def end_fractions(img: np.ndarray, cmap: str, *, n: int = 8000) -> tuple[float, float]:
    """Fractions of the coloured pixels drawn in the lowest / highest :data:`END_ENTRIES` of the
    colour map's 256 entries: each pixel is matched to the entry it is a shade of (lighting only
    scales a colour: the entry c minimising |p - s c| over s in [0.3, 1.05]).

    Raises
    ------
    ValueError
        When the image has fewer than 200 coloured pixels (a blank figure).
    """
    from matplotlib import colormaps

    lut = colormaps[cmap](np.linspace(0.0, 1.0, 256))[:, :3].astype(np.float32) * 255
    px = img[coloured(img)].astype(np.float32)
    if len(px) <= 200:
        raise ValueError("no coloured pixels")
    px = px[np.random.default_rng(0).choice(len(px), min(n, len(px)), replace=False)]
    s = np.clip(px @ lut.T / np.sum(lut**2, axis=1), 0.3, 1.05)  # (n, 256)
    err = np.sum((px[:, None, :] - s[..., None] * lut[None]) ** 2, axis=-1)
    idx = np.argmin(err, axis=1)
    return float(np.mean(idx < END_ENTRIES)), float(np.mean(idx >= 256 - END_ENTRIES))


def figure_end_fractions(img: np.ndarray, layout: Layout) -> tuple[float, float]:
    """:func:`end_fractions` of the pixels of a figure's colour-mapped panels together
    (``img``: (H, W, 3) uint8)."""
    shown = np.concatenate([panel(img, i, layout.cols, layout.rows).reshape(-1, 3) for i in layout.field_panels])
    return end_fractions(shown[:, None], layout.cmap)
