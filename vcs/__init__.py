"""Vessel Coordinate System (Romero et al., Applied Mathematics and Computation, 2024).

Public API (all lengths in mm)::

    model, report, wall_fit = fit_vessel("aorta.stl", units="auto")   # VCS + wall model
    tau, theta, rho, in_omega = model.vcs.to_vcs(points)                # Eqs. 2-4
    x = model.vcs.to_cartesian(tau, theta, rho)                         # Eq. 1
    rho_w = model.wall(tau, theta)                                      # Eq. 5
    model.save("model.json"); VesselModel.load("model.json")
"""

from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as _version

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

try:  # one source of the version: pyproject.toml (also in results/provenance.json and the docs)
    __version__ = _version("vcs-atlas")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

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
