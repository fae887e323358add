"""A fitted vessel: its VCS, its wall model and where it came from; model.json I/O."""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs._signals import signals_held
from vcs.ends import EndSelector, find_ends, parse_end_option
from vcs.errors import VCSInputError
from vcs.io import UNIT_TO_MM, Surface, read_surface
from vcs.mesh import connected_faces, default_vessel_component, self_intersections, triangle_areas
from vcs.model import VesselCoordinateSystem
from vcs.wall import WallFit, WallModel, fit_wall

log = logging.getLogger(__name__)

FORMAT_VERSION = 1


@dataclass(frozen=True)
class VesselModel:
    """VCS + wall model rho_w of one vessel section, all lengths in mm.

    Attributes
    ----------
    vcs : VesselCoordinateSystem
        Centerline c(tau), frame and coordinates (paper Section 2.2).
    wall : WallModel or None
        rho_w(tau, theta) (Eq. 5); None when fitted without K and R.
    units : str
        Unit of the input mesh (``mm``, ``cm`` or ``m``); outputs of the CLI are given back in it.
    meta : dict
        Provenance (source mesh, how the ends were found, end centres in mm, L).
    """

    vcs: VesselCoordinateSystem
    wall: WallModel | None
    units: str = "mm"
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def scale_to_mm(self) -> float:
        """Millimetres per unit of the input mesh (1, 10 or 1000)."""
        return UNIT_TO_MM[self.units]

    # -- feature vector (paper Section 2.3.1) -------------------------------------------------
    def feature_vector(self) -> NDArray[np.floating]:
        """Feature vector a = (c_0..c_n, b_00..b_n1n2) of the model (paper Section 2.3.1).

        Returns
        -------
        (3 (L + 4) [+ (K + 4) (R + 1)],) float, mm
            The centerline control points (row-major, (L + 4, 3)), then the wall coefficients
            (row-major, (K + 4, R + 1)) when there is a wall model.
        """
        parts = [self.vcs.control_points.ravel()]
        if self.wall is not None:
            parts.append(self.wall.coefficients.ravel())
        return np.concatenate(parts)

    @classmethod
    def from_feature_vector(cls, a: ArrayLike, template: VesselModel) -> VesselModel:
        """Rebuild a model from a feature vector with the knots, frame rule and metadata of ``template``.

        The frame's v1(0) is recomputed by transporting the template's choice onto the new
        tangent (it is not part of the vector); every other number comes from ``a``
        (paper Section 2.3.1).

        Parameters
        ----------
        a : (n,) float, mm
            Feature vector laid out as :meth:`feature_vector` of ``template``.
        template : VesselModel
            Supplies the knots, degree, v1(0) rule, units and metadata.

        Returns
        -------
        VesselModel

        Raises
        ------
        VCSInputError
            When ``a`` does not have the template's length.
        """
        from scipy.interpolate import BSpline

        a = np.asarray(a, float)
        n_c = template.vcs.control_points.size
        expected = n_c + (template.wall.coefficients.size if template.wall is not None else 0)
        if a.shape != (expected,):
            raise VCSInputError(f"feature vector has shape {a.shape}; this model needs ({expected},)")
        c = a[:n_c].reshape(template.vcs.control_points.shape)
        curve = BSpline(template.vcs.curve.t, c, template.vcs.curve.k)
        t0 = curve.derivative()(0.0)
        t0 = t0 / np.linalg.norm(t0)
        v = template.vcs.v1_0 - (template.vcs.v1_0 @ t0) * t0
        vcs = VesselCoordinateSystem(curve, v / np.linalg.norm(v), v1_0_from="transported from template")
        wall = None
        if template.wall is not None:
            wall = template.wall.with_coefficients(a[n_c:].reshape(template.wall.coefficients.shape))
        return cls(vcs, wall, template.units, dict(template.meta))

    @property
    def n_knots(self) -> int:
        """L, the centerline's number of uniform interior knots."""
        return int(len(self.vcs.curve.t) - 2 * (self.vcs.curve.k + 1))

    def with_n_knots(self, L: int) -> VesselModel:
        """The same vessel with its centerline refitted with ``L`` knots (the wall model is kept).

        An atlas needs one L for every patient (paper Section 2.3.1: one feature vector layout).
        The curve is refitted by least squares to 4,001 of its own points equally spaced in tau
        (= arc length), with the same end points and end tangents, and re-parametrised by arc
        length (:func:`vcs.centerline.fit_centerline`, Eq. 1); v1(0) is transported onto the new
        t(0). Raising L moves c(tau) by < 0.1 mm (0.06 mm on aorta phantom 1), so (tau, theta,
        rho) and rho_w(tau, theta) keep their meaning.

        Parameters
        ----------
        L : int
            New number of interior knots (>= 1).

        Returns
        -------
        VesselModel
            ``meta`` records the original L as ``L_fitted``.
        """
        from vcs.centerline import fit_centerline

        if L == self.n_knots:
            return self
        c = self.vcs.curve
        tau = np.linspace(0.0, 1.0, 4001)
        d = c.derivative()(np.array([0.0, 1.0]))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        curve = fit_centerline(c(tau), int(L), end_directions=(d[0], d[1]))
        t0 = curve.derivative()(0.0)
        t0 = t0 / np.linalg.norm(t0)
        v = self.vcs.v1_0 - (self.vcs.v1_0 @ t0) * t0
        vcs = VesselCoordinateSystem(curve, v / np.linalg.norm(v), v1_0_from=self.vcs.v1_0_from)
        meta = {**self.meta, "L": int(L), "L_fitted": int(self.meta.get("L_fitted", self.n_knots))}
        return VesselModel(vcs, self.wall, self.units, meta)

    # -- geometry -----------------------------------------------------------------------------
    def fitted_wall(self) -> WallModel:
        """The wall model rho_w (Eq. 5); VCSInputError when the model has none (a centerline-only
        model): refit it with `vcs fit`."""
        if self.wall is None:
            raise VCSInputError("the model has no wall model; refit it with `vcs fit` (K, R)")
        return self.wall

    def surface_points(self, tau: ArrayLike, theta: ArrayLike) -> NDArray[np.floating]:
        """Wall points x(tau, theta) = c(tau) + rho_w(tau, theta) (v1 cos theta + v2 sin theta) (Eq. 8).

        Parameters
        ----------
        tau : float or array of float
            Normalised arc length in [0, 1].
        theta : float or array of float, rad
            Angle about the centerline; broadcast against ``tau``.

        Returns
        -------
        (..., 3) float, mm
            Wall points, leading shape the broadcast shape of ``tau`` and ``theta``.

        Raises
        ------
        VCSInputError
            When the model has no wall model.
        """
        if self.wall is None:
            raise VCSInputError("this model has no wall model; refit it with `vcs fit` (K, R)")
        tau, theta = np.broadcast_arrays(np.asarray(tau, float), np.asarray(theta, float))
        return self.vcs.to_cartesian(tau, theta, self.wall(tau, theta))

    # -- I/O ----------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The model as plain JSON values (the content of model.json).

        Returns
        -------
        dict
            ``format_version``, ``units``, ``centerline`` (see
            :meth:`VesselCoordinateSystem.to_dict`), ``wall`` (:meth:`WallModel.to_dict` or None),
            ``meta``.
        """
        return {
            "format_version": FORMAT_VERSION,
            "units": {"internal": "mm", "input": self.units, "scale_to_mm": self.scale_to_mm},
            "centerline": self.vcs.to_dict(),
            "wall": None if self.wall is None else self.wall.to_dict(),
            "meta": self.meta,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> VesselModel:
        """Rebuild a model from :meth:`to_dict` output (a parsed model.json).

        Parameters
        ----------
        d : dict
            As written by :meth:`to_dict`.

        Returns
        -------
        VesselModel

        Raises
        ------
        VCSInputError
            When ``format_version`` is not the one this code writes, or an array has the wrong
            shape or a NaN or infinite value (:func:`_check_arrays`).
        """
        _check_format_version(d)
        _check_arrays(d)
        wall = None if d.get("wall") is None else WallModel.from_dict(d["wall"])
        return cls(VesselCoordinateSystem.from_dict(d["centerline"]), wall, d["units"]["input"], d.get("meta", {}))

    def save(self, path: Path | str) -> None:
        """Write the model as JSON (deterministic: same model, same bytes), atomically.

        Parameters
        ----------
        path : Path or str
            Output file (model.json); written via a ``.tmp`` file then renamed.
        """
        text = json.dumps(self.to_dict(), indent=1, sort_keys=True)
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text + "\n")
        tmp.replace(path)  # atomic: never a half-written model.json

    @classmethod
    def load(cls, path: Path | str) -> VesselModel:
        """Read a model.json written by :meth:`save`.

        Parameters
        ----------
        path : Path or str
            The model file.

        Returns
        -------
        VesselModel

        Raises
        ------
        VCSInputError
            One line naming the file and what is wrong, when it is missing, not JSON, of another
            format version or inconsistent.
        """
        path = Path(path)
        if not path.is_file():
            raise VCSInputError(f"model file '{path}' does not exist; create it with `vcs fit`")
        try:
            d = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise VCSInputError(f"'{path}' is not a model.json written by `vcs fit`") from None
        if not isinstance(d, dict) or "centerline" not in d:
            raise VCSInputError(f"'{path}' is not a model.json written by `vcs fit`")
        try:
            if d.get("units", {}).get("input") not in UNIT_TO_MM:
                raise ValueError("unknown input units")
            _check_format_version(d)
        except VCSInputError:
            raise  # its own message: which format version, refit
        except (KeyError, ValueError, TypeError, IndexError) as exc:
            raise VCSInputError(
                f"'{path}' is not a valid model.json ({type(exc).__name__}: {exc}); refit it with `vcs fit`"
            ) from None
        try:
            return cls.from_dict(d)
        except VCSInputError as exc:  # e.g. wall coefficients of the wrong shape: name the file
            raise VCSInputError(f"'{path}' is not a valid model.json ({exc}); refit it with `vcs fit`") from None
        except (KeyError, ValueError, TypeError, IndexError) as exc:
            raise VCSInputError(
                f"'{path}' is not a valid model.json ({type(exc).__name__}: {exc}); refit it with `vcs fit`"
            ) from None


def _array(value: Any, what: str, shape: tuple[int | None, ...]) -> NDArray[np.floating]:
    """``value`` as a finite float array of ``shape`` (None: any length), else VCSInputError naming ``what``."""
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise VCSInputError(f"{what} is not an array of numbers") from None
    if a.ndim != len(shape) or any(n is not None and a.shape[i] != n for i, n in enumerate(shape)):
        want = "(" + ", ".join("n" if n is None else str(n) for n in shape) + ")"
        raise VCSInputError(f"{what} has shape {a.shape}, expected {want}")
    n_bad = int((~np.isfinite(a)).sum())
    if n_bad:
        raise VCSInputError(f"{what} holds {n_bad} NaN or infinite value(s)")
    return a


def _check_arrays(d: dict[str, Any]) -> None:
    """Check the arrays of a parsed model.json: shapes that fit together, finite numbers.

    The centerline: ``degree`` 3, ``knots`` clamped on [0, 1] and non-decreasing with L + 8
    entries, ``control_points`` (L + 4, 3), ``v1_0`` (3,) of unit length; the wall (when present):
    ``K``, ``R`` >= 1 and ``coefficients`` (K + 4, R + 1). Every number finite (a hand-edited
    file with a NaN would otherwise fail deep inside a command).

    Raises
    ------
    VCSInputError
        Naming the first entry that is wrong (the caller adds the file name).
    """
    c = d["centerline"]
    if not isinstance(c, dict):
        raise VCSInputError("'centerline' is not an object")
    if c.get("degree") != 3:
        raise VCSInputError(f"centerline degree is {c.get('degree')!r}, expected 3")
    t = _array(c.get("knots"), "centerline knots", (None,))
    if len(t) < 8 or np.any(np.diff(t) < 0) or np.any(t[:4] != 0.0) or np.any(t[-4:] != 1.0):
        raise VCSInputError("centerline knots are not a clamped, non-decreasing knot vector on [0, 1]")
    _array(c.get("control_points"), "centerline control_points", (len(t) - 4, 3))
    v1 = _array(c.get("v1_0"), "centerline v1_0", (3,))
    if abs(float(np.linalg.norm(v1)) - 1.0) > 1e-6:
        raise VCSInputError(f"centerline v1_0 has length {np.linalg.norm(v1):.6g}, expected a unit vector")
    w = d.get("wall")
    if w is None:
        return
    if not isinstance(w, dict):
        raise VCSInputError("'wall' is not an object")
    K, R = w.get("K"), w.get("R")
    if not (isinstance(K, int) and isinstance(R, int) and K >= 1 and R >= 1):
        raise VCSInputError(f"wall K = {K!r}, R = {R!r}: expected integers >= 1")
    _array(w.get("coefficients"), "wall coefficients", (K + 4, R + 1))


def _check_format_version(d: dict[str, Any]) -> None:
    """Raise VCSInputError unless a model dict has this code's ``format_version``."""
    version = d.get("format_version")
    if version != FORMAT_VERSION:
        raise VCSInputError(
            f"model format_version {version!r} is not supported (this vcs reads {FORMAT_VERSION}); refit with `vcs fit`"
        )


