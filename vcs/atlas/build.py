"""Build the cohort atlas on disk: compute it (:mod:`vcs.atlas.cohort`), write atlas.json and
atlas.npz, and the figures (:mod:`vcs.atlas.plots`).

The one module that uses both the atlas statistics and its plotting; the plotting module is
imported only when figures are asked for.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vcs.atlas.cohort import Atlas, atlas_summary, compute_atlas
from vcs.atlas.pca import field_slug

if TYPE_CHECKING:
    from vcs.vessel import VesselModel

log = logging.getLogger("vcs.atlas")  # the logger name of the former vcs/atlas.py: same log lines


def build_atlas(
    models: Mapping[str, VesselModel],
    fields: Mapping[str, Mapping[str, Any] | str | Path],
    statuses: Mapping[str, Mapping[str, Any] | None],
    out_dir: str | Path,
    *,
    n_modes: int = 3,
    figures: bool = True,
    figure_dir: str | Path | None = None,
    figure_scale: int = 1,
    **options: Any,
) -> Atlas:
    """Compute the atlas (:func:`vcs.atlas.cohort.compute_atlas`) and write it to ``out_dir``.

    Writes ``atlas.json`` (patients included/excluded with stages and reasons, explained
    variances, scores, regression R^2 with its status and skill), ``atlas.npz`` (every PCA's mean,
    modes, sigma, scores, as ``shape_*`` and ``flow_{field}_*`` with ``{field}`` the
    :func:`vcs.atlas.pca.field_slug` of the flow field, e.g. ``flow_phase_peak_systole_U_mean``,
    and ``flow_{field}_support`` of a wall field that left cells out (mean and modes NaN there:
    :data:`vcs.atlas.cohort.NON_FINITE_RULE`, recorded in atlas.json ``wall_fields``); the field grid; the
    ``phase_names`` of a pulsatile cohort) and, with ``figures``, the VTP/VTU files of
    :func:`vcs.atlas.plots.write_atlas_figures` in ``out_dir`` and its PNGs in ``figure_dir``.
    A pulsatile cohort's fields (cycle averages, wall markers, phase fields) go through as they
    are: which PCAs an atlas has is decided by :func:`vcs.atlas.cohort.compute_atlas`.

    Parameters
    ----------
    models : {patient id: VesselModel}
    fields : {patient id: dict of resampled arrays, or path of a ``fields.npz``}
    statuses : {patient id: status dict or None}
        See :func:`vcs.atlas.cohort.status_exclusion`.
    out_dir : str or Path
        Output directory (created when missing).
    n_modes : int
        Modes kept per PCA.
    figures : bool
        Also write the figures; atlas.json then lists them (``files``, relative to ``out_dir``),
        the 3-D ``renderer`` and the flow figures' ``colour_limits``.
    figure_dir : str or Path, optional
        Directory of the PNGs (default ``out_dir/figures``); each figure is written once.
    figure_scale : int
        Pixel scale of the 3-D figures (1: 340 x 400 pixels per panel, for the screen; 2-4 for
        print: text and lines scale with it).
    **options
        Further keyword arguments of :func:`vcs.atlas.cohort.compute_atlas` (e.g. ``reports``,
        the fit reports).

    Returns
    -------
    Atlas
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    loaded: dict[str, Mapping[str, Any]] = {}
    for pid, f in fields.items():
        if isinstance(f, (str, Path)):
            with np.load(f) as z:
                loaded[pid] = {k: z[k] for k in z.files}
        else:
            loaded[pid] = f
    atlas = compute_atlas(models, loaded, statuses, n_modes=n_modes, **options)
    summary = atlas_summary(atlas)
    arrays: dict[str, Any] = {
        **atlas.shape.arrays("shape"),
        **{k: v for f, p in atlas.flow.items() for k, v in p.arrays(f"flow_{field_slug(f)}").items()},
    }
    arrays.update({f"grid_{k}": v for k, v in atlas.grid.items()})
    if atlas.phase_names:
        arrays["phase_names"] = np.array(atlas.phase_names)
    np.savez_compressed(out / "atlas.npz", **arrays)
    if figures:
        from vcs.atlas.plots import COLOUR_PERCENTILES, FIELD_LIMIT_PAD, write_atlas_figures
        from vcs.atlas.plots3d import write_listed_3d

        written = write_atlas_figures(atlas, out, png_dir=figure_dir)
        written["figure_seconds"] = write_listed_3d(
            atlas,
            written["mean_model"],
            written["png_dir"],
            out,
            written["files"],
            grid=written["grid"],
            scale=figure_scale,
        )
        summary["files"], summary["renderer"] = written["files"], written["renderer"]
        summary["colour_limits"] = {
            "percentiles": list(COLOUR_PERCENTILES),
            "shared_by": "every figure of a flow field, 3-D and flat: the widest of the percentile "
            "ranges of its figures' values (the mean's; each mode's mean - 2 sigma, mean, mean + 2 "
            f"sigma; of a wall field: its values on the wall), widened by {100 * FIELD_LIMIT_PAD:g} % at "
            "either end (not below 0 when the lower percentile is not)",
            "limits": written["colour_limits"],
        }
        # render times are not written into atlas.json (it holds no timings: a rerun or a SLURM run
        # of the same cohort gives the same file); the log has them
        seconds = written["figure_seconds"]
        if seconds:
            log.info("3-D figures: %d rendered in %.1f s", len(seconds), sum(seconds.values()))
    (out / "atlas.json").write_text(json.dumps(summary, indent=1, sort_keys=True) + "\n")
    log.info("atlas of %d patients (%d excluded) written to %s", len(atlas.patients), len(atlas.excluded), out)
    return atlas
