"""`vcs fit`: fit the VCS and the wall model of a vessel section, write model.json and its report."""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from vcs.cli._args import (
    OutputFolder,
    add_point_argument,
    non_negative_int,
    output_dir,
    positive_int,
    seconds_since_process_start,
    write_json,
)

OUTPUTS = ("centerline.vtp", "wall_residuals.vtp", "residual_map.png", "fit_report.json", "model.json")
"""The files `vcs fit` writes (or removes when a run no longer writes them), in the order they are put in place:
model.json last."""


def cmd_fit(args: argparse.Namespace) -> None:
    """Run `vcs fit`: model.json, fit_report.json, centerline.vtp, wall_residuals.vtp in ``args.output``.

    The outputs are built in a hidden temporary folder and put in place together when the fit
    succeeds (model.json last); a failed or interrupted fit into a folder holding an earlier fit
    leaves that fit whole and usable, and a failed one writes ``fit_failed.json`` beside it
    (:class:`vcs.cli._args.OutputFolder`).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``fit`` arguments (see :func:`add_commands`): ``mesh``, ``output``, ``units``,
        ``inlet``/``outlet`` (x,y,z strings, mesh units), ``inlet_cap``/``outlet_cap``, ``cap_array``,
        ``L``, ``K``, ``R``, ``recentre``, ``residual_png``.

    Raises
    ------
    VCSInputError
        Bad input (reported by :func:`vcs.cli.main.main` as one line, exit code 2).
    """
    from vcs.mesh import write_points_vtp, write_polyline_vtp
    from vcs.vessel import fit_vessel

    startup = seconds_since_process_start()
    out = output_dir(args.output, args.mesh, args.inlet_cap, args.outlet_cap, names=(*OUTPUTS, "fit_failed.json"))
    with OutputFolder(out, OUTPUTS, "fit") as folder:
        model, report, wall_fit = fit_vessel(
            args.mesh,
            units=args.units,
            inlet=args.inlet,
            outlet=args.outlet,
            inlet_cap=args.inlet_cap,
            outlet_cap=args.outlet_cap,
            cap_array=args.cap_array,
            L=args.L,
            K=args.K,
            R=args.R,
            recentre_iterations=args.recentre,
        )
        t_outputs = time.perf_counter()
        s = model.scale_to_mm
        tau = np.linspace(0, 1, 401)
        t, v1, v2 = model.vcs.frame(tau)
        write_polyline_vtp(
            folder.file("centerline.vtp"),
            model.vcs.curve(tau) / s,
            {"tau": tau, "t": t, "v1": v1, "v2": v2, "curvature_per_mm": model.vcs.curvature(tau)},
        )
        if wall_fit is not None:
            write_points_vtp(
                folder.file("wall_residuals.vtp"),
                wall_fit.points / s,
                {
                    "residual": wall_fit.residual / s,
                    "tau": wall_fit.tau,
                    "theta": wall_fit.theta,
                    "rho": wall_fit.rho / s,
                    "used": wall_fit.used.astype(np.int8),
                    "reason": wall_fit.reason,
                },
            )
            if args.residual_png:
                from vcs.plots import residual_map

                residual_map(wall_fit, folder.file("residual_map.png"))
        report["outputs_units"] = model.units
        timings = report["timings_s"]
        timings["outputs"] = time.perf_counter() - t_outputs  # fit_report.json and model.json: ~ms
        timings["startup"] = startup
        timings["command"] = None if startup is None else startup + timings["total"] + timings["outputs"]
        write_json(folder.file("fit_report.json"), report)
        model.save(folder.file("model.json"))  # put in place last: its presence means the fit is complete
    msg = f"fitted {args.mesh}: ends by {report['ends_method']}, length {report['centerline_length_mm']:.1f} mm"
    if wall_fit is not None:
        msg += (
            f", residual mean {report['residual_mean_mm']:.4f} mm over {report['n_points_used']}"
            f"/{report['n_wall_points']} wall points"
        )
    print(msg + f" -> {out}")
    for w in report["warnings"]:
        print(f"warning: {w}", file=sys.stderr)


def _knots(text: str) -> int | str:
    """``--L``: ``auto`` or a positive number of knots.

    Parameters
    ----------
    text : str
        The option's value.

    Returns
    -------
    int or str
        The number, or ``"auto"``.
    """
    return "auto" if text.strip().lower() == "auto" else positive_int(text)


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `vcs fit` on the subparsers object of the `vcs` parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        As returned by :meth:`argparse.ArgumentParser.add_subparsers`.
    """
    f = subparsers.add_parser("fit", help="fit the VCS and wall model of a vessel section")
    f.add_argument("mesh", help="wall surface: STL, VTP, VTK, PLY or OBJ")
    f.add_argument(
        "-o",
        "--output",
        required=True,
        help="output directory (created if missing; its parent must exist); a failed or interrupted fit keeps an "
        "earlier fit there whole (a failed one writes fit_failed.json beside it)",
    )
    f.add_argument(
        "--units",
        default="auto",
        choices=["auto", "mm", "cm", "m"],
        help="units of the mesh; auto: from the lumen radius, the extent as a tie-breaker (reported)",
    )
    add_point_argument(
        f,
        "--inlet",
        metavar="END",
        help="inlet (tau = 0): a point x,y,z in or near its end plane (mesh units; --inlet -40,0,0 is fine), "
        "or an end listed by `vcs ends`: end:N (its index) or NAME=VALUE (its cell-array label)",
    )
    add_point_argument(f, "--outlet", metavar="END", help="outlet (tau = 1): as --inlet")
    f.add_argument("--inlet-cap", help="surface file of the inlet cap (same units as the mesh)")
    f.add_argument("--outlet-cap", help="surface file of the outlet cap")
    f.add_argument("--cap-array", default="auto", help="cell array labelling caps (auto: ModelFaceID, CapID, ...)")
    f.add_argument(
        "--L",
        type=_knots,
        default="auto",
        help="centerline interior knots: a number (paper: 9) or auto (default: the smallest L >= 9 "
        "keeping the centerline inside the lumen and |c'| constant within 2 %%)",
    )
    f.add_argument("--K", type=positive_int, default=19, help="wall knots in tau (paper: 19)")
    f.add_argument("--R", type=positive_int, default=15, help="wall knots in theta (paper: 15)")
    f.add_argument(
        "--recentre",
        type=non_negative_int,
        default=3,
        help="centerline re-centring iterations on the wall (0 = paper's A*+spline only)",
    )
    f.add_argument("--residual-png", action="store_true", help="also write residual_map.png")
    f.set_defaults(func=cmd_fit)
