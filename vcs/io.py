"""Reading surfaces (pyvista readers) and point/coordinate tables; writing tables.

Everything inside `vcs` is in millimetres. `read_surface` converts the input units once, and
records the factor so outputs can be given back in the units of the input mesh.
"""

from __future__ import annotations

import logging
import warnings as pywarnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs._signals import signals_held
from vcs.errors import VCSInputError
from vcs.mesh import connected_faces, consistent_winding, default_vessel_component, lumen_chords, triangle_cross

if TYPE_CHECKING:
    from vtkmodules.vtkCommonDataModel import vtkPolyData

log = logging.getLogger(__name__)

SURFACE_EXTENSIONS = (".stl", ".vtp", ".vtk", ".ply", ".obj")
UNIT_TO_MM = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


@dataclass(frozen=True)
class Surface:
    """A triangulated surface in millimetres.

    Attributes
    ----------
    vertices : (N, 3) float
        Vertex coordinates in mm.
    faces : (M, 3) int
        Triangles.
    cell_data : dict of str -> (M,) array
        Integer/float cell arrays of the input (e.g. ``ModelFaceID``).
    units : str
        Units of the input file (``mm``, ``cm`` or ``m``).
    units_source : str
        ``"given"`` or a sentence explaining how ``auto`` decided.
    path : str
        The file that was read.
    warnings : tuple of str
        Repairs made while reading (degenerate triangles removed, winding fixed, ...).
    units_evidence : dict
        With ``units="auto"``: the measurements behind the choice (:attr:`UnitsGuess.evidence`);
        empty for given units.
    """

    vertices: NDArray[np.floating]
    faces: NDArray[np.integer]
    cell_data: dict[str, NDArray[Any]] = field(default_factory=dict)
    units: str = "mm"
    units_source: str = "given"
    path: str = ""
    warnings: tuple[str, ...] = ()
    units_evidence: dict[str, Any] = field(default_factory=dict)

    @property
    def scale_to_mm(self) -> float:
        """Millimetres per unit of the input file (1, 10 or 1000)."""
        return UNIT_TO_MM[self.units]

    @property
    def lumen_radius_mm(self) -> float | None:
        """Median lumen radius (mm) measured for ``--units auto``; None when the units were given."""
        r = self.units_evidence.get("candidates", {}).get(self.units, {}).get("median_lumen_radius_mm")
        return None if r is None else float(r)


# --units auto: human lumen radii (coronary ~1 mm to an aneurysmal aorta ~25 mm) and a typical
# vessel section (median lumen radius ~6 mm, between small arteries ~3 mm and aortas ~12 mm;
# largest extent ~120 mm); the extent only breaks ties between units whose radii are both plausible
PLAUSIBLE_RADIUS_MM = (1.0, 25.0)
TYPICAL_RADIUS_MM = 6.0
TYPICAL_EXTENT_MM = 120.0
EXTENT_WEIGHT = 0.5
AMBIGUOUS_SCORE_MARGIN = 1.0


@dataclass(frozen=True)
class UnitsGuess:
    """The units ``--units auto`` chose, why, and the measurements behind it.

    Attributes
    ----------
    unit : str
        ``"mm"``, ``"cm"`` or ``"m"``.
    reason : str
        One sentence for the report (``units_source``), starting with ``auto:``.
    evidence : dict
        JSON-ready: ``median_lumen_radius`` and ``largest_extent`` (file units), ``n_chords``,
        ``rule``, and per candidate unit the radius and extent in mm, ``plausible`` and ``score``.
    warning : str or None
        Set when another unit is nearly as likely (the user should check and give ``--units``).
    """

    unit: str
    reason: str
    evidence: dict[str, Any]
    warning: str | None = None