def vessel_component(
    surf: Surface, inlet: ArrayLike | EndSelector | None = None, outlet: ArrayLike | EndSelector | None = None
) -> Surface:
    """Keep the connected component that is the vessel; the others are reported in ``warnings``.

    Which component: the one nearest the ``inlet`` and ``outlet`` points when points are given
    (smallest sum of distances to its vertices); the one holding the cap of a ``NAME=VALUE``
    selector; otherwise, among the components with at least two open ends (boundary loops),
    the largest by area, and the largest of all when none has two
    (:func:`vcs.mesh.default_vessel_component`). A closed blob of noise larger
    than an open vessel is thus not taken for the vessel; between two open tubes, the points
    decide (the warning says so).

    Parameters
    ----------
    surf : Surface
        Triangulated surface (mm).
    inlet, outlet : (3,) float in mm, EndSelector, or None
        The parsed ``--inlet``/``--outlet`` (points already converted to mm).

    Returns
    -------
    Surface
        ``surf`` itself when it is connected; otherwise the chosen component, its unused
        vertices dropped and faces renumbered, cell arrays kept per face, one warning added.
    """
    f = surf.faces
    n = len(surf.vertices)
    face_lab = connected_faces(f, n)
    used = np.unique(face_lab)
    if len(used) <= 1:
        return surf
    area = triangle_areas(surf.vertices, f)
    per = np.bincount(face_lab, area)
    points = [np.asarray(p, float) for p in (inlet, outlet) if isinstance(p, np.ndarray)]
    labels = [p for p in (inlet, outlet) if isinstance(p, EndSelector) and p.array and p.array in surf.cell_data]
    if points:
        from scipy.spatial import cKDTree

        vert_lab = np.full(n, -1)
        vert_lab[f.ravel()] = np.repeat(face_lab, 3)
        dist = np.full(len(per), np.inf)
        for c in used:
            tree = cKDTree(surf.vertices[vert_lab == c])
            dist[c] = sum(float(tree.query(p)[0]) for p in points)
        keep_lab = int(np.argmin(dist))
        why = "the one nearest --inlet/--outlet"
    elif labels and np.any(hit := surf.cell_data[str(labels[0].array)] == labels[0].value):
        keep_lab = int(np.bincount(face_lab[hit]).argmax())
        why = f"the one with the cap {labels[0].label}"
    else:
        keep_lab, not_largest = default_vessel_component(surf.vertices, f, face_lab)
        if not_largest:
            why = "the largest with two open ends, not the largest overall; give --inlet/--outlet points to choose"
        else:
            why = "the largest; give --inlet/--outlet points to choose another"
    keep = face_lab == keep_lab
    dropped = np.delete(per, keep_lab)
    msg = (
        f"{len(used)} disconnected surface components; kept {why} ({int(keep.sum())} triangles, "
        f"{100 * per[keep_lab] / per.sum():.1f}% of the area), dropped {int((~keep).sum())} triangles "
        f"in {len(used) - 1} other component(s) (the largest {100 * dropped.max() / per.sum():.1f}% of the area)"
    )
    # drop the other components' vertices too: they must not size the voxel grid
    kept_v = np.unique(f[keep])
    remap = np.full(n, -1)
    remap[kept_v] = np.arange(len(kept_v))
    return Surface(
        surf.vertices[kept_v],
        remap[f[keep]],
        {k: v[keep] for k, v in surf.cell_data.items()},
        surf.units,
        surf.units_source,
        surf.path,
        (*surf.warnings, msg),
        surf.units_evidence,
    )


