#!/usr/bin/env python3
"""Copy the figures the documentation shows from a finished run into docs/figures/.

    bash scripts/demo.sh                                   # the demo cohort -> results/
    .venv/bin/python scripts/docs_figures.py [RESULTS] [--qc PATIENT] [--prefix NAME]

From RESULTS (default ``results``, the demo's): the 3-D atlas figures of docs/guide/figures.md
(mean shape, shape mode 1, mean U, p and WSS, WSS mode 1), one flat (tau, theta) map and the QC
sheet of one patient (default: the first in the atlas). Each is re-encoded as a palette PNG (a few
tens of kB instead of hundreds) under docs/figures/ (``--prefix real_`` for a real cohort's run).
Prints what it wrote and the total size.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
ATLAS_FIGURES = (
    "shape_mean_3d",
    "shape_mode1_3d",
    "flow_U_mean_3d",
    "flow_p_mean_3d",
    "flow_WSS_mean_3d",
    "flow_WSS_mode1_3d",
    "flow_WSS_mode1",
)


def palette_png(src: Path, dst: Path, colours: int = 128) -> None:
    """``src`` re-encoded as a palette PNG (median-cut, ``colours`` entries)."""
    from PIL import Image

    Image.open(src).convert("RGB").quantize(colours, method=Image.Quantize.MEDIANCUT).save(dst, optimize=True)


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
        palette_png(src, dst)
        total += dst.stat().st_size
        shown = dst.relative_to(REPO) if dst.is_relative_to(REPO) else dst
        print(f"{dst.stat().st_size / 1e3:6.0f} kB  {shown}  <- {src}")
    print(f"{total / 1e3:6.0f} kB  total")
    return 0


if __name__ == "__main__":
    sys.exit(main())
