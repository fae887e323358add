"""OpenFOAM installations and parameters: the CFD defaults, the table of flavours (openfoam.org v10
vs ESI openfoam.com), detection of the installed one, its environment, and the case templates.

Flavours: ``"esi"`` (openfoam.com, tested with Debian's v1912) and ``"org10"`` (openfoam.org v10,
dictionaries checked against the OpenFOAM-10 sources). Both are rendered from
``templates/openfoam/common`` plus the flavour's override directory, driven by the single table
``FLAVOURS`` below; nothing else in the package depends on the flavour.

Detection (:func:`detect_openfoam`, :func:`openfoam_installation`) needs no sourced environment:
the banner of ``simpleFoam -help``, ``$WM_PROJECT_VERSION``, the installation's files and dpkg
are read, and it never raises. openfoam.org 11 and later (``foamRun -solver
incompressibleFluid``) are detected as ``"org11"``, ``"org12"``, ... and not supported.
"""

from __future__ import annotations

import copy
import math
import os
import re
import shutil
import subprocess
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

from vcs.cfd.foamfiles import family_of_version, parse_banner
from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

# --------------------------------------------------------------------------- parameters

GEOMETRIES = ("model", "surface")
"""``cfd.geometry``: the Eq. 8 model wall, or the patient's own surface (:mod:`vcs.lumen`)."""

OUTLET_TYPES = ("free", "murray", "rcr", "rcr_fixed_share")
"""``cfd.outlets.type``."""

