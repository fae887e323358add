"""Vessel Coordinate System (Romero et al., Applied Mathematics and Computation, 2024).

Public API (all lengths in mm)::

    model, report, wall_fit = fit_vessel("aorta.stl", units="auto")   # VCS + wall model
    tau, theta, rho, in_omega = model.vcs.to_vcs(points)                # Eqs. 2-4
    x = model.vcs.to_cartesian(tau, theta, rho)                         # Eq. 1
    rho_w = model.wall(tau, theta)                                      # Eq. 5
    model.save("model.json"); VesselModel.load("model.json")
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

# Public name -> the module that defines it. Imported on first use (PEP 562), so that `import
# vcs.cfd` or `import vcs.errors` does not load the whole geometry stack (scipy.interpolate,
# trimesh, ...): every workflow job imports a submodule of vcs, and the interpreter's start-up is
# the larger part of a short job's time (bench/overhead.py).
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

if TYPE_CHECKING:  # the names as type checkers and the import graph (tests/vcs/test_layout.py) see them
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


def __getattr__(name: str) -> Any:
    """A public name of :data:`__all__`, imported from its module on first use."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'vcs' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
