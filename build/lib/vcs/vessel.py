"""A fitted vessel: its VCS, its wall model and where it came from; model.json I/O."""
from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vcs.ends import find_ends
from vcs.errors import VCSInputError
from vcs.io import UNIT_TO_MM, Surface, read_surface
from vcs.mesh import connected_faces, triangle_areas
from vcs.model import VesselCoordinateSystem
from vcs.wall import WallFit, WallModel, fit_wall

log = logging.getLogger(__name__)

FORMAT_VERSION = 1


@dataclass(frozen=True)
class VesselModel:
    """VCS + wall model rho_w of one vessel section, all lengths in mm.

    ``units`` is the unit of the input mesh (outputs of the CLI are given back in it).
    """

    vcs: VesselCoordinateSystem
    wall: WallModel | None
    units: str = "mm"
    meta: dict = field(default_factory=dict)

    @property
    def scale_to_mm(self) -> float:
        return UNIT_TO_MM[self.units]

    # -- feature vector (paper Section 2.3.1) -------------------------------------------------
    def feature_vector(self) -> np.ndarray:
        """a = (c_0..c_n, b_00..b_n1n2): centerline control points then wall coefficients (mm)."""
        parts = [self.vcs.control_points.ravel()]
        if self.wall is not None:
            parts.append(self.wall.coefficients.ravel())
        return np.concatenate(parts)

    @classmethod
    def from_feature_vector(cls, a: np.ndarray, template: "VesselModel") -> "VesselModel":
        """Rebuild a model with the knots, frame rule and metadata of ``template`` from vector ``a``.

        The frame's v1(0) is recomputed by transporting the template's choice onto the new
        tangent (it is not part of the vector); every other number comes from ``a``.
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

    # -- geometry -----------------------------------------------------------------------------
    def surface_points(self, tau, theta) -> np.ndarray:
        """Wall points x(tau, theta) = c(tau) + rho_w(tau, theta) (v1 cos theta + v2 sin theta) (Eq. 8)."""
        if self.wall is None:
            raise VCSInputError("this model has no wall model; refit it with `vcs fit` (K, R)")
        tau, theta = np.broadcast_arrays(np.asarray(tau, float), np.asarray(theta, float))
        return self.vcs.to_cartesian(tau, theta, self.wall(tau, theta))

    # -- I/O ----------------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "format_version": FORMAT_VERSION,
            "units": {"internal": "mm", "input": self.units, "scale_to_mm": self.scale_to_mm},
            "centerline": self.vcs.to_dict(),
            "wall": None if self.wall is None else self.wall.to_dict(),
            "meta": self.meta,
        }

    @classmethod
    def from_dict(cls, d: dict) -> "VesselModel":
        version = d.get("format_version")
        if version != FORMAT_VERSION:
            raise VCSInputError(
                f"model format_version {version!r} is not supported (this vcs reads {FORMAT_VERSION}); refit with `vcs fit`"
            )
        wall = None if d.get("wall") is None else WallModel.from_dict(d["wall"])
        return cls(VesselCoordinateSystem.from_dict(d["centerline"]), wall, d["units"]["input"], d.get("meta", {}))

    def save(self, path) -> None:
        """Write model.json (deterministic: same model, same bytes)."""
        text = json.dumps(self.to_dict(), indent=1, sort_keys=True)
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(text + "\n")
        tmp.replace(path)  # atomic: never a half-written model.json

    @classmethod
    def load(cls, path) -> "VesselModel":
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
            return cls.from_dict(d)
        except VCSInputError:
            raise
        except (KeyError, ValueError, TypeError, IndexError, AssertionError) as exc:
            raise VCSInputError(f"'{path}' is not a valid model.json ({type(exc).__name__}: {exc}); "
                                "refit it with `vcs fit`") from None


def largest_component(surf: Surface) -> Surface:
    """Keep the connected component of largest area; the others are reported in ``warnings``."""
    f = surf.faces
    n = len(surf.vertices)
    face_lab = connected_faces(f, n)
    used = np.unique(face_lab)
    if len(used) <= 1:
        return surf
    area = triangle_areas(surf.vertices, f)
    per = np.bincount(face_lab, area)
    keep_lab = int(np.argmax(per))
    keep = face_lab == keep_lab
    msg = (f"{len(used)} disconnected surface components; kept the largest ({keep.sum()} triangles, "
           f"{100 * per[keep_lab] / per.sum():.1f}% of the area), dropped {int((~keep).sum())} triangles")
    # drop the other components' vertices too: they must not size the voxel grid
    kept_v = np.unique(f[keep])
    remap = np.full(n, -1)
    remap[kept_v] = np.arange(len(kept_v))
    return Surface(surf.vertices[kept_v], remap[f[keep]], {k: v[keep] for k, v in surf.cell_data.items()},
                   surf.units, surf.units_source, surf.path, (*surf.warnings, msg))


def parse_point(text: str | None, name: str) -> np.ndarray | None:
    """'x,y,z' -> (3,) array (None passes through)."""
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


def fit_vessel(
    mesh,
    *,
    units: str = "auto",
    inlet=None,
    outlet=None,
    inlet_cap=None,
    outlet_cap=None,
    cap_array: str | None = "auto",
    L: int = 9,
    K: int | None = 19,
    R: int | None = 15,
    recentre_iterations: int = 3,
) -> tuple[VesselModel, dict, WallFit | None]:
    """Fit the VCS (and the wall model when K and R are given) to a surface file or :class:`Surface`.

    ``inlet``/``outlet`` are points in the mesh's units (``'x,y,z'`` strings or arrays);
    ``inlet_cap``/``outlet_cap`` paths of cap surfaces in the same units.
    Returns (model, report, wall_fit).
    """
    t0 = time.perf_counter()
    surf = mesh if isinstance(mesh, Surface) else read_surface(mesh, units)
    surf = largest_component(surf)
    s = surf.scale_to_mm
    p_in = parse_point(inlet, "inlet")
    p_out = parse_point(outlet, "outlet")
    if p_in is not None and p_out is not None and np.linalg.norm((p_in - p_out) * s) < 1.0:
        raise VCSInputError("--inlet and --outlet are less than 1 mm apart; give the two ends of the section")
    caps = []
    for cap in (inlet_cap, outlet_cap):
        if cap is None:
            caps.append(None)
        else:
            c = read_surface(cap, surf.units, check_extent=False)  # a cap is only as wide as the vessel
            caps.append((c.vertices, c.faces))
    ends = find_ends(
        surf.vertices, surf.faces, surf.cell_data,
        inlet=None if p_in is None else p_in * s,
        outlet=None if p_out is None else p_out * s,
        inlet_cap=caps[0], outlet_cap=caps[1], cap_array=cap_array,
    )
    t_read = time.perf_counter()
    vcs = VesselCoordinateSystem.from_surface(
        surf.vertices, surf.faces, ends, n_knots=L, recentre_iterations=recentre_iterations
    )
    t_vcs = time.perf_counter()
    wall_fit = None
    if K is not None and R is not None:
        wall_faces = surf.faces[ends.wall_mask]
        wall_fit = fit_wall(vcs, surf.vertices, wall_faces, K=K, R=R)
    t_wall = time.perf_counter()
    warnings = [*surf.warnings, *ends.warnings]
    if wall_fit is not None:
        wr = wall_fit.report
        if wr["not_star_convex_fraction"] > 0.01:
            warnings.append(f"{100 * wr['not_star_convex_fraction']:.1f}% of the wall is not star-convex about "
                            "the centerline (e.g. a saccular aneurysm): left out of the wall model")
        n_out = wr["points_not_used"]["outside_omega"]
        if n_out > 0.01 * wr["n_wall_points"]:
            warnings.append(f"{n_out} wall points ({100 * n_out / wr['n_wall_points']:.1f}%) are outside Omega "
                            "(lumen radius above the centerline's radius of curvature, or closest point not unique)")
    report = {
        "warnings": warnings,
        "mesh": str(surf.path),
        "units": surf.units,
        "units_source": surf.units_source,
        "n_vertices": int(len(surf.vertices)),
        "n_triangles": int(len(surf.faces)),
        **vcs.report,
    }
    if wall_fit is not None:
        report.update(wall_fit.report)
    report["timings_s"] = {
        "read_and_ends": t_read - t0,
        **vcs.report["timings_s"],
        "vcs_build": t_vcs - t_read,
        "wall_fit": t_wall - t_vcs,
        "total": t_wall - t0,
    }
    meta = {
        "source_mesh": Path(str(surf.path)).name,
        "ends_method": ends.method,
        "inlet_center_mm": report["inlet"]["center_mm"],
        "outlet_center_mm": report["outlet"]["center_mm"],
        "L": int(L),
    }
    model = VesselModel(vcs, None if wall_fit is None else wall_fit.model, surf.units, meta)
    return model, report, wall_fit
