"""`vcs wall` and `vcs grid`: the model wall (Eq. 8) as a closed STL, the measurement grid as VTU.

Both write in the units of the fitted mesh (``units.input`` of model.json) unless ``--units`` says
otherwise, like every other output of a fit (`vcs coords`, centerline.vtp).
"""

from __future__ import annotations

import argparse

import numpy as np

from vcs.cli._args import atomic_file, float_at_least, int_at_least, output_file, positive_int
from vcs.errors import VCSInputError
from vcs.grid import GRID_DEFAULTS
from vcs.io import UNIT_TO_MM


def cmd_wall(args: argparse.Namespace) -> None:
    """Run `vcs wall`: the model wall as a closed multi-solid STL (solids wall, inlet, outlet).

    Parameters
    ----------
    args : argparse.Namespace
        ``model`` (model.json), ``output`` (.stl), ``n_tau`` (axial intervals or None: square
        quads), ``n_theta`` (vertices around), ``extend_inlet``/``extend_outlet`` (straight
        extensions, in diameters, >= 0) and ``units`` (of the STL: mm, cm or m; None: the units
        of the fitted mesh, recorded in model.json).

    Raises
    ------
    VCSInputError
        The output does not end in .stl, is the input model, is a directory or cannot be
        written; the model wall folds or is not closed.
    """
    from vcs.surface import check_closed, fold_check, wall_mesh, write_multisolid_stl
    from vcs.vessel import VesselModel

    out = output_file(args.output, args.model, suffixes=(".stl",))
    model = VesselModel.load(args.model)
    units = args.units or model.units
    fold = fold_check(model)
    if fold["min_radius_mm"] <= 0:
        raise VCSInputError(
            f"the wall model's radius is {fold['min_radius_mm']:.3g} mm at tau = {fold['tau_at_min_radius']:.3f} "
            "(it must be positive): the wall would fold through the centerline; check fit_report.json and refit"
        )
    if fold["max_fold"] >= 1:
        raise VCSInputError(
            f"the wall radius exceeds the centerline's radius of curvature at tau = {fold['tau_at_max_fold']:.3f} "
            f"(rho_w kappa = {fold['max_fold']:.3g}): the wall would fold on the inner side of "
            "the bend; check fit_report.json and refit"
        )
    mesh = wall_mesh(
        model, n_tau=args.n_tau, n_theta=args.n_theta, extend_inlet=args.extend_inlet, extend_outlet=args.extend_outlet
    )
    check = check_closed(mesh)
    bad_caps = [name for name, c in check["caps"].items() if not c["disc"]]
    if bad_caps:  # wall_mesh checks its caps: this is a defect of ours, never the fit's
        raise VCSInputError(
            f"the {' and '.join(bad_caps)} cap of the model wall is not a disc ({check['caps'][bad_caps[0]]}): "
            "a defect of `vcs wall`, not of the fit; please report it with the model.json"
        )
    if not check["closed"]:
        raise VCSInputError(
            f"the model wall is not a closed surface (watertight {check['watertight']}, consistent winding "
            f"{check['winding_consistent']}, volume {check['volume_mm3']:.4g} mm3, Euler number "
            f"{check['euler_number']}): the wall model folds over itself; check fit_report.json and refit"
        )
    with atomic_file(out) as tmp:
        write_multisolid_stl(mesh, tmp, scale=1.0 / UNIT_TO_MM[units])
    print(
        f"wall (Eq. 8) with {len(mesh.faces)} triangles, solids wall/inlet/outlet, in {units} -> {out}; "
        f"closed, volume {check['volume_mm3']:.6g} mm3, smallest angle {check['min_angle_deg']:.1f} deg"
    )