def guess_units(radius: float | None, extent: float) -> UnitsGuess:
    """Guess the length unit of a vessel surface from its lumen radius (extent as a tie-breaker).

    For each unit (m, cm, mm) the median lumen radius ``radius`` and the largest bounding-box
    extent ``extent`` are converted to mm. A unit is plausible when the radius lies in
    :data:`PLAUSIBLE_RADIUS_MM` (1-25 mm, human vessels); among the plausible units (all units if
    none is) the one with the lowest score ln(r / 6 mm)^2 + 0.5 ln(E / 120 mm)^2 wins: the radius
    nearest a typical vessel radius, the extent deciding between units whose radii are both
    plausible (a 35 cm long aorta of radius 1.2 cm written in cm is cm; a 60 mm long carotid of
    radius 2 mm is mm). Another plausible unit within :data:`AMBIGUOUS_SCORE_MARGIN` of the best
    gives a warning. Without a radius (no chord found), the extent alone decides as before:
    below 1 -> m, below 25 -> cm, else mm.

    Parameters
    ----------
    radius : float or None
        Median lumen radius in the (unknown) units of the file, e.g. half the median of
        :func:`vcs.mesh.lumen_chords`; None when unknown.
    extent : float
        Largest bounding-box extent of the surface, in the units of the file.

    Returns
    -------
    UnitsGuess
    """
    if radius is None or not np.isfinite(radius) or radius <= 0:
        unit = "m" if extent < 1.0 else "cm" if extent < 25.0 else "mm"
        reason = f"auto: no lumen radius measured; largest bounding-box extent {extent:.4g} read as {unit}"
        return UnitsGuess(unit, reason, {"largest_extent": extent, "rule": "extent <1 m, <25 cm, else mm"})
    lo, hi = PLAUSIBLE_RADIUS_MM
    cands: dict[str, dict[str, Any]] = {}
    for u in ("m", "cm", "mm"):
        r_mm, e_mm = radius * UNIT_TO_MM[u], extent * UNIT_TO_MM[u]
        score = np.log(r_mm / TYPICAL_RADIUS_MM) ** 2 + EXTENT_WEIGHT * np.log(e_mm / TYPICAL_EXTENT_MM) ** 2
        cands[u] = {
            "median_lumen_radius_mm": float(r_mm),
            "largest_extent_mm": float(e_mm),
            "plausible": bool(lo <= r_mm <= hi),
            "score": round(float(score), 4),
        }
    pool = [u for u in cands if cands[u]["plausible"]] or list(cands)
    ranked = sorted(pool, key=lambda u: cands[u]["score"])
    unit = ranked[0]
    c = cands[unit]
    reason = (
        f"auto: median lumen radius {radius:.4g} and largest extent {extent:.4g} read as {unit} "
        f"(radius {c['median_lumen_radius_mm']:.3g} mm, extent {c['largest_extent_mm']:.4g} mm; "
        f"human vessel radii are {lo:g}-{hi:g} mm)"
    )
    warning = None
    if not cands[unit]["plausible"]:
        warning = (
            f"units auto: no unit gives a human vessel radius ({lo:g}-{hi:g} mm); read as {unit} "
            f"(radius {c['median_lumen_radius_mm']:.3g} mm): check it and give --units"
        )
    elif len(ranked) > 1 and cands[ranked[1]]["score"] - c["score"] < AMBIGUOUS_SCORE_MARGIN:
        o = cands[ranked[1]]
        warning = (
            f"units auto: read as {unit} (radius {c['median_lumen_radius_mm']:.3g} mm, extent "
            f"{c['largest_extent_mm']:.4g} mm), but {ranked[1]} is nearly as plausible (radius "
            f"{o['median_lumen_radius_mm']:.3g} mm, extent {o['largest_extent_mm']:.4g} mm); "
            f"give --units {ranked[1]} if the mesh is in {ranked[1]}"
        )
    evidence = {
        "median_lumen_radius": float(radius),
        "largest_extent": float(extent),
        "rule": (
            f"radius in {lo:g}-{hi:g} mm, then lowest ln(r/{TYPICAL_RADIUS_MM:g} mm)^2 + "
            f"{EXTENT_WEIGHT:g} ln(extent/{TYPICAL_EXTENT_MM:g} mm)^2"
        ),
        "candidates": cands,
    }
    return UnitsGuess(unit, reason, evidence, warning)


