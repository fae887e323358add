"""`vcs sensitivity`: wall-model residuals over ranges of the knot numbers L, K, R (paper Fig. 5)."""

from __future__ import annotations

import argparse

import numpy as np

from vcs.cli._args import OutputFolder, output_dir

OUTPUTS = ("sensitivity.csv", "sensitivity.png")


def cmd_sensitivity(args: argparse.Namespace) -> None:
    """Run `vcs sensitivity`: sensitivity.csv and sensitivity.png of a cohort's residual sweep.

    Parameters
    ----------
    args : argparse.Namespace
        ``meshes`` (surfaces whose two ends are found automatically), ``L``, ``K``, ``R`` (range
        strings ``a:b:s`` or ``a``), ``units`` and ``output`` (directory, created when missing; its
        parent must exist). Both files are put in place when the sweep succeeds; a failed or
        interrupted sweep leaves an earlier sweep's files whole (a failed one writes
        ``sensitivity_failed.json`` beside them).
        Residuals are in mm.

    Raises
    ------
    VCSInputError
        A range string is malformed, or a mesh is unreadable.
    """
    from vcs.io import read_surface, write_csv
    from vcs.sensitivity import parse_range, plot_sweep, residual_sweep

    Ls, Ks, Rs = (parse_range(getattr(args, n), n) for n in ("L", "K", "R"))
    out = output_dir(args.output, *args.meshes, names=(*OUTPUTS, "sensitivity_failed.json"))  # before the sweep
    with OutputFolder(out, OUTPUTS, "sensitivity") as folder:
        surfaces = [read_surface(m, args.units) for m in args.meshes]
        rows = residual_sweep(surfaces, Ls, Ks, Rs)
        write_csv(folder.file("sensitivity.csv"), {k: np.array([r[k] for r in rows]) for k in rows[0]})
        plot_sweep(rows, folder.file("sensitivity.png"))
    best = min(rows, key=lambda r: r["residual_mean_mm"])
    print(
        f"{len(rows)} settings x {len(surfaces)} meshes -> {out}; lowest mean residual "
        f"{best['residual_mean_mm']:.4f} mm at L={best['L']} K={best['K']} R={best['R']}"
    )


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `vcs sensitivity` on the subparsers object of the `vcs` parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        As returned by :meth:`argparse.ArgumentParser.add_subparsers`.
    """
    s = subparsers.add_parser("sensitivity", help="residuals over ranges of L, K, R for a cohort (paper Fig. 5)")
    s.add_argument("meshes", nargs="+", help="surfaces whose two ends are found automatically")
    s.add_argument("--L", default="9", help="range a:b:s of centerline knots")
    s.add_argument("--K", default="11:23:4", help="range a:b:s of wall knots in tau")
    s.add_argument("--R", default="7:15:4", help="range a:b:s of wall knots in theta")
    s.add_argument("--units", default="auto", choices=["auto", "mm", "cm", "m"])
    s.add_argument("-o", "--output", required=True, help="output directory (sensitivity.csv, sensitivity.png)")
    s.set_defaults(func=cmd_sensitivity)
