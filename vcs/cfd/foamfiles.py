"""Reading OpenFOAM's own files, dependency-light (used while a case runs):

* ASCII ``constant/polyMesh`` reader for boundary patches (face centres / area vectors)
* solver-log parser (initial residuals, continuity errors, convergence message, time units of
  openfoam.org 10+) and banner parser (both families, solver logs and ``-help``)
* ``postProcessing/*/*.dat`` reader (surfaceFieldValue output), time-weighted window means
* ASCII field readers (internalField, a patch's value), snappyHexMesh's prism-layer report,
  checkMesh's volume, and the oscillatory shear index of time-averaged wall shear stress
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

# ----------------------------------------------------------------- polyMesh (ascii)

_HEADER_RE = re.compile(r"FoamFile\s*\{.*?\}", re.S)


def _strip(text: str) -> str:
    """OpenFOAM file text without comments and without its FoamFile header."""
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    text = re.sub(r"//[^\n]*", "", text)
    return _HEADER_RE.sub("", text, count=1)


def _read_text(path: Path) -> str:
    """Text of an ASCII OpenFOAM file, stripped (VCSInputError for a binary one)."""
    data = Path(path).read_bytes()
    if b"format      binary" in data[:2000] or re.search(rb"format\s+binary", data[:2000]):
        raise VCSInputError(f"{path}: binary OpenFOAM file; the case must be written with writeFormat ascii")
    return _strip(data.decode("ascii", errors="replace"))


def read_boundary(polymesh: Path | str) -> dict[str, dict[str, Any]]:
    """Read the patches of ``constant/polyMesh/boundary`` (ASCII).

    Parameters
    ----------
    polymesh : Path or str
        The ``constant/polyMesh`` folder.

    Returns
    -------
    dict of str -> dict
        Patch name -> {``type``: str, ``nFaces``: int, ``startFace``: int}, in file order.

    Raises
    ------
    VCSInputError
        When the file is binary.
    """
    txt = _read_text(Path(polymesh) / "boundary")
    out = {}
    for m in re.finditer(r"(\w[\w.:-]*)\s*\{([^{}]*)\}", txt):
        body = m.group(2)
        d = dict(re.findall(r"(\w+)\s+([^;]+);", body))
        if "nFaces" in d:
            out[m.group(1)] = {
                "type": d.get("type", "patch").strip(),
                "nFaces": int(d["nFaces"]),
                "startFace": int(d["startFace"]),
            }
    return out


def _list_body(txt: str) -> tuple[int, str]:
    """Length of the first OpenFOAM list ``N ( ... )`` in ``txt`` and the text after its '('."""
    m = re.search(r"(\d+)\s*\(", txt)
    if m is None:
        raise VCSInputError("no OpenFOAM list found")
    return int(m.group(1)), txt[m.end() :]


def read_points(polymesh: Path | str) -> NDArray[np.floating]:
    """Read the mesh points of ``constant/polyMesh/points`` (ASCII).

    Parameters
    ----------
    polymesh : Path or str
        The ``constant/polyMesh`` folder.

    Returns
    -------
    (P, 3) float
        Point coordinates in the case's units (m).

    Raises
    ------
    VCSInputError
        When the file is binary or holds no list.
    """
    n, body = _list_body(_read_text(Path(polymesh) / "points"))
    vals = np.array(re.findall(r"[-+0-9.eE]+", body[: body.rfind(")")]), dtype=float)
    return vals[: 3 * n].reshape(n, 3)


def read_faces(polymesh: Path | str, start: int, count: int) -> list[NDArray[np.integer]]:
    """Read ``count`` faces from ``start`` on of ``constant/polyMesh/faces`` (ASCII).

    Parameters
    ----------
    polymesh : Path or str
        The ``constant/polyMesh`` folder.
    start : int
        Index of the first face (a patch's ``startFace``).
    count : int
        Number of faces (a patch's ``nFaces``).

    Returns
    -------
    list of (k,) int
        Point indices of each face (k >= 3 corners, in OpenFOAM's order).

    Raises
    ------
    VCSInputError
        When the file is binary or holds no list.
    """
    txt = _read_text(Path(polymesh) / "faces")
    n, body = _list_body(txt)
    faces = re.findall(r"\d+\s*\(([\d\s]+)\)", body)
    return [np.array(f.split(), dtype=int) for f in faces[start : start + count]]


def face_geometry(
    points: NDArray[np.floating], faces: list[NDArray[np.integer]]
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Face centres and area vectors, OpenFOAM style (triangle fan about the point average).

    Parameters
    ----------
    points : (P, 3) float, m
        Mesh points.
    faces : list of (k,) int
        Point indices of each face.

    Returns
    -------
    centres : (F, 3) float, m
        Area-weighted face centres.
    areas : (F, 3) float, m^2
        Area vectors Sf (normal by the corner order, length = face area).
    """
    centres = np.empty((len(faces), 3))
    areas = np.empty((len(faces), 3))
    corners = np.fromiter((len(f) for f in faces), np.int64, len(faces))
    for k in np.unique(corners):  # the faces of k corners at once (a wall is mostly quads)
        idx = np.flatnonzero(corners == k)
        p = points[np.stack([faces[i] for i in idx])]  # (n, k, 3)
        if k == 3:
            centres[idx] = p.mean(axis=1)
            areas[idx] = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            continue
        c0 = p.mean(axis=1, keepdims=True)
        p1 = np.roll(p, -1, axis=1)
        sa = 0.5 * np.cross(p - c0, p1 - c0)  # the fan's triangles' area vectors
        tc = (p + p1 + c0) / 3.0
        area = sa.sum(axis=1)
        n = area / np.maximum(np.linalg.norm(area, axis=1), 1e-300)[:, None]
        w = np.abs(np.einsum("nkj,nj->nk", sa, n))
        centres[idx] = (tc * w[..., None]).sum(axis=1) / np.maximum(w.sum(axis=1), 1e-300)[:, None]
        areas[idx] = area
    return centres, areas


def patch_geometry(case_dir: Path | str, patch: str) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Face centres and area vectors of one boundary patch of a case's ASCII polyMesh.

    Parameters
    ----------
    case_dir : Path or str
        The OpenFOAM case.
    patch : str
        Patch name.

    Returns
    -------
    centres : (F, 3) float, m
    areas : (F, 3) float, m^2
        Area vectors Sf, pointing out of the domain.

    Raises
    ------
    KeyError
        When the patch is not in the mesh.
    VCSInputError
        When a polyMesh file is binary.
    """
    pm = Path(case_dir) / "constant" / "polyMesh"
    b = read_boundary(pm)
    if patch not in b:
        raise KeyError(f"patch {patch!r} not in mesh (patches: {sorted(b)})")
    faces = read_faces(pm, b[patch]["startFace"], b[patch]["nFaces"])
    return face_geometry(read_points(pm), faces)


# ----------------------------------------------------------------------- logs
#
# The lines read, and which OpenFOAM source prints them (openfoam.org 10 = OpenFOAM-10, ESI =
# openfoam.com v1912 as packaged by Debian; the other versions print the same unless said):
#
# * time line, once per SIMPLE iteration: "Time = 12" (ESI, openfoam.org <= 9: runTime.timeName())
#   or "Time = 12s" (openfoam.org 10, 11, 12: applications/solvers/incompressible/simpleFoam/
#   simpleFoam.C prints runTime.userTimeName(), which src/OpenFOAM/db/Time/Time.C builds as
#   timeName(userTimeValue()) + userTime_->unit(); the unit is "s" for the default realTime
#   (src/OpenFOAM/db/Time/userTime/realTime/realTime.C) and "CAD" for engineTime). Any
#   alphabetic unit ("s", "ms", "CAD") is accepted; deltaT = 1 makes the time the iteration.
# * linear-solver line: "smoothSolver:  Solving for Ux, Initial residual = ..., Final residual =
#   ..., No Iterations 2" (src/OpenFOAM/matrices/LduMatrix/LduMatrix/SolverPerformance.C, same in
#   both flavours).
# * "time step continuity errors : sum local = ..., global = ..., cumulative = ..."
#   (src/finiteVolume/cfdTools/incompressible/continuityErrs.H).
# * convergence: "SIMPLE solution converged in 129 iterations" (openfoam.org 10:
#   src/finiteVolume/cfdTools/general/solutionControl/convergenceControl/convergenceControl/
#   convergenceControl.C, converged(): algorithmName() + " solution converged in " +
#   time().timeName() + " iterations" -- timeName(), so no unit here; ESI v1912 prints the same).
# * "ExecutionTime = 4.02 s  ClockTime = 4 s" and the final "End" (simpleFoam.C, pimpleFoam.C).
# * transient (pimpleFoam): "Courant Number mean: 0.01 max: 0.98" (src/finiteVolume/cfdTools/
#   incompressible/CourantNo.H) and "deltaT = 0.0004" (src/finiteVolume/cfdTools/general/include/
#   setDeltaT.H), both printed before the step's time line (once more before the time loop,
#   with the restart's time step); the same text in both families.
# * banner of a solver log: openfoam.org 10 (src/OpenFOAM/db/IOobject/IOobjectI.H writeBanner,
#   argList.C): "   \\    /   O peration     | Website:  https://openfoam.org",
#   "    \\  /    A nd           | Version:  10", "Build  : 10-c4cf895ad8fa"; ESI:
#   "|  \\    /   O peration     | Version:  v1912 ... |", "| ... | Website:  www.openfoam.com |",
#   "Build  : _9f29a8da7a-20191219 OPENFOAM=1912" (Debian: empty Version, "Build  : OPENFOAM=1912
#   patch=200626").
# * banner of "<solver> -help": openfoam.org (argList.C printUsage): "Using: OpenFOAM-10 (see
#   https://openfoam.org)", "Build: 10-c4cf895ad8fa"; ESI: "Using: OpenFOAM-v2312 (2312) - visit
#   www.openfoam.com" (Debian v1912: "Using: OpenFOAM- (1912) - visit www.openfoam.com",
#   "Build:  (patch=200626)"); openfoam.org 11+ ship bin/simpleFoam as a script that prints
#   "simpleFoam has been superseded ..." and runs "foamRun -solver incompressibleFluid".

_FLOAT = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_RES_RE = re.compile(
    rf"Solving for (\w+), Initial residual = ({_FLOAT}), Final residual = ({_FLOAT}), No Iterations (\d+)"
)
_TIME_RE = re.compile(rf"^Time = ({_FLOAT})\s*([A-Za-z]*)$")
_CONT_RE = re.compile(
    rf"time step continuity errors : sum local = ({_FLOAT}), global = ({_FLOAT}), cumulative = ({_FLOAT})"
)
_CONV_RE = re.compile(
    r"(SIMPLE solution converged in|reached convergence criteria|solution converged in)\D*(\d+)?", re.I
)
_CONV_ITER_RE = re.compile(rf"solution converged in\s+({_FLOAT})\s*[A-Za-z]*\s+iterations", re.I)
_EXEC_RE = re.compile(rf"^ExecutionTime = ({_FLOAT}) s\s+ClockTime = ({_FLOAT}) s")
_COURANT_RE = re.compile(rf"^Courant Number mean: ({_FLOAT}) max: ({_FLOAT})")
_DELTAT_RE = re.compile(rf"^deltaT = ({_FLOAT})")
_USING_ORG_RE = re.compile(r"Using:\s*OpenFOAM-(\S*)\s*\(see\s+(?:https?://)?(?:www\.)?openfoam\.org\)")
_USING_COM_RE = re.compile(r"Using:\s*OpenFOAM-(\S*)\s*\((\d+)\)\s*-?\s*visit\s+(?:https?://)?www\.openfoam\.com")
_BUILD_RE = re.compile(r"^Build\s*:[ \t]*([^\n]*?)[ \t]*$", re.M)
_BOX_VERSION_RE = re.compile(r"^[| ].*\|\s*Version:[ \t]*([^\s|]+)", re.M)
_BOX_WEBSITE_RE = re.compile(r"^[| ].*\|\s*Website:[ \t]*(\S+)", re.M)
_API_RE = re.compile(r"OPENFOAM=(\d+)")
_SUPERSEDED_RE = re.compile(r"(\w+) has been superseded")


def family_of_version(version: str | None) -> str | None:
    """The OpenFOAM family a version string belongs to, from its form alone.

    Parameters
    ----------
    version : str or None
        E.g. ``"v1912"``, ``"2312"`` or ``"com"`` (ESI, openfoam.com), ``"10"``, ``"12.1"`` or
        ``"dev"`` (openfoam.org).

    Returns
    -------
    str or None
        ``"com"`` (ESI-OpenCFD), ``"org"`` (OpenFOAM Foundation) or None when the form says
        nothing.
    """
    if not version:
        return None
    v = version.strip()
    if re.match(r"^v?\d{4}\b", v) or v == "com":
        return "com"
    if re.match(r"^\d{1,2}(\.\d+)*$", v) or v == "dev":
        return "org"
    return None


def parse_banner(text: str) -> dict[str, Any]:
    """Family, version and build of OpenFOAM from a banner (solver log header or ``-help`` output).

    Reads both families' banners (see the comment block above for the exact lines and the
    OpenFOAM sources printing them). ESI versions are returned as ``"v<api>"`` when the API number
    is known (Debian's v1912 prints an empty version).

    Parameters
    ----------
    text : str
        The banner, or a whole log (only its first 200 lines are read).

    Returns
    -------
    dict
        ``family``: ``"org"``, ``"com"`` or None; ``version``: str or None (``"10"``,
        ``"dev"``, ``"v1912"``); ``api``: ESI API number (str) or None; ``build``: the Build
        line's value or None; ``superseded``: name of a solver the installation replaced by a
        script (openfoam.org 11+: ``"simpleFoam"``) or None.
    """
    head = "\n".join(text.splitlines()[:200])
    out: dict[str, Any] = {"family": None, "version": None, "api": None, "build": None, "superseded": None}
    m = _BUILD_RE.search(head)
    if m:
        out["build"] = m.group(1) or None
    m = _SUPERSEDED_RE.search(head)
    if m:
        out["superseded"] = m.group(1)
        out["family"] = "org"  # only openfoam.org 11+ replaces solvers by such scripts
    m_org = _USING_ORG_RE.search(head)
    m_com = _USING_COM_RE.search(head)
    if m_org:
        out["family"], out["version"] = "org", m_org.group(1) or None
    elif m_com:
        out["family"], out["api"] = "com", m_com.group(2)
        out["version"] = m_com.group(1) or None
    else:
        m = _BOX_WEBSITE_RE.search(head)
        if m and "openfoam.org" in m.group(1):
            out["family"] = "org"
        elif m and "openfoam.com" in m.group(1):
            out["family"] = "com"
        m = _BOX_VERSION_RE.search(head)
        if m:
            out["version"] = m.group(1)
    if out["family"] == "com" or (out["family"] is None and out["build"] and _API_RE.search(out["build"])):
        out["family"] = "com"
        if out["api"] is None and out["build"]:
            m = _API_RE.search(out["build"])
            out["api"] = m.group(1) if m else None
        if out["api"] and (not out["version"] or not re.match(r"^v?\d{4}$", out["version"])):
            out["version"] = f"v{out['api']}"  # "OpenFOAM- (1912)", "OpenFOAM-com (2012)"
        elif out["version"] and re.match(r"^\d{4}$", out["version"]):
            out["version"] = f"v{out['version']}"
    if out["family"] is None:
        out["family"] = family_of_version(out["version"])
    return out


def parse_solver_log(path: str | Path) -> dict[str, Any]:
    """Parse a simpleFoam/pimpleFoam log: initial residuals, continuity errors and convergence, per
    iteration or time step; Courant numbers and time steps of a transient run.

    Initial residuals are those of the first solve per field and iteration (non-orthogonal
    correctors ignored); vectors give the max over components, as OpenFOAM's residualControl
    does. Time lines with a unit (openfoam.org 10+: ``Time = 12s``) and without one (ESI:
    ``Time = 12``) are both read; see the comment block above for every line read and the
    OpenFOAM source that prints it.

    Parameters
    ----------
    path : Path or str
        The log file.

    Returns
    -------
    dict
        ``rows``: list of dicts, one per iteration with data: ``time`` (the iteration, the unit
        stripped), initial residuals by field (``p``, ``U``, ...; dimensionless),
        ``cont_local``, ``cont_global``, ``cont_cumulative`` when logged;
        ``converged_message``: bool, whether the residualControl convergence message was
        printed; ``converged_iterations``: the iteration count of that message (float) or None;
        ``time_unit``: the unit of the time lines (``"s"``, ``"CAD"``; ``""`` without one, None
        when no time line was read); ``time_lines``: number of time lines read; ``ended``:
        whether the solver printed its final ``End``; ``execution_time_s``, ``clock_time_s``:
        last ExecutionTime / ClockTime (s) or None; ``courant_max``: the largest maximum
        Courant number printed after the first time step (transient solvers: the Courant
        numbers of the steps taken) or None; ``delta_t_min``, ``delta_t_max``:
        the range of the printed adjustable time steps (s) or None; ``banner``:
        :func:`parse_banner` of the log's header.
    """
    rows: list[dict[str, Any]] = []
    cur: dict[str, Any] | None = None
    converged_msg = False
    conv_iter: float | None = None
    unit: str | None = None
    n_time = 0
    ended = False
    exec_s: float | None = None
    clock_s: float | None = None
    co_max: float | None = None
    dts: list[float] = []
    head: list[str] = []
    with open(path, errors="replace") as fh:
        for line in fh:
            line = line.rstrip("\n")
            if len(head) < 200:
                head.append(line)
            s = line.strip()
            m = _TIME_RE.match(s)
            if m:
                cur = {"time": float(m.group(1))}
                rows.append(cur)
                unit = m.group(2) if unit is None else unit
                n_time += 1
                continue
            if s == "End":
                ended = True
                continue
            m = _EXEC_RE.match(s)
            if m:
                exec_s, clock_s = float(m.group(1)), float(m.group(2))
                continue
            m = _COURANT_RE.match(s)
            if m:
                if n_time:  # before the first step it is the restart's time step, not one taken
                    co_max = max(co_max or 0.0, float(m.group(2)))
                continue
            m = _DELTAT_RE.match(s)
            if m:
                dts.append(float(m.group(1)))
                continue
            if _CONV_RE.search(line):
                converged_msg = True
                m = _CONV_ITER_RE.search(line)
                if m:
                    conv_iter = float(m.group(1))
                continue
            if cur is None:
                continue
            m = _RES_RE.search(line)
            if m:
                field, r0 = m.group(1), float(m.group(2))
                key = "U" if field in ("Ux", "Uy", "Uz") else field
                seen = cur.setdefault("_seen", set())
                if field in seen:
                    continue  # non-orthogonal correctors: keep the first solve only
                seen.add(field)
                cur[key] = max(cur.get(key, 0.0), r0)
                continue
            m = _CONT_RE.search(line)
            if m:
                cur["cont_local"], cur["cont_global"], cur["cont_cumulative"] = (float(g) for g in m.groups())
    for r in rows:
        r.pop("_seen", None)
    rows = [r for r in rows if len(r) > 1]
    return {
        "rows": rows,
        "converged_message": converged_msg,
        "converged_iterations": conv_iter,
        "time_unit": unit,
        "time_lines": n_time,
        "ended": ended,
        "execution_time_s": exec_s,
        "clock_time_s": clock_s,
        "courant_max": co_max,
        "delta_t_min": min(dts) if dts else None,
        "delta_t_max": max(dts) if dts else None,
        "banner": parse_banner("\n".join(head)),
    }


# -------------------------------------------------------------- postProcessing


def read_dat(path: Path | str) -> NDArray[np.floating]:
    """Numeric table of a function-object .dat file (comments '#', tabs/spaces, vectors in ()).

    Parameters
    ----------
    path : Path or str
        A ``postProcessing/<name>/<time>/*.dat`` file.

    Returns
    -------
    (n, w) float
        The numeric rows (time first), cut to the narrowest row; (0, 2) when there are none.
    """
    data = []
    for line in Path(path).read_text(errors="replace").splitlines():
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        s = s.replace("(", " ").replace(")", " ")
        try:
            data.append([float(x) for x in s.split()])
        except ValueError:
            continue
    if not data:
        return np.zeros((0, 2))
    width = min(len(r) for r in data)
    return np.array([r[:width] for r in data])


def last_function_value(case_dir: Path | str, name: str) -> float | None:
    """Last value written by a function object (latest start time, last row).

    Parameters
    ----------
    case_dir : Path or str
        The OpenFOAM case.
    name : str
        Function-object name (``postProcessing/<name>/<time>/*.dat``).

    Returns
    -------
    float or None
        Second column of the last row (in the function's units, e.g. m^3/s for a flow rate,
        m^2/s^2 for kinematic pressure); None when nothing was written.
    """
    root = Path(case_dir) / "postProcessing" / name
    files = sorted(root.glob("*/*.dat"), key=lambda p: (float(p.parent.name) if _isnum(p.parent.name) else 0.0, p.name))
    for f in reversed(files):
        arr = read_dat(f)
        if arr.shape[0] and arr.shape[1] >= 2:
            return float(arr[-1, 1])
    return None


def function_series(case_dir: Path | str, name: str) -> NDArray[np.floating]:
    """Time series (time, value) written by a function object, over all its start-time folders.

    Parameters
    ----------
    case_dir : Path or str
        The OpenFOAM case.
    name : str
        Function-object name (``postProcessing/<name>/<start time>/*.dat``).

    Returns
    -------
    (n, 2) float
        Rows sorted by time (the function's units, e.g. m^3/s, m^2/s^2); where a restarted stage
        wrote a time twice, the row of the later start folder is kept. (0, 2) when nothing was
        written.
    """
    root = Path(case_dir) / "postProcessing" / name
    files = sorted(root.glob("*/*.dat"), key=lambda p: (float(p.parent.name) if _isnum(p.parent.name) else 0.0, p.name))
    rows: dict[float, float] = {}
    for f in files:
        arr = read_dat(f)
        if arr.shape[0] and arr.shape[1] >= 2:
            rows.update({float(t): float(v) for t, v in arr[:, :2]})
    if not rows:
        return np.zeros((0, 2))
    t = np.array(sorted(rows))
    return np.column_stack([t, [rows[x] for x in t]])


def function_table(case_dir: Path | str, name: str, file: str = "*.dat") -> NDArray[np.floating]:
    """Every column of a function object's record over all its start-time folders (a restarted
    stage starts a new folder): rows sorted by time, a time written twice taken from the later
    folder; vectors flattened (e.g. probes' ``U``: time, then 3 components per probe).

    Parameters
    ----------
    case_dir : Path or str
        The OpenFOAM case.
    name : str
        Function-object name (``postProcessing/<name>/<start time>/<file>``).
    file : str
        File name (glob) in each start folder: ``*.dat`` (surfaceFieldValue), ``U`` (probes).

    Returns
    -------
    (n, w) float
        (0, 2) when nothing was written; w the narrowest row of the files.
    """
    root = Path(case_dir) / "postProcessing" / name
    files = sorted(
        root.glob(f"*/{file}"), key=lambda p: (float(p.parent.name) if _isnum(p.parent.name) else 0.0, p.name)
    )
    rows: dict[float, NDArray[np.floating]] = {}
    for f in files:
        for r in read_dat(f):
            rows[float(r[0])] = r
    if not rows:
        return np.zeros((0, 2))
    width = min(len(r) for r in rows.values())
    return np.array([rows[t][:width] for t in sorted(rows)])


def window_mean(case_dir: Path | str, name: str, start: float, end: float) -> float | None:
    """Time-weighted mean of a function object's values over the time window (start, end].

    Each row (t_i, v_i) stands for the time step ending at t_i, so it weighs
    t_i - max(t_{i-1}, start); the weights sum to the covered part of the window. This is the
    average fieldAverage forms with ``base time``.

    Parameters
    ----------
    case_dir : Path or str
        The OpenFOAM case.
    name : str
        Function-object name.
    start, end : float
        The window, in solver time (s).

    Returns
    -------
    float or None
        The mean (the function's units); None when no row lies in the window.
    """
    arr = function_series(case_dir, name)
    if not arr.shape[0]:
        return None
    t, v = arr[:, 0], arr[:, 1]
    prev = np.concatenate([[-np.inf], t[:-1]])
    eps = 1e-9 * max(abs(end), 1.0)
    sel = (t > start + eps) & (t <= end + eps)
    if not sel.any():
        return None
    w = t[sel] - np.maximum(prev[sel], start)
    return float((v[sel] * w).sum() / w.sum()) if w.sum() > 0 else float(v[sel].mean())


# ------------------------------------------------------------------ field files (ascii)


def _field_text(path: Path | str) -> str:
    """Text of an ASCII field file, header and comments stripped (VCSInputError for binary)."""
    return _read_text(Path(path))


def _parse_values(body: str, n: int, width: int) -> NDArray[np.floating]:
    """The first ``n`` values (``width`` numbers each) of a list body."""
    nums = np.array(re.findall(_FLOAT, body.replace("(", " ").replace(")", " ")), dtype=float)
    if nums.size < n * width:
        raise VCSInputError(f"field list holds {nums.size} numbers, expected {n * width}")
    vals = nums[: n * width]
    return vals.reshape(n, width) if width > 1 else vals


def _value_entry(text: str, n_default: int | None) -> NDArray[np.floating]:
    """Values of a ``uniform x`` / ``nonuniform List<...> N (...)`` entry at the start of ``text``."""
    m = re.match(r"\s*uniform\s+(\([^)]*\)|\S+?)\s*;", text)
    if m:
        v = np.array([float(x) for x in m.group(1).strip("()").split()])
        n = n_default if n_default is not None else 1
        return np.repeat(v[None, :], n, axis=0) if v.size > 1 else np.full(n, float(v[0]))
    m = re.match(r"\s*nonuniform\s+List<(\w+)>\s*(\d+)\s*\(", text)
    if not m:
        raise VCSInputError("field entry is neither uniform nor a nonuniform List")
    width = {"scalar": 1, "vector": 3, "symmTensor": 6, "tensor": 9}.get(m.group(1))
    if width is None:
        raise VCSInputError(f"unsupported field type List<{m.group(1)}>")
    n = int(m.group(2))
    end = text.find(";", m.end())
    return _parse_values(text[m.end() : end if end > 0 else None], n, width)


def read_internal_field(path: Path | str, n_cells: int | None = None) -> NDArray[np.floating]:
    """The ``internalField`` values of an ASCII OpenFOAM volume field file.

    Parameters
    ----------
    path : Path or str
        E.g. ``<case>/<time>/UMean``.
    n_cells : int or None
        Number of cells, to expand a ``uniform`` value (None: one row).

    Returns
    -------
    (n,) or (n, k) float
        Scalars, or k components per cell (vectors k = 3), in the field's units.

    Raises
    ------
    VCSInputError
        For a binary file or an entry that cannot be read.
    """
    txt = _field_text(path)
    i = txt.find("internalField")
    if i < 0:
        raise VCSInputError(f"{path}: no internalField")
    return _value_entry(txt[i + len("internalField") :], n_cells)


def read_patch_field(path: Path | str, patch: str, n_faces: int | None = None) -> NDArray[np.floating] | None:
    """The ``value`` of one patch in the ``boundaryField`` of an ASCII field file.

    Parameters
    ----------
    path : Path or str
        A field file.
    patch : str
        Patch name.
    n_faces : int or None
        Faces of the patch, to expand a ``uniform`` value (None: one row).

    Returns
    -------
    (n,) or (n, k) float or None
        The face values (the field's units); None when the patch or its value is absent.
    """
    txt = _field_text(path)
    bf = txt.find("boundaryField")
    if bf < 0:
        return None
    m = re.search(rf"(?<![\w.:-]){re.escape(patch)}\s*\{{", txt[bf:])
    if not m:
        return None
    body_start = bf + m.end()
    close = txt.find("}", body_start)
    v = re.search(r"\bvalue\b", txt[body_start:close])
    if not v:
        return None
    try:
        return _value_entry(txt[body_start + v.end() :], n_faces)
    except VCSInputError:
        return None


# ------------------------------------------------------------------ utility logs


def parse_check_mesh_volume(text: str) -> float | None:
    """Total cell volume (m^3) printed by checkMesh (``Total volume = ...``), or None."""
    m = re.search(rf"Total volume = ({_FLOAT})", text)
    return float(m.group(1)) if m else None


def parse_layer_summary(text: str) -> dict[str, Any]:
    """The prism-layer report at the end of a snappyHexMesh log (both families).

    snappyHexMesh's addLayers prints, per iteration, ``Extruding N out of M faces (x%)`` and
    ``Added N out of M cells (x%)``, then a table ``patch faces layers overall thickness``
    with, per patch, its faces, the mean number of layers, the overall thickness [m] and that
    thickness as a percentage of the requested one (src/mesh/snappyHexMesh/
    snappyHexMeshDriver/snappyLayerDriver.C).

    Parameters
    ----------
    text : str
        The snappyHexMesh log.

    Returns
    -------
    dict
        ``added`` (bool, whether a layer table was found), ``patches``: {name: {``faces``,
        ``mean_layers``, ``thickness_m``, ``thickness_percent``}}, ``extruded_faces``,
        ``extrudable_faces`` and ``extruded_fraction`` of the last layer iteration, ``cells_added``
        / ``cells_wanted`` of the last iteration.
    """
    out: dict[str, Any] = {"added": False, "patches": {}}
    ext = re.findall(r"Extruding (\d+) out of (\d+) faces", text)
    if ext:
        a, b = (int(x) for x in ext[-1])
        out.update(extruded_faces=a, extrudable_faces=b, extruded_fraction=a / b if b else None)
    added = re.findall(r"Added (\d+) out of (\d+) cells", text)
    if added:
        out.update(cells_added=int(added[-1][0]), cells_wanted=int(added[-1][1]))
    m = list(re.finditer(r"^patch\s+faces\s+layers\s+overall thickness\s*\n.*\n\s*-+.*\n", text, re.M))
    if m:
        out["added"] = True
        for line in text[m[-1].end() :].splitlines():
            parts = line.split()
            if len(parts) < 5:
                break
            try:
                out["patches"][parts[0]] = {
                    "faces": int(parts[1]),
                    "mean_layers": float(parts[2]),
                    "thickness_m": float(parts[3]),
                    "thickness_percent": float(parts[4]),
                }
            except ValueError:
                break
    return out


def oscillatory_shear_index(mean_wss: NDArray[np.floating], tawss: NDArray[np.floating]) -> NDArray[np.floating]:
    """OSI = (1 - |time average of WSS| / time average of |WSS|) / 2, per wall face.

    Parameters
    ----------
    mean_wss : (n, 3) float
        Time-averaged WSS vectors (any stress unit, e.g. kinematic m^2/s^2).
    tawss : (n,) float
        Time-averaged WSS magnitudes (TAWSS), same unit.

    Returns
    -------
    (n,) float
        OSI in [0, 0.5] (dimensionless); 0 where TAWSS is 0.
    """
    m = np.linalg.norm(mean_wss, axis=1)
    ratio = np.divide(m, tawss, out=np.ones_like(m), where=tawss > 0)
    return np.clip(0.5 * (1.0 - ratio), 0.0, 0.5)


def _isnum(s: str) -> bool:
    """True when ``s`` parses as a float."""
    try:
        float(s)
        return True
    except ValueError:
        return False
