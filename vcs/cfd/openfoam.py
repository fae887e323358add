"""OpenFOAM installations and parameters: the CFD defaults, the table of flavours (openfoam.org v10
vs ESI openfoam.com), detection of the installed one, its environment, and the case templates.

Flavours: ``"esi"`` (openfoam.com, tested with Debian's v1912) and ``"org10"`` (openfoam.org v10,
dictionaries checked against the OpenFOAM-10 sources). Both are rendered from
``templates/openfoam/common`` plus the flavour's override directory, driven by the single table
``FLAVOURS`` below; nothing else in the package depends on the flavour.
"""

from __future__ import annotations

import copy
import os
import re
import shutil
import subprocess
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

# --------------------------------------------------------------------------- parameters

DEFAULTS: dict[str, Any] = {
    "flavour": None,  # None = detect the installed OpenFOAM; "esi" (v1912/openfoam.com) or "org10"
    "ranks": 1,  # MPI ranks for simpleFoam (1 = serial); decomposition below
    "mesh": {
        "cell_size": 1.0e-3,  # background (blockMesh) hex edge [m]
        "pad_cells": 3,  # background box = STL bounds + pad_cells cells on every side
        "surface_level": [0, 0],  # snappy (min max) refinement level on the whole vessel surface
        "wall_level": [0, 0],  # ... on the wall solid
        "inlet_level": [0, 0],  # ... on the inlet solid (raise to resolve the jet's shear layer)
        "outlet_level": [0, 0],  # ... on the outlet solid(s)
        "n_cells_between_levels": 2,
        "resolve_feature_angle": 30,
        "snap_solve_iterations": 50,
        "layers": 0,  # wall prism layers (0 = addLayers off)
        "layer_expansion": 1.2,
        "final_layer_thickness": 0.3,
        "min_layer_thickness": 0.1,
        "max_non_ortho": 65,
        "max_local_cells": 2_000_000,
        "max_global_cells": 20_000_000,
        "inside_point": None,  # [x, y, z] inside the lumen; None = automatic (from the inlet)
    },
    "physics": {
        "nu": 3.37e-6,  # kinematic viscosity [m2/s] (Newtonian blood)
        "rho": 1060.0,  # density [kg/m3], only to convert p and WSS to Pa
    },
    "inlet": {
        "type": "jet",  # jet | uniform | parabolic
        "velocity": 1.2,  # jet velocity [m/s] (paper: 1.2 m/s)
        "valve_area": 1.0e-4,  # effective valve area [m2] (paper: 1 cm2) -> Q = velocity * area
        "flow_rate": None,  # [m3/s]; overrides velocity * valve_area when set
        "centre": None,  # jet centre [x, y, z]; None = area centroid of the inlet patch
    },
    "solver": {
        "tolerance": 1.0e-5,  # SIMPLE residualControl (initial residuals of p and U)
        "max_iterations": 2000,  # total SIMPLE iterations (start-up included)
        "startup_iterations": 100,  # first-order start-up iterations (0 = none)
        "startup_scheme": "upwind",
        "div_scheme": "linearUpwind",  # scheme of the main stage for div(phi,U)
        "consistent": True,  # SIMPLEC
        "relax_U": 0.9,
        "relax_p": 1.0,  # with consistent=False use ~0.3 / relax_U ~0.7
        "n_non_orthogonal_correctors": 1,
        "p_solver_tolerance": 1.0e-8,
        "p_rel_tol": 0.05,
        "U_solver_tolerance": 1.0e-9,
        "U_rel_tol": 0.1,
        "fallback": "average",  # none | average: if not converged, continue average_iterations
        # with fieldAverage and report the time-averaged (pseudo-steady) fields
        "average_iterations": 500,
        "relaxed_tolerance": 1.0e-3,  # reported criterion for the fallback (converged stays false)
        "timeout_s": None,  # wall-clock limit per utility call [s]
    },
    "decomposition": {
        "method": "hierarchical",  # hierarchical | simple (scotch is a stub in Debian's package)
    },
    "io": {
        "write_format": "ascii",  # ascii is required by the inlet-profile reader
    },
}

