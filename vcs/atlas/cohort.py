"""The cohort atlas (paper Section 2.3): who is included, and coregistration + shape PCA + flow PCA +
shape -> flow regression of the included patients, as arrays (no files; see :mod:`vcs.atlas.build`).

Missing wall values. A wall field (WSS, the wall markers TAWSS, OSI, log10_RRT, ECAP, and every
phase's WSS: :func:`vcs.atlas.pca.is_wall_field`) may hold NaN or inf at a wall cell: NaN where
the resampling found a side branch's ostium (no wall of the section there:
:data:`vcs.cfd.resample.OSTIUM_CRITERION`), inf/NaN where a marker diverges (RRT where OSI = 0.5).
A cell missing for ANY included patient is left out of that field's PCA (:data:`NON_FINITE_RULE`),
never filled with a number: the PCA is that of the other cells, its mean and modes are NaN there
(``atlas.npz``, ``flow_mean.vtu``, grey in the figures), and the atlas records per field how many
cells were left out, which fraction, and which patients caused them (:attr:`Atlas.wall_fields`,
atlas.json ``wall_fields``). A field with no cell left has no PCA and says so in one log line and
in its record. U and p (whose wall layer is the no-slip U = 0 and the interpolated p) must be
finite everywhere.

Pure numpy/scipy; never imports plotting (:mod:`vcs.atlas.plots`).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from vcs.atlas.pca import (
    FIELD_UNITS,
    FLOW_FIELDS,
    MARKER_TRANSFORMS,
    PCA,
    WALL_MARKERS,
    field_key,
    field_quantity,
    flow_vector,
    is_vector_field,
    is_wall_field,
    pulsatile_fields,
    shape_matrix,
)
from vcs.atlas.procrustes import (
    RigidTransform,
    align_models,
    check_compatible,
    procrustes,
    transform_model,
    wall_grid_points,
)
from vcs.atlas.regression import loo_sufficiency, r2_skill, ridge_loo
from vcs.errors import VCSInputError

if TYPE_CHECKING:
    from vcs.vessel import VesselModel


log = logging.getLogger("vcs.atlas")

#: Stages of a patient's chain, in order (the ``stage`` of an exclusion in atlas.json).
STAGES = ("fit", "wall", "lumen", "case", "mesh", "solve", "sampling")  # wall: model geometry; lumen: surface
#: How a wall field's PCA treats missing values (atlas.json ``wall_fields`` and ``wall_markers``).
NON_FINITE_RULE = (
    "a wall cell where any included patient's wall field (WSS, TAWSS, OSI, log10_RRT, ECAP, a phase's "
    "WSS) is not finite (NaN at a side branch's ostium, where the resampling found no wall of the "
    "section; log10_RRT: where RRT is not finite and positive, i.e. OSI = 0.5 or TAWSS = 0) is left out "
    "of that field's PCA, all of its vector components: NaN in its mean, modes and +-2 sigma maps, "
    "never replaced by a number; a field with no cell left has no PCA (its record's 'excluded' says why)"
)
_MESH_UTILITIES = ("blockMesh", "snappyHexMesh", "checkMesh")


def fit_exclusion(model: VesselModel) -> str | None:
    """Reason to exclude a patient for the quality of its VCS fit (None: include).

    ``vcs fit`` writes ``quality`` (``ok`` or ``poor``) and ``quality_reasons`` into the model's
    ``meta`` (model.json), see :func:`vcs.vessel.fit_quality`.

    Parameters
    ----------
    model : VesselModel

    Returns
    -------
    str or None
        One line: ``fit quality poor: <reasons>``.
    """
    if model.meta.get("quality") == "poor":
        return "fit quality poor: " + "; ".join(model.meta.get("quality_reasons") or ["no reason recorded"])
    return None


def status_exclusion(status: Mapping[str, Any] | None, *, accept_relaxed: bool = False) -> str | None:
    """Reason to exclude a patient from its case ``status.json`` (None: include).

    Excluded when the file is missing, ``failed`` is true, ``status``/``state`` names a failure,
    or ``converged`` is false (vcs.cfd.run_case writes ``converged`` and ``reason``; a stationary
    time average of its transient fallback is ``converged`` true). With ``accept_relaxed``, a
    legacy status of the removed SIMPLE-iterate averaging with ``converged_relaxed`` true is
    included (new runs never write it). The reason quotes the
    status's own ``reason``/``error``/``message``; a failure recorded before the solver (a status
    whose ``stage`` is ``fit``, ``wall``, ``lumen`` or ``case``: the workflow propagates those), or a mesh
    that stopped the patient before the solver (``stage`` ``mesh``, ``mesh_ok`` false: an end lost
    in meshing, a leak), is its reason as is.

    Parameters
    ----------
    status : mapping or None
        The parsed status.json; None when the file is missing.
    accept_relaxed : bool
        Include legacy statuses that met only the relaxed criterion (``converged_relaxed``).

    Returns
    -------
    str or None
        One-line reason, or None to include the patient.
    """
    if status is None:
        return "no status.json"
    detail = next((str(status[k]) for k in ("reason", "error", "message") if status.get(k)), "")
    state = str(status.get("status", status.get("state", ""))).lower()
    failed = status.get("failed") is True or state in ("failed", "error", "crashed", "diverged", "timeout")
    if failed and status.get("stage") in ("fit", "wall", "lumen", "case") and detail:
        return detail
    if status.get("stage") == "mesh" and status.get("mesh_ok") is False and detail:
        return detail  # run_case's patch check: already what happened, in words
    detail = f": {detail}" if detail else ""
    if failed:
        return f"solver failed ({state or 'failed'}){detail}"
    if status.get("converged") is False:
        if accept_relaxed and status.get("converged_relaxed") is True:
            return None
        return f"not converged{detail}"
    return None


def status_stage(status: Mapping[str, Any] | None) -> str:
    """The stage of :data:`STAGES` at which a case status ended: its own ``stage`` when it has one,
    else ``mesh`` when meshing failed (``mesh_ok`` false, or the failed log is blockMesh's,
    snappyHexMesh's or checkMesh's), else ``solve``."""
    if not status:
        return "solve"
    if status.get("stage") in STAGES:
        return str(status["stage"])
    log = str(status.get("failed_log") or "")
    if status.get("mesh_ok") is False or any(log.endswith(f"log.{u}") for u in _MESH_UTILITIES):
        return "mesh"
    return "solve"


def fit_failure(report: Mapping[str, Any] | None) -> str | None:
    """Reason to exclude a patient from its ``fit_report.json`` (None: include, or no report).

    A fit that failed (the workflow then writes a failure record, ``failed: true``, in place of
    the fit's outputs) is excluded with its ``reason``.
    """
    if report is None or report.get("failed") is not True:
        return None
    return str(report.get("reason") or f"{report.get('stage', 'fit')} failed")


def fields_exclusion(fields: Mapping[str, Any] | None) -> str | None:
    """Reason to exclude a patient from its resampled fields (None: include).

    No fields, or a placeholder that carries an ``excluded`` reason instead of the arrays (the
    workflow writes one when the case had no usable solution or the resampling failed).
    """
    if fields is None:
        return "no resampled fields"
    if "excluded" in fields:
        return str(np.asarray(fields["excluded"]))
    return None


def patient_exclusion(
    report: Mapping[str, Any] | None,
    status: Mapping[str, Any] | None,
    fields: Mapping[str, Any] | None,
    *,
    accept_relaxed: bool = False,
) -> tuple[str, str] | None:
    """(stage, reason) of the first reason to leave a patient out, looked for in its fit report
    (:func:`fit_failure`), its status.json (:func:`status_exclusion`, stage :func:`status_stage`)
    and its fields (:func:`fields_exclusion`, stage ``sampling`` unless the fields name another);
    None to include the patient.

    Parameters
    ----------
    report : mapping or None
        fit_report.json (None: not known, nothing to say).
    status : mapping or None
        status.json (None: missing, which excludes).
    fields : mapping or None
        The resampled fields (None: missing, which excludes).
    accept_relaxed : bool
        See :func:`status_exclusion`.
    """
    reason = fit_failure(report)
    if reason is not None:
        return str((report or {}).get("stage") or "fit"), reason
    reason = status_exclusion(status, accept_relaxed=accept_relaxed)
    if reason is not None:
        return status_stage(status), reason
    reason = fields_exclusion(fields)
    if reason is not None:
        stage = str(np.asarray(fields["stage"])) if fields is not None and "stage" in fields else "sampling"
        return stage, reason
    return None


@dataclass(frozen=True)
class Atlas:
    """Result of :func:`compute_atlas` (all arrays; no files).

    Attributes
    ----------
    patients : list of str
        Included patient ids (n), in input order.
    excluded : dict
        {patient id: reason} of the excluded patients.
    exclusion_stages : dict
        {patient id: stage of :data:`STAGES`} of the excluded patients (see :func:`patient_exclusion`).
    aligned_models : list of VesselModel
        The included models in atlas space.
    transforms : list of RigidTransform
        Model -> atlas space, one per included patient.
    alignment_report : dict
        GPA report (:func:`vcs.atlas.procrustes.align_models`) without the mean points.
    shape : PCA
        Shape PCA of the aligned feature vectors (mm).
    flow : dict
        {field: PCA} of the flow measurement vectors (names: :mod:`vcs.atlas.pca`; of a pulsatile
        cohort also the wall markers and the phase fields).
    field_shapes : dict
        {field: grid shape of the measurement vector}, e.g. (n_tau, n_theta, n_rho, 3).
    grid : dict
        ``tau``, ``theta`` (rad), ``rho_n`` 1-D arrays of the resampled fields' grid.
    regression : dict
        {field: :func:`vcs.atlas.regression.ridge_loo` result, plus ``status`` (``ok`` or
        ``insufficient_patients``, :func:`vcs.atlas.regression.loo_sufficiency`), ``status_reason``
        and ``skill`` per flow mode (:func:`vcs.atlas.regression.r2_skill`; all
        ``insufficient_patients`` when the status is)}.
    options : dict
        The options the atlas was computed with.
    alignment_mean : (n_tau_align * n_theta_align, 3) float, mm
        GPA mean wall grid, the target a new vessel is aligned to.
    field_sources : dict
        {included patient id: ``time_average`` (the transient fallback's window means),
        ``instantaneous`` (a converged steady state), ``pulsatile`` (cardiac-cycle averages,
        markers and phases), from each patient's fields ``field_source``, or
        ``simple_iterate_average`` (a legacy status admitted by ``accept_relaxed``)}.
    time_average_errors : dict
        {included patient id whose flow is a time average: its status ``time_average_errors``
        (the relative half-widths of the confidence intervals of its means, their confidence
        level and tolerances, the window in flow-through times)}.
    flow_kind : {"steady", "pulsatile"}
        ``pulsatile`` when the included patients' ``field_source`` is (all of them, see
        :func:`cohort_flow_kind`), else ``steady``.
    phase_names : tuple of str
        The phases of a pulsatile cohort's phase fields (empty for a steady one).
    wall_markers : dict
        {wall marker asked for: its record of ``wall_fields``}.
    wall_fields : dict
        {wall field asked for (:func:`vcs.atlas.pca.is_wall_field`): ``data`` (its fields.npz
        array), ``transform`` (None or ``log10``), ``units``, ``n_cells`` (wall grid cells),
        ``n_left_out`` (cells left out of its PCA, :data:`NON_FINITE_RULE`), ``fraction_left_out``,
        ``non_finite_by_patient`` ({patient: cells whose value is not finite (log10_RRT: whose
        RRT is not finite and positive)}, only patients that have some), ``ostium_by_patient``
        ({patient: wall cells its resampling marked at an ostium}, only patients that have some)
        and, for a field without a PCA, ``excluded`` (the reason)}.
    """

    patients: list[str]
    excluded: dict[str, str]
    aligned_models: list[VesselModel]
    transforms: list[RigidTransform]
    alignment_report: dict[str, Any]
    shape: PCA
    flow: dict[str, PCA]  # field -> PCA
    field_shapes: dict[str, tuple[int, ...]]  # field -> grid shape of the measurement vector
    grid: dict[str, np.ndarray]  # tau, theta, rho_n of the resampled fields
    regression: dict[str, dict[str, Any]]  # field -> ridge_loo result
    options: dict[str, Any]
    alignment_mean: np.ndarray  # (n_tau_align * n_theta_align, 3) GPA mean wall grid, mm
    exclusion_stages: dict[str, str] = field(default_factory=dict)  # excluded id -> stage
    field_sources: dict[str, str] = field(default_factory=dict)  # included id -> time_average | instantaneous | ...
    time_average_errors: dict[str, dict[str, Any]] = field(default_factory=dict)  # included id -> error bars
    flow_kind: str = "steady"  # steady | pulsatile
    phase_names: tuple[str, ...] = ()  # phases of a pulsatile cohort's phase fields
    wall_markers: dict[str, dict[str, Any]] = field(default_factory=dict)  # marker -> non-finite record
    wall_fields: dict[str, dict[str, Any]] = field(default_factory=dict)  # wall field -> non-finite record


def compute_atlas(
    models: Mapping[str, VesselModel],
    fields: Mapping[str, Mapping[str, Any]],
    statuses: Mapping[str, Mapping[str, Any] | None],
    *,
    reports: Mapping[str, Mapping[str, Any] | None] | None = None,
    n_modes: int = 3,
    n_regression_scores: int | None = None,
    scale: bool = False,
    n_tau_align: int = 40,
    n_theta_align: int = 24,
    flow_frame: str = "vcs",
    flow_fields: Sequence[str] | None = None,
    shape_block: str = "all",
    accept_relaxed: bool = False,
) -> Atlas:
    """Coregistration, shape PCA, flow PCA and shape -> flow regression of a cohort.

    Parameters
    ----------
    models : {patient id: VesselModel}
        The fitted models; a patient of ``reports`` without a model (its fit failed) is excluded.
    fields : {patient id: dict of resampled arrays}
        As returned by :func:`vcs.cfd.resample.sample_case` or loaded from ``fields.npz``; a patient
        without fields, or with a placeholder carrying an ``excluded`` reason, is excluded.
    statuses : {patient id: status dict or None}
        From each case's status.json; see :func:`status_exclusion`. Patients absent from
        ``statuses`` count as included.
    reports : {patient id: fit_report dict or None}, optional
        From each fit's fit_report.json; see :func:`fit_failure`. The patients are those of
        ``models`` and ``reports`` (in that order); each is excluded with the first reason of
        :func:`patient_exclusion`.
    n_modes : int
        Modes kept per PCA (at most n_included - 1).
    n_regression_scores : int, optional
        k shape scores used to predict flow scores (default ``n_modes``).
    scale : bool
        Similarity instead of rigid alignment (default rigid; see
        :func:`vcs.atlas.procrustes.generalized_procrustes`).
    n_tau_align, n_theta_align : int
        Wall grid of the alignment correspondences.
    flow_frame : {"vcs", "cartesian"}
        Local-frame vector components (default) or Cartesian ones (:func:`vcs.atlas.pca.flow_vector`).
    flow_fields : sequence of str, optional
        Fields with a flow PCA (names of :mod:`vcs.atlas.pca`). Default by the cohort's flow
        (:func:`cohort_flow_kind`): U, p, WSS of a steady cohort; of a pulsatile one also the wall
        markers TAWSS, OSI, log10_RRT, ECAP (scalar (n_tau, n_theta) maps) and
        ``phase/<name>/U|p|WSS`` of each of its ``phase_names``
        (:func:`vcs.atlas.pca.pulsatile_fields`). A wall field's PCA (WSS, the markers, a phase's
        WSS) leaves out the cells where any patient's value is not finite, e.g. NaN at an ostium
        (:data:`NON_FINITE_RULE`); U and p must be finite.
    shape_block : {"all", "wall", "centerline"}
        Which part of the feature vector the shape PCA varies (:func:`vcs.atlas.pca.shape_matrix`).
    accept_relaxed : bool
        Include legacy statuses that met only the relaxed criterion (:func:`status_exclusion`).

    Returns
    -------
    Atlas

    Raises
    ------
    VCSInputError
        Fewer than 3 included patients; pulsatile and steady patients together
        (:func:`cohort_flow_kind`); pulsatile patients sampled at different phases; fields
        missing, resampled on different grids or (U, p) not finite.

    Examples
    --------
    Four straight tubes of radius 4-7 mm with a Poiseuille-like pressure (proportional to
    1 / r^4): one shape mode (the radius) and one pressure mode carry all the variance.

    >>> import numpy as np
    >>> from vcs import VesselCoordinateSystem, VesselModel, WallModel
    >>> from vcs.atlas import compute_atlas
    >>> from vcs.centerline import fit_centerline
    >>> axis = fit_centerline(np.linspace(0.0, 1.0, 50)[:, None] * [0.0, 0.0, 100.0], 5)
    >>> vcs = VesselCoordinateSystem(axis, [1.0, 0.0, 0.0])  # 100 mm along z
    >>> tau = np.linspace(0.0, 1.0, 9)
    >>> grid = {"tau": tau, "theta": np.linspace(0.0, 2 * np.pi, 8, endpoint=False), "rho_n": np.linspace(0.0, 1.0, 3)}
    >>> models, fields = {}, {}
    >>> for i, r in enumerate([4.0, 5.0, 6.0, 7.0]):
    ...     models[f"P{i}"] = VesselModel(vcs, WallModel(7, 7, np.full((11, 8), r)))  # rho_w = r
    ...     p = np.broadcast_to(1e3 / r**4 * (1.0 - tau)[:, None, None], (9, 8, 3))
    ...     fields[f"P{i}"] = {**grid, "p": p}
    >>> atlas = compute_atlas(models, fields, {}, n_modes=2, flow_fields=["p"])
    >>> atlas.patients
    ['P0', 'P1', 'P2', 'P3']
    >>> [round(float(pca.explained_variance_ratio[0]), 9) for pca in (atlas.shape, atlas.flow["p"])]
    [1.0, 1.0]
    >>> bool(np.all(np.diff(atlas.shape.scores[:, 0]) > 0))  # the shape score grows with the radius
    True
    """
    reports = reports or {}
    excluded, stages = _exclusions(models, fields, statuses, reports, accept_relaxed)
    patients = [pid for pid in models if pid not in excluded]
    if len(patients) < 3:
        listed = "; ".join(f"{p} ({stages[p]}: {r})" for p, r in excluded.items()) or "none"
        raise VCSInputError(f"an atlas needs at least 3 included patients, got {len(patients)} (excluded: {listed})")
    sources = {p: _field_source(fields[p], statuses.get(p)) for p in patients}
    kind = cohort_flow_kind(sources)
    phases = _phase_names(fields, patients) if kind == "pulsatile" else ()
    if flow_fields is None:
        flow_fields = pulsatile_fields(phases) if kind == "pulsatile" else FLOW_FIELDS
    flow_fields = tuple(flow_fields)
    shapes0 = _check_fields(fields, patients, flow_fields, flow_frame)
    # one L for the cohort: the largest any included patient was fitted with (each fitted with
    # --L auto picks what its vessel needs); the others are refitted to it (VesselModel.with_n_knots)
    knots = {p: models[p].n_knots for p in patients}
    L = max(knots.values())
    aligned, transforms, report = align_models(
        [models[p].with_n_knots(L) for p in patients], n_tau=n_tau_align, n_theta=n_theta_align, scale=scale
    )
    report["knots"] = {
        "L": L,
        "K": None if aligned[0].wall is None else aligned[0].wall.K,
        "R": None if aligned[0].wall is None else aligned[0].wall.R,
        "L_rule": "the largest L of the included patients; smaller ones refitted to it",
        "L_fitted": knots,
    }
    gpa_mean = report.pop("mean_points_mm")
    shape = PCA.from_data(shape_matrix(aligned, shape_block), n_modes)
    flow, walls = _flow_pcas(fields, patients, flow_fields, flow_frame, n_modes)
    k = min(n_regression_scores or n_modes, shape.n_modes)
    regression = _regressions(shape, flow, k, len(patients))
    f0 = fields[patients[0]]
    grid = {key: np.asarray(f0[key]) for key in ("tau", "theta", "rho_n") if key in f0}
    return Atlas(
        patients,
        excluded,
        aligned,
        transforms,
        report,
        shape,
        flow,
        shapes0,
        grid,
        regression,
        {
            "n_modes": n_modes,
            "n_regression_scores": k,
            "scale": scale,
            "flow_frame": flow_frame,
            "n_tau_align": n_tau_align,
            "n_theta_align": n_theta_align,
            "shape_block": shape_block,
            "accept_relaxed": accept_relaxed,
            "flow_fields": list(flow_fields),
        },
        gpa_mean,
        stages,
        sources,
        {
            p: dict(st["time_average_errors"])
            for p in patients
            if (st := statuses.get(p)) and st.get("time_average_errors")
        },
        kind,
        phases,
        {f: r for f, r in walls.items() if f in WALL_MARKERS},
        walls,
    )


def _exclusions(
    models: Mapping[str, VesselModel],
    fields: Mapping[str, Mapping[str, Any]],
    statuses: Mapping[str, Mapping[str, Any] | None],
    reports: Mapping[str, Mapping[str, Any] | None],
    accept_relaxed: bool,
) -> tuple[dict[str, str], dict[str, str]]:
    """({patient: reason}, {patient: stage}) of the patients of ``models`` and ``reports`` left out
    (:func:`fit_exclusion`, then :func:`patient_exclusion`; no model: ``fit``)."""
    excluded, stages = {}, {}
    for pid in dict.fromkeys([*models, *reports]):
        reason = fit_exclusion(models[pid]) if pid in models else None
        found = ("fit", reason) if reason is not None else None
        if found is None:
            found = patient_exclusion(
                reports.get(pid),
                statuses[pid] if pid in statuses else {},  # not given: nothing to say
                fields.get(pid),
                accept_relaxed=accept_relaxed,
            )
        if found is None and pid not in models:
            found = ("fit", "no model")
        if found is not None:
            stages[pid], excluded[pid] = found
    return excluded, stages


def _flow_pcas(
    fields: Mapping[str, Mapping[str, Any]],
    patients: Sequence[str],
    flow_fields: Sequence[str],
    frame: str,
    n_modes: int,
) -> tuple[dict[str, PCA], dict[str, dict[str, Any]]]:
    """({field: PCA}, {wall field: record}) of the flow fields; a wall field's PCA leaves out the
    cells missing for any patient (:data:`NON_FINITE_RULE`), a field with none left has no PCA."""
    flow: dict[str, PCA] = {}
    walls: dict[str, dict[str, Any]] = {}
    for f in flow_fields:
        X = np.array([flow_vector(fields[p], f, frame=frame) for p in patients])
        if not is_wall_field(f):
            flow[f] = PCA.from_data(X, n_modes)
            continue
        walls[f], X = _left_out_cells(f, X, fields, patients, frame)
        if "excluded" in walls[f]:
            log.warning("%s has no PCA: %s", f, walls[f]["excluded"])
            continue
        flow[f] = PCA.from_data(X, n_modes, drop_non_finite=True)
    return flow, walls


def _left_out_cells(
    f: str, X: np.ndarray, fields: Mapping[str, Mapping[str, Any]], patients: Sequence[str], frame: str
) -> tuple[dict[str, Any], np.ndarray]:
    """The record of a wall field's missing cells (:attr:`Atlas.wall_fields`) and its data with
    every component of a cell missing in one component set to NaN (a cell is in or out whole)."""
    per_cell = 3 if is_vector_field(f) else 1
    bad = ~np.isfinite(X.reshape(len(X), -1, per_cell)).all(axis=-1)  # (n patients, n cells)
    out = bad.any(axis=0)
    X = X.copy()
    X.reshape(len(X), -1, per_cell)[:, out] = np.nan
    ostia = {p: int(np.asarray(fields[p]["ostium"]).sum()) for p in patients if "ostium" in fields[p]}
    rec: dict[str, Any] = {
        "data": field_key(f, frame),
        "transform": "log10" if f in MARKER_TRANSFORMS else None,
        "units": FIELD_UNITS[field_quantity(f)],
        "n_cells": int(out.size),
        "n_left_out": int(out.sum()),
        "fraction_left_out": float(out.mean()),
        "non_finite_by_patient": {p: int(n) for p, n in zip(patients, bad.sum(axis=1)) if n},
        "ostium_by_patient": {p: n for p, n in ostia.items() if n},
    }
    if out.all():
        rec["excluded"] = (
            f"no wall cell where every included patient's {rec['data']} is finite"
            + (" and positive" if f in MARKER_TRANSFORMS else "")
            + f" (missing for {', '.join(rec['non_finite_by_patient'])})"
        )
    elif out.any():
        log.info(
            "%s: %d of %d wall cells (%.1f%%) left out of its PCA (missing for %s)",
            f,
            rec["n_left_out"],
            rec["n_cells"],
            100 * rec["fraction_left_out"],
            ", ".join(f"{p} {n}" for p, n in rec["non_finite_by_patient"].items()),
        )
    return rec, X


def _regressions(shape: PCA, flow: Mapping[str, PCA], k: int, n_patients: int) -> dict[str, dict[str, Any]]:
    """{field: :func:`vcs.atlas.regression.ridge_loo` of the first k shape scores -> the field's
    scores, with ``status``, ``status_reason`` and ``skill`` per mode}."""
    sufficiency, why = loo_sufficiency(n_patients, k)
    regression = {}
    for f in flow:
        r = ridge_loo(shape.scores[:, :k], flow[f].scores)
        r["status"], r["status_reason"] = sufficiency, why
        r["skill"] = [sufficiency if sufficiency != "ok" else r2_skill(float(v)) for v in np.atleast_1d(r["r2"])]
        regression[f] = r
    return regression


def cohort_flow_kind(sources: Mapping[str, str]) -> str:
    """``pulsatile`` when every patient's field source is ``pulsatile``, ``steady`` when none is.

    An atlas never mixes the two: a steady flow (``instantaneous``, ``time_average``,
    ``simple_iterate_average``) and the cycle average of a pulsatile one are different quantities,
    and only pulsatile patients have the wall markers and phase fields.

    Parameters
    ----------
    sources : {patient id: field source}

    Returns
    -------
    {"steady", "pulsatile"}

    Raises
    ------
    VCSInputError
        Pulsatile and steady patients together: one line naming both groups and the fix.
    """
    pulsatile = [p for p, s in sources.items() if s == "pulsatile"]
    steady = [f"{p} ({s})" for p, s in sources.items() if s != "pulsatile"]
    if pulsatile and steady:
        raise VCSInputError(
            f"an atlas cannot mix pulsatile and steady flows: pulsatile {', '.join(pulsatile)}; "
            f"steady {', '.join(steady)}; run every patient with the same cfd.inlet.waveform setting"
        )
    return "pulsatile" if pulsatile else "steady"


def _phase_names(fields: Mapping[str, Mapping[str, Any]], patients: Sequence[str]) -> tuple[str, ...]:
    """The pulsatile patients' common ``phase_names`` (the first patient's order).

    Raises
    ------
    VCSInputError
        The patients were sampled at different phases.
    """
    names = {p: tuple(str(x) for x in np.atleast_1d(np.asarray(fields[p].get("phase_names", [])))) for p in patients}
    first = names[patients[0]]
    differ = [p for p in patients if set(names[p]) != set(first)]
    if differ:
        listed = "; ".join(f"{p} {', '.join(names[p]) or 'none'}" for p in [patients[0], *differ])
        raise VCSInputError(
            f"the pulsatile patients were sampled at different phases ({listed}); "
            "sample every patient at the same phases"
        )
    return first


def _check_fields(
    fields: Mapping[str, Mapping[str, Any]], patients: Sequence[str], flow_fields: Sequence[str], frame: str
) -> dict[str, tuple[int, ...]]:
    """{field: grid shape} of the flow fields, the same for every patient.

    Raises
    ------
    VCSInputError
        A patient lacks a field's array, its shape differs from the first patient's, or a field
        other than a wall field (U, p) holds non-finite values.
    """
    shapes: dict[str, tuple[int, ...]] = {}
    for f in flow_fields:
        key = field_key(f, frame)
        for pid in patients:
            if key not in fields[pid]:
                raise VCSInputError(
                    f"patient {pid}: the resampled fields have no '{key}' (for the {f} PCA); "
                    "resample the case with vcs.cfd.resample.sample_case"
                )
            a = np.asarray(fields[pid][key])
            shapes.setdefault(f, a.shape)
            if a.shape != shapes[f]:
                raise VCSInputError(
                    f"patient {pid}: field {key} has shape {a.shape}, patient {patients[0]} "
                    f"{shapes[f]}; resample every case on the same (n_tau, n_theta, n_rho) grid"
                )
            if not is_wall_field(f) and not np.isfinite(a).all():
                raise VCSInputError(
                    f"patient {pid}: field {key} has {int((~np.isfinite(a)).sum())} non-finite values; "
                    "resample the case (only the wall fields WSS, TAWSS, OSI, RRT, ECAP may be non-finite)"
                )
    return shapes


def _field_source(fields: Mapping[str, Any], status: Mapping[str, Any] | None) -> str:
    """What an included patient's flow is: ``time_average``, ``instantaneous`` (a steady state),
    ``pulsatile`` or, for a legacy status admitted by ``accept_relaxed``, ``simple_iterate_average``."""
    if status and status.get("converged") is False and status.get("converged_relaxed") is True:
        return "simple_iterate_average"
    return str(np.asarray(fields.get("field_source", "instantaneous")))


def project_model(atlas: Atlas, model: VesselModel, *, n_modes: int | None = None) -> dict[str, Any]:
    """Project a new vessel onto the atlas's shape modes.

    The model is first aligned rigidly (or by similarity, as the atlas) to the atlas's GPA mean wall
    grid by :func:`vcs.atlas.procrustes.procrustes` on its Eq. 8 wall grid (as the cohort was); its
    feature vector is then projected.

    Parameters
    ----------
    atlas : Atlas
    model : VesselModel
        Compatible with the atlas's models (same L, K, R).
    n_modes : int, optional
        Modes used (default all of the shape PCA's).

    Returns
    -------
    dict
        ``scores`` (k,) mm, ``scores_sigma`` (k,) (scores / sigma), ``reconstruction`` (d,) (feature
        vector from the first k modes), ``error`` (float, |a - a_hat| in mm over the whole
        vector), ``transform`` (RigidTransform, model -> atlas space), ``aligned_model``.

    Raises
    ------
    VCSInputError
        ``model`` is incompatible with the atlas (:func:`vcs.atlas.procrustes.check_compatible`).
    """
    template = atlas.aligned_models[0]
    model = model.with_n_knots(template.n_knots)
    check_compatible([template, model])
    n_tau, n_theta = atlas.options["n_tau_align"], atlas.options["n_theta_align"]
    T = procrustes(wall_grid_points(model, n_tau, n_theta), atlas.alignment_mean, scale=atlas.options["scale"])
    aligned = transform_model(model, T)
    a = aligned.feature_vector()
    k = atlas.shape.n_modes if n_modes is None else min(n_modes, atlas.shape.n_modes)
    s = atlas.shape.transform(a)[:k]
    a_hat = atlas.shape.mean + s @ atlas.shape.components[:k]
    return {
        "scores": s,
        "scores_sigma": s / atlas.shape.sigma[:k],
        "reconstruction": a_hat,
        "error": float(np.linalg.norm(a - a_hat)),
        "transform": T,
        "aligned_model": aligned,
    }


def atlas_summary(atlas: Atlas) -> dict[str, Any]:
    """The content of atlas.json.

    Parameters
    ----------
    atlas : Atlas

    Returns
    -------
    dict
        JSON-ready: patients included/excluded (with reasons), options, ``field_sources`` (which
        included patients' flow is a time average, which a steady state), ``time_average_errors``
        (the error bars of the time averages), alignment (with each
        patient's transform), explained variances, sigmas and scores of the shape and flow PCAs,
        and the leave-one-out R^2 of the shape -> flow regression (null where undefined) with its
        ``status`` (``insufficient_patients`` when leave-one-out cannot say anything) and the
        ``skill`` of each flow mode (``none`` for R^2 <= 0). The flow entries are keyed by the
        PCAs' names (:mod:`vcs.atlas.pca`): U, p, WSS, and for a pulsatile cohort (``flow_kind``,
        with its ``phase_names``) also TAWSS, OSI, log10_RRT, ECAP and ``phase/<name>/U|p|WSS``;
        ``wall_markers`` (null without markers) says how each marker's PCA treated non-finite
        values (``non_finite_rule``, ``transforms``, and per marker its record of
        :attr:`Atlas.wall_markers`); ``wall_fields`` (null without wall fields) the same for every
        wall field (WSS, the markers, the phases' WSS): ``non_finite_rule`` and per field its
        record of :attr:`Atlas.wall_fields` (cells left out, their fraction, the patients missing
        them, the patients' ostium cells).
    """
    first = next(iter(atlas.regression.values()), {})
    markers = None
    if atlas.wall_markers:
        markers = {
            "non_finite_rule": NON_FINITE_RULE,
            "transforms": {f: MARKER_TRANSFORMS[f] for f in atlas.wall_markers if f in MARKER_TRANSFORMS},
            "markers": atlas.wall_markers,
        }
    return {
        "patients_included": list(atlas.patients),
        "patients_excluded": [
            {"id": p, "stage": atlas.exclusion_stages.get(p, "solve"), "reason": r} for p, r in atlas.excluded.items()
        ],
        "options": atlas.options,
        "field_sources": atlas.field_sources,
        "flow_kind": atlas.flow_kind,
        "phase_names": list(atlas.phase_names),
        "wall_markers": markers,
        "wall_fields": {"non_finite_rule": NON_FINITE_RULE, "fields": atlas.wall_fields} if atlas.wall_fields else None,
        "time_average_errors": atlas.time_average_errors,
        "knots": atlas.alignment_report.get("knots"),
        "alignment": {
            **atlas.alignment_report,
            "transforms": {p: t.to_dict() for p, t in zip(atlas.patients, atlas.transforms)},
        },
        "shape_explained_variance": atlas.shape.explained_variance_ratio.tolist(),
        "shape_sigma": atlas.shape.sigma.tolist(),
        "shape_scores": {p: s.tolist() for p, s in zip(atlas.patients, atlas.shape.scores)},
        "flow_explained_variance": {f: pca.explained_variance_ratio.tolist() for f, pca in atlas.flow.items()},
        "flow_sigma": {f: pca.sigma.tolist() for f, pca in atlas.flow.items()},
        "flow_scores": {
            f: {p: s.tolist() for p, s in zip(atlas.patients, pca.scores)} for f, pca in atlas.flow.items()
        },
        "shape_to_flow_regression": {
            "method": "ridge on the first k standardised shape scores, alpha by inner leave-one-out; "
            "R^2 by outer leave-one-out (1 - PRESS / SS_tot)",
            "k_shape_scores": atlas.options["n_regression_scores"],
            "n_patients": len(atlas.patients),
            "status": first.get("status", "ok"),
            "status_reason": first.get("status_reason", ""),
            "loo_r2": {
                f: [None if not np.isfinite(v) else float(v) for v in r["r2"]] for f, r in atlas.regression.items()
            },
            "skill": {f: list(r.get("skill", [])) for f, r in atlas.regression.items()},
        },
    }
