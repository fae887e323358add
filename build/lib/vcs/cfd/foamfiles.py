"""Reading OpenFOAM's own files, dependency-light (used while a case runs):

* ASCII ``constant/polyMesh`` reader for boundary patches (face centres / area vectors)
* solver-log parser (initial residuals, continuity errors, convergence message)
* ``postProcessing/*/*.dat`` reader (surfaceFieldValue output)
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

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
