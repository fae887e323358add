"""Reading OpenFOAM's own files, dependency-light (used while a case runs):

* ASCII ``constant/polyMesh`` reader for boundary patches (face centres / area vectors)
* solver-log parser (initial residuals, continuity errors, convergence message)
* ``postProcessing/*/*.dat`` reader (surfaceFieldValue output)
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
    for i, f in enumerate(faces):
        p = points[f]
        if len(f) == 3:
            centres[i] = p.mean(axis=0)
            areas[i] = 0.5 * np.cross(p[1] - p[0], p[2] - p[0])
            continue
        c0 = p.mean(axis=0)
        p1 = np.roll(p, -1, axis=0)
        sa = 0.5 * np.cross(p - c0, p1 - c0)
        tc = (p + p1 + c0) / 3.0
        area = sa.sum(axis=0)
        n = area / max(np.linalg.norm(area), 1e-300)
        w = np.abs(sa @ n)
        centres[i] = (tc * w[:, None]).sum(axis=0) / max(w.sum(), 1e-300)
        areas[i] = area
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

_RES_RE = re.compile(
    r"Solving for (\w+), Initial residual = ([-+0-9.eE]+), Final residual = ([-+0-9.eE]+), No Iterations (\d+)"
)
_TIME_RE = re.compile(r"^Time = ([-+0-9.eE]+)\s*$")
_CONT_RE = re.compile(
    r"time step continuity errors : sum local = ([-+0-9.eE]+), global = ([-+0-9.eE]+), cumulative = ([-+0-9.eE]+)"
)
_CONV_RE = re.compile(
    r"(SIMPLE solution converged in|reached convergence criteria|solution converged in)\D*(\d+)?", re.I
)


def parse_solver_log(path: str | Path) -> dict[str, Any]:
    """Parse a simpleFoam log: initial residuals, continuity errors and convergence, per iteration.

    Initial residuals are those of the first solve per field and iteration (non-orthogonal
    correctors ignored); vectors give the max over components, as OpenFOAM's residualControl
    does.

    Parameters
    ----------
    path : Path or str
        The log file.

    Returns
    -------
    dict
        ``rows``: list of dicts, one per iteration with data: ``time`` (the iteration), initial
        residuals by field (``p``, ``U``, ...; dimensionless), ``cont_local``, ``cont_global``,
        ``cont_cumulative`` when logged; ``converged_message``: bool, whether the
        residualControl convergence message was printed.
    """
    rows: list[dict[str, Any]] = []
    cur: dict[str, Any] | None = None
    converged_msg = False
    with open(path, errors="replace") as fh:
        for line in fh:
            line = line.rstrip("\n")
            m = _TIME_RE.match(line.strip())
            if m:
                cur = {"time": float(m.group(1))}
                rows.append(cur)
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
                continue
            if _CONV_RE.search(line):
                converged_msg = True
    for r in rows:
        r.pop("_seen", None)
    rows = [r for r in rows if len(r) > 1]
    return {"rows": rows, "converged_message": converged_msg}


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


def mean_function_value(case_dir: Path | str, name: str, after: float) -> float | None:
    """Mean value written by a function object after a given time (the fallback's averaging window).

    Parameters
    ----------
    case_dir : Path or str
        The OpenFOAM case.
    name : str
        Function-object name (``postProcessing/<name>/*/*.dat``).
    after : float
        Only rows with time (iteration) > ``after`` count.

    Returns
    -------
    float or None
        Mean of the second column (the function's units); None when no row qualifies.
    """
    root = Path(case_dir) / "postProcessing" / name
    rows = [read_dat(f) for f in root.glob("*/*.dat")]
    rows = [r for r in rows if r.shape[0] and r.shape[1] >= 2]
    if not rows:
        return None
    arr = np.concatenate([r[:, :2] for r in rows])
    sel = arr[arr[:, 0] > after]
    return float(sel[:, 1].mean()) if sel.shape[0] else None


def _isnum(s: str) -> bool:
    """True when ``s`` parses as a float."""
    try:
        float(s)
        return True
    except ValueError:
        return False
