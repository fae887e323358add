#!/usr/bin/env python3
"""Pixel checks of a finished run's 3-D atlas figures (vcs.atlas.figure_checks): for every
``*_3d.png`` in FIGURES, the share of coloured pixels (of its colour-mapped panels) at the low
and at the high end of its colour map, and whether the figure is blank.

    .venv/bin/python bench/figure_pixels.py results/atlas/figures [MORE_FIGURE_DIRS ...]

Prints one line per figure and the worst end share of each folder.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    from matplotlib.image import imread

    from vcs.atlas.figure_checks import figure_end_fractions, figure_layout

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path, help="results/atlas/figures of finished runs")
    args = ap.parse_args(argv)
    for folder in args.folders:
        worst = 0.0
        for png in sorted(folder.glob("*_3d.png")):
            layout = figure_layout(png.stem)
            if layout is None:
                continue
            img = (255 * imread(png)[..., :3]).round().astype(np.uint8)
            try:
                lo, hi = figure_end_fractions(img, layout)
            except ValueError as e:
                print(f"{png}: {e}")
                continue
            worst = max(worst, lo, hi)
            print(f"{100 * lo:5.1f} % low {100 * hi:5.1f} % high  {png}")
        print(f"{100 * worst:5.1f} % worst end share in {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
