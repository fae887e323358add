"""Sizing a patient's CFD case from its vessel: the cell size (cells across the smallest end and
across the narrowest section of the wall model), the background box (bounded cell count, coarsened
by powers of two with the refinement levels raised by as many), and the inflow (fixed, scaled by
the inlet area, or the patient's own).

All lengths here are SI (m) unless a name says otherwise; the vessel model is in mm.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message
from vcs.mesh import triangle_cross

if TYPE_CHECKING:
    from vcs.vessel import VesselModel

CELL_SIZE_AUTO = "auto"
#: the background (blockMesh) cell is never coarsened beyond this fraction of the narrowest
#: diameter: snappyHexMesh finds the surface by cutting the lines between neighbouring cell
#: centres, so a background cell must not swallow the narrowest section whole
BACKGROUND_CELLS_ACROSS = 2.0


def _floor3(x: float) -> float:
    """``x`` rounded down to 3 significant digits (a cell size never coarser than computed)."""
    e = math.floor(math.log10(x)) - 2
    return float(f"{math.floor(x / 10.0**e * (1 + 1e-12))}e{e}")


def _ceil3(x: float) -> float:
    """``x`` rounded up to 3 significant digits (a cell size never finer than computed)."""
    e = math.floor(math.log10(x)) - 2
    return float(f"{math.ceil(x / 10.0**e * (1 - 1e-12))}e{e}")


# --------------------------------------------------------------------------- vessel sizes


def section_diameters(
    model: VesselModel, n_tau: int = 401, n_theta: int = 72
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Equivalent-circle diameter of the model wall's cross-sections along the centerline.

    The wall point at (tau, theta) is c(tau) + rho_w(tau, theta) (v1 cos theta + v2 sin theta)
    (Eq. 8), a closed curve in the normal plane of c(tau) given in polar form by rho_w (Eq. 5), so
    the section's area is A(tau) = 1/2 int_0^{2 pi} rho_w(tau, theta)^2 d theta (periodic
    trapezoidal rule on ``n_theta`` angles: spectrally accurate) and its equivalent-circle
    diameter d(tau) = 2 sqrt(A(tau) / pi).

    Parameters
    ----------
    model : VesselModel
        A fitted model with a wall model (mm).
    n_tau : int
        Sections, uniformly in tau over [0, 1] (both ends included).
    n_theta : int
        Angles per section.

    Returns
    -------
    tau : (n_tau,) float
    diameter : (n_tau,) float, mm
    """
    wall = model.fitted_wall()
    tau = np.linspace(0.0, 1.0, n_tau)
    theta = 2.0 * np.pi * np.arange(n_theta) / n_theta
    rho = wall(tau[:, None], theta[None, :])
    area = np.pi * (rho**2).mean(axis=1)  # 1/2 * 2 pi * mean(rho^2)
    return tau, 2.0 * np.sqrt(area / np.pi)


def vessel_sizes(model: VesselModel) -> dict[str, Any]:
    """End diameters and the narrowest section of a vessel model (:func:`section_diameters`).

    The narrowest section is the smallest equivalent-circle diameter over tau in [0, 1] (the ends
    included), located on 401 sections and refined by a bounded scalar minimisation between the
    neighbours of the smallest sample.

    Parameters
    ----------
    model : VesselModel
        A fitted model with a wall model (mm).

    Returns
    -------
    dict
        ``source`` ("vessel model"), ``inlet_diameter_m``, ``outlet_diameter_m``,
        ``narrowest_diameter_m``, ``narrowest_tau``, ``length_m`` (centerline).
    """
    from scipy.optimize import minimize_scalar

    tau, d = section_diameters(model)
    i = int(np.argmin(d))
    d_min, t_min = float(d[i]), float(tau[i])
    lo, hi = tau[max(i - 1, 0)], tau[min(i + 1, len(tau) - 1)]
    theta = 2.0 * np.pi * np.arange(72) / 72
    wall = model.fitted_wall()

    def diameter(t: float) -> float:
        return float(2.0 * np.sqrt((wall(np.full_like(theta, t), theta) ** 2).mean()))

    res = minimize_scalar(diameter, bounds=(lo, hi), method="bounded", options={"xatol": 1e-7})
    if res.success and res.fun < d_min:
        d_min, t_min = float(res.fun), float(res.x)
    mm = 1e-3
    return {
        "source": "vessel model",
        "inlet_diameter_m": float(d[0]) * mm,
        "outlet_diameter_m": float(d[-1]) * mm,
        "narrowest_diameter_m": d_min * mm,
        "narrowest_tau": t_min,
        "length_m": float(model.vcs.length) * mm,
    }


