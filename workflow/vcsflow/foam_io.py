"""Small, dependency-light readers/writers used by :mod:`vcsflow.openfoam`.

* multi-solid ASCII STL reader (solid names, triangles, bounds, point-in-surface test)
* ASCII ``constant/polyMesh`` reader for boundary patches (face centres / area vectors)
* solver-log parser (initial residuals, continuity errors, convergence message)
* ``postProcessing/*/*.dat`` reader (surfaceFieldValue output)
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

# --------------------------------------------------------------------------- STL


def read_stl_solids(path: str | Path) -> dict[str, np.ndarray]:
    """Read a multi-solid ASCII STL -> {solid name: (n, 3, 3) triangle vertices}."""
    solids: dict[str, list] = {}
    name = None
    tri: list = []
    with open(path, "r", encoding="ascii", errors="replace") as fh:
        for line in fh:
            tok = line.split()
            if not tok:
                continue
            key = tok[0].lower()
            if key == "solid":
                name = tok[1] if len(tok) > 1 else "solid"
                solids.setdefault(name, [])
            elif key == "vertex":
                tri.append([float(tok[1]), float(tok[2]), float(tok[3])])
                if len(tri) == 3:
                    solids.setdefault(name or "solid", []).append(tri)
                    tri = []
            elif key == "endsolid":
                name = None
    if not solids:
        raise VCSInputError(f"{path}: no ASCII STL solids found (binary STL is not supported)")
    return {k: np.asarray(v, dtype=float).reshape(-1, 3, 3) for k, v in solids.items()}


def triangle_area_vectors(tris: np.ndarray) -> np.ndarray:
    return 0.5 * np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])


def points_inside(points: np.ndarray, tris: np.ndarray, direction=(0.5773, 0.5774, 0.5775)) -> np.ndarray:
    """Ray-parity point-in-closed-surface test (Moeller-Trumbore, vectorised over triangles)."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    v0, v1, v2 = tris[:, 0], tris[:, 1], tris[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    h = np.cross(d, e2)
    a = np.einsum("ij,ij->i", e1, h)
    ok = np.abs(a) > 1e-30
    f = np.where(ok, 1.0 / np.where(ok, a, 1.0), 0.0)
    out = []
    for p in np.atleast_2d(points):
        s = p - v0
        u = f * np.einsum("ij,ij->i", s, h)
        q = np.cross(s, e1)
        v = f * (q @ d)
        t = f * np.einsum("ij,ij->i", e2, q)
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        out.append(int(hit.sum()) % 2 == 1)
    return np.asarray(out)


# ----------------------------------------------------------------- polyMesh (ascii)

_HEADER_RE = re.compile(r"FoamFile\s*\{.*?\}", re.S)


def _strip(text: str) -> str:
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    text = re.sub(r"//[^\n]*", "", text)
    return _HEADER_RE.sub("", text, count=1)


def _read_text(path: Path) -> str:
    data = Path(path).read_bytes()
    if b"format      binary" in data[:2000] or re.search(rb"format\s+binary", data[:2000]):
        raise VCSInputError(f"{path}: binary OpenFOAM file; the case must be written with writeFormat ascii")
    return _strip(data.decode("ascii", errors="replace"))


def read_boundary(polymesh: Path) -> dict[str, dict]:
    """constant/polyMesh/boundary -> {patch: {type, nFaces, startFace}}."""
    txt = _read_text(Path(polymesh) / "boundary")
    out = {}
    for m in re.finditer(r"(\w[\w.:-]*)\s*\{([^{}]*)\}", txt):
        body = m.group(2)
        d = dict(re.findall(r"(\w+)\s+([^;]+);", body))
        if "nFaces" in d:
            out[m.group(1)] = {"type": d.get("type", "patch").strip(),
                               "nFaces": int(d["nFaces"]), "startFace": int(d["startFace"])}
    return out


def _list_body(txt: str) -> tuple[int, str]:
    m = re.search(r"(\d+)\s*\(", txt)
    if m is None:
        raise VCSInputError("no OpenFOAM list found")
    return int(m.group(1)), txt[m.end():]


def read_points(polymesh: Path) -> np.ndarray:
    n, body = _list_body(_read_text(Path(polymesh) / "points"))
    vals = np.array(re.findall(r"[-+0-9.eE]+", body[: body.rfind(")")]), dtype=float)
    return vals[: 3 * n].reshape(n, 3)


def read_faces(polymesh: Path, start: int, count: int) -> list[np.ndarray]:
    txt = _read_text(Path(polymesh) / "faces")
    n, body = _list_body(txt)
    faces = re.findall(r"\d+\s*\(([\d\s]+)\)", body)
    return [np.array(f.split(), dtype=int) for f in faces[start:start + count]]


def face_geometry(points: np.ndarray, faces: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Face centres and area vectors, OpenFOAM style (triangle fan about the point average)."""
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


def patch_geometry(case_dir: Path, patch: str) -> tuple[np.ndarray, np.ndarray]:
    pm = Path(case_dir) / "constant" / "polyMesh"
    b = read_boundary(pm)
    if patch not in b:
        raise KeyError(f"patch {patch!r} not in mesh (patches: {sorted(b)})")
    faces = read_faces(pm, b[patch]["startFace"], b[patch]["nFaces"])
    return face_geometry(read_points(pm), faces)


# ----------------------------------------------------------------------- logs

_RES_RE = re.compile(r"Solving for (\w+), Initial residual = ([-+0-9.eE]+), Final residual = ([-+0-9.eE]+), No Iterations (\d+)")
_TIME_RE = re.compile(r"^Time = ([-+0-9.eE]+)\s*$")
_CONT_RE = re.compile(r"time step continuity errors : sum local = ([-+0-9.eE]+), global = ([-+0-9.eE]+), cumulative = ([-+0-9.eE]+)")
_CONV_RE = re.compile(r"(SIMPLE solution converged in|reached convergence criteria|solution converged in)\D*(\d+)?", re.I)


def parse_solver_log(path: str | Path) -> dict:
    """Parse a simpleFoam log: per-iteration initial residuals (first solve per field and
    iteration; vectors -> max over components, as OpenFOAM's residualControl does),
    continuity errors and the residualControl convergence message."""
    rows: list[dict] = []
    cur: dict | None = None
    converged_msg = False
    with open(path, "r", errors="replace") as fh:
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


def read_dat(path: Path) -> np.ndarray:
    """Numeric table of a function-object .dat file (comments '#', tabs/spaces, vectors in ())."""
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


def last_function_value(case_dir: Path, name: str) -> float | None:
    """Last value of postProcessing/<name>/<time>/*.dat (latest start time, last row)."""
    root = Path(case_dir) / "postProcessing" / name
    files = sorted(root.glob("*/*.dat"), key=lambda p: (float(p.parent.name) if _isnum(p.parent.name) else 0.0, p.name))
    for f in reversed(files):
        arr = read_dat(f)
        if arr.shape[0] and arr.shape[1] >= 2:
            return float(arr[-1, 1])
    return None


def mean_function_value(case_dir: Path, name: str, after: float) -> float | None:
    """Mean of postProcessing/<name>/*/*.dat rows with time > ``after`` (fallback averaging window)."""
    root = Path(case_dir) / "postProcessing" / name
    rows = [read_dat(f) for f in root.glob("*/*.dat")]
    rows = [r for r in rows if r.shape[0] and r.shape[1] >= 2]
    if not rows:
        return None
    arr = np.concatenate([r[:, :2] for r in rows])
    sel = arr[arr[:, 0] > after]
    return float(sel[:, 1].mean()) if sel.shape[0] else None


def _isnum(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
