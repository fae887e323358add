"""`vcs phantom`: write a synthetic vessel surface (STL, mm) and optionally its generator parameters."""

from __future__ import annotations

import argparse
from pathlib import Path

from vcs.cli._args import atomic_file, float_at_least, non_negative_int, output_file, write_json
from vcs.errors import VCSInputError


def cmd_phantom(args: argparse.Namespace) -> None:
    """Run `vcs phantom`: the STL of a synthetic vessel (mm), and its parameters as JSON if asked.

    An existing file is never replaced unless ``--overwrite`` is given (``-o`` could name a real
    vessel mesh); both files are written atomically.

    Parameters
    ----------
    args : argparse.Namespace
        ``kind`` (aorta, tube, torus, helix), ``seed``, ``resolution`` (target triangle edge, mm),
        ``params`` (JSON path or None), ``output`` (STL path; its directory must exist) and
        ``overwrite``.

    Raises
    ------
    VCSInputError
        An output exists (without ``--overwrite``), is a directory, has another extension, or its
        directory is missing or not writable; ``--params`` is the output STL.
    """
    from vcs.phantoms.factory import make_phantom
    from vcs.phantoms.sweep import write_stl

    out = output_file(args.output, suffixes=(".stl",), overwrite=args.overwrite)
    params = None
    if args.params:
        if Path(args.params).resolve() == out.resolve():
            raise VCSInputError(f"--params '{args.params}' is the output STL; give another file for the parameters")
        params = output_file(args.params, suffixes=(".json",), overwrite=args.overwrite, option="--params")
    ph = make_phantom(args.kind, seed=args.seed, resolution=args.resolution)
    with atomic_file(out) as tmp:
        write_stl(ph, tmp)
        if params is not None:
            with atomic_file(params) as tmp_params:
                write_json(tmp_params, {"kind": ph.kind, "seed": args.seed, **ph.params})
    print(f"{args.kind} phantom (seed {args.seed}, {len(ph.faces)} triangles) -> {out}")


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `vcs phantom` on the subparsers object of the `vcs` parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        As returned by :meth:`argparse.ArgumentParser.add_subparsers`.
    """
    ph = subparsers.add_parser("phantom", help="write a synthetic vessel surface")
    ph.add_argument("--kind", default="aorta", choices=["aorta", "tube", "torus", "helix"])
    ph.add_argument("--seed", type=non_negative_int, default=0, help="random seed (>= 0)")
    ph.add_argument("--resolution", type=float_at_least(0.1), default=1.0, help="target triangle edge, mm (>= 0.1)")
    ph.add_argument("--params", help="also write the generator parameters to this .json")
    ph.add_argument("-o", "--output", required=True, help="output .stl (mm); its directory must exist")
    ph.add_argument("--overwrite", action="store_true", help="replace existing output files (refused otherwise)")
    ph.set_defaults(func=cmd_phantom)