def surface_area(tris: NDArray[np.floating]) -> float:
    """Area of a set of triangles (T, 3, 3) (units squared)."""
    return float(0.5 * np.linalg.norm(triangle_cross(tris), axis=1).sum())


def stl_sizes(solids: dict[str, NDArray[np.floating]], roles: dict[str, str]) -> dict[str, Any]:
    """End diameters from the caps of a multi-solid STL (no vessel model at hand).

    The equivalent-circle diameter of each cap is 2 sqrt(area / pi); the narrowest section is not
    known without the model and is taken as the smaller end.

    Parameters
    ----------
    solids : dict of str -> (T, 3, 3) float, m
        Triangles by solid.
    roles : dict of str -> str
        ``inlet``, ``outlet``, ``wall`` or ``other`` per solid.

    Returns
    -------
    dict
        As :func:`vessel_sizes` (``source`` "STL caps (no vessel model: the narrowest section is
        the smaller end)", ``narrowest_tau`` None, ``length_m`` None).
    """
    d = {k: 2.0 * math.sqrt(surface_area(t) / math.pi) for k, t in solids.items()}
    d_in = min(v for k, v in d.items() if roles[k] == "inlet")
    d_out = min(v for k, v in d.items() if roles[k] == "outlet")
    return {
        "source": "STL caps (no vessel model: the narrowest section is the smaller end)",
        "inlet_diameter_m": d_in,
        "outlet_diameter_m": d_out,
        "narrowest_diameter_m": min(d_in, d_out),
        "narrowest_tau": None,
        "length_m": None,
    }


def closed_volume(solids: dict[str, NDArray[np.floating]]) -> float:
    """Volume (m^3) enclosed by a closed, outward-oriented multi-solid STL (divergence theorem)."""
    t = np.concatenate(list(solids.values()))
    return float(abs(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum()) / 6.0)


# --------------------------------------------------------------------------- cell size


def cell_size_value(value: Any, what: str) -> float | str:
    """``"auto"`` or a positive number of metres; VCSInputError (one line) otherwise."""
    if value == CELL_SIZE_AUTO:
        return CELL_SIZE_AUTO
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
    if not ok:
        raise VCSInputError(f"{what} must be 'auto' or a positive number of metres, not {value!r}")
    return float(value)


def choose_cell_size(
    mesh: dict[str, Any], sizes: dict[str, Any], volume: float, *, override: float | None = None
) -> dict[str, Any]:
    """The lumen cell size h of a case, and why.

    ``mesh.cell_size: auto``: h = min(d_end / ``cells_across_end``, d_narrow /
    ``cells_across_narrowest``) with d_end the smaller end diameter and d_narrow the narrowest
    section (:func:`vessel_sizes`), rounded down to 3 significant digits; when the estimated lumen
    cell count V / h^3 exceeds ``max_cells``, h is raised to (V / max_cells)^(1/3), rounded up to
    3 significant digits (and the cells across fall below the request: said in ``why``). A number is used as it is; a
    patient's ``override`` (m) takes precedence over both.

    Parameters
    ----------
    mesh : dict
        ``cfd.mesh`` (``cell_size``, ``cells_across_end``, ``cells_across_narrowest``,
        ``max_cells``).
    sizes : dict
        :func:`vessel_sizes` or :func:`stl_sizes`.
    volume : float, m^3
        Lumen volume (the closed wall STL, flow extensions included).
    override : float, "auto" or None
        The patient's own cell size (m, or ``"auto"``: the auto rule whatever ``cell_size`` says;
        patients sheet), or None.

    Returns
    -------
    dict
        ``cell_size_m``, ``source`` (``auto``, ``config`` or ``patient``), ``governed_by``
        (``smallest end``, ``narrowest section``, ``max_cells``, ``config``, ``patient``),
        ``cells_across_end``, ``cells_across_narrowest`` (as obtained), ``requested`` (the
        auto rule's parameters), ``estimated_lumen_cells`` (V / h^3), ``why`` (one line).
    """
    d_end = min(sizes["inlet_diameter_m"], sizes["outlet_diameter_m"])
    d_narrow = sizes["narrowest_diameter_m"]
    n_end = float(mesh["cells_across_end"])
    n_narrow = float(mesh["cells_across_narrowest"])
    max_cells = int(mesh["max_cells"])
    requested = {"cells_across_end": n_end, "cells_across_narrowest": n_narrow, "max_cells": max_cells}
    mm = 1e3
    if override is not None and cell_size_value(override, "the patient's cell size") != CELL_SIZE_AUTO:
        h = float(override)
        source, governed = "patient", "patient"
        why = f"the patient's own cell size {h * mm:.4g} mm (patients sheet cell_size_mm)"
    elif override is None and mesh["cell_size"] != CELL_SIZE_AUTO:
        h = float(cell_size_value(mesh["cell_size"], "cfd.mesh.cell_size"))
        source, governed = "config", "config"
        why = f"cfd.mesh.cell_size {h * mm:.4g} mm"
    else:
        source = "auto"
        h_end, h_narrow = d_end / n_end, d_narrow / n_narrow
        if h_narrow < h_end:
            h, governed = _floor3(h_narrow), "narrowest section"
            why = f"{n_narrow:g} cells across the narrowest section (d = {d_narrow * mm:.3g} mm"
            why += f" at tau {sizes['narrowest_tau']:.3f})" if sizes.get("narrowest_tau") is not None else ")"
        else:
            h, governed = _floor3(h_end), "smallest end"
            why = f"{n_end:g} cells across the smallest end (d = {d_end * mm:.3g} mm)"
        if volume / h**3 > max_cells:
            h_cap = _ceil3((volume / max_cells) ** (1.0 / 3.0))
            why = (
                f"{why} would give ~{volume / h**3:,.0f} lumen cells, more than cfd.mesh.max_cells {max_cells:,}: "
                f"raised from {h * mm:.3g} mm to {h_cap * mm:.3g} mm"
            )
            h, governed = h_cap, "max_cells"
        mine = " (the patient's cell_size_mm)" if override is not None else ""
        why = f"auto{mine}: {why}"
    return {
        "cell_size_m": h,
        "source": source,
        "governed_by": governed,
        "cells_across_end": d_end / h,
        "cells_across_narrowest": d_narrow / h,
        "requested": requested,
        "estimated_lumen_cells": int(round(volume / h**3)),
        "why": why,
    }