def measure_units(vertices: NDArray[np.floating], faces: NDArray[np.integer]) -> UnitsGuess:
    """:func:`guess_units` of a surface: its median lumen radius by ray casting and its extent.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates in the (unknown) units of the file.
    faces : (M, 3) int
        Triangles, consistently wound.

    Returns
    -------
    UnitsGuess
        With ``evidence["n_chords"]``, the number of chords measured (:func:`vcs.mesh.lumen_chords`).
    """
    chords = lumen_chords(vertices, faces)
    radius = 0.5 * float(np.median(chords)) if len(chords) >= 8 else None
    guess = guess_units(radius, float(np.ptp(vertices, axis=0).max()))
    guess.evidence["n_chords"] = int(len(chords))
    return guess


def _is_ascii_stl(path: Path) -> bool:
    """True for an ASCII STL file (it starts with ``solid`` and its second line is a facet or endsolid)."""
    if path.suffix.lower() != ".stl":
        return False
    with open(path, "rb") as fh:
        head = fh.read(512)
    lines = head.lstrip().split(b"\n", 2)
    return head.lstrip().startswith(b"solid") and len(lines) > 1 and lines[1].strip()[:5] in (b"facet", b"endso")


def _read_ascii_stl_solids(path: Path) -> vtkPolyData:
    """An ASCII STL read by VTK's STL reader (as pyvista does) with its solids as a cell array.

    A multi-solid STL (``solid wall`` ... ``solid inlet`` ...) gets the cell array
    ``STLSolidLabeling`` (0, 1, ... in file order), so that caps written as separate solids are
    labelled caps (:func:`vcs.ends.list_ends`); a single-solid file gets no array.
    """
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOGeometry import vtkSTLReader

    reader = vtkSTLReader()
    reader.SetFileName(str(path))
    reader.ScalarTagsOn()
    reader.Update()
    mesh = reader.GetOutput()
    solids = mesh.GetCellData().GetArray("STLSolidLabeling")
    if solids is not None and len(np.unique(vtk_to_numpy(solids))) < 2:
        mesh.GetCellData().RemoveArray("STLSolidLabeling")
    return mesh


#: The VTK reader of each surface extension (module, class): the ones :func:`pyvista.read` uses.
_VTK_READERS = {
    ".stl": ("vtkmodules.vtkIOGeometry", "vtkSTLReader"),
    ".vtp": ("vtkmodules.vtkIOXML", "vtkXMLPolyDataReader"),
    ".vtk": ("vtkmodules.vtkIOLegacy", "vtkDataSetReader"),
    ".ply": ("vtkmodules.vtkIOPLY", "vtkPLYReader"),
    ".obj": ("vtkmodules.vtkIOGeometry", "vtkOBJReader"),
}


def _read_with_vtk(path: Path) -> vtkPolyData:
    """The surface in ``path`` read by its VTK reader (:data:`_VTK_READERS`), as pyvista.read does it
    (a legacy .vtk reads all its arrays; a failed update raises); another kind of data set than
    PolyData (a legacy .vtk volume mesh) gives its outer surface (pyvista's ``extract_surface``)."""
    import importlib

    from vtkmodules.vtkCommonDataModel import vtkPolyData

    module, name = _VTK_READERS[path.suffix.lower()]
    reader = getattr(importlib.import_module(module), name)()
    reader.SetFileName(str(path))
    if name == "vtkDataSetReader":
        for what in ("Scalars", "ColorScalars", "Normals", "TCoords", "Vectors", "Fields", "Tensors"):
            getattr(reader, f"ReadAll{what}On")()
    ok = reader.Update() != 0  # VTK >= 9.7 says whether the update worked (older: None)
    mesh = reader.GetOutputDataObject(0)
    if mesh is None:
        raise RuntimeError(f"{name} produced no output")
    if not ok and not (isinstance(mesh, vtkPolyData) and mesh.GetNumberOfPoints() == 0):
        raise RuntimeError(f"{name} failed")
    # (a failed update that left an empty surface, e.g. text in a .stl: the caller's one line,
    # "contains no surface triangles", as with pyvista.read, README "Bad input")
    if not isinstance(mesh, vtkPolyData):  # rare: loads pyvista (held signals: no SIGSEGV on Ctrl-C)
        import pyvista as pv

        mesh = pv.wrap(mesh).extract_surface()
    return mesh


