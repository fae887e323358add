"""OpenFOAM case generation and execution for the haemodynamic atlas (paper Section 2.4.1).

Public API
----------
``DEFAULTS``                      all CFD parameters (mirrored by the Snakemake config ``cfd:`` block)
``detect_openfoam()``             -> (flavour, version) of the installed OpenFOAM
``render_case(case_dir, stl_path, cfd, *, flavour=None) -> dict``
``run_case(case_dir, *, ranks=1) -> dict``   (also written to ``case_dir/status.json``)

Flavours: ``"esi"`` (openfoam.com, tested with Debian's v1912) and ``"org10"`` (openfoam.org v10,
dictionaries checked against the OpenFOAM-10 tutorials; it cannot be executed here).  Both are
rendered from ``templates/openfoam/common`` plus the flavour's override directory, driven by the
single table ``FLAVOURS`` below.
"""
from __future__ import annotations

import copy
import json
import os
import re
import shutil
import subprocess
import time
from functools import lru_cache
from pathlib import Path

import numpy as np

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

from . import foam_io

TEMPLATE_DIR = Path(__file__).resolve().parents[2] / "templates" / "openfoam"

# --------------------------------------------------------------------------- parameters

DEFAULTS: dict = {
    "flavour": None,          # None = detect the installed OpenFOAM; "esi" (v1912/openfoam.com) or "org10"
    "ranks": 1,               # MPI ranks for simpleFoam (1 = serial); decomposition below
    "mesh": {
        "cell_size": 1.0e-3,          # background (blockMesh) hex edge [m]
        "pad_cells": 3,               # background box = STL bounds + pad_cells cells on every side
        "surface_level": [0, 0],      # snappy (min max) refinement level on the whole vessel surface
        "wall_level": [0, 0],         # ... on the wall solid
        "inlet_level": [0, 0],        # ... on the inlet solid (raise to resolve the jet's shear layer)
        "outlet_level": [0, 0],       # ... on the outlet solid(s)
        "n_cells_between_levels": 2,
        "resolve_feature_angle": 30,
        "snap_solve_iterations": 50,
        "layers": 0,                  # wall prism layers (0 = addLayers off)
        "layer_expansion": 1.2,
        "final_layer_thickness": 0.3,
        "min_layer_thickness": 0.1,
        "max_non_ortho": 65,
        "max_local_cells": 2_000_000,
        "max_global_cells": 20_000_000,
        "inside_point": None,         # [x, y, z] inside the lumen; None = automatic (from the inlet)
    },
    "physics": {
        "nu": 3.37e-6,                # kinematic viscosity [m2/s] (Newtonian blood)
        "rho": 1060.0,                # density [kg/m3], only to convert p and WSS to Pa
    },
    "inlet": {
        "type": "jet",                # jet | uniform | parabolic
        "velocity": 1.2,              # jet velocity [m/s] (paper: 1.2 m/s)
        "valve_area": 1.0e-4,         # effective valve area [m2] (paper: 1 cm2) -> Q = velocity * area
        "flow_rate": None,            # [m3/s]; overrides velocity * valve_area when set
        "centre": None,               # jet centre [x, y, z]; None = area centroid of the inlet patch
    },
    "solver": {
        "tolerance": 1.0e-5,          # SIMPLE residualControl (initial residuals of p and U)
        "max_iterations": 2000,       # total SIMPLE iterations (start-up included)
        "startup_iterations": 100,    # first-order start-up iterations (0 = none)
        "startup_scheme": "upwind",
        "div_scheme": "linearUpwind", # scheme of the main stage for div(phi,U)
        "consistent": True,           # SIMPLEC
        "relax_U": 0.9,
        "relax_p": 1.0,               # with consistent=False use ~0.3 / relax_U ~0.7
        "n_non_orthogonal_correctors": 1,
        "p_solver_tolerance": 1.0e-8,
        "p_rel_tol": 0.05,
        "U_solver_tolerance": 1.0e-9,
        "U_rel_tol": 0.1,
        "fallback": "average",        # none | average: if not converged, continue average_iterations
                                      # with fieldAverage and report the time-averaged (pseudo-steady) fields
        "average_iterations": 500,
        "relaxed_tolerance": 1.0e-3,  # reported criterion for the fallback (converged stays false)
        "timeout_s": None,            # wall-clock limit per utility call [s]
    },
    "decomposition": {
        "method": "hierarchical",     # hierarchical | simple (scotch is a stub in Debian's package)
    },
    "io": {
        "write_format": "ascii",      # ascii is required by the inlet-profile reader
    },
}

