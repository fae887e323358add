"""Command line: `vcs fit|coords|cartesian|wall|grid|phantom|sensitivity`.

Bad input ends with one line on stderr naming the problem and the fix, and exit code 2.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import warnings
from pathlib import Path

import numpy as np

from vcs.errors import VCSInputError

log = logging.getLogger("vcs")


def _int_at_least(minimum: int):
    """argparse type: an integer >= ``minimum``."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"{v} must be >= {minimum}")
        return v

    return parse


_positive_int = _int_at_least(1)
_non_negative_int = _int_at_least(0)


def _out_dir(path: str) -> Path:
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise VCSInputError(f"output '{p}' exists and is not a directory; choose another -o")
    p.mkdir(parents=True, exist_ok=True)
    return p


def _not_an_input(output, *inputs) -> Path:
    """Refuse to overwrite a file the user gave as input."""
    out = Path(output)
    for i in inputs:
        if i is not None and out.resolve() == Path(i).resolve():
            raise VCSInputError(f"output '{out}' is also an input; choose another -o (inputs are never overwritten)")
    return out


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")


def cmd_fit(args) -> None:
    from vcs.mesh import write_points_vtp, write_polyline_vtp
    from vcs.vessel import fit_vessel

    out = _out_dir(args.output)
    for name in ("model.json", "fit_report.json", "centerline.vtp", "wall_residuals.vtp"):
        _not_an_input(out / name, args.mesh, args.inlet_cap, args.outlet_cap)
    model, report, wall_fit = fit_vessel(
        args.mesh, units=args.units, inlet=args.inlet, outlet=args.outlet,
        inlet_cap=args.inlet_cap, outlet_cap=args.outlet_cap, cap_array=args.cap_array,
        L=args.L, K=args.K, R=args.R, recentre_iterations=args.recentre,
    )
    s = model.scale_to_mm
    tau = np.linspace(0, 1, 401)
    t, v1, v2 = model.vcs.frame(tau)
    write_polyline_vtp(
        out / "centerline.vtp", model.vcs.curve(tau) / s,
        {"tau": tau, "t": t, "v1": v1, "v2": v2, "curvature_per_mm": model.vcs.curvature(tau)},
    )
    if wall_fit is not None:
        write_points_vtp(
            out / "wall_residuals.vtp", wall_fit.points / s,
            {"residual": wall_fit.residual / s, "tau": wall_fit.tau, "theta": wall_fit.theta,
             "rho": wall_fit.rho / s, "used": wall_fit.used.astype(np.int8), "reason": wall_fit.reason},
        )
        if args.residual_png:
            from vcs.plots import residual_map

            residual_map(wall_fit, out / "residual_map.png")
    report["outputs_units"] = model.units
    _write_json(out / "fit_report.json", report)
    model.save(out / "model.json")  # last and atomic: its presence means the fit is complete
    msg = f"fitted {args.mesh}: ends by {report['ends_method']}, length {report['centerline_length_mm']:.1f} mm"
    if wall_fit is not None:
        msg += (f", residual mean {report['residual_mean_mm']:.4f} mm over {report['n_points_used']}"
                f"/{report['n_wall_points']} wall points")
    print(msg + f" -> {out}")
    for w in report["warnings"]:
        print(f"warning: {w}", file=sys.stderr)


def cmd_coords(args) -> None:
    from vcs.io import read_points_table, write_csv
    from vcs.vessel import VesselModel

    model = VesselModel.load(args.model)
    s = model.scale_to_mm
    pts = read_points_table(args.points) * s
    tau, theta, rho, ok = model.vcs.to_vcs(pts)
    write_csv(_not_an_input(args.output, args.points, args.model), {"tau": tau, "theta": theta, "rho": rho / s, "in_omega": ok.astype(int)})
    print(f"{len(pts)} points -> {args.output} ({int((~ok).sum())} outside Omega)")


def cmd_cartesian(args) -> None:
    from vcs.io import read_table_columns, write_csv
    from vcs.vessel import VesselModel

    model = VesselModel.load(args.model)
    s = model.scale_to_mm
    tab = read_table_columns(args.coords, ("tau", "theta", "rho"))
    x = model.vcs.to_cartesian(tab[:, 0], tab[:, 1], tab[:, 2] * s) / s
    write_csv(_not_an_input(args.output, args.coords, args.model), {"x": x[:, 0], "y": x[:, 1], "z": x[:, 2]})
    print(f"{len(x)} points -> {args.output}")


