"""Reading surfaces (pyvista readers) and point/coordinate tables; writing tables.

Everything inside `vcs` is in millimetres. `read_surface` converts the input units once, and
records the factor so outputs can be given back in the units of the input mesh.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError
from vcs.mesh import consistent_winding, triangle_cross

if TYPE_CHECKING:
    import pyvista as pv

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
    """

    vertices: NDArray[np.floating]
    faces: NDArray[np.integer]
    cell_data: dict[str, NDArray[Any]] = field(default_factory=dict)
    units: str = "mm"
    units_source: str = "given"
    path: str = ""
    warnings: tuple[str, ...] = ()

    @property
    def scale_to_mm(self) -> float:
        """Millimetres per unit of the input file (1, 10 or 1000)."""
        return UNIT_TO_MM[self.units]


def guess_units(extent: float) -> tuple[str, str]:
    """Guess the length unit of a vessel surface from its largest bounding-box extent.

    Human vessel sections span a few centimetres to ~40 cm. A largest extent below 1.0 is read as
    metres, from 1.0 to below 25 as centimetres, otherwise millimetres. The decision and the
    reason are reported; give ``--units`` explicitly when in doubt.

    Parameters
    ----------
    extent : float
        Largest bounding-box extent of the surface, in the (unknown) units of the file.

    Returns
    -------
    unit : str
        ``"m"``, ``"cm"`` or ``"mm"``.
    reason : str
        One sentence for the report.
    """
    if extent < 1.0:
        unit = "m"
    elif extent < 25.0:
        unit = "cm"
    else:
        unit = "mm"
    return unit, f"auto: largest bounding-box extent {extent:.4g} read as {unit}"


def _read_polydata(path: Path) -> pv.PolyData:
    """Read any pyvista-readable surface file as PolyData (VTK reader errors -> VCSInputError)."""
    import pyvista as pv
    import vtk

    vtk.vtkObject.GlobalWarningDisplayOff()  # reader errors become our one-line message

    try:
        mesh = pv.read(str(path))
    except Exception as exc:  # VTK readers raise many kinds of errors
        raise VCSInputError(
            f"cannot read '{path}' as a surface mesh ({type(exc).__name__}); "
            f"give a valid {'/'.join(e[1:].upper() for e in SURFACE_EXTENSIONS)} file"
        ) from None
    if isinstance(mesh, pv.MultiBlock):
        mesh = mesh.combine().extract_surface()
    if not isinstance(mesh, pv.PolyData):
        mesh = mesh.extract_surface()
    return mesh


def read_surface(path: Path | str, units: str = "auto", *, check_extent: bool = True) -> Surface:
    """Read a triangulated vessel wall (STL, VTP, VTK, PLY, OBJ) and convert it to mm.

    Degenerate triangles are removed and the winding made consistent (both reported in
    ``Surface.warnings``); scalar cell arrays are kept.

    Parameters
    ----------
    path : Path or str
        Surface file.
    units : {"auto", "mm", "cm", "m"}
        Units of the file; ``auto`` uses :func:`guess_units`.
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
    if mesh.n_points == 0 or mesh.n_cells == 0:
        raise VCSInputError(f"'{path}' contains no surface triangles; export the surface again")
    mesh = mesh.triangulate()
    faces = np.asarray(mesh.faces).reshape(-1, 4)
    if faces.size == 0 or np.any(faces[:, 0] != 3):
        raise VCSInputError(f"'{path}' has no triangle faces (lines or points only); give a surface mesh")
    faces = faces[:, 1:].astype(np.int64)
    vertices = np.asarray(mesh.points, dtype=float)
    if not np.all(np.isfinite(vertices)):
        n_bad = int((~np.isfinite(vertices).all(axis=1)).sum())
        raise VCSInputError(f"'{path}' has {n_bad} vertices with NaN or infinite coordinates; repair the mesh")
    cell_data = {
        name: np.asarray(mesh.cell_data[name])
        for name in mesh.cell_data.keys()
        if np.asarray(mesh.cell_data[name]).ndim == 1
    }
    warnings: list[str] = []
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
    if units == "auto":
        units, source = guess_units(extent)
    else:
        source = "given"
        extent_mm = extent * UNIT_TO_MM[units]
        if check_extent and not 5.0 <= extent_mm <= 3000.0:
            better = guess_units(extent)[0]
            raise VCSInputError(
                f"with --units {units} the mesh spans {extent_mm:.3g} mm, not a blood vessel; "
                f"is it in {better}? give --units {better} (or auto)"
            )
    vertices = vertices * UNIT_TO_MM[units]
    return Surface(vertices, faces, cell_data, units, source, str(path), tuple(warnings))


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
    headerless, its first ``len(names)`` columns in order.

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
        For a missing file, missing columns, no data rows, or non-numeric or wrongly shaped data.
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
            arr = np.loadtxt(path, delimiter=",", skiprows=0 if missing else 1, ndmin=2)
            if arr.size == 0:
                raise VCSInputError(f"'{path}' has no data rows; give at least one row")
            arr = arr[:, : len(names)] if missing else arr[:, [header.index(n) for n in names]]
        arr = np.asarray(arr, dtype=float)
    except VCSInputError:
        raise
    except Exception as exc:
        raise VCSInputError(
            f"cannot read '{path}' ({type(exc).__name__}: {exc}); give numeric {','.join(names)} columns"
        ) from None
    if arr.ndim != 2 or arr.shape[1] != len(names):
        raise VCSInputError(f"'{path}' holds an array of shape {arr.shape}; expected {len(names)} columns")
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