# ONE table for both flavours: names that differ, the geometry folder and the case files.
_COMMON_FILES = [
    "system/blockMeshDict",
    "system/snappyHexMeshDict",
    "system/controlDict",
    "system/fvSchemes",
    "system/fvSolution",
    "system/decomposeParDict",
    "0/U",
    "0/p",
]
FLAVOURS: dict[str, dict[str, Any]] = {
    "esi": {
        "label": "ESI-OpenCFD OpenFOAM (openfoam.com), v1912+",
        "header_version": True,
        "geometry_dir": "constant/triSurface",
        "inside_point_key": "locationInMesh",
        "decomposer_key": "method",
        "medial_axis_key": "minMedianAxisAngle",
        "files": _COMMON_FILES + ["constant/transportProperties", "constant/turbulenceProperties"],
    },
    "org10": {
        "label": "OpenFOAM Foundation (openfoam.org) v10",
        "header_version": False,
        "geometry_dir": "constant/geometry",
        "inside_point_key": "insidePoint",
        "decomposer_key": "decomposer",
        "medial_axis_key": "minMedialAxisAngle",
        "files": _COMMON_FILES + ["constant/physicalProperties", "constant/momentumTransport"],
    },
}


def deep_merge(base: dict[str, Any], over: dict[str, Any] | None) -> dict[str, Any]:
    """A deep copy of ``base`` with ``over`` merged into it key by key.

    Parameters
    ----------
    base : dict
        Defaults (not modified).
    over : dict or None
        Overrides: nested dicts are merged, other values (lists included) replace those of
        ``base``.

    Returns
    -------
    dict
        A new dict sharing no mutable value with ``base`` or ``over``.
    """
    out = copy.deepcopy(base)
    for k, v in (over or {}).items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


def template_dir() -> Path:
    """Folder of the jinja2 case templates (``common/``, ``esi/``, ``org10/``).

    Installed from a wheel they are package data (``vcs/cfd/templates/openfoam``, copied there by
    setup.py); in a source checkout (editable install) they are the repository's
    ``templates/openfoam``.

    Returns
    -------
    Path
        The folder holding ``common/``, ``esi/`` and ``org10/``.
    """
    packaged = Path(str(resources.files("vcs.cfd"))) / "templates" / "openfoam"
    if (packaged / "common").is_dir():
        return packaged
    return Path(__file__).resolve().parents[2] / "templates" / "openfoam"


# --------------------------------------------------------------------------- environment


def foam_env() -> dict[str, str]:
    """The environment for OpenFOAM utilities: ``os.environ`` plus WM_PROJECT_DIR when unset.

    Returns
    -------
    dict of str -> str
        A copy of ``os.environ``; WM_PROJECT_DIR is set to ``/usr/share/openfoam`` (Debian's
        package) when it is unset and that folder exists.
    """
    env = dict(os.environ)
    if "WM_PROJECT_DIR" not in env and Path("/usr/share/openfoam").is_dir():
        env["WM_PROJECT_DIR"] = "/usr/share/openfoam"
    return env


@lru_cache(maxsize=1)
def detect_openfoam() -> tuple[str | None, str | None]:
    """(flavour, version) of the installed OpenFOAM, or (None, None) when none is found.

    Order: $VCSFLOW_OPENFOAM_FLAVOUR, $WM_PROJECT_VERSION, the banner of ``simpleFoam -help``
    (openfoam.com vs openfoam.org), dpkg's version of the ``openfoam`` package. The result is
    cached for the process.

    Returns
    -------
    flavour : str or None
        ``"esi"``, ``"org10"`` (openfoam.org 10 or later), ``"org<N>"`` for older openfoam.org,
        the forced value, or None.
    version : str or None
        The version string found, or None.
    """
    forced = os.environ.get("VCSFLOW_OPENFOAM_FLAVOUR")
    wmv = os.environ.get("WM_PROJECT_VERSION")
    version = wmv
    banner = ""
    if shutil.which("simpleFoam"):
        try:
            banner = subprocess.run(
                ["simpleFoam", "-help"], env=foam_env(), capture_output=True, text=True, timeout=60
            ).stdout
        except (OSError, subprocess.SubprocessError):
            banner = ""
    if version is None:
        m = re.search(r"Using:\s*OpenFOAM-\S*\s*\(([^)]+)\)", banner) or re.search(r"Version:\s*(\S+)", banner)
        if m:
            version = m.group(1)
    if version is None and shutil.which("dpkg-query"):
        r = subprocess.run(["dpkg-query", "-W", "-f=${Version}", "openfoam"], capture_output=True, text=True)
        if r.returncode == 0 and r.stdout.strip():
            version = r.stdout.strip()
    if forced:
        return forced, version
    if "openfoam.com" in banner or (version and re.match(r"v?\d{4}", version)):
        return "esi", version
    if "openfoam.org" in banner or (version and re.match(r"\d{1,2}(\.\d+)?$", version)):
        # known gap, left as it was: a version not starting with digits (e.g. "dev" with an
        # openfoam.org banner) makes re.match None and raises AttributeError here
        major = int(re.match(r"(\d+)", version).group(1)) if version else 10  # type: ignore[union-attr]
        return ("org10" if major >= 10 else f"org{major}"), version
    return None, version