def cmd_grid(args: argparse.Namespace) -> None:
    """Run `vcs grid`: the (tau, theta, rho_n) measurement grid as a hexahedral VTU.

    Parameters
    ----------
    args : argparse.Namespace
        ``model`` (model.json), ``output`` (.vtu), ``n_tau``, ``n_theta``, ``n_rho`` (grid sizes),
        ``scheme`` (cylindrical or ogrid) and ``units`` (of the VTU points: mm, cm or m; None:
        the units of the fitted mesh, recorded in model.json). Point data: ``tau``, ``theta``
        (rad), ``rho_n`` (rho / rho_w, in [0, 1]).

    Raises
    ------
    VCSInputError
        The output does not end in .vtu, is the input model, is a directory or cannot be written.
    """
    import pyvista as pv

    from vcs.grid import measurement_grid
    from vcs.vessel import VesselModel

    out = output_file(args.output, args.model, suffixes=(".vtu",))
    model = VesselModel.load(args.model)
    units = args.units or model.units
    g = measurement_grid(model, n_tau=args.n_tau, n_theta=args.n_theta, n_rho=args.n_rho, scheme=args.scheme)
    cells = np.hstack([np.full((len(g.cells), 1), 8), g.cells]).ravel()
    ug = pv.UnstructuredGrid(
        cells, np.full(len(g.cells), pv.CellType.HEXAHEDRON, np.uint8), g.points / UNIT_TO_MM[units]
    )
    ug.point_data["tau"] = g.tau
    ug.point_data["theta"] = g.theta
    ug.point_data["rho_n"] = g.rho_n
    with atomic_file(out) as tmp:
        ug.save(str(tmp))
    print(
        f"{args.scheme} grid {args.n_tau}x{args.n_theta}x{args.n_rho}: {ug.n_points} points, "
        f"{ug.n_cells} cells, in {units} -> {out}"
    )


def add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register `vcs wall` and `vcs grid` on the subparsers object of the `vcs` parser.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        As returned by :meth:`argparse.ArgumentParser.add_subparsers`.
    """
    w = subparsers.add_parser("wall", help="write the model wall (Eq. 8) as a closed multi-solid STL")
    w.add_argument("model", help="model.json from `vcs fit`")
    w.add_argument("-o", "--output", required=True, help="output .stl")
    w.add_argument("--n-tau", type=positive_int, default=None, help="axial intervals (default: square quads)")
    w.add_argument("--n-theta", type=int_at_least(8), default=64, help="vertices around the circumference (>= 8)")
    extension = float_at_least(0.0, maximum=100.0)
    w.add_argument("--extend-inlet", type=extension, default=0.0, help="straight inlet extension, 0-100 diameters")
    w.add_argument("--extend-outlet", type=extension, default=0.0, help="straight outlet extension, 0-100 diameters")
    w.add_argument(
        "--units",
        default=None,
        choices=["mm", "cm", "m"],
        help="units of the STL (OpenFOAM: m); default: the units of the fitted mesh (model.json)",
    )
    w.set_defaults(func=cmd_wall, heavy_modules=("trimesh",))  # check_closed uses trimesh

    g = subparsers.add_parser("grid", help="write the (tau, theta, rho_n) measurement grid as VTU")
    g.add_argument("model", help="model.json from `vcs fit`")
    g.add_argument("-o", "--output", required=True, help="output .vtu")
    g.add_argument(
        "--n-tau",
        type=int_at_least(2),
        default=GRID_DEFAULTS["n_tau"],
        help="nodes along tau, both ends included (as grid.n_tau of the workflow)",
    )
    g.add_argument(
        "--n-theta", type=int_at_least(4), default=GRID_DEFAULTS["n_theta"], help="nodes around theta (as grid.n_theta)"
    )
    g.add_argument(
        "--n-rho",
        type=int_at_least(2),
        default=GRID_DEFAULTS["n_rho"],
        help="nodes from the axis to the wall, both included (as grid.n_rho)",
    )
    g.add_argument(
        "--scheme",
        default="cylindrical",
        choices=["cylindrical", "ogrid"],
        help="cylindrical: the paper's grid, the nodes of fields.npz; ogrid: Cartesian core (visual)",
    )
    g.add_argument(
        "--units",
        default=None,
        choices=["mm", "cm", "m"],
        help="units of the VTU points; default: the units of the fitted mesh (model.json)",
    )
    g.set_defaults(func=cmd_grid, heavy_modules=("pyvista",))  # the grid is built and written with pyvista