def parse_point(text: str | ArrayLike | None, name: str) -> NDArray[np.floating] | None:
    """Parse a point given as ``'x,y,z'`` (or already as 3 numbers) into a (3,) array.

    Parameters
    ----------
    text : str, array-like of 3 floats, or None
        The point, in mesh units; None passes through.
    name : str
        Option name for the error message (``inlet`` -> ``--inlet``).

    Returns
    -------
    (3,) float or None
        In the units of ``text`` (mesh units; not converted).

    Raises
    ------
    VCSInputError
        When a string is not three finite comma-separated numbers.
    """
    if text is None:
        return None
    if not isinstance(text, str):
        return np.asarray(text, float)
    try:
        p = np.array([float(v) for v in text.replace(" ", "").split(",")])
    except ValueError:
        p = np.zeros(0)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise VCSInputError(f"--{name} '{text}' is not a point; write it as x,y,z (mesh units)")
    return p


class _Background:
    """``fn(*args)`` on a second thread, started at once, when this process may use a second core
    (:func:`spare_core`), else run by the first :meth:`result`; :meth:`result` waits for it (and
    raises what it raised). A daemon thread: an interrupted fit does not wait for it to end."""

    def __init__(self, fn: Callable[..., Any], *args: Any, threaded: bool | None = None) -> None:
        self._out: list[Any] = []

        def run() -> None:
            try:
                self._out.append((True, fn(*args)))
            except BaseException as exc:  # handed to the caller of result()
                self._out.append((False, exc))

        self._run = run
        self._thread: threading.Thread | None = None
        if spare_core() if threaded is None else threaded:
            self._thread = threading.Thread(target=run, name=getattr(fn, "__name__", "background"), daemon=True)
            # started with SIGINT/SIGTERM blocked, which it keeps: the kernel then hands a Ctrl-C to
            # the main thread only, so that signals_held() there still holds it back (a signal the
            # thread took would raise in the main thread at once, inside VTK: a crash)
            with signals_held():
                self._thread.start()

    def result(self) -> Any:
        if self._thread is not None:
            self._thread.join()
        elif not self._out:
            self._run()
        ok, value = self._out[0]
        if not ok:
            raise value
        return value