DEFAULTS: dict[str, Any] = {
    "flavour": None,  # None = detect the installed OpenFOAM; "esi" (v1912/openfoam.com) or "org10"
    "ranks": 1,  # MPI ranks for simpleFoam (1 = serial); decomposition below
    "mesh": {
        "cell_size": "auto",  # lumen cell size [m], or "auto": from the vessel (vcs.cfd.sizing)
        "cells_across_end": 12,  # auto: at least this many cells across the smaller end diameter
        "cells_across_narrowest": 8,  # auto: ... and across the narrowest section
        "cells_across_branch": 8,  # every branch end (geometry: surface) refined to this many cells across
        "max_cells": 1_000_000,  # auto: estimated lumen cells (V / h^3) above this coarsen h (recorded)
        "max_background_cells": 100_000,  # blockMesh box cells; above: coarser box, levels raised
        "min_patch_faces": 20,  # each STL solid must become a patch of at least this many faces
        "pad_cells": 3,  # background box = STL bounds + pad_cells background cells on every side
        # background grid along the coordinate axes, or the inlet's frame (its plane parallel to
        # the grid: no snapped prisms in the inflow, the jet along a grid axis)
        "background_frame": "axes",
        "surface_level": [0, 0],  # snappy (min max) refinement level on the whole vessel surface
        "wall_level": [0, 0],  # ... on the wall solid
        "inlet_level": [0, 0],  # ... on the inlet solid (raise to resolve the jet's shear layer)
        "outlet_level": [0, 0],  # ... on the outlet solid(s)
        "n_cells_between_levels": 2,
        "resolve_feature_angle": 30,
        "snap_solve_iterations": 50,
        "layers": 3,  # wall prism layers (snappy addLayers; 0 = off)
        "layer_expansion": 1.2,  # thickness ratio of consecutive layers
        "final_layer_thickness": 0.3,  # last layer / local cell size
        "min_layer_thickness": 0.1,  # thinner layers are not added (/ local cell size)
        "jet_refinement": {  # refinement cylinder along the jet (inlet.type jet only)
            "enabled": True,
            "cells_across": 10,  # at least this many cells across the jet diameter (sets the level)
            "length": 5.0,  # cylinder length from the inlet along its inward normal [jet diameters]
            "radius": 2.0,  # cylinder radius [jet radii]
        },
        "max_non_ortho": 65,
        "max_boundary_skewness": 4,  # snappy's limit on boundary faces (= checkMesh's, which fails above)
        "max_local_cells": 2_000_000,
        "max_global_cells": 20_000_000,
        "inside_point": None,  # [x, y, z] inside the lumen; None = automatic (from the inlet)
    },
    # the lumen the CFD runs on: "model" (the Eq. 8 model wall, one outlet) or "surface" (the
    # patient's own surface with every end a patch: inlet, outlet and branch_<k>; vcs.lumen)
    "geometry": "model",
    "outlets": {
        # free: p = 0 on every outlet; murray: every branch_<k> takes fraction r_k^n / sum r^n of
        # the inflow, the main outlet (p = 0) the rest; rcr: a three-element Windkessel on every
        # outlet, coupled implicitly (the split comes out of the solution); rcr_fixed_share: the
        # branches take their Windkessel's fixed share, the main outlet alone a Windkessel pressure
        "type": "free",
        "rcr": {
            "resistance": 1.33e8,  # total peripheral resistance [Pa s/m3] (~100 mmHg / 6 L/min), split by Murray's law
            "compliance": 1.0e-8,  # total compliance [m3/Pa] (~1.3 mL/mmHg), split by Murray's law
            "proximal_fraction": 0.09,  # R_p / (R_p + R_d) of every outlet
            "distal_pressure": 0.0,  # P_d [Pa] (the pressures are relative: p = 0 is P_d)
            "split_exponent": 3.0,  # n of the split r^n / sum r^n (3: Murray's law, 2: by area)
        },
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
        "scaling": "fixed",  # fixed | scaled_by_inlet_area: Q x min(A_inlet / reference_inlet_area, max_scale)
        "reference_inlet_area": 4.909e-4,  # [m2] inlet area at which Q applies unscaled (25 mm diameter)
        "max_scale": 1.0,  # largest scale factor (1: a dilated root gets no more than Q)
        "centre": None,  # jet centre [x, y, z]; None = area centroid of the inlet patch
        # pulsatile flow: a CSV of one cardiac cycle (time_s,flow_rate_l_min), scaled as the flow
        # above (its mean takes the place of Q); None = steady (vcs.cfd.waveform, vcs.cfd.pulsatile)
        "waveform": None,
    },
    "pulsatile": {  # used when inlet.waveform (or the patient's inflow_waveform) is set
        "profile": "womersley",  # womersley | parabolic | plug, mapped to the inlet's shape
        "harmonics": 20,  # Fourier harmonics of the Womersley profile
        "samples_per_cycle": 100,  # instants per cycle of the inlet boundary data (linear between)
        "cycles": 3,  # cycles run at least ...
        "discard_cycles": 1,  # ... of which the first are wash-in from rest (not averaged)
        "max_cycles": 6,  # one more cycle while not periodic, up to this; then not converged
        "periodicity_tolerance": 0.02,  # cycle-to-cycle change of the dp and outlet flow waveforms
        # ... and of the TAWSS map (area-weighted L2): the diastolic vortices of a real aorta decay
        # over R^2/nu ~ 1 min, so its TAWSS changes 4-6 % per cycle for many cycles (demo aortas)
        "tawss_tolerance": 0.05,
        "phases": ["peak_systole", "end_systole", "mid_diastole"],  # instantaneous fields written
        "max_co": 1.0,  # Courant number limit on the cells the flow crosses
        "max_co_end_cells": 4.0,  # at most this on the slivers snapped at the end planes
        "min_steps_per_cycle": 200,  # largest time step = period / this
        "outer_correctors": 2,  # PIMPLE outer correctors when some cells run above Co 1
        "probes": [],  # points [x, y, z] m where U and p are recorded at every time step
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
        "plateau": {  # SIMPLE above the tolerance: a steady solution whose residuals level off?
            "iterations": 100,  # extra SIMPLE iterations compared with the last state (0 = no check)
            "max_residual": 1.0e-3,  # only when the last initial residuals of p and U are below this
            "tolerance": 1.0e-4,  # steady: dp, mean |WSS| and U (volume L2) change by less (relative)
            "early_stop": True,  # stop the main stage as soon as its residuals level off (not at max_iterations)
        },
        "fallback": "transient",  # none | transient: if SIMPLE does not converge, run pimpleFoam
        # from the SIMPLE state and report time averages (converged only when stationary)
        "transient": {
            # start-up wash-out before averaging [flow-through times V_lumen / Q]: ended once the
            # start-up transient is over (MSER-5), after at least min_washout_flow_throughs
            "washout_flow_throughs": 1.0,
            "min_washout_flow_throughs": 0.25,
            "min_flow_throughs": 2.0,  # shortest averaging window [flow-through times]: slow modes (a jet)
            # longest: a window whose means are not known to the tolerance by then is not stationary
            "max_flow_throughs": 10.0,
            "error_tolerance": 0.03,  # half-width of the confidence interval of the mean, relative:
            # inlet-outlet pressure difference and area-mean TAWSS (vcs.cfd.transient.window_statistics)
            "error_tolerance_U": 0.20,  # ... of U at the probe cells (L2, relative): the slowest to converge
            "confidence": 0.95,  # confidence level of those intervals
            "max_co": 1.0,  # Courant number limit on the cells the flow crosses
            "max_co_end_cells": 4.0,  # at most this on the slivers snapped at the end planes
            "outer_correctors": 1,  # PIMPLE outer correctors when some cells run above Co 1 (1: PISO-like)
            "non_orthogonal_correctors": 0,  # of pimpleFoam's pressure equation (SIMPLE: solver's own)
        },
        "timeout_s": None,  # wall-clock limit per utility call [s]
    },
    "decomposition": {
        "method": "hierarchical",  # hierarchical | simple (scotch is a stub in Debian's package)
    },
    "io": {
        "write_format": "ascii",  # ascii is required by the inlet-profile reader
    },
}

