"""`vcs lumen`: the patient's own surface closed into a CFD lumen, every end a patch (:mod:`vcs.lumen`)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from vcs.cli._args import atomic_file, output_file


def cmd_lumen(args: argparse.Namespace) -> None:
    """Run `vcs lumen`: the surface as a closed multi-solid STL (wall, inlet, outlet, branch_<k>).

    Parameters
    ----------
    args : argparse.Namespace
        ``mesh`` (the surface the model was fitted to), ``model`` (its model.json: the section's
        end centres and the mesh's units), ``output`` (.stl), ``ends`` (.json of the ends, or None)
        ``units`` (of the STL and the JSON: mm, cm or m), ``extend_inlet``/``extend_outlet`` (flow
        extensions in end diameters, every branch end takes the outlet's) and ``grid`` (the CFD's
        background grid frame the far faces are turned to: none, axes or inlet).

    Raises
    ------
    VCSInputError
        An output that does not end in .stl / .json or is an input; a surface that cannot be made
        a lumen (see :func:`vcs.lumen.build_lumen`).
    """
    import numpy as np

    from vcs.lumen import build_lumen, read_lumen_surface, write_lumen
    from vcs.vessel import VesselModel

    out = output_file(args.output, args.mesh, args.model, suffixes=(".stl",))
    ends_out = None
    if args.ends:
        ends_out = output_file(args.ends, args.mesh, args.model, suffixes=(".json",), option="--ends")
    model = VesselModel.load(args.model)
    c_in = np.asarray(model.meta["inlet_center_mm"], float)
    c_out = np.asarray(model.meta["outlet_center_mm"], float)
    surf = read_lumen_surface(args.mesh, model.units, c_in, c_out)
    lumen = build_lumen(
        surf, c_in, c_out, extend_inlet=args.extend_inlet, extend_outlet=args.extend_outlet, grid=args.grid
    )
    with atomic_file(out) as tmp:
        info = write_lumen(lumen, tmp, None, units=args.units)
    if ends_out is not None:
        with atomic_file(ends_out) as tmp:
            Path(tmp).write_text(json.dumps(info, indent=2) + "\n")
    ends = ", ".join(f"{e['name']} r={e['equivalent_radius']:.4g}" for e in info["ends"])
    print(
        f"lumen of {args.mesh}: {sum(info['triangles'].values())} triangles, closed, volume "
        f"{info['volume']:.6g} {args.units}3; ends {ends} ({args.units}) -> {out}"
    )


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `vcs lumen` on the subparsers object of the `vcs` parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        As returned by :meth:`argparse.ArgumentParser.add_subparsers`.
    """
    p = subparsers.add_parser(
        "lumen", help="close the patient's own surface into a CFD lumen (patches inlet, outlet, branch_<k>)"
    )
    p.add_argument("mesh", help="the surface `vcs fit` was given (its units are model.json's)")
    p.add_argument("--model", required=True, help="model.json from `vcs fit` of that surface (the section's ends)")
    p.add_argument("-o", "--output", required=True, help="output .stl (solids wall, inlet, outlet, branch_<k>)")
    p.add_argument("--ends", default=None, help="also write the ends (name, role, centre, area, source) as .json")
    p.add_argument("--units", default="m", choices=["mm", "cm", "m"], help="units of the outputs (OpenFOAM: m)")
    p.add_argument(
        "--extend-inlet", type=float, default=0.0, help="straight inlet extension, diameters (as `vcs wall`)"
    )
    p.add_argument(
        "--extend-outlet", type=float, default=0.0, help="straight extension of the outlet and every branch, diameters"
    )
    p.add_argument(
        "--grid",
        default="none",
        choices=["none", "axes", "inlet"],
        help="the CFD background grid (cfd.mesh.background_frame): an end within 30 degrees of a grid plane ends on it",
    )
    p.set_defaults(func=cmd_lumen)