def _read_polydata(path: Path) -> vtkPolyData:
    """Read a surface file (:data:`SURFACE_EXTENSIONS`) as VTK PolyData (VTK reader errors -> VCSInputError).

    VTK's readers directly (not pyvista, whose import takes ~0.2 s and ~35 MB), the same ones
    with the same settings as :func:`pyvista.read`.
    """
    from vtkmodules.vtkCommonCore import vtkObject  # not `import vtk`: that loads all of VTK's ~250 modules

    vtkObject.GlobalWarningDisplayOff()  # reader errors become our one-line message

    try:
        with signals_held():  # a Ctrl-C inside VTK (or a lazy import of its modules) is a SIGSEGV
            return _read_ascii_stl_solids(path) if _is_ascii_stl(path) else _read_with_vtk(path)
    except Exception as exc:  # VTK readers raise many kinds of errors
        raise VCSInputError(
            f"cannot read '{path}' as a surface mesh ({type(exc).__name__}); "
            f"give a valid {'/'.join(e[1:].upper() for e in SURFACE_EXTENSIONS)} file"
        ) from None


def _triangles(
    mesh: vtkPolyData,
) -> tuple[NDArray[np.floating], NDArray[np.int64] | None, dict[str, NDArray[Any]]]:
    """Points, triangles and 1-D numeric cell arrays of a surface after VTK's triangle filter
    (polygons and strips split into triangles, vertices and lines dropped: pyvista's ``triangulate``).

    Returns
    -------
    points : (N, 3) float
    faces : (M, 3) int64, or None when the filter left no triangle
    cell_data : dict of str -> (M,) array
        Copies (no view into VTK's memory).
    """
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkFiltersCore import vtkTriangleFilter

    tri = vtkTriangleFilter()
    tri.SetInputData(mesh)
    tri.PassVertsOff()
    tri.PassLinesOff()
    tri.Update()
    out = tri.GetOutput()
    points = vtk_to_numpy(out.GetPoints().GetData()).astype(float) if out.GetPoints() else np.zeros((0, 3))
    polys = out.GetPolys()
    conn = vtk_to_numpy(polys.GetConnectivityArray()).astype(np.int64)
    size = np.diff(vtk_to_numpy(polys.GetOffsetsArray()))
    faces = conn.reshape(-1, 3) if len(size) and np.all(size == 3) else None
    cells = out.GetCellData()
    cell_data = {}
    for i in range(cells.GetNumberOfArrays()):
        arr = cells.GetArray(i)  # None for a non-numeric (string) array
        if arr is not None and arr.GetNumberOfComponents() == 1:
            cell_data[cells.GetArrayName(i)] = np.array(vtk_to_numpy(arr))
    return points, faces, cell_data


#: Vertices closer than this fraction of the median edge length are one vertex (:func:`read_surface`).
MERGE_TOLERANCE = 1e-4