def background_plan(
    h: float, lo: NDArray[np.floating], hi: NDArray[np.floating], mesh: dict[str, Any], narrowest: float
) -> dict[str, Any]:
    """The blockMesh box and its cell size for a lumen cell size h.

    The box is the STL bounds padded by ``pad_cells`` background cells. Its cell is h 2^k with the
    smallest k >= 0 that keeps the box at or below ``max_background_cells``, but never larger than
    narrowest / :data:`BACKGROUND_CELLS_ACROSS`; every snappyHexMesh level (surface, wall, inlet,
    outlet) is raised by k and the whole lumen is refined k levels (refinement region ``inside``
    the vessel surface), so the lumen and wall cells stay at h while only the box outside the
    vessel, which snappyHexMesh removes, is coarse.

    Parameters
    ----------
    h : float, m
        Lumen cell size (:func:`choose_cell_size`).
    lo, hi : (3,) float, m
        Bounds of the STL.
    mesh : dict
        ``cfd.mesh`` (``pad_cells``, ``max_background_cells``).
    narrowest : float, m
        Narrowest diameter of the vessel.

    Returns
    -------
    dict
        ``background_cell_size_m``, ``level_offset`` (k), ``background_cells`` (box), ``ncells``
        (per axis), ``bmin``, ``bmax`` (m), ``max_background_cells``, ``over_limit`` (bool: the
        narrowest section stopped the coarsening above the limit), ``why`` (one line).
    """
    pad = int(mesh["pad_cells"])
    limit = int(mesh["max_background_cells"])
    ext = np.asarray(hi, float) - np.asarray(lo, float)

    def box(hb: float) -> NDArray[np.integer]:
        return np.ceil(ext / hb - 1e-9 + 2 * pad).astype(int)

    k = 0
    while int(np.prod(box(h * 2**k))) > limit and h * 2 ** (k + 1) <= narrowest / BACKGROUND_CELLS_ACROSS:
        k += 1
    hb = h * 2**k
    n = box(hb)
    bmin = np.asarray(lo, float) - pad * hb
    total = int(np.prod(n))
    over = total > limit
    why = f"box {'x'.join(map(str, n))} = {total:,} cells of {hb * 1e3:.4g} mm"
    if k:
        why += (
            f" (lumen cell {h * 1e3:.4g} mm x 2^{k}: {int(np.prod(box(h))):,} cells would exceed "
            f"cfd.mesh.max_background_cells {limit:,}; refinement levels raised by {k}, lumen refined {k} levels)"
        )
    if over:
        why += (
            f"; above cfd.mesh.max_background_cells {limit:,}: a coarser background would exceed half "
            f"the narrowest diameter ({narrowest * 1e3:.3g} mm)"
        )
    return {
        "background_cell_size_m": hb,
        "level_offset": k,
        "background_cells": total,
        "ncells": [int(x) for x in n],
        "bmin": [float(x) for x in bmin],
        "bmax": [float(x) for x in bmin + n * hb],
        "max_background_cells": limit,
        "over_limit": bool(over),
        "why": why,
    }