def spare_core() -> bool:
    """May this process use a second core? Not when it is pinned to one (``taskset``, SLURM's
    ``--cpus-per-task=1``) or told to use one thread (``OMP_NUM_THREADS=1``, as Snakemake sets it
    for a job of one thread: the cohort's other jobs have the other cores, and a second thread
    would only add its GIL hand-overs to the job's CPU time)."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        n = os.cpu_count() or 1
    omp = os.environ.get("OMP_NUM_THREADS", "").strip()
    if omp.isdigit() and int(omp) > 0:
        n = min(n, int(omp))
    return n > 1


def fit_vessel(
    mesh: Surface | Path | str,
    *,
    units: str = "auto",
    inlet: str | ArrayLike | None = None,
    outlet: str | ArrayLike | None = None,
    inlet_cap: Path | str | None = None,
    outlet_cap: Path | str | None = None,
    cap_array: str | None = "auto",
    L: int | str = "auto",
    K: int | None = 19,
    R: int | None = 15,
    recentre_iterations: int = 3,
) -> tuple[VesselModel, dict[str, Any], WallFit | None]:
    """Fit the VCS (and the wall model when K and R are given) to a surface file or :class:`Surface`.

    Reads and cleans the mesh (the vessel's component, :func:`vessel_component`), finds the two
    ends (Section 2.2.1), builds the centerline and frame (Sections 2.2.1-2.2.2) and fits rho_w
    (Section 2.3.1, Eqs. 5-7).

    Parameters
    ----------
    mesh : Surface, Path or str
        A surface file (see :func:`vcs.io.read_surface`) or an already read :class:`Surface`.
    units : {"auto", "mm", "cm", "m"}
        Units of the file (ignored for a :class:`Surface`).
    inlet, outlet : str, array-like of 3 floats, or None
        End points in the mesh's units (``'x,y,z'`` strings or arrays), or ends listed by
        :func:`vcs.ends.list_ends` (``'end:N'``, ``'NAME=VALUE'``); see :func:`vcs.ends.find_ends`.
    inlet_cap, outlet_cap : Path, str or None
        Cap surface files, in the mesh's units; give both or neither.
    cap_array : str or None
        Cell array labelling the caps; ``"auto"`` tries the usual names, None disables.
    L : int or "auto"
        Interior knots of the centerline c(tau); "auto" (default) picks the smallest L >= 9 that
        keeps the curve inside the lumen with a margin and tau the arc length within 2 %
        (:func:`vcs.centerline.choose_n_knots`).
    K, R : int or None
        Interior knots of the wall model in tau and theta; None for no wall model.
    recentre_iterations : int
        Re-centring steps of the centerline.

    Returns
    -------
    model : VesselModel
        All lengths in mm; ``units`` is the mesh's.
    report : dict
        JSON-ready fit report (warnings, counts, end planes, wall residuals in mm, timings in s).
        ``timings_s``: the stages ``read_and_ends``, ``vcs_build`` (itself ``voxelize``, ``astar``,
        ``spline_fit``, ``recentre``, ``choose_L``, ``frame``, ``checks``), ``wall_fit``,
        ``wall_quality`` and ``self_intersection`` (the self-intersection test; with a core to
        spare, :func:`spare_core`, it runs on a second thread from the end of ``read_and_ends``
        and this is the wait for it: 0 when it ended first), and ``total``, the whole of this
        function (wall clock).
        `vcs fit` adds ``startup`` (interpreter and imports), ``outputs`` (the VTP files) and
        ``command`` (their sum with ``total``).
    wall_fit : WallFit or None
        Per-vertex wall-fit arrays; None without a wall model.

    Examples
    --------
    Fit a phantom tube (5 mm radius, 40 mm long; open ends, found as its two boundary loops):
    the centerline is its axis and the wall model its radius.

    >>> import numpy as np
    >>> from vcs import fit_vessel, make_phantom
    >>> from vcs.io import Surface
    >>> tube = make_phantom("tube", radius_mm=5.0, length_mm=40.0)
    >>> model, report, wall_fit = fit_vessel(Surface(tube.vertices, tube.faces), K=9, R=7)
    >>> report["quality"]
    'ok'
    >>> round(model.vcs.length, 6)
    40.0
    >>> rho_w = model.wall(np.linspace(0.0, 1.0, 11)[:, None], np.linspace(0.0, 6.0, 7)[None, :])
    >>> bool(np.abs(rho_w - 5.0).max() < 1e-3)
    True
    """
    t0 = time.perf_counter()
    surf = mesh if isinstance(mesh, Surface) else read_surface(mesh, units)
    p_in = parse_end_option(inlet, "inlet")
    p_out = parse_end_option(outlet, "outlet")
    s = surf.scale_to_mm
    surf = vessel_component(
        surf,
        p_in * s if isinstance(p_in, np.ndarray) else p_in,
        p_out * s if isinstance(p_out, np.ndarray) else p_out,
    )
    if isinstance(p_in, np.ndarray) and isinstance(p_out, np.ndarray) and np.linalg.norm((p_in - p_out) * s) < 1.0:
        raise VCSInputError("--inlet and --outlet are less than 1 mm apart; give the two ends of the section")
    caps: list[tuple[NDArray[np.floating], NDArray[np.integer]] | None] = []
    for cap in (inlet_cap, outlet_cap):
        if cap is None:
            caps.append(None)
        else:
            c = read_surface(cap, surf.units, check_extent=False)  # a cap is only as wide as the vessel
            caps.append((c.vertices, c.faces))
    ends = find_ends(
        surf.vertices,
        surf.faces,
        surf.cell_data,
        inlet=p_in * s if isinstance(p_in, np.ndarray) else p_in,
        outlet=p_out * s if isinstance(p_out, np.ndarray) else p_out,
        inlet_cap=caps[0],
        outlet_cap=caps[1],
        cap_array=cap_array,
        lumen_radius=surf.lumen_radius_mm,
        units=surf.units,
    )
    t_read = time.perf_counter()
    # does the surface cross itself (every fit reports it: 0.3-0.5 s on a 61k-triangle aorta)? It
    # needs only the surface, so, with a core to spare, it runs on a second thread while the
    # coordinate system and the wall are fitted (numpy's array loops and scipy's k-d trees release
    # the GIL): the command's wall time drops by about that much, its CPU time does not. Started
    # once the ends are found, the usual place for bad input to stop the fit
    crossing_job = _Background(self_intersections, surf.vertices, surf.faces)
    try:
        vcs = VesselCoordinateSystem.from_surface(
            surf.vertices, surf.faces, ends, n_knots=L, recentre_iterations=recentre_iterations
        )
        t_vcs = time.perf_counter()
        wall_fit = None
        if K is not None and R is not None:
            wall_faces = surf.faces[ends.wall_mask]
            wall_fit = fit_wall(vcs, surf.vertices, wall_faces, K=K, R=R)
    except VCSInputError as exc:  # a surface crossing itself is the cause to name, if it is one
        crossing = self_intersection_message(surf, crossing=crossing_job.result())
        if crossing:
            raise VCSInputError(f"{crossing}; repair the mesh (the fit stopped: {exc})") from None
        raise
    t_wall = time.perf_counter()
    warnings = [*surf.warnings, *ends.warnings]
    if wall_fit is not None:
        wr = wall_fit.report
        if wr["not_star_convex_fraction"] > 0.01:
            warnings.append(
                f"{100 * wr['not_star_convex_fraction']:.1f}% of the wall is not star-convex about "
                "the centerline (e.g. a saccular aneurysm): left out of the wall model"
            )
        n_out = wr["points_not_used"]["outside_omega"]
        if n_out > 0.01 * wr["n_wall_points"]:
            warnings.append(
                f"{n_out} wall points ({100 * n_out / wr['n_wall_points']:.1f}%) are outside Omega "
                "(lumen radius above the centerline's radius of curvature, or closest point not unique)"
            )
    if not vcs.report["centerline_inside_lumen"]:
        warnings.append(
            f"the centerline leaves the lumen (minimum wall distance "
            f"{vcs.report['centerline_min_wall_distance_mm']:.3f} mm): the fit is poor, see quality_reasons"
        )
    if vcs.report.get("L_auto", {}).get("criteria_met") is False:
        warnings.append(
            f"--L auto: no L up to {vcs.report['L_working']} keeps |c'| within 2 % inside the lumen; "
            f"took L = {vcs.report['L']} (deviation {100 * vcs.report['arc_length_speed_deviation']:.1f} %)"
        )
    report = {
        "warnings": warnings,
        "mesh": str(surf.path),
        "units": surf.units,
        "units_source": surf.units_source,
        "units_evidence": surf.units_evidence,
        "n_vertices": int(len(surf.vertices)),
        "n_triangles": int(len(surf.faces)),
        **vcs.report,
    }
    if wall_fit is not None:
        report.update(wall_fit.report)
        report.update(wall_quality(wall_fit))
    t_quality = time.perf_counter()
    # every fit: does the surface cross itself, and where (the test started with the fit)
    t_si0 = time.perf_counter()
    crossing = self_intersection_message(surf, report, vcs, crossing=crossing_job.result())
    t_si = time.perf_counter()
    if crossing:
        warnings.append(crossing)
    report.update(fit_quality(report))
    report["timings_s"] = {
        "read_and_ends": t_read - t0,
        **vcs.report["timings_s"],
        "vcs_build": t_vcs - t_read,
        "wall_fit": t_wall - t_vcs,
        "wall_quality": t_quality - t_wall,
        "self_intersection": t_si - t_si0,
        "total": time.perf_counter() - t0,
    }
    meta = {
        "source_mesh": Path(str(surf.path)).name,
        "ends_method": ends.method,
        "inlet_center_mm": report["inlet"]["center_mm"],
        "outlet_center_mm": report["outlet"]["center_mm"],
        "L": int(report["L"]),
        "L_source": report["L_source"],
        "quality": report["quality"],
        "quality_reasons": report["quality_reasons"],
    }
    model = VesselModel(vcs, None if wall_fit is None else wall_fit.model, surf.units, meta)
    return model, report, wall_fit


def self_intersection_message(
    surf: Surface,
    report: dict[str, Any] | None = None,
    vcs: VesselCoordinateSystem | None = None,
    *,
    crossing: NDArray[np.integer] | None = None,
) -> str | None:
    """One line saying that (and where) the surface intersects itself, or None when it does not.

    Parameters
    ----------
    surf : Surface
        The vessel's surface (mm).
    report : dict, optional
        Fit report: gains ``self_intersecting_triangles`` (a count, 0 when none), which
        :func:`fit_quality` turns into a quality reason, and ``self_intersections``: one entry
        per connected patch of crossing triangles (largest first, at most 10): ``triangles``,
        ``center`` (mesh units) and, with ``vcs``, its vessel coordinates ``tau`` and
        ``theta_deg`` (of the patch's centre) and, when the centerline leaves the lumen,
        ``at_centerline_exit`` (the patch lies within 2.5 lumen radii of where it leaves: then
        :func:`fit_quality` names the crossing as the cause).
    vcs : VesselCoordinateSystem, optional
        The fitted coordinate system (mm), to locate the patches.
    crossing : (K,) int, optional
        :func:`vcs.mesh.self_intersections` of ``surf`` when already computed.

    Returns
    -------
    str or None
    """
    if crossing is None:
        crossing = self_intersections(surf.vertices, surf.faces)
    patches: list[dict[str, Any]] = []
    if len(crossing):
        sub = surf.faces[crossing]
        labels = np.unique(connected_faces(sub, len(surf.vertices)), return_inverse=True)[1]
        sizes = np.bincount(labels)
        for k in np.argsort(-sizes, kind="stable")[:10]:
            centre = surf.vertices[sub[labels == k]].mean(axis=(0, 1))
            patch: dict[str, Any] = {"triangles": int(sizes[k]), "center": (centre / surf.scale_to_mm).tolist()}
            if vcs is not None:
                tau, theta, _, _ = vcs.to_vcs(centre[None])
                patch.update(tau=float(tau[0]), theta_deg=float(np.degrees(theta[0])))
                exit_tau = vcs.report.get("centerline_min_wall_distance_tau")
                if not vcs.report.get("centerline_inside_lumen", True) and exit_tau is not None:
                    # where the centerline leaves the lumen: within 2.5 lumen radii of this patch?
                    gap = float(np.linalg.norm(vcs.curve(exit_tau) - centre))
                    radius = (report or {}).get("median_radius_mm") or surf.lumen_radius_mm or 0.0
                    patch["at_centerline_exit"] = bool(gap <= 2.5 * radius)
            patches.append(patch)
    if report is not None:
        report["self_intersecting_triangles"] = int(len(crossing))
        report["self_intersections"] = patches
    if not len(crossing):
        return None
    c = np.asarray(patches[0]["center"])
    where = f" (around ({c[0]:.4g}, {c[1]:.4g}, {c[2]:.4g}) {surf.units}"
    if "tau" in patches[0]:
        where += f", tau = {patches[0]['tau']:.3f}, theta = {patches[0]['theta_deg']:.0f} deg"
    where += ")" if len(patches) == 1 else f"; {len(patches)} places, see self_intersections in fit_report.json)"
    return (
        f"the surface intersects itself: {len(crossing)} triangles cross another part of the wall{where}; "
        "the lumen, centerline and wall model are not reliable there"
    )


#: Limits of :func:`fit_quality` (dimensionless): beyond any of them a fit is ``poor``.
QUALITY_LIMITS = {
    "max_arc_length_speed_deviation": 0.05,
    "min_centerline_wall_distance_ratio": 0.25,
    "min_model_radius_ratio": 0.5,
    "min_fraction_points_used": 0.25,
    "min_fraction_points_used_of_vessel": 0.9,
    "max_residual_p95_ratio": 0.1,
}


def wall_quality(wall_fit: WallFit, n_tau: int = 201, n_theta: int = 64) -> dict[str, Any]:
    """Checks of a fitted wall model rho_w against the wall it was fitted to (fit_report.json keys).

    Parameters
    ----------
    wall_fit : WallFit
        From :func:`vcs.wall.fit_wall` (mm).
    n_tau, n_theta : int
        Grid on which rho_w (Eq. 5) is evaluated.

    Returns
    -------
    dict
        ``model_radius_min_mm`` (min of rho_w on the grid), ``model_radius_min_ratio`` (the
        smallest ratio, over tau, of min_theta rho_w to the median radius of the wall points used
        around that tau; dimensionless), ``model_radius_min_tau``, ``residual_p95_mm``,
        ``median_radius_mm``, ``fraction_points_used`` (of the wall points between the end planes),
        ``fraction_points_used_of_vessel`` (the same without the points on side branches and
        those where the wall is not star-convex about the centerline, separate reasons).
    """
    tau = np.linspace(0.0, 1.0, n_tau)
    rho_w = wall_fit.model(tau[:, None], np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)[None, :])
    used = wall_fit.used
    n_bins = 40
    b = np.minimum((wall_fit.tau[used] * n_bins).astype(int), n_bins - 1)
    from vcs.centerline import group_median

    med = group_median(b, wall_fit.rho[used], n_bins)
    has = np.bincount(b, minlength=n_bins) > 0
    centres = (np.arange(n_bins) + 0.5) / n_bins
    local = np.interp(tau, centres[has], med[has]) if has.any() else np.full(n_tau, np.nan)
    ratio = rho_w.min(axis=1) / np.maximum(local, 1e-9)
    i = int(np.nanargmin(ratio)) if np.isfinite(ratio).any() else 0
    r = wall_fit.report
    n_between = r["n_wall_points"] - r["points_not_used"]["beyond_end_planes"]
    n_vessel = n_between - r["points_not_used"]["branch"] - r["points_not_used"]["not_first_crossing"]
    res = wall_fit.residual[used]
    return {
        "model_radius_min_mm": float(rho_w.min()),
        "model_radius_min_ratio": float(ratio[i]),
        "model_radius_min_tau": float(tau[i]),
        "median_radius_mm": float(np.median(wall_fit.rho[used])) if used.any() else None,
        "residual_p95_mm": float(np.percentile(res, 95)) if res.size else None,
        "fraction_points_used": r["n_points_used"] / max(n_between, 1),
        "fraction_points_used_of_vessel": r["n_points_used"] / max(n_vessel, 1),
    }


def fit_quality(report: dict[str, Any], limits: dict[str, float] | None = None) -> dict[str, Any]:
    """``quality`` (``ok`` or ``poor``) and ``quality_reasons`` (one line each) of a fit report.

    A fit is poor when the surface intersects itself (``self_intersecting_triangles``, set by
    :func:`self_intersection_message`), when the centerline leaves the lumen or comes within a quarter of the local
    lumen radius of the wall, when tau is not the arc length of paper Section 2.2.1 (|c'| varies
    by more than 5 %), when the wall model rho_w (Eq. 5) reaches zero or falls below half the
    local lumen radius, when less than a quarter of the wall points between the end planes, or
    less than 90 % of those not on side branches, were used, or when the 95th percentile of the
    residuals (Eq. 11) exceeds 10 % of the median radius (:data:`QUALITY_LIMITS`).

    Parameters
    ----------
    report : dict
        The fit report so far (the keys of :meth:`VesselCoordinateSystem.from_surface`'s report
        and, with a wall model, of :func:`vcs.wall.fit_wall` and :func:`wall_quality`).
    limits : dict or None
        Overrides of :data:`QUALITY_LIMITS`.

    Returns
    -------
    dict
        ``quality`` and ``quality_reasons`` (list of str).
    """
    lim = {**QUALITY_LIMITS, **(limits or {})}
    why: list[str] = []
    if report.get("self_intersecting_triangles"):
        why.append(
            f"the surface intersects itself ({report['self_intersecting_triangles']} triangles cross another "
            "part of the wall): repair the mesh"
        )
    d = report["centerline_min_wall_distance_mm"]
    if not report["centerline_inside_lumen"]:
        tau_out = report.get("centerline_min_wall_distance_tau", float("nan"))
        near = [p for p in report.get("self_intersections", []) if p.get("at_centerline_exit")]
        if near:  # the crossing is the cause: more knots would not help
            c = near[0]["center"]
            why.append(
                f"the centerline leaves the lumen at tau = {tau_out:.3f} (minimum wall distance {d:.3f} mm), where "
                f"the surface intersects itself ({near[0]['triangles']} triangles around ({c[0]:.4g}, {c[1]:.4g}, "
                f"{c[2]:.4g})): repair the mesh there (more knots would not help)"
            )
        else:
            why.append(f"the centerline leaves the lumen (minimum wall distance {d:.3f} mm); use more knots (--L auto)")
    elif report["centerline_min_wall_distance_ratio"] < lim["min_centerline_wall_distance_ratio"]:
        pct = 100 * report["centerline_min_wall_distance_ratio"]
        why.append(
            f"the centerline touches the wall: it comes within {pct:.0f} % of the local lumen radius of it "
            f"(minimum wall distance {d:.3f} mm)"
        )
    dev = report["arc_length_speed_deviation"]
    if dev > lim["max_arc_length_speed_deviation"]:
        why.append(f"tau is not the arc length: |c'| varies by {100 * dev:.1f} % (> 5 %); use more knots (--L auto)")
    if "model_radius_min_mm" in report:
        if report["model_radius_min_mm"] <= 0:
            why.append(
                f"the model radius reaches {report['model_radius_min_mm']:.2f} mm (<= 0) near tau = "
                f"{report['model_radius_min_tau']:.2f}"
            )
        elif report["model_radius_min_ratio"] < lim["min_model_radius_ratio"]:
            why.append(
                f"the model radius falls to {100 * report['model_radius_min_ratio']:.0f} % of the lumen radius "
                f"near tau = {report['model_radius_min_tau']:.2f}"
            )
        if report["fraction_points_used"] < lim["min_fraction_points_used"]:
            why.append(
                f"only {100 * report['fraction_points_used']:.0f} % of the wall points between the end planes "
                f"were used ({report['points_not_used']})"
            )
        elif report["fraction_points_used_of_vessel"] < lim["min_fraction_points_used_of_vessel"]:
            why.append(
                f"only {100 * report['fraction_points_used_of_vessel']:.0f} % of the star-convex wall points "
                f"off side branches were used ({report['points_not_used']})"
            )
        p95, r_med = report.get("residual_p95_mm"), report.get("median_radius_mm")
        if p95 is not None and r_med and p95 > lim["max_residual_p95_ratio"] * r_med:
            why.append(f"residual p95 {p95:.2f} mm is above 10 % of the median radius ({r_med:.1f} mm)")
    return {"quality": "poor" if why else "ok", "quality_reasons": why}