def cmd_phantom(args) -> None:
    from vcs.phantom import make_phantom, write_stl

    ph = make_phantom(args.kind, seed=args.seed, resolution=args.resolution)
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_stl(ph, out)
    if args.params:
        _write_json(Path(args.params), {"kind": ph.kind, "seed": args.seed, **ph.params})
    print(f"{args.kind} phantom (seed {args.seed}, {len(ph.faces)} triangles) -> {out}")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vcs", description=__doc__.splitlines()[0])
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    sub = p.add_subparsers(dest="command", required=True)

    f = sub.add_parser("fit", help="fit the VCS and wall model of a vessel section")
    f.add_argument("mesh", help="wall surface: STL, VTP, VTK, PLY or OBJ")
    f.add_argument("-o", "--output", required=True, help="output directory")
    f.add_argument("--units", default="auto", choices=["auto", "mm", "cm", "m"],
                   help="units of the mesh; auto: largest extent <1 -> m, <25 -> cm, else mm (reported)")
    f.add_argument("--inlet", help="x,y,z point in or near the inlet end plane (tau = 0), mesh units")
    f.add_argument("--outlet", help="x,y,z point in or near the outlet end plane (tau = 1), mesh units")
    f.add_argument("--inlet-cap", help="surface file of the inlet cap (same units as the mesh)")
    f.add_argument("--outlet-cap", help="surface file of the outlet cap")
    f.add_argument("--cap-array", default="auto", help="cell array labelling caps (auto: ModelFaceID, CapID, ...)")
    f.add_argument("--L", type=_positive_int, default=9, help="centerline interior knots (paper: 9)")
    f.add_argument("--K", type=_positive_int, default=19, help="wall knots in tau (paper: 19)")
    f.add_argument("--R", type=_positive_int, default=15, help="wall knots in theta (paper: 15)")
    f.add_argument("--recentre", type=_non_negative_int, default=3,
                   help="centerline re-centring iterations on the wall (0 = paper's A*+spline only)")
    f.add_argument("--residual-png", action="store_true", help="also write residual_map.png")
    f.set_defaults(func=cmd_fit)

    c = sub.add_parser("coords", help="VCS coordinates of points")
    c.add_argument("model", help="model.json from `vcs fit`")
    c.add_argument("points", help=".csv with x,y,z columns or .npy (N, 3), mesh units")
    c.add_argument("-o", "--output", required=True, help="output CSV: tau,theta,rho,in_omega")
    c.set_defaults(func=cmd_coords)

    k = sub.add_parser("cartesian", help="points from VCS coordinates (inverse of coords)")
    k.add_argument("model", help="model.json from `vcs fit`")
    k.add_argument("coords", help="CSV with tau,theta,rho columns (rho in mesh units)")
    k.add_argument("-o", "--output", required=True, help="output CSV: x,y,z")
    k.set_defaults(func=cmd_cartesian)

    ph = sub.add_parser("phantom", help="write a synthetic vessel surface")
    ph.add_argument("--kind", default="aorta", choices=["aorta", "tube", "torus", "helix"])
    ph.add_argument("--seed", type=int, default=0)
    ph.add_argument("--resolution", type=float, default=1.0, help="target triangle edge (mm)")
    ph.add_argument("--params", help="also write the generator parameters to this JSON")
    ph.add_argument("-o", "--output", required=True, help="output STL (mm)")
    ph.set_defaults(func=cmd_phantom)

    from vcs import cli_wall

    cli_wall.add_commands(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    if not args.verbose:  # numerical warnings are for developers; users get fit_report warnings
        warnings.simplefilter("ignore")
    try:
        args.func(args)
    except VCSInputError as exc:
        print(f"vcs {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"vcs {args.command}: error: out of memory; coarsen the input mesh or the grid", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug, not bad input: one line, the traceback only with -v
        if args.verbose:
            raise
        print(f"vcs {args.command}: internal error: {type(exc).__name__}: {exc} (rerun with -v and report it)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
