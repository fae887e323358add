"""`vcs phantom`: write a synthetic vessel surface (STL, mm) and optionally its generator parameters."""

from __future__ import annotations

import argparse
from pathlib import Path

from vcs.cli._args import write_json
from vcs.errors import VCSInputError


def cmd_phantom(args: argparse.Namespace) -> None:
    """Run `vcs phantom`: the STL of a synthetic vessel (mm), and its parameters as JSON if asked.

    Parameters
    ----------
    args : argparse.Namespace
        ``kind`` (aorta, tube, torus, helix), ``seed``, ``resolution`` (target triangle edge, mm),
        ``params`` (JSON path or None) and ``output`` (STL path; parent directories are created).
    """
    from vcs.phantoms.factory import make_phantom
    from vcs.phantoms.sweep import write_stl

    out = Path(args.output)
    if args.params and Path(args.params).resolve() == out.resolve():
        raise VCSInputError(f"--params '{args.params}' is the output STL; give another file for the parameters")
    ph = make_phantom(args.kind, seed=args.seed, resolution=args.resolution)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_stl(ph, out)
    if args.params:
        write_json(Path(args.params), {"kind": ph.kind, "seed": args.seed, **ph.params})
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
    ph.add_argument("--seed", type=int, default=0)
    ph.add_argument("--resolution", type=float, default=1.0, help="target triangle edge (mm)")
    ph.add_argument("--params", help="also write the generator parameters to this JSON")
    ph.add_argument("-o", "--output", required=True, help="output STL (mm)")
    ph.set_defaults(func=cmd_phantom)
