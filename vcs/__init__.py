"""Vessel Coordinate System (Romero et al., Applied Mathematics and Computation, 2024).

Public API (all lengths in mm)::

    model, report, wall_fit = fit_vessel("aorta.stl", units="auto")   # VCS + wall model
    tau, theta, rho, in_omega = model.vcs.to_vcs(points)                # Eqs. 2-4
    x = model.vcs.to_cartesian(tau, theta, rho)                         # Eq. 1
    rho_w = model.wall(tau, theta)                                      # Eq. 5
    model.save("model.json"); VesselModel.load("model.json")
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vcs._lazy import lazy_exports

#: where each public name lives: imported on first use (PEP 562), so that a job that needs only
#: part of the package (the CFD jobs, `vcs wall`) does not pay for scipy and VTK it never calls
_EXPORTS = {
    "Ends": "vcs.ends",
    "find_ends": "vcs.ends",
    "VCSInputError": "vcs.errors",
    "MeasurementGrid": "vcs.grid",
    "measurement_grid": "vcs.grid",
    "Surface": "vcs.io",
    "read_surface": "vcs.io",
    "VesselCoordinateSystem": "vcs.model",
    "make_phantom": "vcs.phantoms.factory",
    "Phantom": "vcs.phantoms.sweep",
    "WallMesh": "vcs.surface",
    "wall_mesh": "vcs.surface",
    "VesselModel": "vcs.vessel",
    "fit_vessel": "vcs.vessel",
    "WallFit": "vcs.wall",
    "WallModel": "vcs.wall",
    "fit_wall": "vcs.wall",
}

if TYPE_CHECKING:  # the same names, for type checkers and editors
    from vcs.ends import Ends, find_ends
    from vcs.errors import VCSInputError
    from vcs.grid import MeasurementGrid, measurement_grid
    from vcs.io import Surface, read_surface
    from vcs.model import VesselCoordinateSystem
    from vcs.phantoms.factory import make_phantom
    from vcs.phantoms.sweep import Phantom
    from vcs.surface import WallMesh, wall_mesh
    from vcs.vessel import VesselModel, fit_vessel
    from vcs.wall import WallFit, WallModel, fit_wall

    __version__: str


def _package_version() -> str:
    """One source of the version: pyproject.toml (also in results/provenance.json and the docs)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("vcs-atlas")
    except PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, {"__version__": _package_version})

__all__ = [
    "Ends",
    "MeasurementGrid",
    "Phantom",
    "Surface",
    "VCSInputError",
    "VesselCoordinateSystem",
    "VesselModel",
    "WallFit",
    "WallMesh",
    "WallModel",
    "find_ends",
    "fit_vessel",
    "fit_wall",
    "make_phantom",
    "measurement_grid",
    "read_surface",
    "wall_mesh",
]
