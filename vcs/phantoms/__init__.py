"""Synthetic vessel surface phantoms (open tubes, lengths in mm).

These phantoms are test fixtures and the source of the demo cohort; they are not an equation of
Romero et al. (2024). They give surfaces whose generating centreline, rotation-minimising frame
and wall radius rho_w(tau, theta) are known exactly, so the VCS fit can be checked against truth.

Modules
-------
``vcs.phantoms.sweep``     the :class:`Phantom` record and the shared swept-tube meshing
                           (rings -> triangles, ring spacing, self-intersection check, STL output).
``vcs.phantoms.analytic``  tube, torus arc and helix with closed-form truth; the closed tube STL
                           (metres, wall/inlet/outlet) for OpenFOAM Hagen-Poiseuille tests.
``vcs.phantoms.aorta``     the seeded synthetic thoracic aorta.
``vcs.phantoms.factory``   :func:`make_phantom` (dispatch on ``kind``).

Only numpy and scipy are used (no mesh libraries), so the package can run anywhere the VCS runs.
"""

from vcs.phantoms.analytic import write_closed_tube_stl
from vcs.phantoms.aorta import AORTA_EDGE_SCALE
from vcs.phantoms.factory import KINDS, make_phantom
from vcs.phantoms.sweep import Phantom, sweep_tube, write_stl

__all__ = [
    "AORTA_EDGE_SCALE",
    "KINDS",
    "Phantom",
    "make_phantom",
    "sweep_tube",
    "write_closed_tube_stl",
    "write_stl",
]