def _merge_and_deduplicate(
    vertices: NDArray[np.floating], faces: NDArray[np.integer], cell_data: dict[str, NDArray[Any]], warnings: list[str]
) -> tuple[NDArray[np.floating], NDArray[np.integer], dict[str, NDArray[Any]]]:
    """Merge duplicate vertices and drop repeated triangles, saying so in ``warnings``.

    A triangle soup (every triangle with its own three vertices, as some PLY/OBJ/VTP exporters
    write) has no shared edges: every edge would be a boundary and the surface one open end per
    triangle. Vertices closer than :data:`MERGE_TOLERANCE` times the median edge length (far
    below any real edge) are merged (scipy's KD-tree pairs, joined transitively). A triangle
    listed twice (the same three vertices, in any order) makes its edges non-manifold and the
    surface look closed; repeats after the first are dropped.

    Parameters
    ----------
    vertices : (N, 3) float
        Vertex coordinates (file units).
    faces : (M, 3) int
        Triangles.
    cell_data : dict of str -> (M,) array
        Cell arrays, kept per remaining triangle.
    warnings : list of str
        Appended to (in place) when something was merged or dropped.

    Returns
    -------
    vertices : (N', 3) float
        Without the merged copies (the same array when nothing was merged).
    faces : (M', 3) int
    cell_data : dict of str -> (M',) array
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    edge = np.linalg.norm(vertices[faces] - vertices[np.roll(faces, 1, axis=1)], axis=2)
    tol = MERGE_TOLERANCE * float(np.median(edge[edge > 0])) if (edge > 0).any() else 0.0
    used = np.unique(faces)
    pairs = cKDTree(vertices[used]).query_pairs(tol, output_type="ndarray") if tol > 0 else np.zeros((0, 2), int)
    if len(pairs):
        n = len(used)
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        _, label = connected_components(graph, directed=False)
        n_merged = n - int(label.max()) - 1
        first = np.full(label.max() + 1, -1)
        first[label[::-1]] = np.arange(n)[::-1]  # the lowest-numbered vertex of each group stays
        remap = np.full(len(vertices), -1)
        remap[used] = used[first[label]]
        faces = remap[faces]
        warnings.append(
            f"{n_merged} duplicate vertices merged (closer than {tol:.2g} file units, "
            f"{MERGE_TOLERANCE:g} of the median edge): the triangles were not connected"
        )
    key = np.sort(faces, axis=1).astype(np.int64)
    n = int(key.max()) + 1 if len(key) else 1
    if n < 2**21:  # one int64 key per triangle: the same first occurrences as rows, ~10x faster
        _, first_face = np.unique((key[:, 0] * n + key[:, 1]) * n + key[:, 2], return_index=True)
    else:
        _, first_face = np.unique(key, axis=0, return_index=True)
    if len(first_face) < len(faces):
        keep = np.zeros(len(faces), bool)
        keep[first_face] = True
        warnings.append(f"{int((~keep).sum())} repeated triangles removed (the same three vertices listed again)")
        faces = faces[keep]
        cell_data = {k: v[keep] for k, v in cell_data.items()}
    if len(pairs):  # the merged copies are unused now: drop them (no other vertex is touched)
        keep_v = np.ones(len(vertices), bool)
        keep_v[used[used[first[label]] != used]] = False
        renumber = np.cumsum(keep_v) - 1
        vertices, faces = vertices[keep_v], renumber[faces]
    return vertices, faces, cell_data


def read_surface(path: Path | str, units: str = "auto", *, check_extent: bool = True) -> Surface:
    """Read a triangulated vessel wall (STL, VTP, VTK, PLY, OBJ) and convert it to mm.

    Degenerate triangles are removed and the winding made consistent (both reported in
    ``Surface.warnings``); scalar cell arrays are kept.

    Parameters
    ----------
    path : Path or str
        Surface file.
    units : {"auto", "mm", "cm", "m"}
        Units of the file; ``auto`` uses :func:`measure_units` (lumen radius, then extent).
    check_extent : bool
        Refuse explicit units that make the surface smaller than 5 mm or larger than 3 m (a whole
        vessel); off for cap surfaces.

    Returns
    -------
    Surface
        Vertices in mm.

    Raises
    ------
    VCSInputError
        For an unsupported, missing, empty or unreadable file, non-triangle or non-finite
        geometry, unknown units, or an implausible size with explicit units.
    """
    path = Path(path)
    if path.suffix.lower() not in SURFACE_EXTENSIONS:
        raise VCSInputError(
            f"unsupported file extension '{path.suffix}' for '{path}'; "
            f"convert it to one of {', '.join(SURFACE_EXTENSIONS)}"
        )
    if not path.is_file():
        raise VCSInputError(f"mesh file '{path}' does not exist; check the path")
    if path.stat().st_size == 0:
        raise VCSInputError(f"mesh file '{path}' is empty; export the surface again")
    if units not in ("auto", *UNIT_TO_MM):
        raise VCSInputError(f"unknown units '{units}'; use one of auto, mm, cm, m")
    mesh = _read_polydata(path)
    if mesh.GetNumberOfPoints() == 0:  # (points without cells: "no triangle faces" below)
        raise VCSInputError(f"'{path}' contains no surface triangles; export the surface again")
    vertices, tri_faces, cell_data = _triangles(mesh)
    del mesh
    if tri_faces is None:
        raise VCSInputError(f"'{path}' has no triangle faces (lines or points only); give a surface mesh")
    faces: NDArray[np.integer] = tri_faces
    if not np.all(np.isfinite(vertices)):
        n_bad = int((~np.isfinite(vertices).all(axis=1)).sum())
        raise VCSInputError(f"'{path}' has {n_bad} vertices with NaN or infinite coordinates; repair the mesh")
    warnings: list[str] = []
    vertices, faces, cell_data = _merge_and_deduplicate(vertices, faces, cell_data, warnings)
    tri = vertices[faces]
    area2 = np.linalg.norm(triangle_cross(tri), axis=1)
    degenerate = (
        (area2 <= 1e-12 * max(float(np.ptp(vertices)), 1e-300) ** 2)
        | (faces[:, 0] == faces[:, 1])
        | (faces[:, 1] == faces[:, 2])
        | (faces[:, 0] == faces[:, 2])
    )
    if degenerate.any():
        warnings.append(f"{int(degenerate.sum())} degenerate (zero-area) triangles removed")
        faces = faces[~degenerate]
        cell_data = {k: v[~degenerate] for k, v in cell_data.items()}
        if len(faces) == 0:
            raise VCSInputError(f"'{path}' has only degenerate triangles; export the surface again")
    faces, winding = consistent_winding(vertices, faces)
    if winding:
        warnings.append("inconsistent triangle winding repaired")
    extent = float(np.ptp(vertices, axis=0).max())
    evidence: dict[str, Any] = {}
    if units == "auto":  # measured on the vessel's component, not on a larger blob of noise beside it
        labels = connected_faces(faces, len(vertices))
        one = labels == default_vessel_component(vertices, faces, labels)[0] if labels.max() > 0 else slice(None)
        guess = measure_units(vertices, faces[one])
        units, source, evidence = guess.unit, guess.reason, guess.evidence
        if guess.warning:
            warnings.append(guess.warning)
    else:
        source = "given"
        extent_mm = extent * UNIT_TO_MM[units]
        if check_extent and not 5.0 <= extent_mm <= 3000.0:
            better = measure_units(vertices, faces).unit
            raise VCSInputError(
                f"with --units {units} the mesh spans {extent_mm:.3g} mm, not a blood vessel; "
                f"is it in {better}? give --units {better} (or auto)"
            )
    vertices = vertices * UNIT_TO_MM[units]
    return Surface(vertices, faces, cell_data, units, source, str(path), tuple(warnings), evidence)


def read_points_table(path: Path | str) -> NDArray[np.floating]:
    """Read (N, 3) points from ``.npy`` or ``.csv`` (header optional, columns x,y,z).

    Parameters
    ----------
    path : Path or str
        A ``.csv`` with columns x,y,z (header optional) or a ``.npy`` array of shape (N, 3).

    Returns
    -------
    (N, 3) float
        The points, in the units of the file (not converted).

    Raises
    ------
    VCSInputError
        For another extension, a missing file, or non-numeric or wrongly shaped data.
    """
    path = Path(path)
    if path.is_file() and path.suffix.lower() not in (".npy", ".csv"):
        raise VCSInputError(f"unsupported points file '{path}'; give a .csv (x,y,z) or .npy (N, 3)")
    return read_table_columns(path, ("x", "y", "z"), header_required=False, what="points file")


def read_table_columns(
    path: Path | str, names: tuple[str, ...], *, header_required: bool = True, what: str = "file"
) -> NDArray[np.floating]:
    """Read named columns of a CSV (or an (N, len(names)) ``.npy``) as an (N, len(names)) array.

    Without ``header_required``, a CSV whose first line does not name the columns is read as
    headerless; it must then have exactly ``len(names)`` columns, in order (a fourth column is
    refused rather than silently ignored). A header may name more columns than ``names``.

    Parameters
    ----------
    path : Path or str
        A ``.csv`` (comma-separated, header names case-insensitive) or a ``.npy`` file.
    names : tuple of str
        Column names wanted, in the order of the result (e.g. ``("tau", "theta", "rho")``).
    header_required : bool
        Refuse a CSV whose header lacks one of ``names``.
    what : str
        What the file is, for the error messages.

    Returns
    -------
    (N, len(names)) float
        The columns, in the units of the file.

    Raises
    ------
    VCSInputError
        For a missing file, missing columns, no data rows (an empty CSV, a header-only CSV and an
        empty ``.npy`` alike), a headerless CSV with another number of columns, NaN or infinite
        values, or non-numeric or wrongly shaped data.
    """
    path = Path(path)
    if not path.is_file():
        raise VCSInputError(f"{what} '{path}' does not exist; check the path")
    try:
        if path.suffix.lower() == ".npy":
            arr = np.load(path, allow_pickle=False)
        else:
            with open(path) as fh:
                header = [h.strip().lower() for h in fh.readline().strip().split(",")]
            missing = [n for n in names if n not in header]
            if missing and header_required:
                raise VCSInputError(
                    f"'{path}' lacks column(s) {', '.join(missing)}; header must name {','.join(names)}"
                )
            with pywarnings.catch_warnings():  # an empty file: numpy warns, we say it in one line below
                pywarnings.simplefilter("ignore")
                arr = np.loadtxt(path, delimiter=",", skiprows=0 if missing else 1, ndmin=2)
            if arr.size and missing and arr.shape[1] != len(names):
                raise VCSInputError(
                    f"'{path}' has {arr.shape[1]} columns and no header; give exactly {len(names)} columns "
                    f"({','.join(names)}) or a header line naming them"
                )
            if arr.size:
                arr = arr[:, : len(names)] if missing else arr[:, [header.index(n) for n in names]]
        arr = np.asarray(arr, dtype=float)
    except VCSInputError:
        raise
    except Exception as exc:
        raise VCSInputError(
            f"cannot read '{path}' ({type(exc).__name__}: {exc}); give numeric {','.join(names)} columns"
        ) from None
    if arr.size == 0:  # the same for an empty CSV, a header-only CSV and an empty .npy
        raise VCSInputError(f"'{path}' has no data rows; give at least one row of {','.join(names)}")
    if arr.ndim != 2 or arr.shape[1] != len(names):
        raise VCSInputError(f"'{path}' holds an array of shape {arr.shape}; expected {len(names)} columns")
    bad = ~np.isfinite(arr).all(axis=1)
    if bad.any():
        raise VCSInputError(
            f"'{path}' has {int(bad.sum())} row(s) with NaN or infinite values (first: data row "
            f"{int(np.argmax(bad)) + 1}); remove or fix them"
        )
    return arr


def write_csv(path: Path | str, columns: dict[str, ArrayLike]) -> None:
    """Write equal-length columns as a CSV with a header (full float precision).

    Parameters
    ----------
    path : Path or str
        Output file.
    columns : dict of str -> (N,) array-like of float
        Header name -> values, in column order; written as ``%.17g`` (round-trips float64).
    """
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
