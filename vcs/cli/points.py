"""`vcs coords` and `vcs cartesian`: points <-> VCS coordinates (tau, theta, rho) with a fitted model."""

from __future__ import annotations

import argparse

from vcs.cli._args import atomic_file, output_file

CSV = (".csv", ".txt")


def cmd_coords(args: argparse.Namespace) -> None:
    """Run `vcs coords`: write tau, theta, rho, in_omega of the points to a CSV.

    Parameters
    ----------
    args : argparse.Namespace
        ``model`` (model.json), ``points`` (.csv with x,y,z or .npy (N, 3), mesh units) and
        ``output`` (CSV; rho in mesh units, tau in [0, 1], theta in rad).
    """
    from vcs.io import read_points_table, write_csv
    from vcs.vessel import VesselModel

    out = output_file(args.output, args.points, args.model, suffixes=CSV)
    model = VesselModel.load(args.model)
    s = model.scale_to_mm
    pts = read_points_table(args.points) * s
    tau, theta, rho, ok = model.vcs.to_vcs(pts)
    with atomic_file(out) as tmp:
        write_csv(tmp, {"tau": tau, "theta": theta, "rho": rho / s, "in_omega": ok.astype(int)})
    print(f"{len(pts)} points -> {args.output} ({int((~ok).sum())} outside Omega)")


def cmd_cartesian(args: argparse.Namespace) -> None:
    """Run `vcs cartesian` (inverse of `vcs coords`): write x, y, z of VCS coordinates to a CSV.

    Parameters
    ----------
    args : argparse.Namespace
        ``model`` (model.json), ``coords`` (CSV with tau, theta, rho columns, rho in mesh units)
        and ``output`` (CSV, mesh units).
    """
    from vcs.io import read_table_columns, write_csv
    from vcs.vessel import VesselModel

    out = output_file(args.output, args.coords, args.model, suffixes=CSV)
    model = VesselModel.load(args.model)
    s = model.scale_to_mm
    tab = read_table_columns(args.coords, ("tau", "theta", "rho"))
    x = model.vcs.to_cartesian(tab[:, 0], tab[:, 1], tab[:, 2] * s) / s
    with atomic_file(out) as tmp:
        write_csv(tmp, {"x": x[:, 0], "y": x[:, 1], "z": x[:, 2]})
    print(f"{len(x)} points -> {args.output}")


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `vcs coords` and `vcs cartesian` on the subparsers object of the `vcs` parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        As returned by :meth:`argparse.ArgumentParser.add_subparsers`.
    """
    c = subparsers.add_parser("coords", help="VCS coordinates of points")
    c.add_argument("model", help="model.json from `vcs fit`")
    c.add_argument("points", help=".csv with x,y,z columns or .npy (N, 3), mesh units")
    c.add_argument("-o", "--output", required=True, help="output .csv (or .txt): tau,theta,rho,in_omega")
    c.set_defaults(func=cmd_coords)

    k = subparsers.add_parser("cartesian", help="points from VCS coordinates (inverse of coords)")
    k.add_argument("model", help="model.json from `vcs fit`")
    k.add_argument("coords", help="CSV with tau,theta,rho columns (rho in mesh units)")
    k.add_argument("-o", "--output", required=True, help="output .csv (or .txt): x,y,z")
    k.set_defaults(func=cmd_cartesian)