# --------------------------------------------------------------------------- inflow


def choose_inflow(
    inlet: dict[str, Any], inlet_area: float, *, patient: dict[str, float] | None = None
) -> dict[str, Any]:
    """The inflow of one patient: its own (patients sheet) or the config's, fixed or scaled.

    The config gives Q = ``flow_rate`` or, when that is unset, ``velocity`` x ``valve_area``.
    ``scaling: fixed`` applies it to every patient; ``scaling: scaled_by_inlet_area`` multiplies
    it by min(A_inlet / ``reference_inlet_area``, ``max_scale``) (the same mean inlet velocity for
    every patient up to the cap, so a small or paediatric aorta gets a proportionally smaller flow,
    while with ``max_scale`` 1 a dilated root gets no more than the config's flow); for a jet this
    scales the valve area and keeps the jet velocity. A patient's own ``flow_rate`` (m^3/s), or ``velocity`` (m/s)
    with ``valve_area`` (m^2), replaces the config's and is applied as given (never scaled).

    Parameters
    ----------
    inlet : dict
        ``cfd.inlet`` (``type``, ``velocity``, ``valve_area``, ``flow_rate``, ``scaling``,
        ``reference_inlet_area``, ``max_scale``).
    inlet_area : float, m^2
        Area of the patient's inlet (the STL's inlet solid).
    patient : dict or None
        The patient's own ``flow_rate`` or ``velocity`` + ``valve_area`` (SI), or None.

    Returns
    -------
    dict
        ``source`` (``config`` or ``patient``), ``scaling`` (``fixed``, ``scaled_by_inlet_area``
        or ``patient``), ``scale_factor``, ``flow_rate_m3_s``, ``flow_rate_l_min``,
        ``jet_velocity_m_s`` (jet only, else None), ``valve_area_m2`` (as applied: the jet's disc),
        ``inlet_area_m2``,
        ``reference_inlet_area_m2``, ``mean_inlet_velocity_m_s`` (Q / A_inlet), ``why``.
    """
    patient = {k: v for k, v in (patient or {}).items() if v is not None}
    velocity = float(inlet["velocity"])
    valve = float(inlet["valve_area"])
    q_set = inlet.get("flow_rate")
    scaling = inlet.get("scaling", "fixed")
    a_ref = float(inlet.get("reference_inlet_area") or inlet_area)
    if patient:
        source, factor = "patient", 1.0
        if "flow_rate" in patient:
            q = float(patient["flow_rate"])
            why = f"the patient's flow rate {q * 6e4:.4g} L/min (patients sheet)"
        else:
            velocity, valve = float(patient["velocity"]), float(patient["valve_area"])
            q = velocity * valve
            why = f"the patient's inlet velocity {velocity:.4g} m/s x valve area {valve * 1e4:.4g} cm2 (patients sheet)"
        applied = "patient"
    else:
        source = "config"
        q0 = float(q_set) if q_set else velocity * valve
        max_scale = float(inlet.get("max_scale", 1.0))
        factor = min(inlet_area / a_ref, max_scale) if scaling == "scaled_by_inlet_area" else 1.0
        q = q0 * factor
        valve *= factor  # a jet keeps its velocity; its valve area follows the inlet
        base = f"{q0 * 6e4:.4g} L/min" + (
            "" if q_set else f" ({velocity:.4g} m/s x {inlet['valve_area'] * 1e4:.4g} cm2)"
        )
        if scaling == "scaled_by_inlet_area":
            capped = factor < inlet_area / a_ref
            why = (
                f"config {base} x inlet area {inlet_area * 1e4:.4g} cm2 / reference {a_ref * 1e4:.4g} cm2"
                + (f" (capped at cfd.inlet.max_scale {max_scale:g})" if capped else "")
                + f" = {q * 6e4:.4g} L/min"
            )
        else:
            why = f"config {base}, fixed"
        applied = scaling
    return {
        "source": source,
        "scaling": applied,
        "scale_factor": factor,
        "flow_rate_m3_s": q,
        "flow_rate_l_min": q * 6e4,
        "jet_velocity_m_s": q / valve if inlet["type"] == "jet" else None,
        "valve_area_m2": valve,
        "inlet_area_m2": inlet_area,
        "reference_inlet_area_m2": a_ref,
        "mean_inlet_velocity_m_s": q / inlet_area,
        "why": why,
    }