# ONE table for both flavours: names that differ, the geometry folder and the case files.
_COMMON_FILES = [
    "system/blockMeshDict", "system/snappyHexMeshDict", "system/controlDict", "system/fvSchemes",
    "system/fvSolution", "system/decomposeParDict", "0/U", "0/p",
]
FLAVOURS: dict[str, dict] = {
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

STL_NAME = "vessel.stl"
CASE_JSON = "vcsflow_case.json"


def deep_merge(base: dict, over: dict | None) -> dict:
    out = copy.deepcopy(base)
    for k, v in (over or {}).items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out


# --------------------------------------------------------------------------- environment


def foam_env() -> dict:
    env = dict(os.environ)
    if "WM_PROJECT_DIR" not in env and Path("/usr/share/openfoam").is_dir():
        env["WM_PROJECT_DIR"] = "/usr/share/openfoam"
    return env


@lru_cache(maxsize=1)
def detect_openfoam() -> tuple[str | None, str | None]:
    """(flavour, version) of the installed OpenFOAM, or (None, None) when none is found.

    Order: $VCSFLOW_OPENFOAM_FLAVOUR, $WM_PROJECT_VERSION, the banner of ``simpleFoam -help``
    (openfoam.com vs openfoam.org), dpkg's version of the ``openfoam`` package."""
    forced = os.environ.get("VCSFLOW_OPENFOAM_FLAVOUR")
    wmv = os.environ.get("WM_PROJECT_VERSION")
    version = wmv
    banner = ""
    if shutil.which("simpleFoam"):
        try:
            banner = subprocess.run(["simpleFoam", "-help"], env=foam_env(), capture_output=True,
                                    text=True, timeout=60).stdout
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
        major = int(re.match(r"(\d+)", version).group(1)) if version else 10
        return ("org10" if major >= 10 else f"org{major}"), version
    return None, version


# --------------------------------------------------------------------------- rendering


def _jinja_env(flavour: str):
    import jinja2
    return jinja2.Environment(
        loader=jinja2.ChoiceLoader([
            jinja2.FileSystemLoader(str(TEMPLATE_DIR / flavour)),
            jinja2.FileSystemLoader(str(TEMPLATE_DIR / "common")),
        ]),
        undefined=jinja2.StrictUndefined, keep_trailing_newline=True, autoescape=False,
    )


def _role(name: str) -> str:
    n = name.lower()
    if n.startswith("inlet"):
        return "inlet"
    if n.startswith("outlet"):
        return "outlet"
    if n.startswith("wall"):
        return "wall"
    return "other"


def _inside_point(solids: dict[str, np.ndarray], bmin: np.ndarray, h: float) -> list[float]:
    alltris = np.concatenate(list(solids.values()))
    inlets = [k for k in solids if _role(k) == "inlet"]
    seeds = []
    if inlets:
        t = solids[inlets[0]]
        s = foam_io.triangle_area_vectors(t)
        a = np.linalg.norm(s, axis=1)
        c = (t.mean(axis=1) * a[:, None]).sum(0) / a.sum()
        n = s.sum(0) / max(np.linalg.norm(s.sum(0)), 1e-300)
        for k in (4, 8, 16, 2, 32):
            seeds += [c - k * h * n, c + k * h * n]
    seeds.append(alltris.reshape(-1, 3).mean(0))
    frac = np.array([0.371, 0.413, 0.437])
    for p in seeds:
        q = bmin + (np.floor((p - bmin) / h) + frac) * h   # keep it off background-mesh faces
        if foam_io.points_inside(q[None], alltris)[0]:
            return [float(x) for x in q]
    raise VCSInputError("could not find a point inside the vessel surface; set mesh.inside_point")


def _context(state: dict, **extra) -> dict:
    cfd = state["cfd"]
    ctx = {
        "flavour": state["flavour"], "flav": FLAVOURS[state["flavour"]],
        "mesh": cfd["mesh"], "physics": cfd["physics"], "inlet": cfd["inlet"], "solver": cfd["solver"],
        "io": cfd["io"], "ranks": max(int(cfd["ranks"]), 1),
        "decomposition": {"method": cfd["decomposition"]["method"], "n": state["decomposition_n"]},
        "bmin": state["bmin"], "bmax": state["bmax"], "ncells": state["ncells"],
        "inside_point": state["inside_point"], "stl_name": STL_NAME,
        "solids": state["solids"], "patches": state["patches"],
        "end_time": cfd["solver"]["max_iterations"], "div_scheme": cfd["solver"]["div_scheme"],
        "residual_control": True, "average": False, "inlet_values": None,
    }
    ctx.update(extra)
    return ctx


def _render(case_dir: Path, state: dict, files: list[str], **extra) -> None:
    env = _jinja_env(state["flavour"])
    ctx = _context(state, **extra)
    for rel in files:
        out = case_dir / rel
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(env.get_template(rel).render(**ctx))


def _flow_rate(inlet: dict) -> float:
    if inlet.get("flow_rate"):
        return float(inlet["flow_rate"])
    return float(inlet["velocity"]) * float(inlet["valve_area"])


def render_case(case_dir, stl_path, cfd: dict | None = None, *, flavour: str | None = None) -> dict:
    """Write a complete OpenFOAM case for a multi-solid ASCII STL (metres; solids wall/inlet/outlet...).

    ``cfd`` is merged over ``DEFAULTS``. The flavour is ``flavour`` or ``cfd['flavour']`` or the
    detected installation.  Returns the case description (also saved as ``vcsflow_case.json``)."""
    case_dir = Path(case_dir)
    cfd = deep_merge(DEFAULTS, cfd)
    flavour = flavour or cfd.get("flavour") or detect_openfoam()[0] or "esi"
    if flavour not in FLAVOURS:
        raise VCSInputError(f"unknown OpenFOAM flavour {flavour!r}; known: {sorted(FLAVOURS)}")
    cfd["flavour"] = flavour
    if cfd["inlet"]["type"] not in ("jet", "uniform", "parabolic"):
        raise VCSInputError(f"inlet.type must be jet, uniform or parabolic, not {cfd['inlet']['type']!r}")
    fl = FLAVOURS[flavour]

    solids = foam_io.read_stl_solids(stl_path)
    roles = {k: _role(k) for k in solids}
    if sum(r == "inlet" for r in roles.values()) != 1:
        raise VCSInputError(f"the STL needs exactly one inlet solid, found {list(solids)}")
    if not any(r == "outlet" for r in roles.values()):
        raise VCSInputError(f"the STL has no outlet solid: {list(solids)}")
    pts = np.concatenate([t.reshape(-1, 3) for t in solids.values()])
    lo, hi = pts.min(0), pts.max(0)
    m = cfd["mesh"]
    h = float(m["cell_size"])
    bmin = lo - m["pad_cells"] * h
    ncells = np.ceil((hi - lo) / h + 2 * m["pad_cells"]).astype(int)
    bmax = bmin + ncells * h
    inside = m.get("inside_point") or _inside_point(solids, bmin, h)
    ranks = max(int(cfd["ranks"]), 1)
    n = [1, 1, 1]
    n[int(np.argmax(hi - lo))] = ranks

    level = {"wall": m["wall_level"], "inlet": m["inlet_level"], "outlet": m["outlet_level"], "other": m["surface_level"]}
    state = {
        "flavour": flavour, "cfd": cfd, "stl_source": str(Path(stl_path).resolve()),
        "bmin": [float(x) for x in bmin], "bmax": [float(x) for x in bmax], "ncells": [int(x) for x in ncells],
        "inside_point": [float(x) for x in inside], "decomposition_n": n,
        "solids": [{"name": k, "role": roles[k], "patch_type": "wall" if roles[k] == "wall" else "patch",
                    "level": level[roles[k]]} for k in solids],
        "patches": [{"name": k, "role": roles[k]} for k in solids] + [{"name": "background", "role": "other"}],
        "flow_rate": _flow_rate(cfd["inlet"]),
        "stl_bounds": [[float(x) for x in lo], [float(x) for x in hi]],
    }
    case_dir.mkdir(parents=True, exist_ok=True)
    geo = case_dir / fl["geometry_dir"]
    geo.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(stl_path, geo / STL_NAME)
    _render(case_dir, state, fl["files"])
    state["files"] = list(fl["files"]) + [f"{fl['geometry_dir']}/{STL_NAME}"]
    (case_dir / CASE_JSON).write_text(json.dumps(state, indent=2))
    return state


# --------------------------------------------------------------------------- inlet profile


def inlet_profile(case_dir: Path, state: dict) -> dict:
    """Face-wise inlet velocities on the meshed inlet patch, scaled so sum(U.Sf) = -Q exactly."""
    inlet = state["cfd"]["inlet"]
    name = next(p["name"] for p in state["patches"] if p["role"] == "inlet")
    centres, sf = foam_io.patch_geometry(case_dir, name)
    mag = np.linalg.norm(sf, axis=1)
    ntot = sf.sum(0)
    n_in = -ntot / np.linalg.norm(ntot)              # Sf points out of the domain
    area = float(mag.sum())
    c0 = np.asarray(inlet.get("centre") or (centres * mag[:, None]).sum(0) / area, float)
    d = centres - c0
    d -= np.outer(d @ n_in, n_in)
    r = np.linalg.norm(d, axis=1)
    q = state["flow_rate"]
    kind = inlet["type"]
    if kind == "jet":
        r_jet = np.sqrt(float(inlet["valve_area"]) / np.pi)
        shape = (r <= r_jet).astype(float)
        if shape.sum() == 0:
            raise VCSInputError("jet disc contains no inlet face centre: refine the inlet or enlarge valve_area")
    elif kind == "uniform":
        shape = np.ones_like(r)
    else:  # parabolic over the equivalent-circle radius of the inlet
        r_eq = np.sqrt(area / np.pi)
        shape = np.clip(1.0 - (r / r_eq) ** 2, 0.0, None)
    inflow_per_unit = float((shape * (sf @ (-n_in))).sum())   # sum shape * (n_in . -Sf)
    scale = q / inflow_per_unit
    values = scale * shape[:, None] * n_in[None, :]
    flux = float(-(values * sf).sum())
    covered = float(mag[shape > 0].sum())
    return {"patch": name, "values": values, "n_faces": int(len(mag)), "patch_area": area,
            "direction": [float(x) for x in n_in], "centre": [float(x) for x in c0],
            "flow_rate_target": q, "flow_rate_discrete": flux,
            "flux_error_rel": abs(flux - q) / q, "covered_area": covered,
            "peak_velocity": float(np.abs(values @ n_in).max())}


# --------------------------------------------------------------------------- running


class _Runner:
    def __init__(self, case_dir: Path, timings: dict, timeout: float | None):
        self.case = case_dir
        self.logs = case_dir / "logs"
        self.logs.mkdir(exist_ok=True)
        self.timings = timings
        self.timeout = timeout
        self.env = foam_env()

    def __call__(self, args: list[str], log: str, ranks: int = 1) -> subprocess.CompletedProcess:
        cmd = list(args)
        if ranks > 1:
            mpi = ["mpirun", "--oversubscribe", "-np", str(ranks)]
            if hasattr(os, "geteuid") and os.geteuid() == 0:
                mpi.insert(1, "--allow-run-as-root")
            for var in ("WM_PROJECT_DIR", "FOAM_SIGFPE"):
                if var in self.env:
                    mpi += ["-x", var]
            cmd = mpi + cmd + ["-parallel"]
        t0 = time.perf_counter()
        with open(self.logs / f"log.{log}", "w") as fh:
            fh.write(f"# {' '.join(cmd)}\n")
            fh.flush()
            try:
                r = subprocess.run(cmd, cwd=self.case, env=self.env, stdout=fh, stderr=subprocess.STDOUT,
                                   timeout=self.timeout)
            except subprocess.TimeoutExpired:
                r = subprocess.CompletedProcess(cmd, returncode=-9)
                fh.write(f"\n# vcsflow: timeout after {self.timeout} s\n")
        self.timings[log] = round(self.timings.get(log, 0.0) + time.perf_counter() - t0, 3)
        return r


def _latest_time(case_dir: Path) -> str | None:
    times = []
    for p in case_dir.iterdir():
        if p.is_dir():
            try:
                times.append((float(p.name), p.name))
            except ValueError:
                pass
    return max(times)[1] if times else None


def _check_mesh(log: Path) -> tuple[bool, int | None, str]:
    txt = log.read_text(errors="replace")
    m = re.search(r"^\s*cells:\s+(\d+)", txt, re.M)
    cells = int(m.group(1)) if m else None
    if "Mesh OK." in txt:
        return True, cells, ""
    fails = re.findall(r"\*\*\*.*", txt)
    m = re.search(r"Failed (\d+) mesh checks", txt)
    why = (f"checkMesh failed {m.group(1)} check(s): " if m else "checkMesh did not report 'Mesh OK.': ") + "; ".join(
        f.strip() for f in fails[:5])
    return False, cells, why


def _read_patch_vectors(field_file: Path, patch: str) -> np.ndarray | None:
    txt = field_file.read_text(errors="replace")
    bf = txt.find("boundaryField")
    m = re.search(rf"\b{re.escape(patch)}\s*\{{[^{{}}]*?value\s+nonuniform\s+List<vector>\s*(\d+)\s*\(", txt[bf:], re.S)
    if not m:
        m2 = re.search(rf"\b{re.escape(patch)}\s*\{{[^{{}}]*?value\s+uniform\s*\(([^)]*)\)", txt[bf:], re.S)
        return None if not m2 else np.array([[float(x) for x in m2.group(1).split()]])
    n = int(m.group(1))
    start = bf + m.end()
    vals = re.findall(r"\(([^()]*)\)", txt[start:start + n * 80 + 1000])[:n]
    return np.array([[float(x) for x in v.split()] for v in vals])


def _write_residuals(case_dir: Path, rows: list[dict]) -> None:
    import csv
    keys = ["iteration", "p", "U", "cont_local", "cont_global", "cont_cumulative"]
    with open(case_dir / "residuals.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            w.writerow([r.get("time") if k == "iteration" else r.get(k, "") for k in keys])
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(6, 4))
        it = [r["time"] for r in rows]
        for k in ("p", "U"):
            ax.semilogy(it, [r.get(k, np.nan) for r in rows], label=k)
        ax.set_xlabel("SIMPLE iteration")
        ax.set_ylabel("initial residual")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(case_dir / "residuals.png", dpi=100)
        plt.close(fig)
    except Exception:  # plotting must never fail a run
        pass


def _use_means(time_dir: Path) -> None:
    """Fallback: replace U and p by their fieldAverage means (instantaneous kept as *.instantaneous)."""
    for f in ("U", "p"):
        mean = time_dir / f"{f}Mean"
        if mean.exists():
            shutil.move(time_dir / f, time_dir / f"{f}.instantaneous")
            txt = mean.read_text()
            txt = re.sub(rf"(object\s+){f}Mean;", rf"\1{f};", txt, count=1)
            (time_dir / f).write_text(txt)


def run_case(case_dir, *, ranks: int | None = None) -> dict:
    """Mesh and solve a rendered case; writes ``status.json``, ``residuals.csv/png``, ``logs/log.*``.

    Steps: blockMesh, snappyHexMesh -overwrite, checkMesh (failure stops), inlet profile,
    [decomposePar], simpleFoam start-up (first order) then main stage (residualControl);
    if not converged and solver.fallback == 'average': averaging stage with fieldAverage whose
    means replace U and p; [reconstructPar]; wallShearStress."""
    case_dir = Path(case_dir).resolve()
    state = json.loads((case_dir / CASE_JSON).read_text())
    cfd = state["cfd"]
    sol = cfd["solver"]
    ranks = max(int(ranks if ranks is not None else cfd.get("ranks", 1)), 1)
    n = [1, 1, 1]                       # hierarchical/simple: split along the longest STL extent
    lo, hi = (np.array(b) for b in state["stl_bounds"])
    n[int(np.argmax(hi - lo))] = ranks
    state["decomposition_n"] = n
    state["cfd"]["ranks"] = ranks
    timings: dict = {}
    installed, version = detect_openfoam()
    status: dict = {
        "case": str(case_dir), "flavour": state["flavour"], "openfoam_version": version, "ranks": ranks,
        "converged": False, "criterion": f"initial residuals of p and U < {sol['tolerance']:g}",
        "iterations": 0, "final_residuals": {}, "mass_imbalance": None, "cells": None,
        "timings_s": timings, "reason": None, "inlet": {"type": cfd["inlet"]["type"]},
        "units": {"p": "m2/s2 (kinematic); *_Pa = x rho", "wallShearStress": "m2/s2 (kinematic); *_Pa = x rho"},
        "rho": cfd["physics"]["rho"], "nu": cfd["physics"]["nu"],
    }

    def finish(reason: str | None = None, failed_log: str | None = None) -> dict:
        if reason:
            status["reason"] = reason
        if failed_log:  # the log of the utility that failed (absolute path), for the user and the atlas
            status["failed_log"] = str(case_dir / "logs" / f"log.{failed_log}")
        status["timings_s"]["total"] = round(sum(v for k, v in timings.items() if k != "total"), 3)
        (case_dir / "status.json").write_text(json.dumps(status, indent=2, default=float))
        return status

    if installed is None:
        return finish("no OpenFOAM installation found (simpleFoam not on PATH)")
    if installed != state["flavour"]:
        return finish(f"case rendered for flavour {state['flavour']!r} but the installed OpenFOAM is {installed!r}")

    run = _Runner(case_dir, timings, sol.get("timeout_s"))
    for d in case_dir.glob("processor*"):
        shutil.rmtree(d)
    for d in case_dir.iterdir():  # restart from a clean 0/ (re-run safety)
        if d.is_dir() and d.name not in ("0", "constant", "system", "logs"):
            try:
                if float(d.name) > 0:
                    shutil.rmtree(d)
            except ValueError:
                if d.name == "postProcessing":
                    shutil.rmtree(d)
    shutil.rmtree(case_dir / "constant" / "polyMesh", ignore_errors=True)
    for f in (case_dir / "logs").glob("log.*"):
        f.unlink()
    _render(case_dir, state, ["0/U", "0/p"])     # placeholder inlet until the mesh exists

    if run(["blockMesh"], "blockMesh").returncode != 0:
        return finish(_utility_failure(case_dir, "blockMesh"), "blockMesh")
    if run(["snappyHexMesh", "-overwrite"], "snappyHexMesh").returncode != 0:
        return finish(_utility_failure(case_dir, "snappyHexMesh"), "snappyHexMesh")
    run(["checkMesh"], "checkMesh")
    ok, cells, why = _check_mesh(case_dir / "logs" / "log.checkMesh")
    status["cells"] = cells
    if not ok:
        status["mesh_ok"] = False
        return finish(why, "checkMesh")
    status["mesh_ok"] = True

    # inlet profile on the real mesh faces, flux exact
    t0 = time.perf_counter()
    try:
        prof = inlet_profile(case_dir, state)
    except Exception as exc:  # noqa: BLE001
        return finish(f"inlet profile: {exc}")
    _render(case_dir, state, ["0/U"], inlet_values=prof["values"].tolist())
    timings["inletProfile"] = round(time.perf_counter() - t0, 3)
    status["inlet"].update({k: v for k, v in prof.items() if k != "values"})

    if ranks > 1:
        _render(case_dir, state, ["system/decomposeParDict"])
        if run(["decomposePar", "-force"], "decomposePar").returncode != 0:
            return finish(_utility_failure(case_dir, "decomposePar"), "decomposePar")

    stage_files = ["system/controlDict", "system/fvSchemes", "system/fvSolution"]
    logs = []
    n_start = int(sol["startup_iterations"])
    if n_start > 0:
        _render(case_dir, state, stage_files, end_time=n_start, div_scheme=sol["startup_scheme"],
                residual_control=False)
        r = run(["simpleFoam"], "simpleFoam.startup", ranks)
        logs.append(case_dir / "logs" / "log.simpleFoam.startup")
        if r.returncode != 0:
            return finish(_solver_failure(logs[-1], "start-up"), "simpleFoam.startup")
    _render(case_dir, state, stage_files, end_time=int(sol["max_iterations"]))
    r = run(["simpleFoam"], "simpleFoam", ranks)
    logs.append(case_dir / "logs" / "log.simpleFoam")
    main = foam_io.parse_solver_log(logs[-1])
    if r.returncode != 0:
        _collect(case_dir, status, logs, state)
        return finish(_solver_failure(logs[-1], "main"), "simpleFoam")
    last = main["rows"][-1] if main["rows"] else {}
    tol = float(sol["tolerance"])
    converged = bool(last) and (main["converged_message"] or
                                (last.get("p", 1) < tol and last.get("U", 1) < tol))
    status["converged"] = converged
    averaged = False
    if not converged:
        status["reason"] = (f"SIMPLE did not reach initial residuals < {tol:g} in {int(last.get('time', 0))} "
                            f"iterations (last p {last.get('p', float('nan')):.3g}, U {last.get('U', float('nan')):.3g})")
        if sol.get("fallback") == "average" and int(sol["average_iterations"]) > 0:
            status["averaging_from"] = int(last.get("time", sol["max_iterations"]))
            end = status["averaging_from"] + int(sol["average_iterations"])
            _render(case_dir, state, stage_files, end_time=end, residual_control=False, average=True)
            r = run(["simpleFoam"], "simpleFoam.average", ranks)
            logs.append(case_dir / "logs" / "log.simpleFoam.average")
            if r.returncode != 0:
                _collect(case_dir, status, logs, state)
                return finish(status["reason"] + "; " + _solver_failure(logs[-1], "averaging"), "simpleFoam.average")
            averaged = True
    if ranks > 1:
        if run(["reconstructPar", "-latestTime"], "reconstructPar").returncode != 0:
            return finish((status["reason"] + "; " if status["reason"] else "") + "reconstructPar failed",
                          "reconstructPar")
    if averaged:
        tdir = case_dir / _latest_time(case_dir)
        _use_means(tdir)
        run(["simpleFoam", "-postProcess", "-func", "wallShearStress", "-latestTime"], "wallShearStress")
        status["criterion_used"] = "pseudo_steady_time_average"
        status["average_iterations"] = int(sol["average_iterations"])
    else:
        status["criterion_used"] = "residualControl" if converged else "none"
    _collect(case_dir, status, logs, state)
    if averaged:
        rel = status.get("averaging", {}).get("max_initial_residual")
        status["converged_relaxed"] = bool(rel is not None and rel < float(sol["relaxed_tolerance"]))
        status["reason"] += (f"; fallback: U and p are the time averages over the last {sol['average_iterations']} "
                             f"iterations (pseudo-steady), max residual during averaging {rel:.3g} "
                             f"(relaxed criterion {sol['relaxed_tolerance']:g}: "
                             f"{'met' if status['converged_relaxed'] else 'not met'})")
    return finish()


def _utility_failure(case_dir: Path, utility: str) -> str:
    """'<utility> failed: <FOAM FATAL ERROR message> (see logs/log.<utility>)'."""
    log = case_dir / "logs" / f"log.{utility}"
    txt = log.read_text(errors="replace")[-4000:] if log.exists() else ""
    m = re.search(r"FOAM FATAL (?:IO )?ERROR[^\n]*\n((?:[^\n]*\n){0,8})", txt)
    detail = ""
    if m:  # the message lines, without the "From ..."/"in file ..." trailer
        lines = [ln.strip() for ln in m.group(1).splitlines() if ln.strip()]
        lines = [ln for ln in lines if not ln.startswith(("From ", "in file ", "at line ", "FOAM exiting"))]
        detail = ": " + " ".join(" ".join(lines).split())[:300] if lines else ""
    elif "# vcsflow: timeout" in txt:
        detail = ": timeout"
    return f"{utility} failed{detail} (see logs/log.{utility})"


def _solver_failure(log: Path, stage: str) -> str:
    txt = log.read_text(errors="replace")[-4000:] if log.exists() else ""
    m = re.search(r"(FOAM FATAL[^\n]*\n(?:[^\n]*\n){0,6})", txt)
    if "Floating point exception" in txt or "sigFpe" in txt:
        return f"simpleFoam ({stage}) diverged: floating point exception (see logs/{log.name})"
    if m:
        return f"simpleFoam ({stage}) failed: " + " ".join(m.group(1).split())[:400]
    return f"simpleFoam ({stage}) exited with an error (see logs/{log.name})"


def _pyfoam_check(log: Path) -> dict | None:
    """Cross-check of the own log parser with PyFoam's BoundingLogAnalyzer (last iteration)."""
    try:
        from PyFoam.LogAnalysis.BoundingLogAnalyzer import BoundingLogAnalyzer
        a = BoundingLogAnalyzer(doFiles=False, doTimelines=True)
        with open(log) as fh:
            a.analyze(fh)
        lin = a.getAnalyzer("Linear").getCurrentData()
        cont = a.getAnalyzer("Continuity").getCurrentData()
        return {"log": log.name, "last_iteration": float(a.getTime()),
                "initial_residuals": {k: v for k, v in lin.items() if "_" not in k},
                "continuity": cont}
    except Exception as exc:  # noqa: BLE001 - optional cross-check only
        return {"error": f"{type(exc).__name__}: {exc}"}


def _collect(case_dir: Path, status: dict, logs: list[Path], state: dict) -> None:
    rows: list[dict] = []
    stage_iters = {}
    for lg in logs:
        if lg.exists():
            parsed = foam_io.parse_solver_log(lg)
            rows += parsed["rows"]
            stage_iters[lg.name.replace("log.", "")] = len(parsed["rows"])
    status["stage_iterations"] = stage_iters
    if rows:
        _write_residuals(case_dir, rows)
        last = rows[-1]
        status["iterations"] = int(last["time"])
        status["final_residuals"] = {k: last[k] for k in ("p", "U") if k in last}
        status["continuity_errors"] = {k.replace("cont_", ""): last[k] for k in
                                       ("cont_local", "cont_global", "cont_cumulative") if k in last}
        if logs and logs[-1].name.endswith(".average"):
            avg_rows = foam_io.parse_solver_log(logs[-1])["rows"]
            status["averaging"] = {"max_initial_residual": float(max(max(r.get("p", 0), r.get("U", 0)) for r in avg_rows))
                                   if avg_rows else None}
    status["pyfoam_log_analysis"] = _pyfoam_check(logs[-1]) if logs else None
    rho = float(state["cfd"]["physics"]["rho"])
    avg_from = status.get("averaging_from")

    def fo_value(name: str):
        # fallback: mean over the averaging window (consistent with UMean/pMean); else last iteration
        if avg_from is not None:
            return foam_io.mean_function_value(case_dir, name, avg_from)
        return foam_io.last_function_value(case_dir, name)

    flows = {}
    for p in state["patches"]:
        if p["role"] in ("inlet", "outlet"):
            flows[p["name"]] = fo_value(f"flowRate_{p['name']}")
    status["flow_rates"] = flows
    q_in = sum(v for k, v in flows.items() if v is not None and _role(k) == "inlet")
    q_out = sum(v for k, v in flows.items() if v is not None and _role(k) == "outlet")
    if q_in:
        status["mass_imbalance"] = abs(q_in + q_out) / abs(q_in)
    pin = {p["name"]: fo_value(f"pressure_{p['name']}") for p in state["patches"]
           if p["role"] in ("inlet", "outlet")}
    status["patch_pressure"] = pin
    pi = [v for k, v in pin.items() if _role(k) == "inlet" and v is not None]
    po = [v for k, v in pin.items() if _role(k) == "outlet" and v is not None]
    if pi and po:
        dp = pi[0] - float(np.mean(po))
        status["pressure_drop"] = {"kinematic_m2s2": dp, "Pa": dp * rho}
    latest = _latest_time(case_dir)
    if latest and float(latest) > 0:
        wss_file = case_dir / latest / "wallShearStress"
        walls = [p["name"] for p in state["patches"] if p["role"] == "wall"]
        if wss_file.exists() and walls:
            try:
                vals, areas = [], []
                for w in walls:
                    v = _read_patch_vectors(wss_file, w)
                    _, sf = foam_io.patch_geometry(case_dir, w)
                    a = np.linalg.norm(sf, axis=1)
                    if v is not None and len(v) == 1:
                        v = np.repeat(v, len(a), 0)
                    if v is not None and len(v) == len(a):
                        vals.append(np.linalg.norm(v, axis=1))
                        areas.append(a)
                if vals:
                    mag, a = np.concatenate(vals), np.concatenate(areas)
                    status["wall_shear_stress_Pa"] = {"mean": float((mag * a).sum() / a.sum() * rho),
                                                      "max": float(mag.max() * rho), "min": float(mag.min() * rho)}
            except Exception as exc:  # noqa: BLE001
                status["wall_shear_stress_Pa"] = {"error": str(exc)}
