"""Per-outlet boundary-condition tables: a three-element Windkessel (RCR) for every outlet, given
by the user (pure numpy; reading cap or mesh files is left to :func:`outlet_rcrs`).

Two file formats give the parameters, one row (block) per outlet end:

* a CSV table (:func:`read_outlet_table`)::

      # optional comment lines
      end,R_p,C,R_d,P_d,units
      outlet1.stl,1000,1.0e-4,15000,0,cgs
      "-12.3,4.5,60.1",1.2e8,9e-10,1.5e9,0,SI
      end:3,0.1,0.9,1.2,0,mmHg

  columns ``end``, ``R_p``, ``C``, ``R_d``, ``units`` and optionally ``P_d`` (0 when absent or
  empty); ``units`` (per row) is one of :data:`UNIT_SYSTEMS`: ``SI`` (Pa s/m^3, m^3/Pa, Pa), ``cgs``
  (dyn s/cm^5, cm^5/dyn, dyn/cm^2: SimVascular's) or ``mmHg`` (mmHg s/mL, mL/mmHg, mmHg: the
  clinical units). A point ``x,y,z`` holds commas: quote it (``"x,y,z"``);
* SimVascular's ``rcrt.dat`` (:func:`read_rcrt_dat`, cgs units): the largest number of distal
  pressure points on the first line, then per outlet the number of points, the face (cap) name,
  R_p, C, R_d, and the points ``time P_d``::

      2
      2
      outlet1
      1000
      1.0e-4
      15000
      0.0 0
      1.0 0

Every value is converted once, here, to SI: resistances Pa s/m^3, compliances m^3/Pa, pressures Pa
(1 dyn s/cm^5 = 1e5 Pa s/m^3, 1 cm^5/dyn = 1e-5 m^3/Pa, 1 dyn/cm^2 = 0.1 Pa, 1 mmHg = 133.322 Pa,
1 mL = 1e-6 m^3).

A row's ``end`` names one end of the lumen as the patients sheet names ends
(:func:`match_outlet_table`): ``end:N`` (candidate N of `vcs ends`), ``NAME=VALUE`` (a labelled
cap), a point ``x,y,z`` near the end (mesh units), or a cap surface file (its area centroid); an
``rcrt.dat`` face name is the stem of a cap file (``outlet1`` -> ``outlet1.vtp``). The point
stands for the end whose centre is nearest, within max(``MATCH_RADII`` r, ``MATCH_MIN_MM``) (r: the
end's equivalent radius), the rule by which the lumen finds the section's ends
(:mod:`vcs.lumen`). Each outlet of the lumen must have exactly one row; no row may name the inlet.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message
from vcs.io import UNIT_TO_MM
from vcs.lumen import MATCH_MIN_MM, MATCH_RADII

MMHG = 133.322387415
"""1 mmHg in Pa."""

UNIT_SYSTEMS: dict[str, tuple[float, float, float, str]] = {
    "SI": (1.0, 1.0, 1.0, "Pa s/m^3, m^3/Pa, Pa"),
    "cgs": (1e5, 1e-5, 0.1, "dyn s/cm^5, cm^5/dyn, dyn/cm^2"),
    "mmHg": (MMHG / 1e-6, 1e-6 / MMHG, MMHG, "mmHg s/mL, mL/mmHg, mmHg"),
}
"""Units of a table row: name -> (factor of R to Pa s/m^3, of C to m^3/Pa, of P to Pa, the units)."""

TABLE_COLUMNS = ("end", "R_p", "C", "R_d", "P_d", "units")
"""Columns of the CSV table (``P_d`` optional; names case-insensitive, ``Rp``/``Rd``/``Pd`` too)."""

SURFACE_SUFFIXES = (".stl", ".vtp", ".vtk", ".ply", ".obj")
"""Cap files searched for an ``rcrt.dat`` face name."""

_END_INDEX = re.compile(r"end\s*:\s*(\d+)", re.IGNORECASE)
_END_LABEL = re.compile(r"([A-Za-z_][A-Za-z0-9_.\-]*)\s*=\s*([-+]?\d+)")


@dataclass(frozen=True)
class OutletRCR:
    """The RCR Windkessel of one outlet end, in SI.

    Attributes
    ----------
    end : str
        The end as the table names it (``end:N``, ``NAME=VALUE``, ``x,y,z``, a cap file, or an
        ``rcrt.dat`` face name), stripped.
    r_p : float
        Proximal resistance R_p >= 0, Pa s/m^3.
    c : float
        Compliance C > 0, m^3/Pa.
    r_d : float
        Distal resistance R_d > 0, Pa s/m^3.
    p_d : float
        Distal pressure P_d, Pa.
    where : str
        File and line of the row (for messages); not compared.
    """

    end: str
    r_p: float
    c: float
    r_d: float
    p_d: float = 0.0
    where: str = field(default="", compare=False)

    def to_dict(self) -> dict[str, float]:
        """``{"r_p", "c", "r_d", "p_d"}``, SI, JSON-ready."""
        return {"r_p": self.r_p, "c": self.c, "r_d": self.r_d, "p_d": self.p_d}


@dataclass(frozen=True)
class PatchEnd:
    """One end (patch) of the CFD lumen, as the table's rows are matched to it.

    Attributes
    ----------
    name : str
        Patch name: ``inlet``, ``outlet``, ``branch_<k>``.
    role : str
        ``inlet`` or ``outlet`` (a branch is an outlet).
    center_mm : (3,) float
        Area centroid of the patch, mm.
    radius_mm : float
        Equivalent radius sqrt(area / pi), mm.
    """

    name: str
    role: str
    center_mm: NDArray[np.floating]
    radius_mm: float


# --------------------------------------------------------------------------- reading


def _number(text: str, what: str, where: str) -> float:
    """``text`` as a finite float, or a one-line error naming the row and the column."""
    try:
        v = float(text)
    except ValueError:
        raise VCSInputError(f"{where}: {what} {text[:30]!r} is not a number; write a decimal number") from None
    if not math.isfinite(v):
        raise VCSInputError(f"{where}: {what} is {text!r}; give a finite number")
    return v


def _units(text: str, where: str) -> tuple[str, tuple[float, float, float, str]]:
    """The unit system a row names (case-insensitive), or a one-line error listing the known ones."""
    for name, system in UNIT_SYSTEMS.items():
        if text.strip().lower() == name.lower():
            return name, system
    known = "; ".join(f"{k} ({v[3]})" for k, v in UNIT_SYSTEMS.items())
    raise VCSInputError(f"{where}: units {text[:20]!r} is not known; give one of {known}")


def _rcr(end: str, r_p: float, c: float, r_d: float, p_d: float, units: str, where: str) -> OutletRCR:
    """A checked :class:`OutletRCR` from values in ``units`` (one-line errors for bad values)."""
    name, (fr, fc, fp, unit_text) = _units(units, where)
    ur, uc, up = unit_text.split(", ")
    if not r_p >= 0.0:
        raise VCSInputError(f"{where}: R_p {r_p:g} {ur} is negative; give R_p >= 0 (0: a two-element Windkessel)")
    if not c > 0.0:
        raise VCSInputError(f"{where}: C {c:g} {uc} is not positive; give the compliance C > 0")
    if not r_d > 0.0:
        raise VCSInputError(f"{where}: R_d {r_d:g} {ur} is not positive; give the distal resistance R_d > 0")
    return OutletRCR(end, r_p * fr, c * fc, r_d * fr, p_d * fp, where)


def _end_key(end: str) -> object:
    """What two rows naming the same end share: ``end:N``, a label, a point, a normalised path."""
    t = end.strip()
    m = _END_INDEX.fullmatch(t)
    if m:
        return ("index", int(m.group(1)))
    m = _END_LABEL.fullmatch(t)
    if m:
        return ("label", m.group(1), int(m.group(2)))
    point = _point(t)
    if point is not None:
        return ("point", *point.tolist())
    return ("name", os.path.normpath(t))


def _no_duplicates(rows: list[OutletRCR], what: str) -> list[OutletRCR]:
    """``rows``, or a one-line error when two name the same end."""
    seen: dict[object, OutletRCR] = {}
    for r in rows:
        key = _end_key(r.end)
        if key in seen:
            raise VCSInputError(
                f"{r.where}: end {r.end!r} already has a {what} ({seen[key].where.rsplit(': ', 1)[-1]}); "
                f"give each outlet end one {what}"
            )
        seen[key] = r
    return rows


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise VCSInputError(f"cannot read {what} {path}: {e.strerror or e}; check the path") from None


def read_outlet_table(path: str | Path) -> list[OutletRCR]:
    """Read a CSV table of per-outlet RCR parameters (format: the module docstring).

    Parameters
    ----------
    path : str or Path
        CSV file: optional ``#`` comment and blank lines, a header with the columns ``end``,
        ``R_p``, ``C``, ``R_d``, ``units`` and optionally ``P_d`` (any order, case-insensitive),
        then one row per outlet end.

    Returns
    -------
    list of OutletRCR
        One per row, in file order, converted to SI (Pa s/m^3, m^3/Pa, Pa).

    Raises
    ------
    VCSInputError
        One line naming the file and line: unreadable file, no header, a missing or unknown
        column, a row with the wrong number of cells, a value that is not a finite number, R_p < 0,
        C <= 0 or R_d <= 0, unknown units, an empty ``end``, two rows naming the same end, no rows.
    """
    path = Path(path)
    text = _read_text(path, "outlet table")
    numbered = enumerate(text.splitlines(), start=1)
    lines = [(n, raw) for n, raw in numbered if raw.strip() and not raw.lstrip().startswith("#")]
    where = f"outlet table {path}"
    if not lines:
        raise VCSInputError(f"{where}: empty; give a header {','.join(TABLE_COLUMNS)} and one row per outlet end")
    header = [h.strip() for h in next(csv.reader([lines[0][1]], skipinitialspace=True))]
    canon = {c.lower().replace("_", ""): c for c in TABLE_COLUMNS}
    names = [canon.get(h.lower().replace("_", "")) for h in header]
    unknown = [h for h, c in zip(header, names) if c is None]
    missing = [c for c in TABLE_COLUMNS if c != "P_d" and c not in names]
    if unknown or missing:
        raise VCSInputError(
            f"{where}: line {lines[0][0]}: header {','.join(header)[:80]!r} "
            + (f"has unknown column(s) {', '.join(unknown)}" if unknown else f"lacks column(s) {', '.join(missing)}")
            + f"; the columns are end, R_p, C, R_d, units and optionally P_d (units: {', '.join(UNIT_SYSTEMS)})"
        )
    col = {c: i for i, c in enumerate(names) if c is not None}
    rows: list[OutletRCR] = []
    for n, raw in lines[1:]:
        at = f"{where}: line {n}"
        cells = [c.strip() for c in next(csv.reader([raw], skipinitialspace=True))]
        if len(cells) != len(header):
            raise VCSInputError(
                f"{at}: {len(cells)} cells but the header has {len(header)} columns; "
                'quote an end that holds commas (a point "x,y,z")'
            )
        end = cells[col["end"]]
        if not end:
            raise VCSInputError(f"{at}: the end is empty; name the outlet end (end:N, x,y,z or a cap file)")
        values = {k: _number(cells[col[k]], k, at) for k in ("R_p", "C", "R_d")}
        p_d = _number(cells[col["P_d"]], "P_d", at) if "P_d" in col and cells[col["P_d"]] else 0.0
        rows.append(_rcr(end, values["R_p"], values["C"], values["R_d"], p_d, cells[col["units"]], at))
    if not rows:
        raise VCSInputError(f"{where}: line {lines[0][0]}: no rows after the header; give one row per outlet end")
    return _no_duplicates(rows, "row")


def read_rcrt_dat(path: str | Path) -> list[OutletRCR]:
    """Read SimVascular's ``rcrt.dat`` (cgs units) with the face name of every outlet.

    Format (one value or pair per line; blank and ``#`` lines are skipped)::

        nmax                  largest number of distal-pressure points of a block (usually 2)
        n                     this block's number of points (1 <= n <= nmax)
        face_name             the cap (face) name, e.g. outlet1
        R_p                   dyn s/cm^5
        C                     cm^5/dyn
        R_d                   dyn s/cm^5
        t_1 P_d,1             n lines: time (s) and distal pressure (dyn/cm^2)
        ...

    repeated for every outlet (the format SimVascular's reduced-order and 1-D exports write; the
    3-D svSolver's blocks without a face name are refused: nothing says which outlet each is).

    Parameters
    ----------
    path : str or Path
        The ``rcrt.dat`` file.

    Returns
    -------
    list of OutletRCR
        One per block, ``end`` the face name, converted to SI; P_d from the first point.

    Raises
    ------
    VCSInputError
        One line naming the file and line: a missing or non-integer count, a block without a face
        name, a value that is not a number, R_p < 0, C <= 0 or R_d <= 0, a distal pressure that
        varies in time (not supported), two blocks with the same face, no blocks.
    """
    path = Path(path)
    text = _read_text(path, "rcrt.dat")
    where = f"rcrt.dat {path}"
    lines = [(n, raw.split()) for n, raw in enumerate(text.splitlines(), start=1)]
    lines = [(n, tok) for n, tok in lines if tok and not tok[0].startswith("#")]
    pos = 0

    def take(what: str) -> tuple[int, list[str]]:
        nonlocal pos
        if pos >= len(lines):
            last = lines[-1][0] if lines else 1
            raise VCSInputError(f"{where}: line {last}: the file ends where {what} is expected; complete the block")
        pos += 1
        return lines[pos - 1]

    def count(what: str) -> int:
        n, tok = take(what)
        if len(tok) != 1 or not tok[0].isdigit() or int(tok[0]) < 1:
            raise VCSInputError(f"{where}: line {n}: {' '.join(tok)[:30]!r} is not {what} (a whole number >= 1)")
        return int(tok[0])

    nmax = count("the largest number of distal-pressure points")
    rows: list[OutletRCR] = []
    while pos < len(lines):
        k = len(rows) + 1
        npts = count(f"the number of distal-pressure points of outlet block {k}")
        if npts > nmax:
            raise VCSInputError(
                f"{where}: line {lines[pos - 1][0]}: outlet block {k} has {npts} points, more than the "
                f"{nmax} of the first line; correct the counts"
            )
        n, tok = take(f"the face name of outlet block {k}")
        at = f"{where}: line {n}"
        if _is_number(tok[0]):
            raise VCSInputError(
                f"{at}: outlet block {k} has no face name (the line after its point count is a number); "
                "write the face (cap) name there, as SimVascular's ROM export does, or give a CSV table"
            )
        face = " ".join(tok)
        values = []
        for name in ("R_p", "C", "R_d"):
            n, tok = take(f"{name} of outlet {face}")
            values.append(_number(" ".join(tok), name, f"{where}: line {n} ({face})"))
        pd = []
        for _ in range(npts):
            n, tok = take(f"a 'time P_d' line of outlet {face}")
            if len(tok) != 2:
                raise VCSInputError(f"{where}: line {n} ({face}): expected 'time P_d', got {' '.join(tok)[:40]!r}")
            pd.append(_number(tok[1], "P_d", f"{where}: line {n} ({face})"))
        if any(p != pd[0] for p in pd):
            raise VCSInputError(
                f"{at} ({face}): the distal pressure varies in time ({', '.join(f'{p:g}' for p in pd)} dyn/cm^2); "
                "a time-varying P_d is not supported: give one constant value"
            )
        rows.append(_rcr(face, values[0], values[1], values[2], pd[0], "cgs", f"{at} ({face})"))
    if not rows:
        raise VCSInputError(f"{where}: no outlet blocks after the first line; give one block per outlet face")
    return _no_duplicates(rows, "block")


def read_outlet_bc(path: str | Path) -> list[OutletRCR]:
    """Read per-outlet RCR parameters: ``rcrt.dat`` (suffix ``.dat``) or a CSV table (any other).

    Parameters
    ----------
    path : str or Path
        The file (the patients sheet's ``outlet_bc``).

    Returns
    -------
    list of OutletRCR
        As :func:`read_rcrt_dat` or :func:`read_outlet_table`.
    """
    return read_rcrt_dat(path) if Path(path).suffix.lower() == ".dat" else read_outlet_table(path)


# --------------------------------------------------------------------------- matching


def _point(text: str) -> NDArray[np.floating] | None:
    """``x,y,z`` as a (3,) float array, else None."""
    parts = text.split(",")
    if len(parts) != 3:
        return None
    try:
        p = np.array([float(v) for v in parts])
    except ValueError:
        return None
    return p if np.all(np.isfinite(p)) else None


def _fmt(x: ArrayLike, units: str) -> str:
    s = np.asarray(x, float) / UNIT_TO_MM[units]
    return f"({s[0]:.4g}, {s[1]:.4g}, {s[2]:.4g})"


def _listing(ends: Sequence[PatchEnd], units: str) -> str:
    s = UNIT_TO_MM[units]
    return "; ".join(f"{e.name} at {_fmt(e.center_mm, units)} r={e.radius_mm / s:.3g}" for e in ends) + f" ({units})"


def match_outlet_table(
    rows: Sequence[OutletRCR],
    ends: Sequence[PatchEnd],
    *,
    units: str = "mm",
    candidates: Sequence[tuple[ArrayLike, str | None]] | None = None,
    cap_centres: Mapping[str, ArrayLike] | None = None,
    cap_stems: Mapping[str, ArrayLike] | None = None,
    complete: bool = True,
) -> dict[str, OutletRCR]:
    """Match each row of an outlet table to exactly one outlet end of the lumen.

    A row's ``end`` is resolved to a point (mm), then to the end whose centre is nearest within
    max(:data:`vcs.lumen.MATCH_RADII` r, :data:`vcs.lumen.MATCH_MIN_MM`) (r: that end's radius):

    * ``end:N``: the centre of ``candidates[N]`` (the list of `vcs ends`, as the sheet's
      ``inlet``/``outlet`` use it); ``NAME=VALUE``: the candidate with that label;
    * ``x,y,z``: that point, in ``units``;
    * a cap file: ``cap_centres[end]``; an ``rcrt.dat`` face name: ``cap_stems[end]`` (the centroid
      of the cap file of that stem).

    Parameters
    ----------
    rows : sequence of OutletRCR
        From :func:`read_outlet_table` or :func:`read_rcrt_dat`.
    ends : sequence of PatchEnd
        The lumen's patches (:func:`solid_ends`), one of role ``inlet``.
    units : {"mm", "cm", "m"}
        Units of the mesh: of the points, the candidates and the cap centroids, and of messages.
    candidates : sequence of ((3,) float, str or None), optional
        Centre (mesh units) and label (``NAME=VALUE`` or None) of every candidate end of `vcs ends`.
    cap_centres : mapping of str -> (3,) float, optional
        Area centroid (mesh units) of each cap file a row names, keyed by the row's ``end``.
    cap_stems : mapping of str -> (3,) float, optional
        Area centroid (mesh units) of the cap files found for face names, keyed by file stem.
    complete : bool
        Also require a row for every outlet end (False: only check the rows).

    Returns
    -------
    dict of str -> OutletRCR
        Patch name -> its row, in the order of ``ends``.

    Raises
    ------
    VCSInputError
        One line naming the row (file, line) and the ends: an end that cannot be resolved (an index
        out of range, an unknown label, a file that is not given), a row matching no end, a row
        matching the inlet, two rows matching the same end, an outlet end without a row.
    """
    s = UNIT_TO_MM[units]
    cap_centres = cap_centres or {}
    cap_stems = cap_stems or {}
    listed = _listing(ends, units)
    got: dict[str, OutletRCR] = {}
    for row in rows:
        t = row.end.strip()
        at = f"{row.where}: end {t!r}" if row.where else f"end {t!r}"
        m_index, m_label, point = _END_INDEX.fullmatch(t), _END_LABEL.fullmatch(t), _point(t)
        if m_index or m_label:
            if not candidates:
                raise VCSInputError(
                    f"{at}: end:N and NAME=VALUE need the surface's ends (`vcs ends MESH`); give the mesh"
                )
            if m_index:
                i = int(m_index.group(1))
                if i >= len(candidates):
                    raise VCSInputError(
                        f"{at}: the surface has {len(candidates)} candidate ends, end:0 to end:{len(candidates) - 1}; "
                        "see `vcs ends MESH`"
                    )
                centre = candidates[i][0]
            else:
                label = f"{m_label.group(1)}={int(m_label.group(2))}"  # type: ignore[union-attr]
                hits = [c for c, lab in candidates if lab == label]
                if not hits:
                    labels = sorted(str(lab) for _, lab in candidates if lab)
                    raise VCSInputError(
                        f"{at}: no cap labelled {label} (labelled caps: {', '.join(labels) or 'none'}); "
                        "see `vcs ends MESH`"
                    )
                centre = hits[0]
        elif point is not None:
            centre = point
        elif t in cap_centres:
            centre = cap_centres[t]
        elif t in cap_stems:
            centre = cap_stems[t]
        else:
            raise VCSInputError(
                f"{at}: not end:N, NAME=VALUE, a point x,y,z or a cap file that exists; "
                "name the end in one of these ways (`vcs ends MESH` lists the ends)"
            )
        c_mm = np.asarray(centre, float) * s
        best, best_d = None, math.inf
        for e in ends:
            d = float(np.linalg.norm(e.center_mm - c_mm))
            if d <= max(MATCH_RADII * e.radius_mm, MATCH_MIN_MM) and d < best_d:
                best, best_d = e, d
        if best is None:
            raise VCSInputError(f"{at} at {_fmt(c_mm, units)} {units} is at no end of the lumen; the ends: {listed}")
        if best.role == "inlet":
            raise VCSInputError(
                f"{at} is the inlet ({best.name}); an RCR belongs on an outlet: remove that row (ends: {listed})"
            )
        if best.name in got:
            raise VCSInputError(
                f"{at} is the same end ({best.name}) as the row of {got[best.name].end!r} "
                f"({got[best.name].where or 'above'}); give each outlet end one row"
            )
        got[best.name] = row
    missing = [e.name for e in ends if e.role != "inlet" and e.name not in got]
    if complete and missing:
        where = rows[0].where.split(": line")[0] if rows else "the outlet table"
        raise VCSInputError(
            f"{where}: no row for outlet end(s) {', '.join(missing)}; every outlet needs its RCR "
            f"(add a row naming each; ends: {listed})"
        )
    return {e.name: got[e.name] for e in ends if e.name in got}


def solid_ends(solids: Mapping[str, ArrayLike], units: str = "m") -> list[PatchEnd]:
    """The lumen's patches from the STL's solids (what :func:`vcs.cfd.render_case` reads).

    Parameters
    ----------
    solids : mapping of str -> (T, 3, 3) float
        Triangles per solid, in ``units``: ``inlet*`` the inlet, ``outlet*`` and ``branch*``
        outlets; ``wall*`` and others are left out.
    units : {"mm", "cm", "m"}
        Units of the triangles (the case's STL: m).

    Returns
    -------
    list of PatchEnd
        Each end with its area centroid and equivalent radius, mm.
    """
    s = UNIT_TO_MM[units]
    out = []
    for name, tris in solids.items():
        low = name.lower()
        role = "inlet" if low.startswith("inlet") else "outlet" if low.startswith(("outlet", "branch")) else None
        if role is None:
            continue
        t = np.asarray(tris, float).reshape(-1, 3, 3) * s
        a = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
        area = float(a.sum())
        centre = (t.mean(axis=1) * a[:, None]).sum(0) / max(area, 1e-300)
        out.append(PatchEnd(name, role, centre, math.sqrt(area / math.pi)))
    return out


def lumen_ends(ends_json: str | Path) -> list[PatchEnd]:
    """The ends of a lumen (``vcs lumen``'s ``ends.json``) as PatchEnd: each at its opening on the
    input surface (``opening_center``; the patch itself may lie a flow extension further out), with
    its equivalent radius, mm."""
    info = json.loads(Path(ends_json).read_text())
    s = UNIT_TO_MM[str(info.get("units", "m"))]
    out = []
    for e in info["ends"]:
        role = "inlet" if e["role"] == "inlet" else "outlet"
        centre = np.asarray(e.get("opening_center") or e["center"], float) * s
        out.append(PatchEnd(str(e["name"]), role, centre, float(e["equivalent_radius"]) * s))
    return out


def cap_centroid(vertices: ArrayLike, faces: ArrayLike) -> NDArray[np.floating]:
    """Area centroid of a cap surface.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertices (any units; the result is in the same).
    faces : (M, 3) int
        Triangles.

    Returns
    -------
    (3,) float
    """
    t = np.asarray(vertices, float)[np.asarray(faces, int)]
    a = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    return np.asarray((t.mean(axis=1) * a[:, None]).sum(0) / max(float(a.sum()), 1e-300))


# --------------------------------------------------------------------------- files (I/O)


def _resolve_file(text: str, table: Path) -> Path | None:
    """A cap file a row names: relative to the working directory, else to the table's directory."""
    for p in (Path(text), table.parent / text):
        if p.is_file():
            return p
    return None


def cap_file_stems(*dirs: str | Path) -> dict[str, Path]:
    """Surface files (:data:`SURFACE_SUFFIXES`) in ``dirs`` and their ``mesh-surfaces/`` and
    ``mesh-complete/mesh-surfaces/`` folders (SimVascular's), by stem; the first found wins.

    Parameters
    ----------
    *dirs : str or Path
        Folders to search.

    Returns
    -------
    dict of str -> Path
    """
    out: dict[str, Path] = {}
    for d in dirs:
        for sub in (Path(d), Path(d) / "mesh-surfaces", Path(d) / "mesh-complete" / "mesh-surfaces"):
            if sub.is_dir():
                for p in sorted(sub.iterdir()):
                    if p.suffix.lower() in SURFACE_SUFFIXES and p.is_file():
                        out.setdefault(p.stem, p)
    return out


def resolve_ends(
    rows: Sequence[OutletRCR],
    table: str | Path,
    *,
    units: str,
    mesh: str | Path | None = None,
    candidates: Sequence[tuple[ArrayLike, str | None]] | None = None,
) -> dict[str, Any]:
    """What :func:`match_outlet_table` needs to resolve the rows' ends, read from files.

    Reads the cap files the rows name (relative to the working directory, else to the table's),
    the cap files whose stems are ``rcrt.dat`` face names (beside the table or the mesh,
    :func:`cap_file_stems`), and, when a row is ``end:N`` or ``NAME=VALUE``, the candidate ends of
    the mesh exactly as `vcs ends` lists them.

    Parameters
    ----------
    rows : sequence of OutletRCR
        The table's rows.
    table : str or Path
        The table's path.
    units : {"mm", "cm", "m"}
        Units of the mesh (and of the cap files).
    mesh : str or Path, optional
        The patient's surface (needed for ``end:N`` / ``NAME=VALUE`` rows).
    candidates : sequence of ((3,) float, str or None), optional
        The mesh's candidate ends when already listed (:func:`surface_ends`); else listed here
        when a row needs them.

    Returns
    -------
    dict
        ``candidates``, ``cap_centres``, ``cap_stems``: keyword arguments of
        :func:`match_outlet_table` (mesh units).

    Raises
    ------
    VCSInputError
        A row naming ``end:N`` without a mesh; an unreadable cap file or mesh.
    """
    from vcs.io import read_surface

    table = Path(table)
    cap_centres: dict[str, NDArray[np.floating]] = {}
    cap_stems: dict[str, NDArray[np.floating]] = {}
    stems: dict[str, Path] | None = None
    need_listing = False
    for row in rows:
        t = row.end.strip()
        if _END_INDEX.fullmatch(t) or _END_LABEL.fullmatch(t):
            need_listing = True
            continue
        if _point(t) is not None:
            continue
        found = _resolve_file(t, table)
        if found is not None:
            cap = read_surface(found, units, check_extent=False)
            cap_centres[t] = cap_centroid(cap.vertices, cap.faces) / UNIT_TO_MM[units]
            continue
        if stems is None:
            stems = cap_file_stems(table.parent, *([Path(mesh).parent] if mesh else []))
        if t in stems:
            cap = read_surface(stems[t], units, check_extent=False)
            cap_stems[t] = cap_centroid(cap.vertices, cap.faces) / UNIT_TO_MM[units]
        elif Path(t).suffix.lower() in SURFACE_SUFFIXES:
            raise VCSInputError(
                f"{row.where}: cap file {t!r} not found (relative to {os.getcwd()} or to {table.parent}); "
                "check the path"
            )
    if need_listing and candidates is None:
        if mesh is None:
            raise VCSInputError(f"{table}: a row names end:N or NAME=VALUE but no mesh is given to list the ends")
        candidates = surface_ends(mesh, units)[0]
    return {"candidates": candidates, "cap_centres": cap_centres, "cap_stems": cap_stems}


def outlet_rcrs(
    path: str | Path,
    solids: Mapping[str, ArrayLike],
    *,
    units: str,
    mesh: str | Path | None = None,
    ends: Sequence[PatchEnd] | None = None,
) -> dict[str, dict[str, float]]:
    """The RCR of every outlet patch of a case, from the patient's table (``outlet_bc``).

    Reads the table (:func:`read_outlet_bc`), resolves its ends (:func:`resolve_ends`) and matches
    them to the case's patches (:func:`solid_ends`, :func:`match_outlet_table`): every outlet patch
    gets exactly one row.

    Parameters
    ----------
    path : str or Path
        The CSV table or ``rcrt.dat``.
    solids : mapping of str -> (T, 3, 3) float, m
        The case STL's solids by patch name (``inlet``, ``outlet``, ``branch_<k>``, ``wall``), as
        :func:`vcs.mesh.read_stl_solids` returns them.
    units : {"mm", "cm", "m"}
        Units of the patient's mesh: of the table's points and cap files (``VesselModel.units``,
        model.json ``units.input``).
    mesh : str or Path, optional
        The patient's surface (the sheet's ``mesh``): needed for ``end:N`` / ``NAME=VALUE`` rows;
        its folder is also searched for the cap files of ``rcrt.dat`` face names.
    ends : sequence of PatchEnd, optional
        The patches' ends to match instead of the solids' centres: a lumen's openings on the input
        surface (:func:`lumen_ends`), where the rows point, when its patches sit at the far ends of
        flow extensions.

    Returns
    -------
    dict of str -> dict
        Patch name -> ``{"r_p": Pa s/m^3, "c": m^3/Pa, "r_d": Pa s/m^3, "p_d": Pa}`` (dynamic SI:
        divide the resistances by rho and multiply C by rho for OpenFOAM's kinematic pressure).

    Raises
    ------
    VCSInputError
        One line: a bad table (see the readers), an end that cannot be resolved or matched, a row
        on the inlet, two rows on one end, an outlet without a row.
    """
    if units not in UNIT_TO_MM:
        raise VCSInputError(f"mesh units {units!r} must be one of {', '.join(UNIT_TO_MM)}")
    rows = read_outlet_bc(path)
    found = resolve_ends(rows, path, units=units, mesh=mesh)
    matched = match_outlet_table(
        rows, list(ends) if ends is not None else solid_ends(solids, "m"), units=units, **found
    )
    return {name: row.to_dict() for name, row in matched.items()}


def surface_ends(
    mesh: str | Path, units: str = "auto"
) -> tuple[list[tuple[NDArray[np.floating], str | None]], list[PatchEnd], str]:
    """The candidate ends of a surface exactly as `vcs ends` lists them (``end:N`` is the N-th).

    Parameters
    ----------
    mesh : str or Path
        The patient's surface.
    units : {"auto", "mm", "cm", "m"}
        Its units (as the sheet's ``units``).

    Returns
    -------
    candidates : list of ((3,) float, str or None)
        Centre (mesh units) and label of every candidate, in `vcs ends` order.
    ends : list of PatchEnd
        The candidates that can be patches (closed ends left out), named ``end:N``, role ``outlet``.
    units : str
        The mesh's units (resolved when ``auto``).
    """
    from vcs.ends import list_ends
    from vcs.io import read_surface
    from vcs.vessel import vessel_component

    surf = vessel_component(read_surface(mesh, units))
    listing = list_ends(surf.vertices, surf.faces, surf.cell_data, lumen_radius=surf.lumen_radius_mm)
    candidates = [(np.asarray(c.end.center / surf.scale_to_mm), c.label) for c in listing.candidates]
    ends = [
        PatchEnd(f"end:{i}", "outlet", np.asarray(c.end.center, float), float(c.radius))
        for i, c in enumerate(listing.candidates)
        if c.kind != "closed end"
    ]
    return candidates, ends, surf.units


def check_outlet_bc(
    path: str | Path,
    mesh: str | Path,
    *,
    units: str = "auto",
    inlet: str | None = None,
    complete: bool = False,
    surface: tuple[list[tuple[NDArray[np.floating], str | None]], list[PatchEnd], str] | None = None,
) -> list[OutletRCR]:
    """Check an outlet table against the patient's surface before any job runs (the workflow's
    planning): every row names one end of the surface (`vcs ends`), no two rows the same, none the
    inlet.

    The lumen's patches are the surface's candidate ends but its closed (rounded) ends, so the
    check is the one :func:`outlet_rcrs` makes on the case, with the ends named ``end:N``.

    Parameters
    ----------
    path : str or Path
        The CSV table or ``rcrt.dat``.
    mesh : str or Path
        The patient's surface.
    units : {"auto", "mm", "cm", "m"}
        Its units (the sheet's).
    inlet : str, optional
        The section's inlet as the sheet gives it (``end:N``, ``NAME=VALUE``, ``x,y,z`` or a cap
        file); None: the larger of the two ends when the surface has exactly two, else unknown
        (then no row is checked against it); also unknown when it is at no end (a point inside).
    complete : bool
        Also require a row for every end but the inlet (the CFD runs on the whole surface and the
        inlet is known).
    surface : tuple, optional
        :func:`surface_ends` of ``mesh`` when already computed.

    Returns
    -------
    list of OutletRCR
        The table's rows.

    Raises
    ------
    VCSInputError
        One line: a bad table, or a row that names no end, the inlet, or the end of another row
        (with the surface's ends listed), or an end without a row (``complete``).
    """
    rows = read_outlet_bc(path)
    candidates, ends, mesh_units = surface if surface is not None else surface_ends(mesh, units)
    i_inlet = None
    if inlet is not None:
        probe = OutletRCR(inlet, 0.0, 1.0, 1.0, 0.0, "the sheet's inlet")
        try:  # a point inside the vessel (no end): the inlet is then not known here
            found = resolve_ends([probe], Path(mesh), units=mesh_units, mesh=mesh, candidates=candidates)
            i_inlet = next(iter(match_outlet_table([probe], ends, units=mesh_units, complete=False, **found)))
        except VCSInputError:
            i_inlet = None
    elif len(ends) == 2:
        i_inlet = max(ends, key=lambda e: e.radius_mm).name
    if i_inlet is not None:
        ends = [PatchEnd(e.name, "inlet", e.center_mm, e.radius_mm) if e.name == i_inlet else e for e in ends]
    found = resolve_ends(rows, path, units=mesh_units, mesh=mesh, candidates=candidates)
    match_outlet_table(rows, ends, units=mesh_units, complete=complete and i_inlet is not None, **found)
    return rows
