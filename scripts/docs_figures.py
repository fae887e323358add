#!/usr/bin/env python3
"""Copy the figures the documentation shows from a finished run into docs/figures/.

    bash scripts/demo.sh                                   # the demo cohort -> results/
    .venv/bin/python scripts/docs_figures.py [RESULTS] [--qc PATIENT] [--prefix NAME]

From RESULTS (default ``results``, the demo's): the 3-D atlas figures of docs/guide/figures.md
(mean shape, shape mode 1, mean U, p and WSS, WSS mode 1), one flat (tau, theta) map and the QC
sheet of one patient (default: the first in the atlas), as lossless PNGs under docs/figures/ (the
QC sheet scaled to 1100 pixels wide; ``--prefix real_`` for a real cohort's run).
Prints what it wrote and the total size.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
QC_WIDTH = 1100  # pixels: a QC sheet is 1440 wide
ATLAS_FIGURES = (
    "shape_mean_3d",
    "shape_mode1_3d",
    "flow_U_mean_3d",
    "flow_p_mean_3d",
    "flow_WSS_mean_3d",
    "flow_WSS_mode1_3d",
    "flow_WSS_mode1",
)


def copy_png(src: Path, dst: Path, *, width: int | None = None) -> None:
    """``src`` as a lossless, optimised PNG (a palette would band the colour bars), scaled down to
    ``width`` pixels (Lanczos) when it is wider."""
    from PIL import Image

    im = Image.open(src).convert("RGB")
    if width and im.width > width:
        im = im.resize((width, round(im.height * width / im.width)), Image.Resampling.LANCZOS)
    im.save(dst, optimize=True)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="?", type=Path, default=Path("results"), help="a finished run's results/")
    ap.add_argument("--qc", help="patient whose QC sheet to copy (default: the atlas's first)")
    ap.add_argument("--prefix", default="", help="prefix of the copied files' names (e.g. real_)")
    ap.add_argument("-o", "--out", type=Path, default=REPO / "docs" / "figures")
    args = ap.parse_args(argv)
    atlas_json = args.results / "atlas" / "atlas.json"
    if not atlas_json.is_file():
        print(
            f"docs_figures: error: {atlas_json} not found; run the workflow first (bash scripts/demo.sh)",
            file=sys.stderr,
        )
        return 2
    figures = args.results / "atlas" / "figures"
    patient = args.qc or json.loads(atlas_json.read_text())["patients_included"][0]
    sources = {name: figures / f"{name}.png" for name in ATLAS_FIGURES}
    sources["qc"] = args.results / "patients" / patient / "qc.png"
    missing = [str(p) for p in sources.values() if not p.is_file()]
    if missing:
        print(f"docs_figures: error: not in this run: {', '.join(missing)}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    total = 0
    for name, src in sources.items():
        dst = args.out / f"{args.prefix}{name}.png"
        copy_png(src, dst, width=QC_WIDTH if name == "qc" else None)
        total += dst.stat().st_size
        shown = dst.relative_to(REPO) if dst.is_relative_to(REPO) else dst
        print(f"{dst.stat().st_size / 1e3:6.0f} kB  {shown}  <- {src}")
    print(f"{total / 1e3:6.0f} kB  total")
    return 0


if __name__ == "__main__":
    sys.exit(main())
