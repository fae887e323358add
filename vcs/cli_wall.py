"""Subcommands built on the wall model: `vcs wall`, `vcs grid`, `vcs sensitivity`."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vcs.errors import VCSInputError
from vcs.io import UNIT_TO_MM


def _positive_int(text: str) -> int:
    from vcs.cli import _positive_int as parse  # vcs.cli imports this module: import late

    return parse(text)


def cmd_wall(args) -> None:
    from vcs.surface import wall_mesh, write_multisolid_stl
    from vcs.vessel import VesselModel

    model = VesselModel.load(args.model)
    mesh = wall_mesh(model, n_tau=args.n_tau, n_theta=args.n_theta,
                     extend_inlet=args.extend_inlet, extend_outlet=args.extend_outlet)
    from vcs.cli import _not_an_input

    out = _not_an_input(args.output, args.model)
    if out.suffix.lower() != ".stl":
        raise VCSInputError(f"output '{out}' must end in .stl")
    out.parent.mkdir(parents=True, exist_ok=True)
    write_multisolid_stl(mesh, out, scale=1.0 / UNIT_TO_MM[args.units])
    print(f"wall (Eq. 8) with {len(mesh.faces)} triangles, solids wall/inlet/outlet, in {args.units} -> {out}")


def cmd_grid(args) -> None:
    import pyvista as pv

    from vcs.grid import measurement_grid
    from vcs.vessel import VesselModel

    model = VesselModel.load(args.model)
    g = measurement_grid(model, n_tau=args.n_tau, n_theta=args.n_theta, n_rho=args.n_rho, scheme=args.scheme)
    cells = np.hstack([np.full((len(g.cells), 1), 8), g.cells]).ravel()
    ug = pv.UnstructuredGrid(cells, np.full(len(g.cells), pv.CellType.HEXAHEDRON, np.uint8),
                             g.points / UNIT_TO_MM[args.units])
    ug.point_data["tau"] = g.tau
    ug.point_data["theta"] = g.theta
    ug.point_data["rho_n"] = g.rho_n
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    ug.save(str(out))
    print(f"{args.scheme} grid {args.n_tau}x{args.n_theta}x{args.n_rho}: {ug.n_points} points, {ug.n_cells} cells -> {out}")


def cmd_sensitivity(args) -> None:
    from vcs.io import read_surface, write_csv
    from vcs.sensitivity import parse_range, plot_sweep, residual_sweep

    Ls, Ks, Rs = (parse_range(getattr(args, n), n) for n in ("L", "K", "R"))
    surfaces = [read_surface(m, args.units) for m in args.meshes]
    rows = residual_sweep(surfaces, Ls, Ks, Rs)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "sensitivity.csv", {k: np.array([r[k] for r in rows]) for k in rows[0]})
    plot_sweep(rows, out / "sensitivity.png")
    best = min(rows, key=lambda r: r["residual_mean_mm"])
    print(f"{len(rows)} settings x {len(surfaces)} meshes -> {out}; lowest mean residual "
          f"{best['residual_mean_mm']:.4f} mm at L={best['L']} K={best['K']} R={best['R']}")


def add_commands(sub) -> None:
    """Register the wall-model subcommands on an argparse subparsers object."""
    w = sub.add_parser("wall", help="write the model wall (Eq. 8) as a closed multi-solid STL")
    w.add_argument("model", help="model.json from `vcs fit`")
    w.add_argument("-o", "--output", required=True, help="output .stl")
    w.add_argument("--n-tau", type=_positive_int, default=None, help="axial intervals (default: square quads)")
    w.add_argument("--n-theta", type=_positive_int, default=64, help="vertices around the circumference")
    w.add_argument("--extend-inlet", type=float, default=0.0, help="straight inlet extension, in diameters")
    w.add_argument("--extend-outlet", type=float, default=0.0, help="straight outlet extension, in diameters")
    w.add_argument("--units", default="mm", choices=["mm", "cm", "m"], help="units of the STL (OpenFOAM: m)")
    w.set_defaults(func=cmd_wall)

    g = sub.add_parser("grid", help="write the (tau, theta, rho_n) measurement grid as VTU")
    g.add_argument("model", help="model.json from `vcs fit`")
    g.add_argument("-o", "--output", required=True, help="output .vtu")
    g.add_argument("--n-tau", type=_positive_int, default=64)
    g.add_argument("--n-theta", type=_positive_int, default=32)
    g.add_argument("--n-rho", type=_positive_int, default=8)
    g.add_argument("--scheme", default="cylindrical", choices=["cylindrical", "ogrid"])
    g.add_argument("--units", default="mm", choices=["mm", "cm", "m"], help="units of the VTU points")
    g.set_defaults(func=cmd_grid)

    s = sub.add_parser("sensitivity", help="residuals over ranges of L, K, R for a cohort (paper Fig. 5)")
    s.add_argument("meshes", nargs="+", help="surfaces whose two ends are found automatically")
    s.add_argument("--L", default="9", help="range a:b:s of centerline knots")
    s.add_argument("--K", default="11:23:4", help="range a:b:s of wall knots in tau")
    s.add_argument("--R", default="7:15:4", help="range a:b:s of wall knots in theta")
    s.add_argument("--units", default="auto", choices=["auto", "mm", "cm", "m"])
    s.add_argument("-o", "--output", required=True, help="output directory (sensitivity.csv, sensitivity.png)")
    s.set_defaults(func=cmd_sensitivity)
