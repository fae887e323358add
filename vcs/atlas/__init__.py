"""Statistical atlas of vessel shape and flow (paper Section 2.3: coregistration, PCA).

The pieces, each a plain function or a small frozen value object:

* :mod:`vcs.atlas.procrustes`: :func:`procrustes` / :func:`generalized_procrustes`, rigid
  (optionally similarity) alignment of corresponding point sets (Section 2.3.2) on the Eq. 8 wall
  grid (:func:`wall_grid_points`); :func:`transform_model`, :func:`align_models`.
* :mod:`vcs.atlas.pca`: :class:`PCA` (Section 2.3.3) of feature vectors (:func:`shape_matrix`) or
  of resampled flow fields (:func:`flow_vector`; of a pulsatile cohort also the
  :data:`WALL_MARKERS` and the phase fields, :func:`pulsatile_fields`); a wall field's cells
  missing for any patient (NaN at a side branch's ostium, a diverging RRT; :func:`is_wall_field`)
  are left out of its PCA and recorded, NaN in its mean and modes (:data:`NON_FINITE_RULE`);
  :func:`mode_deformation` (paper Fig. 7); :func:`top_variation_mask`.
* :mod:`vcs.atlas.regression`: :func:`ridge_loo` (beyond the paper), shape scores -> flow scores
  ridge regression with leave-one-out cross-validated R^2; :func:`loo_sufficiency` (too few
  patients to say anything) and :func:`r2_skill` (``none`` for R^2 <= 0).
* :mod:`vcs.atlas.cohort`: :func:`patient_exclusion` (stage and reason from the fit report,
  :func:`status_exclusion`, the fields), :func:`cohort_flow_kind` (steady or pulsatile, never
  both), :func:`compute_atlas` (the whole cohort pipeline, arrays only), :func:`project_model`,
  :func:`atlas_summary`.
* :mod:`vcs.atlas.build`: :func:`build_atlas` writes ``atlas.json``, ``atlas.npz`` and the figures.
* :mod:`vcs.atlas.plots`: the figures and geometry files (pyvista, matplotlib).

The statistics modules (procrustes, pca, regression, cohort) are pure numpy/scipy and never import
:mod:`vcs.atlas.plots`; plotting imports them, and :mod:`vcs.atlas.build` (imported here) imports
the plotting module only when it writes figures.
"""

from vcs.atlas.build import build_atlas
from vcs.atlas.cohort import (
    NON_FINITE_RULE,
    STAGES,
    Atlas,
    atlas_summary,
    cohort_flow_kind,
    compute_atlas,
    fit_exclusion,
    patient_exclusion,
    project_model,
    status_exclusion,
    status_stage,
)
from vcs.atlas.pca import (
    FLOW_FIELDS,
    PCA,
    PHASE_QUANTITIES,
    SHAPE_BLOCKS,
    VECTOR_FIELDS,
    WALL_MARKERS,
    field_key,
    field_slug,
    flow_vector,
    is_wall_field,
    mode_deformation,
    phase_field,
    pulsatile_fields,
    shape_matrix,
    top_variation_mask,
)
from vcs.atlas.procrustes import (
    TWO_PI,
    RigidTransform,
    align_models,
    check_compatible,
    generalized_procrustes,
    procrustes,
    transform_model,
    wall_grid,
    wall_grid_points,
)
from vcs.atlas.regression import DEFAULT_ALPHAS, loo_sufficiency, r2_skill, ridge_loo

__all__ = [
    "DEFAULT_ALPHAS",
    "FLOW_FIELDS",
    "NON_FINITE_RULE",
    "PCA",
    "PHASE_QUANTITIES",
    "SHAPE_BLOCKS",
    "STAGES",
    "TWO_PI",
    "VECTOR_FIELDS",
    "WALL_MARKERS",
    "Atlas",
    "RigidTransform",
    "align_models",
    "atlas_summary",
    "build_atlas",
    "check_compatible",
    "cohort_flow_kind",
    "compute_atlas",
    "field_key",
    "field_slug",
    "flow_vector",
    "is_wall_field",
    "generalized_procrustes",
    "loo_sufficiency",
    "mode_deformation",
    "patient_exclusion",
    "phase_field",
    "procrustes",
    "project_model",
    "pulsatile_fields",
    "r2_skill",
    "ridge_loo",
    "shape_matrix",
    "status_exclusion",
    "status_stage",
    "fit_exclusion",
    "top_variation_mask",
    "transform_model",
    "wall_grid",
    "wall_grid_points",
]