# the words a config may put into an OpenFOAM dictionary (everything else there is a number)
INLET_TYPES = ("jet", "uniform", "parabolic")
PULSATILE_PROFILES = ("womersley", "parabolic", "plug")
INFLOW_SCALINGS = ("fixed", "scaled_by_inlet_area")
DIV_SCHEMES = ("upwind", "linearUpwind", "LUST", "limitedLinearV")  # div(phi,U), see fvSchemes
FALLBACKS = ("none", "transient")

# transient keys of earlier versions and what took their place (a one-line error names it)
_REPLACED_TRANSIENT_KEYS = {
    "flow_throughs": "the averaging window now ends when its means are known to error_tolerance, between "
    "min_flow_throughs and max_flow_throughs",
    "max_doublings": "the window grows until its means are known to error_tolerance, up to max_flow_throughs",
    "stationarity_tolerance": "use error_tolerance (half-width of the mean's confidence interval, relative)",
    "stationarity_tolerance_U": "use error_tolerance_U",
}
DECOMPOSITION_METHODS = ("hierarchical", "simple")

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
        # adjustableRunTime writes are counted from the run's start time (Time.C adjustDeltaT)
        "write_origin": "start",
        "files": _COMMON_FILES + ["constant/transportProperties", "constant/turbulenceProperties"],
    },
    "org10": {
        "label": "OpenFOAM Foundation (openfoam.org) v10",
        "header_version": False,
        "geometry_dir": "constant/geometry",
        "inside_point_key": "insidePoint",
        "decomposer_key": "decomposer",
        "medial_axis_key": "minMedialAxisAngle",
        # adjustableRunTime writes are counted from beginTime, kept in <time>/uniform/time across
        # restarts (OpenFOAM-10 src/OpenFOAM/db/Time/Time.C setControls, TimeIO.C)
        "write_origin": "begin_time",
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


def _number(
    cfd: dict[str, Any], dotted: str, lo: float, hi: float, *, lo_open: bool = False, hi_open: bool = False
) -> None:
    """Raise VCSInputError unless ``cfd[dotted]`` is a number in [lo, hi] (open ends when asked)."""
    node: Any = cfd
    for k in dotted.split("."):
        node = node.get(k) if isinstance(node, dict) else None
    ok = isinstance(node, (int, float)) and not isinstance(node, bool) and (node > lo if lo_open else node >= lo)
    if not ok or node > hi or (hi_open and node >= hi):
        bound = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
        raise VCSInputError(f"cfd.{dotted} must be a number in {bound}, not {node!r}")


def _word(cfd: dict[str, Any], dotted: str, allowed: tuple[str, ...]) -> None:
    """Raise VCSInputError unless ``cfd[dotted]`` is one of ``allowed``."""
    node: Any = cfd
    for k in dotted.split("."):
        node = node.get(k) if isinstance(node, dict) else None
    if node not in allowed:
        raise VCSInputError(f"cfd.{dotted} must be one of {', '.join(allowed)}, not {node!r}")


def check_cfd(cfd: dict[str, Any]) -> None:
    """Check the CFD parameters that reach OpenFOAM dictionaries (words from fixed lists, numbers
    in range); a user-fixable error is a one-line VCSInputError.

    Parameters
    ----------
    cfd : dict
        Parameters merged over :data:`DEFAULTS`.

    Raises
    ------
    VCSInputError
        For a word outside its list (inlet type and scaling, div schemes, fallback, decomposition
        method, write format), the removed ``fallback: average``, a cell size that is neither
        ``auto`` nor a length, or a sizing, inflow, transient or jet-refinement number out of
        range.
    """
    if cfd["solver"].get("fallback") == "average":
        raise VCSInputError(
            "cfd.solver.fallback 'average' (averaging SIMPLE iterates) was removed: it is not a time average; "
            "use 'transient' (pimpleFoam, time-averaged fields) or 'none'"
        )
    _word(cfd, "geometry", GEOMETRIES)
    _word(cfd, "outlets.type", OUTLET_TYPES)
    _number(cfd, "outlets.rcr.resistance", 0.0, 1e13, lo_open=True)
    _number(cfd, "outlets.rcr.compliance", 0.0, 1e-3, lo_open=True)
    _number(cfd, "outlets.rcr.proximal_fraction", 0.0, 1.0, hi_open=True)
    _number(cfd, "outlets.rcr.distal_pressure", -1e6, 1e6)
    _number(cfd, "outlets.rcr.split_exponent", 0.0, 10.0, lo_open=True)
    _word(cfd, "inlet.type", INLET_TYPES)
    _word(cfd, "inlet.scaling", INFLOW_SCALINGS)
    _number(cfd, "inlet.reference_inlet_area", 0.0, 1.0, lo_open=True)
    _number(cfd, "inlet.max_scale", 0.0, 100.0, lo_open=True)
    size = cfd["mesh"].get("cell_size")
    if size != "auto" and not (isinstance(size, (int, float)) and not isinstance(size, bool) and 0 < size <= 10):
        raise VCSInputError(f"cfd.mesh.cell_size must be 'auto' or a number of metres in (0, 10], not {size!r}")
    _number(cfd, "mesh.cells_across_end", 1, 1000)
    _number(cfd, "mesh.cells_across_narrowest", 1, 1000)
    _number(cfd, "mesh.cells_across_branch", 3, 1000)
    _number(cfd, "mesh.max_cells", 1, 1e10)
    _number(cfd, "mesh.max_background_cells", 1, 1e10)
    _number(cfd, "mesh.min_patch_faces", 1, 1e9)
    _word(cfd, "mesh.background_frame", ("axes", "inlet"))
    _word(cfd, "solver.fallback", FALLBACKS)
    _word(cfd, "solver.startup_scheme", DIV_SCHEMES)
    _word(cfd, "solver.div_scheme", DIV_SCHEMES)
    _word(cfd, "decomposition.method", DECOMPOSITION_METHODS)
    _word(cfd, "io.write_format", ("ascii",))
    tr = cfd["solver"]["transient"]
    for gone, new in _REPLACED_TRANSIENT_KEYS.items():
        if gone in tr:
            raise VCSInputError(f"cfd.solver.transient.{gone} was replaced: {new}")
    _number(cfd, "solver.transient.washout_flow_throughs", 0.0, 1e3)
    _number(cfd, "solver.transient.min_washout_flow_throughs", 0.0, 1e3)
    _number(cfd, "solver.transient.min_flow_throughs", 0.0, 1e3, lo_open=True)
    _number(cfd, "solver.transient.max_flow_throughs", 0.0, 1e4, lo_open=True)
    if float(tr["max_flow_throughs"]) < float(tr["min_flow_throughs"]):
        raise VCSInputError(
            f"cfd.solver.transient.max_flow_throughs ({tr['max_flow_throughs']}) must not be below min_flow_throughs "
            f"({tr['min_flow_throughs']})"
        )
    _number(cfd, "solver.transient.error_tolerance", 0.0, 1.0, lo_open=True)
    _number(cfd, "solver.transient.error_tolerance_U", 0.0, 1.0, lo_open=True)
    _number(cfd, "solver.transient.confidence", 0.5, 1.0, lo_open=True, hi_open=True)
    _number(cfd, "solver.transient.max_co", 0.0, 2.0, lo_open=True)
    _number(cfd, "solver.transient.max_co_end_cells", 0.0, 10.0, lo_open=True)
    n_out = tr.get("outer_correctors")
    if not (isinstance(n_out, int) and not isinstance(n_out, bool) and 1 <= n_out <= 10):
        raise VCSInputError(f"cfd.solver.transient.outer_correctors must be a whole number in [1, 10], not {n_out!r}")
    _whole(cfd, "solver.transient.non_orthogonal_correctors", 0, 10)
    pl_it = (cfd["solver"].get("plateau") or {}).get("iterations")
    n_it = float(pl_it) if isinstance(pl_it, (int, float)) and not isinstance(pl_it, bool) else math.nan
    if not (n_it.is_integer() and (n_it == 0 or 10 <= n_it <= 100000)):
        raise VCSInputError(
            "cfd.solver.plateau.iterations must be 0 (no plateau check) or a whole number in [10, 100000], "
            f"not {pl_it!r}"
        )
    _number(cfd, "solver.plateau.max_residual", 0.0, 1.0e-2, lo_open=True)
    _number(cfd, "solver.plateau.tolerance", 0.0, 1.0e-2, lo_open=True)
    unknown = set(cfd["solver"].get("plateau") or {}) - {"iterations", "max_residual", "tolerance", "early_stop"}
    if unknown:
        raise VCSInputError(
            f"unknown key(s) in cfd.solver.plateau: {', '.join(sorted(unknown))}; "
            "known: iterations, max_residual, tolerance, early_stop"
        )
    if not isinstance((cfd["solver"].get("plateau") or {}).get("early_stop", False), bool):
        raise VCSInputError("cfd.solver.plateau.early_stop must be true or false")
    _check_pulsatile(cfd)
    _number(cfd, "mesh.layers", 0, 20)
    _number(cfd, "mesh.max_boundary_skewness", 0.0, 100.0, lo_open=True)
    _number(cfd, "mesh.jet_refinement.cells_across", 1, 100)
    _number(cfd, "mesh.jet_refinement.length", 0.0, 100.0, lo_open=True)
    _number(cfd, "mesh.jet_refinement.radius", 1.0, 20.0)
    if not isinstance(cfd["mesh"]["jet_refinement"].get("enabled"), bool):
        raise VCSInputError("cfd.mesh.jet_refinement.enabled must be true or false")


def _whole(cfd: dict[str, Any], dotted: str, lo: int, hi: int) -> int:
    """A whole-number parameter in [lo, hi] (one-line VCSInputError otherwise)."""
    node: Any = cfd
    for part in dotted.split("."):
        node = node[part]
    if not (isinstance(node, int) and not isinstance(node, bool) and lo <= node <= hi):
        raise VCSInputError(f"cfd.{dotted} must be a whole number in [{lo}, {hi}], not {node!r}")
    return int(node)


def _check_pulsatile(cfd: dict[str, Any]) -> None:
    """The ``cfd.pulsatile`` parameters (see :func:`check_cfd`)."""
    _word(cfd, "pulsatile.profile", PULSATILE_PROFILES)
    _whole(cfd, "pulsatile.harmonics", 1, 200)
    _whole(cfd, "pulsatile.samples_per_cycle", 20, 10000)
    cycles = _whole(cfd, "pulsatile.cycles", 2, 100)
    discard = _whole(cfd, "pulsatile.discard_cycles", 0, 99)
    max_cycles = _whole(cfd, "pulsatile.max_cycles", 2, 1000)
    if discard >= cycles:
        raise VCSInputError(
            f"cfd.pulsatile.discard_cycles ({discard}) must be below cycles ({cycles}): at least one cycle is kept"
        )
    if max_cycles < cycles:
        raise VCSInputError(f"cfd.pulsatile.max_cycles ({max_cycles}) must not be below cycles ({cycles})")
    _number(cfd, "pulsatile.periodicity_tolerance", 0.0, 1.0, lo_open=True)
    _number(cfd, "pulsatile.tawss_tolerance", 0.0, 1.0, lo_open=True)
    _number(cfd, "pulsatile.max_co", 0.0, 5.0, lo_open=True)
    _number(cfd, "pulsatile.max_co_end_cells", 0.0, 10.0, lo_open=True)
    _whole(cfd, "pulsatile.min_steps_per_cycle", 10, 1_000_000)
    _whole(cfd, "pulsatile.outer_correctors", 1, 10)
    phases = cfd["pulsatile"]["phases"]
    known = ("peak_systole", "end_systole", "mid_diastole")
    if not isinstance(phases, list) or any(ph not in known for ph in phases) or len(set(phases)) != len(phases):
        raise VCSInputError(
            f"cfd.pulsatile.phases must be a list of distinct names from {', '.join(known)}, not {phases!r}"
        )
    probes = cfd["pulsatile"]["probes"]
    if not isinstance(probes, list) or not all(
        isinstance(x, list) and len(x) == 3 and all(isinstance(v, (int, float)) and math.isfinite(v) for v in x)
        for x in probes
    ):
        raise VCSInputError(f"cfd.pulsatile.probes must be a list of points [x, y, z] (m), not {probes!r}")
    wf = cfd["inlet"].get("waveform")
    if wf is not None and not isinstance(wf, str):
        raise VCSInputError(f"cfd.inlet.waveform must be null (steady) or the path of a CSV file, not {wf!r}")


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


def flavour_of(family: str | None, version: str | None) -> str | None:
    """The case flavour for an OpenFOAM family and version.

    Parameters
    ----------
    family : str or None
        ``"com"`` (ESI-OpenCFD, openfoam.com), ``"org"`` (OpenFOAM Foundation, openfoam.org) or
        None (taken from the version's form, :func:`vcs.cfd.foamfiles.family_of_version`).
    version : str or None
        E.g. ``"v1912"``, ``"10"``, ``"12"``, ``"dev"``.

    Returns
    -------
    str or None
        ``"esi"`` for any openfoam.com version; ``"org<N>"`` for openfoam.org N (``"org10"`` is
        the supported one: 11 and later replaced simpleFoam by ``foamRun``, so they get their
        own, unsupported, name); ``"orgdev"`` for the development line; ``"org"`` when the
        openfoam.org version is unknown; None when the family is unknown.
    """
    family = family or family_of_version(version)
    if family == "com":
        return "esi"
    if family != "org":
        return None
    m = re.match(r"^(\d+)", version or "")
    if m:
        return f"org{int(m.group(1))}"
    word = re.sub(r"[^A-Za-z0-9]", "", version or "")
    return f"org{word}" if word else "org"


def _run_text(cmd: list[str], timeout: float = 30.0) -> str:
    """stdout + stderr of a command, or "" when it cannot run (never raises)."""
    try:
        r = subprocess.run(cmd, env=foam_env(), capture_output=True, text=True, errors="replace", timeout=timeout)
        return (r.stdout or "") + "\n" + (r.stderr or "")
    except Exception:  # noqa: BLE001 - detection must never fail
        return ""


def _project_dirs(executable: str | None) -> list[Path]:
    """Candidate installation folders: $WM_PROJECT_DIR (Debian's default) and the one holding
    ``executable`` (``<dir>/platforms/<arch>/bin/simpleFoam`` or ``<dir>/bin/simpleFoam``)."""
    out: list[Path] = []
    env_dir = foam_env().get("WM_PROJECT_DIR")
    if env_dir:
        out.append(Path(env_dir))
    if executable:
        try:
            exe = Path(executable).resolve()
            if exe.parent.name == "bin" and len(exe.parents) > 3 and exe.parents[2].name == "platforms":
                out.append(exe.parents[3])
            elif exe.parent.name == "bin":
                out.append(exe.parents[1])
        except (OSError, RuntimeError):
            pass
    return [d for i, d in enumerate(out) if d not in out[:i]]


def _files_facts(project_dir: Path) -> tuple[str | None, str | None]:
    """(family, version) from an installation's files: ESI's ``META-INFO/api-info`` (``api=2312``)
    and ``etc/bashrc`` (``export WM_PROJECT_VERSION=...`` and the website in its header)."""
    family: str | None = None
    version: str | None = None
    try:
        api = project_dir / "META-INFO" / "api-info"
        if api.is_file():
            m = re.search(r"^api=(\d+)", api.read_text(errors="replace"), re.M)
            if m:
                family, version = "com", f"v{m.group(1)}"
        bashrc = project_dir / "etc" / "bashrc"
        if bashrc.is_file():
            txt = bashrc.read_text(errors="replace")
            if "openfoam.org" in txt[:2000]:
                family = family or "org"
            elif "openfoam.com" in txt[:2000]:
                family = family or "com"
            m = re.search(r"^\s*export\s+WM_PROJECT_VERSION=['\"]?([\w.-]+)", txt, re.M)
            if m and version is None:
                version = m.group(1)
    except (OSError, ValueError):
        pass
    return family or family_of_version(version), version


def _dpkg_facts() -> tuple[str | None, str | None, str | None]:
    """(family, version, package) of an installed OpenFOAM Debian package: Debian's ``openfoam``
    (ESI; version ``1912.200626-1+b1``), openfoam.com's ``openfoam2312``, openfoam.org's
    ``openfoam10`` / ``openfoam-dev``."""
    if not shutil.which("dpkg-query"):
        return None, None, None
    txt = _run_text(["dpkg-query", "-W", "-f=${Package}\t${Version}\t${db:Status-Abbrev}\n", "openfoam*"], 20.0)
    for line in txt.splitlines():
        parts = line.split("\t")
        if len(parts) < 3 or not parts[2].startswith("ii"):
            continue
        pkg, ver = parts[0].strip(), parts[1].strip()
        if pkg == "openfoam":
            m = re.match(r"^(?:\d+:)?v?(\d{4})", ver)
            return "com", (f"v{m.group(1)}" if m else ver), pkg
        m = re.match(r"^openfoam(\d{4})$", pkg)
        if m:
            return "com", f"v{m.group(1)}", pkg
        m = re.match(r"^openfoam(\d{1,2}|-dev)$", pkg)
        if m:
            return "org", m.group(1).lstrip("-"), pkg
    return None, None, None


@lru_cache(maxsize=1)
def openfoam_installation() -> dict[str, Any]:
    """Everything known about the installed OpenFOAM, from every source; never raises.

    Sources, in order of trust: the banner of ``simpleFoam -help`` (the executable that
    :func:`vcs.cfd.run.run_case` runs; openfoam.org 11+ ship a ``simpleFoam`` script that runs
    ``foamRun``, whose banner is read the same way), ``$WM_PROJECT_VERSION``, the installation's
    files (``$WM_PROJECT_DIR`` or the folder holding simpleFoam: ``META-INFO/api-info``,
    ``etc/bashrc``), dpkg. The family (openfoam.com / openfoam.org) is that of the first source
    that tells it; the version that of the first source of the same family. No sourced
    environment is needed. ``$VCSFLOW_OPENFOAM_FLAVOUR`` forces the flavour (the version is still
    detected). Cached for the process (``openfoam_installation.cache_clear()``).

    Returns
    -------
    dict
        ``flavour`` (see :func:`flavour_of`; the forced value when set), ``family``, ``version``,
        ``build`` (str or None each), ``executable`` (path of simpleFoam or None), ``forced``
        (bool), ``sources``: list of {``source``, ``family``, ``version``} for every source
        that said something, ``notes``: list of str.
    """
    info: dict[str, Any] = {
        "flavour": None,
        "family": None,
        "version": None,
        "build": None,
        "executable": None,
        "forced": False,
        "sources": [],
        "notes": [],
    }
    facts: list[dict[str, Any]] = []
    try:
        exe = shutil.which("simpleFoam")
        info["executable"] = exe
        if exe:
            b = parse_banner(_run_text([exe, "-help"], 60.0))
            info["build"] = b["build"]
            if b["superseded"]:
                info["notes"].append(
                    f"{b['superseded']} is a script that runs foamRun (openfoam.org 11+): not supported, use 10"
                )
            facts.append({"source": "simpleFoam -help", "family": b["family"], "version": b["version"]})
        wmv = os.environ.get("WM_PROJECT_VERSION", "").strip()
        if wmv:
            facts.append({"source": "$WM_PROJECT_VERSION", "family": family_of_version(wmv), "version": wmv})
        for d in _project_dirs(exe):
            fam, ver = _files_facts(d)
            if fam or ver:
                facts.append({"source": str(d), "family": fam, "version": ver})
        fam, ver, pkg = _dpkg_facts()
        if fam or ver:
            facts.append({"source": f"dpkg {pkg}", "family": fam, "version": ver})
    except Exception as exc:  # noqa: BLE001 - detection must never fail
        info["notes"].append(f"detection stopped early: {type(exc).__name__}: {exc}")
    info["sources"] = [f for f in facts if f["family"] or f["version"]]
    family = next((f["family"] for f in facts if f["family"]), None)
    version = next((f["version"] for f in facts if f["version"] and f["family"] in (None, family)), None)
    info["family"], info["version"] = family, version
    info["flavour"] = flavour_of(family, version)
    forced = os.environ.get("VCSFLOW_OPENFOAM_FLAVOUR", "").strip()
    if forced:
        info["flavour"], info["forced"] = forced, True
    return info


OPENFOAM_DEV_DIR = "/opt/vcs-openfoam-dev"
"""Where ``scripts/openfoam_dev.sh`` prepares OpenFOAM's headers and wmake and puts the project's
compiled libraries (``lib/``); ``$VCS_OPENFOAM_DEV`` overrides it (as it does for the script)."""


def foam_library(name: str) -> str:
    """The absolute path of one of the project's OpenFOAM libraries (``lib<name>.so``, compiled by
    ``bash scripts/install.sh`` from ``templates/openfoam/lib/<name>``), or a one-line VCSInputError
    saying how to build it."""
    root = Path(os.environ.get("VCS_OPENFOAM_DEV") or OPENFOAM_DEV_DIR)
    lib = root / "lib" / f"lib{name}.so"
    if not lib.is_file():
        raise VCSInputError(
            f"the OpenFOAM library {lib} is not built (needed by the rcr outlets): run bash scripts/install.sh, "
            f"which compiles templates/openfoam/lib/{name} against the installed OpenFOAM"
        )
    return str(lib)


def detect_openfoam() -> tuple[str | None, str | None]:
    """(flavour, version) of the installed OpenFOAM, or (None, None) when none is found.

    See :func:`openfoam_installation` for the sources (banner of ``simpleFoam -help``,
    $WM_PROJECT_VERSION, the installation's files, dpkg; no sourced environment needed) and the
    $VCSFLOW_OPENFOAM_FLAVOUR override. Never raises; cached for the process (clear with
    ``openfoam_installation.cache_clear()``).

    Returns
    -------
    flavour : str or None
        ``"esi"``, ``"org10"``, another ``"org<N>"`` / ``"orgdev"`` (not supported by the
        templates), the forced value, or None.
    version : str or None
        The version string found (``"v1912"``, ``"10"``, ``"dev"``), or None.
    """
    info = openfoam_installation()
    return info["flavour"], info["version"]
