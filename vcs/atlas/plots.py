"""Atlas figures and geometry files: VTP/VTU (pyvista) and PNG (pyvista off-screen, matplotlib Agg).

Imports the atlas statistics (:mod:`vcs.atlas.procrustes`, :mod:`vcs.atlas.pca`,
:mod:`vcs.atlas.cohort`); they never import this module.

Everything renders headless. 3-D views use pyvista off-screen; when VTK cannot open an off-screen
render window (no OSMesa/EGL build, no display), the same figure is drawn with matplotlib as a 2-D
longitudinal section (tau, signed rho) and the fallback is recorded in the returned file list.

Files written by :func:`write_atlas_figures` into ``out_dir`` (VTP/VTU, all in mm, atlas space)
and its ``png_dir`` (PNG, default ``out_dir/figures``; each figure is written once):

* ``shape_mean.vtp``: the mean shape, wall surface (Eq. 8) + centerline polyline;
* ``shape_mode{k}_{plus,minus}2sigma.vtp``: mean +- 2 sigma along shape mode k, with point data
  ``centerline_displacement`` (|delta c(tau)|), ``radius_change`` (delta rho_w), ``displacement``;
* ``shape_mean.png``: the mean wall radius map and cross-sections near the inlet;
* ``shape_mode{k}_deformation.png``: paper Fig. 7 (|delta c| vs tau, delta rho_w over (tau, theta));
* ``explained_variance.png``: shape and flow explained variance per mode (a pulsatile cohort's in
  panels: shape and cycle averages, wall markers, one per phase);
* ``flow_mean.vtu``: the mean of every flow field (U, p, WSS; of a pulsatile cohort also TAWSS,
  OSI, log10_RRT, ECAP and the phase fields) on the mean shape's grid; per field and mode the
  mode's +-2 sigma fields and a ``{field}_mode{k}_top20`` mask (cells in the top 20 % of the
  variation). Array names use :func:`vcs.atlas.pca.field_slug` (``phase_peak_systole_U_mean``);
  wall fields are on the rho_n = 1 layer (zero inside); a wall field's cells left out of its PCA
  (missing for some patient: a side branch's ostium, a diverging RRT;
  :data:`vcs.atlas.cohort.NON_FINITE_RULE`) are NaN there, and grey in the PNGs (:data:`NAN_COLOUR`,
  with a note saying so);
* ``flow_{field}_mode{k}.png`` (field slug, e.g. ``flow_phase_peak_systole_U_mode1.png``):
  theta-clipped lumen views of U, p and the phase U, p, and (tau, theta) maps of the wall fields
  (WSS magnitude, the wall markers, the phase WSS: :func:`wall_map_png`, e.g.
  ``flow_TAWSS_mode1.png``): mean - 2 sigma, mean, mean + 2 sigma, and the top-20 % region. Every
  figure of a field (these and its 3-D ones) has one colour scale: the widest of its figures'
  2nd-98th percentiles of their values (:func:`field_limits`, :func:`robust_limits`: one
  outlying patient, whose mode sends a few cells far off, does not darken every panel); values
  beyond are drawn at the ends of the scale;
* the 3-D figures of :mod:`vcs.atlas.plots3d` (``*_3d.png``: the mean shape, the shape modes, each
  flow field's mean and modes on the wall or in the clipped lumen, seen from the mean shape's own
  frame), unless no off-screen render window can be opened.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vcs.atlas.cohort import Atlas
from vcs.atlas.pca import (
    PCA,
    WALL_MARKERS,
    field_phase,
    field_quantity,
    field_slug,
    is_vector_field,
    mode_deformation,
    top_variation_mask,
)
from vcs.atlas.procrustes import TWO_PI
from vcs.grid import from_vcs_components, grid_points, grid_to_vtk, local_frame

#: Colour of NaN values (wall cells left out of a PCA) in every figure, and the note that says so.
NAN_COLOUR = "#b3b3b3"  # matplotlib "0.7"; pyvista takes no grey level
LEFT_OUT_NOTE = "grey: left out of the PCA (missing for a patient)"

if TYPE_CHECKING:
    import pyvista

    from vcs.vessel import VesselModel

PathLike = str | Path

log = logging.getLogger(__name__)

#: Percentiles of a flow figure's values that set its (shared) colour limits.
COLOUR_PERCENTILES = (2.0, 98.0)
#: Margin added to a flow field's colour range at either end (fraction of its width): :func:`field_limits`.
FIELD_LIMIT_PAD = 0.05
#: Percentiles of a mean figure's own colour limits (:func:`mean_limits`): one field, no modes, its
#: peak (p on an arch's outer curve) is a large part of the picture.
MEAN_PERCENTILES = (1.0, 99.0)
#: Width of a label character relative to the font size (digits, '-', '.' of VTK's Arial: ~0.55).
_CHAR_WIDTH = 0.6
PANEL_PX = (420, 520)  # width, height of one panel of a clipped view
LABEL_FONT_PX = 14
TITLE_FONT_PT = 9  # panel titles (pyvista font size)
NOTE_FONT_PT = 7


def text_font_file() -> str:
    """The TrueType file of the 3-D figures' titles: matplotlib's DejaVu Sans (as the flat
    figures), which has the divides sign of :func:`vtk_text` (VTK's built-in Arial has not)."""
    from matplotlib import font_manager

    return str(font_manager.findfont("DejaVu Sans", fallback_to_default=False))


def vtk_text(text: str) -> str:
    """``text`` as VTK draws it faithfully: '|' replaced by U+2223 (the divides sign, drawn alike).
    VTK's text renderer takes '|' for a column separator (MathText tables): ``|U| (m/s)`` came
    out as ``U`` and a raised ``(m/s)``."""
    return text.replace("|", "\u2223")


BAR_Y, BAR_HEIGHT = 0.05, 0.08  # colour bar position and height (fractions of the panel)


def _plt() -> Any:
    """matplotlib.pyplot with the off-screen Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ---------------------------------------------------------------------------------------------
# Shapes
# ---------------------------------------------------------------------------------------------
def shape_polydata(
    model: VesselModel, *, n_tau: int = 101, n_theta: int = 48, point_arrays: dict[str, np.ndarray] | None = None
) -> pyvista.PolyData:
    """Wall surface (Eq. 8 on a (tau, theta) grid, seam closed) plus the centerline as one PolyData.

    Parameters
    ----------
    model : VesselModel
    n_tau, n_theta : int
        Wall grid: tau in [0, 1] (ends included), theta = 2 pi j / n_theta.
    point_arrays : dict of (n_tau, n_theta[, ...]) arrays, optional
        Point data on the wall grid; the centerline points get 0. Point data ``tau`` and
        ``theta`` are always added.

    Returns
    -------
    pyvista.PolyData
        Points in mm: the wall quads, then the n_tau centerline points as one polyline.
    """
    import pyvista as pv

    tau = np.linspace(0.0, 1.0, n_tau)
    theta = TWO_PI * np.arange(n_theta) / n_theta
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    arrays = {"tau": T, "theta": TH, **(point_arrays or {})}
    wall = grid_to_vtk(model.surface_points(T, TH), arrays)
    line = pv.lines_from_points(model.vcs.curve(tau))
    for k, v in wall.point_data.items():
        line.point_data[k] = np.zeros((line.n_points, *np.shape(v)[1:]))
    line.point_data["tau"] = tau
    return wall.append_polydata(line)


def write_shape_files(
    pca: PCA,
    template: VesselModel,
    out_dir: PathLike,
    *,
    n_modes: int | None = None,
    n_sigma: float = 2.0,
    png_dir: PathLike | None = None,
) -> dict[str, str]:
    """Mean shape and mean +- n_sigma shapes (VTP) and the Fig. 7 deformation PNG per mode.

    Parameters
    ----------
    pca : PCA
        Shape PCA of feature vectors.
    template : VesselModel
        Rebuilds models from feature vectors (knots, K, R, frame rule).
    out_dir : str or Path
        Existing output directory.
    n_modes : int, optional
        Modes written (default all).
    n_sigma : float
        The +- shapes are mean +- n_sigma sigma_m u_m.
    png_dir : str or Path, optional
        Existing directory of the PNGs (default ``out_dir``).

    Returns
    -------
    dict
        {what: file name relative to ``out_dir``}: ``shape_mean`` (VTP), ``shape_mean_png`` and per
        mode k (1-based) ``shape_mode{k}_plus``, ``shape_mode{k}_minus`` (VTP, mm) and
        ``shape_mode{k}_deformation`` (PNG).
    """
    from vcs.vessel import VesselModel

    out = Path(out_dir)
    pngs = Path(png_dir) if png_dir is not None else out
    files = {"shape_mean": "shape_mean.vtp"}
    mean = VesselModel.from_feature_vector(pca.mean, template)
    shape_polydata(mean).save(str(out / files["shape_mean"]))
    mean_shape_png(mean, pngs / "shape_mean.png")
    files["shape_mean_png"] = _relative(pngs / "shape_mean.png", out)
    for k in range(min(n_modes or pca.n_modes, pca.n_modes)):
        for sign, tag in ((1.0, "plus"), (-1.0, "minus")):
            d = mode_deformation(pca, template, k, n_sigma=sign * n_sigma)
            T, TH = np.meshgrid(d["tau"], d["theta"], indexing="ij")
            disp = np.linalg.norm(d["mode_model"].surface_points(T, TH) - mean.surface_points(T, TH), axis=-1)
            arrays = {
                "centerline_displacement": np.repeat(d["centerline_displacement"][:, None], len(d["theta"]), 1),
                "radius_change": d["radius_change"],
                "displacement": disp,
            }
            name = f"shape_mode{k + 1}_{tag}{n_sigma:g}sigma.vtp"
            shape_polydata(d["mode_model"], n_tau=len(d["tau"]), n_theta=len(d["theta"]), point_arrays=arrays).save(
                str(out / name)
            )
            files[f"shape_mode{k + 1}_{tag}"] = name
            if sign > 0:
                png = pngs / f"shape_mode{k + 1}_deformation.png"
                deformation_png(
                    d,
                    png,
                    title=f"shape mode {k + 1} (+{n_sigma:g} sigma, "
                    f"{100 * pca.explained_variance_ratio[k]:.1f}% variance)",
                )
                files[f"shape_mode{k + 1}_deformation"] = _relative(png, out)
    return files


def _relative(path: Path, root: Path) -> str:
    """``path`` relative to ``root`` when inside it (POSIX separators), else absolute."""
    try:
        return path.resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        return str(path.resolve())


def sinus_lobes(wall: Any, *, taus: np.ndarray | None = None) -> float:
    """Largest relative amplitude of the three-fold harmonic of rho_w(theta) near the inlet.

    The three sinuses of Valsalva of an aortic root make the cross-sections three-lobed (~3.5 % of
    the radius on the demo phantoms' mean shape; < 0.5 % elsewhere and on plain tubes).

    Parameters
    ----------
    wall : callable (tau, theta) -> rho_w
        The wall model (e.g. ``VesselModel.fitted_wall()``).
    taus : (m,) float, optional
        Sections searched (default 16 in tau in [0, 0.15]).

    Returns
    -------
    float
        max over the sections of |3rd Fourier coefficient| / mean radius.
    """
    th = np.linspace(0.0, TWO_PI, 256, endpoint=False)
    best = 0.0
    for t in np.linspace(0.0, 0.15, 16) if taus is None else taus:
        r = np.asarray(wall(np.full_like(th, t), th), float)
        best = max(best, float(2 * np.abs(np.fft.rfft(r)[3]) / len(r) / max(r.mean(), 1e-12)))
    return best


#: Three-fold harmonic (relative) above which the inlet is called an aortic root (:func:`sinus_lobes`).
ROOT_LOBES = 0.02


def mean_shape_png(
    mean: VesselModel, path: PathLike, *, inlet_taus: tuple[float, ...] = (0.0, 0.04, 0.07, 0.1, 0.2)
) -> None:
    """PNG of the mean shape's wall radius: a map and cross-sections near the inlet
    (:func:`mean_shape_figure`).

    Parameters
    ----------
    mean : VesselModel
        The mean shape (a wall model is needed).
    path : str or Path
        Output PNG.
    inlet_taus : tuple of float
        tau of the cross-sections, in [0, 1].
    """
    plt = _plt()
    fig = mean_shape_figure(mean, inlet_taus=inlet_taus)
    fig.savefig(path)
    plt.close(fig)


def mean_shape_figure(mean: VesselModel, *, inlet_taus: tuple[float, ...] = (0.0, 0.04, 0.07, 0.1, 0.2)) -> Any:
    """matplotlib Figure of the mean shape's wall radius: a map and cross-sections near the inlet.

    The wall radius rho_w(tau, theta) (mm) as a map over (tau, theta), and the cross-sections at
    ``inlet_taus`` as polar curves. The cross-sections are said to be near an aortic root only
    when they show its three sinus lobes (:func:`sinus_lobes` above :data:`ROOT_LOBES`); otherwise
    near the inlet (tau = 0), whatever the vessel is.

    Parameters
    ----------
    mean : VesselModel
        The mean shape (a wall model is needed).
    inlet_taus : tuple of float
        tau of the cross-sections, in [0, 1].

    Returns
    -------
    matplotlib.figure.Figure
        Axes 0: the map; axes 2: the polar cross-sections (axes 1 is the map's colour bar).
    """
    from matplotlib.ticker import MaxNLocator

    plt = _plt()
    th = np.linspace(0.0, TWO_PI, 181)
    tau = np.linspace(0.0, 1.0, 201)
    wall = mean.fitted_wall()
    R = wall(tau[:, None], th[None, :])
    fig = plt.figure(figsize=(10, 3.8), dpi=110)
    ax = fig.add_subplot(1, 2, 1)
    centre, half = 0.5 * (R.max() + R.min()), max(0.5 * np.ptp(R), 1e-3 * abs(R.mean()))  # no round-off noise map
    im = ax.imshow(
        R.T,
        origin="lower",
        aspect="auto",
        extent=(0, 1, 0, TWO_PI),
        cmap="viridis",
        vmin=centre - half,
        vmax=centre + half,
    )
    ax.set_xlabel("tau")
    ax.set_ylabel("theta (rad)")
    ax.set_title("mean shape: wall radius rho_w")
    cb = fig.colorbar(im, ax=ax, label="rho_w (mm)")
    cb.locator = MaxNLocator(5)
    cb.update_ticks()
    axp = fig.add_subplot(1, 2, 2, projection="polar")
    radii = [wall(np.full_like(th, t), th) for t in inlet_taus]
    for t, r in zip(inlet_taus, radii):
        axp.plot(th, r, label=f"tau = {t:g}")
    axp.set_rmin(0.8 * min(r.min() for r in radii))  # an offset radial axis shows the lobes
    axp.yaxis.set_major_locator(MaxNLocator(3))  # few radial labels: they sit in a narrow band
    axp.set_rlabel_position(112.5)
    axp.tick_params(labelsize=7)
    lobes = sinus_lobes(wall)
    where = (
        f"near the inlet: an aortic root\n(three sinus lobes, {100 * lobes:.1f} % of the radius)"
        if lobes > ROOT_LOBES
        else f"near the inlet (tau {min(inlet_taus):g}-{max(inlet_taus):g})"
    )
    axp.set_title(f"rho_w (mm) of cross-sections {where}", fontsize=9)
    axp.legend(fontsize=7, loc="lower left", bbox_to_anchor=(1.05, 0.0))
    fig.tight_layout()
    return fig


def deformation_png(d: dict[str, Any], path: PathLike, *, title: str = "") -> None:
    """PNG of paper Fig. 7: centerline displacement |delta c(tau)| and radius change delta rho_w(tau, theta).

    Parameters
    ----------
    d : dict
        A :func:`vcs.atlas.pca.mode_deformation` result (mm).
    path : str or Path
        Output PNG.
    title : str
        Figure title (default ``"mode <m + 1>"``).
    """
    plt = _plt()
    fig, (a0, a1) = plt.subplots(2, 1, figsize=(7, 5.5), dpi=110, sharex=True)
    a0.plot(d["tau"], d["centerline_displacement"], "k-")
    a0.set_ylabel("|delta c(tau)| (mm)")
    a0.set_title(title or f"mode {d['mode'] + 1}")
    lim = max(float(np.abs(d["radius_change"]).max()), 1e-12)
    im = a1.imshow(
        d["radius_change"].T,
        origin="lower",
        aspect="auto",
        cmap="RdBu_r",
        vmin=-lim,
        vmax=lim,
        extent=(0, 1, 0, TWO_PI),
    )
    a1.set_xlabel("tau")
    a1.set_ylabel("theta (rad)")
    fig.colorbar(im, ax=[a0, a1], label="delta rho_w (mm)", shrink=0.6)
    fig.savefig(path)
    plt.close(fig)


def variance_groups(atlas: Atlas) -> list[tuple[str, dict[str, np.ndarray]]]:
    """The panels of :func:`explained_variance_png`: (title, {series: explained variance ratio}).

    One untitled panel of the shape and every flow PCA for a steady cohort; for a pulsatile one,
    the shape with the cycle-averaged U, p, WSS (and any other field), the wall markers, and one
    panel per phase (its U, p, WSS).
    """
    flow = {f: p.explained_variance_ratio for f, p in atlas.flow.items()}
    main = {"shape": atlas.shape.explained_variance_ratio}
    if atlas.flow_kind != "pulsatile":
        return [("", {**main, **flow})]
    markers = {f: v for f, v in flow.items() if f in WALL_MARKERS}
    phases: dict[str, dict[str, np.ndarray]] = {}
    for f, v in flow.items():
        phase = field_phase(f)
        if phase is not None:
            phases.setdefault(phase, {})[field_quantity(f)] = v
        elif f not in markers:
            main[f] = v
    groups = [("shape and cycle-averaged flow", main)]
    if markers:
        groups.append(("wall markers", markers))
    groups += [(f"phase {ph}", series) for ph, series in phases.items()]
    return groups


def explained_variance_png(atlas: Atlas, path: PathLike) -> None:
    """PNG bar chart of the explained variance (%) per mode of the shape PCA and each flow PCA,
    in the panels of :func:`variance_groups`.

    Parameters
    ----------
    atlas : Atlas
    path : str or Path
        Output PNG.
    """
    plt = _plt()
    groups = variance_groups(atlas)
    size = (6, 3.5) if len(groups) == 1 else (7, 0.5 + 2.6 * len(groups))
    fig, axes = plt.subplots(len(groups), 1, figsize=size, dpi=110, squeeze=False)
    for ax, (title, series) in zip(axes[:, 0], groups):
        w = 0.8 / len(series)
        for i, (name, v) in enumerate(series.items()):
            ax.bar(np.arange(1, len(v) + 1) + (i - (len(series) - 1) / 2) * w, 100 * v, w, label=name)
        ax.set_xlabel("mode")
        ax.set_ylabel("explained variance (%)")
        ax.set_xticks(np.arange(1, atlas.shape.n_modes + 1))
        if title:  # the panels of a pulsatile cohort: legend beside the bars, which reach 100 %
            ax.set_title(title, fontsize=9)
            ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
        else:
            ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Flow
# ---------------------------------------------------------------------------------------------
def _field_cartesian(vec: np.ndarray, name: str, shape: tuple, frame: np.ndarray, flow_frame: str) -> np.ndarray:
    a = np.asarray(vec).reshape(shape)
    if is_vector_field(name) and flow_frame == "vcs":
        a = from_vcs_components(a, frame)
    return a


def _scalar(a: np.ndarray) -> np.ndarray:
    """Magnitude of a (n_tau, n_theta, n_rho, 3) vector field; scalars pass through."""
    return np.linalg.norm(a, axis=-1) if a.ndim == 4 else a


def flow_grid(atlas: Atlas, mean_model: VesselModel) -> tuple[pyvista.UnstructuredGrid, dict[str, Any]]:
    """The flow atlas on the mean shape's (tau, theta, rho_n) grid as a pyvista UnstructuredGrid (mm).

    Surface fields (WSS (n_tau, n_theta, 3), the wall markers (n_tau, n_theta)) are put on the
    rho_n = 1 layer (zero inside). Vector fields are Cartesian (converted from VCS components when
    the atlas used them).

    Parameters
    ----------
    atlas : Atlas
        With flow PCAs and the field grid.
    mean_model : VesselModel
        The mean shape, whose grid points carry the fields.

    Returns
    -------
    grid : pyvista.UnstructuredGrid
        Point data ``{field}_mean``, ``{field}_mode{k}_plus2sigma``, ``{field}_mode{k}_minus2sigma``,
        ``{field}_mode{k}_top20`` (uint8 mask) and ``rho_n``, ``{field}`` the field's
        :func:`vcs.atlas.pca.field_slug`.
    info : dict
        ``points`` ((n_tau, n_theta, n_rho, 3) float, mm) and ``panels``: {field: {"mean": array,
        "modes": [(minus, plus, top20 mask) per mode]}}, arrays of shape (n_tau, n_theta, n_rho[, 3]).
    """
    tau, theta, rho_n = atlas.grid["tau"], atlas.grid["theta"], atlas.grid["rho_n"]
    pts, _ = grid_points(mean_model, tau, theta, rho_n)
    frame = local_frame(mean_model, tau, theta)
    n_rho = len(rho_n)
    arrays, panels = {}, {}
    for f, pca in atlas.flow.items():
        shape = atlas.field_shapes[f]
        ff = atlas.options["flow_frame"]

        def vol(a: np.ndarray) -> np.ndarray:
            if a.shape[:3] != pts.shape[:3]:  # wall field (n_tau, n_theta[, 3]) -> rho_n = 1 layer
                full = np.zeros((*a.shape[:2], n_rho, *a.shape[2:]))
                full[:, :, -1] = a
                return full
            return a

        name = field_slug(f)
        mean = vol(_field_cartesian(pca.mean, f, shape, frame, ff))
        arrays[f"{name}_mean"] = mean
        modes: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        panels[f] = {"mean": mean, "modes": modes}
        for k in range(pca.n_modes):
            plus = vol(_field_cartesian(pca.mode_sample(k, 2.0), f, shape, frame, ff))
            minus = vol(_field_cartesian(pca.mode_sample(k, -2.0), f, shape, frame, ff))
            mask = top_variation_mask(pca, k, shape, vector=is_vector_field(f))
            if mask.shape != pts.shape[:3]:
                full = np.zeros((*mask.shape, n_rho), bool)
                full[:, :, -1] = mask
                mask = full
            arrays[f"{name}_mode{k + 1}_plus2sigma"] = plus
            arrays[f"{name}_mode{k + 1}_minus2sigma"] = minus
            arrays[f"{name}_mode{k + 1}_top20"] = mask.astype(np.uint8)
            modes.append((minus, plus, mask))
    arrays["rho_n"] = np.broadcast_to(rho_n, pts.shape[:3])
    return grid_to_vtk(pts, arrays), {"points": pts, "panels": panels}


def _half(a: np.ndarray, theta: np.ndarray) -> np.ndarray:
    keep = theta <= np.pi + 1e-9
    return a[:, keep]


def robust_limits(arrays: Any, percentiles: tuple[float, float] = COLOUR_PERCENTILES) -> tuple[float, float]:
    """Colour limits shared by several panels: percentiles of all their finite values together.

    Parameters
    ----------
    arrays : iterable of arrays
        The values of every panel that shares the scale.
    percentiles : (lo, hi)
        Default the 2nd and 98th percentile (:data:`COLOUR_PERCENTILES`).

    Returns
    -------
    (float, float)
        lo < hi (widened around a constant value; (0, 1) without finite values).
    """
    v = np.concatenate([np.ravel(np.asarray(a, float)) for a in arrays])
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0
    lo, hi = (float(x) for x in np.percentile(v, percentiles))
    if not hi > lo:
        pad = max(abs(lo), 1.0) * 1e-6
        lo, hi = lo - pad, hi + pad
    return lo, hi


def colour_bar_labels(lo: float, hi: float, *, width_px: float, font_px: float = LABEL_FONT_PX) -> tuple[str, int]:
    """printf format and number of labels (at most 5) of a horizontal colour bar whose labels do
    not overlap: VTK spaces them evenly over ``width_px``, so the widest label (at
    :data:`_CHAR_WIDTH` x ``font_px`` per character) plus a 25 % gap must fit the spacing.

    Parameters
    ----------
    lo, hi : float
        Colour limits.
    width_px : float
        Width of the bar in pixels.
    font_px : float
        Label font size in pixels.

    Returns
    -------
    (str, int)
        e.g. ``("%.1f", 5)``; at least 2 labels.
    """
    for n in range(5, 1, -1):
        ticks = np.linspace(lo, hi, n)
        big = max(abs(lo), abs(hi))
        if big >= 1e5 or big < 1e-3:
            fmt = "%.1e"
        else:
            step = (hi - lo) / (n - 1)
            fmt = f"%.{max(0, -int(np.floor(np.log10(step))))}f"
        widest = max(len(fmt % t) for t in ticks) * _CHAR_WIDTH * font_px
        if 1.25 * widest <= width_px / (n - 1):
            return fmt, n
    return fmt, 2


def clipped_view_plotter(
    points: np.ndarray,
    theta: np.ndarray,
    panels: list[tuple[str, np.ndarray, str]],
    *,
    label: str,
    clim: tuple[float, float],
    view_normal: np.ndarray | None = None,
    note: str = "",
) -> pyvista.Plotter:
    """The off-screen pyvista Plotter of :func:`clipped_view_png` (one subplot per panel).

    The panels whose colour map is the first panel's share ``clim`` and one colour bar titled
    ``label`` (in the middle one of them); the other panels (the top-20 % mask) have none: their
    title says what the colour means.

    Raises
    ------
    Exception
        Whatever VTK raises when no off-screen render window can be opened.
    """
    import pyvista as pv

    pv.OFF_SCREEN = True
    w, h = PANEL_PX
    pts = _half(points, theta)
    pl = pv.Plotter(off_screen=True, shape=(1, len(panels)), window_size=[w * len(panels), h])
    centre = points.reshape(-1, 3).mean(axis=0)
    if view_normal is None:
        view_normal = np.array([0.0, 0.0, 1.0])
    shared = [i for i, (_, _, c) in enumerate(panels) if c == panels[0][2]]
    bar_panel = shared[len(shared) // 2]
    bar_width = 0.8
    fmt, n_labels = colour_bar_labels(*clim, width_px=bar_width * w)
    for i, (title, values, cmap) in enumerate(panels):
        pl.subplot(0, i)
        g = grid_to_vtk(pts, {label: _half(values, theta)}, close_theta=False)
        surf = g.extract_surface(algorithm="dataset_surface")
        pl.add_mesh(
            surf,
            scalars=label,
            cmap=cmap,  # type: ignore[arg-type]  # any matplotlib colour-map name
            clim=clim if i in shared else (0.0, 1.0),
            nan_color=NAN_COLOUR,
            show_scalar_bar=i == bar_panel,
            scalar_bar_args={
                "title": label,
                "vertical": False,
                "width": bar_width,
                "position_x": (1.0 - bar_width) / 2,
                "position_y": BAR_Y,
                "height": BAR_HEIGHT,
                "n_labels": n_labels,
                "fmt": fmt,
                "label_font_size": LABEL_FONT_PX,
            },
        )
        if i == bar_panel:
            # VTK draws a horizontal bar's title over its middle label: labels below the bar,
            # the title as a text of its own above it
            bar = pl.scalar_bars[label]
            bar.SetTitle("")
            bar.SetTextPositionToPrecedeScalarBar()
            text = pl.add_text(
                vtk_text(label),
                position=(0.5, BAR_Y + BAR_HEIGHT + 0.005),
                viewport=True,
                font_size=TITLE_FONT_PT,
                name="colour_bar_title",
                font_file=text_font_file(),
            )
            text.prop.justification_horizontal = "center"
        # text actors at fixed pixel sizes (corner annotations rescale per viewport)
        pl.add_text(
            vtk_text(title), position=(0.03, 0.93), viewport=True, font_size=TITLE_FONT_PT, font_file=text_font_file()
        )
        if note and i == 0:
            pl.add_text(
                vtk_text(note), position=(0.03, 0.02), viewport=True, font_size=NOTE_FONT_PT, font_file=text_font_file()
            )
        pl.camera_position = [
            tuple(centre + view_normal * 3.5 * np.ptp(points.reshape(-1, 3), axis=0).max()),
            tuple(centre),
            (0.0, 0.0, 1.0) if abs(view_normal[2]) < 0.9 else (0.0, 1.0, 0.0),
        ]
        pl.renderer.reset_camera()  # same direction, the vessel fills the panel
    return pl


def clipped_view_png(
    points: np.ndarray,
    theta: np.ndarray,
    panels: list[tuple[str, np.ndarray, str]],
    path: PathLike,
    *,
    label: str,
    clim: tuple[float, float] | None = None,
    view_normal: np.ndarray | None = None,
    note: str = "",
) -> str:
    """PNG of theta-clipped lumen views (paper Figs. 8-9), one view per panel.

    Shows the half theta in [0, pi] of each panel's grid, so the cut planes theta = 0 and
    theta = pi show the field inside the lumen. Without an off-screen render window, a 2-D
    longitudinal section (tau, signed rho_n) is drawn with matplotlib instead.

    Parameters
    ----------
    points : (n_tau, n_theta, n_rho, 3) float, mm
        Grid points.
    theta : (n_theta,) float, rad
    panels : list of (title, (n_tau, n_theta, n_rho) float array, colour map name)
        Panels sharing the first panel's colour map share ``clim`` and one colour bar; the others
        are drawn on (0, 1) without a colour bar (a mask). NaN values (wall cells left out of a
        PCA) are drawn in :data:`NAN_COLOUR` (grey).
    path : str or Path
        Output PNG.
    label : str
        Name (with units) of the scalar shown: the colour bar's title.
    clim : (float, float), optional
        Colour limits of the shared panels (default :func:`robust_limits` of their values).
    view_normal : (3,) float, optional
        Camera direction from the centre (default +z).
    note : str
        A small line at the bottom of the first panel (e.g. how the limits were chosen).

    Returns
    -------
    str
        The renderer used: ``"pyvista"`` or ``"matplotlib"``.
    """
    if clim is None:
        clim = robust_limits([v for _, v, c in panels if c == panels[0][2]])
    try:
        pl = clipped_view_plotter(points, theta, panels, label=label, clim=clim, view_normal=view_normal, note=note)
        pl.screenshot(str(path))
        pl.close()
        return "pyvista"
    except Exception as exc:  # no off-screen render window: fall back to a 2-D section
        log.warning("pyvista off-screen rendering failed (%s); drawing %s with matplotlib", exc, Path(path).name)
    plt = _plt()
    fig = clipped_view_figure(theta, panels, label=label, clim=clim, note=note)
    fig.savefig(path)
    plt.close(fig)
    return "matplotlib"


def clipped_view_figure(
    theta: np.ndarray,
    panels: list[tuple[str, np.ndarray, str]],
    *,
    label: str,
    clim: tuple[float, float],
    note: str = "",
) -> Any:
    """The matplotlib fallback of :func:`clipped_view_png`: longitudinal sections (tau, signed
    rho_n; theta = 0 above the axis, theta = pi below), the shared panels on ``clim`` with one
    colour bar titled ``label``, at most 5 ticks."""
    from matplotlib.ticker import MaxNLocator

    plt = _plt()
    fig, axes = plt.subplots(
        1,
        len(panels),
        figsize=(3.6 * len(panels) + 1.2, 3.4),
        dpi=110,
        squeeze=False,
        sharey=True,
        layout="constrained",
    )
    j_pi = int(np.argmin(np.abs(theta - np.pi)))
    shared_axes, image = [], None
    for ax, (title, values, cmap) in zip(axes[0], panels):
        sec = np.concatenate([values[:, j_pi, ::-1], values[:, 0, 1:]], axis=1)
        lim = clim if cmap == panels[0][2] else (0.0, 1.0)
        cm = plt.get_cmap(cmap).with_extremes(bad=NAN_COLOUR)
        im = ax.imshow(sec.T, origin="lower", aspect="auto", cmap=cm, extent=(0, 1, -1, 1), vmin=lim[0], vmax=lim[1])
        if cmap == panels[0][2]:
            shared_axes.append(ax)
            image = im
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("tau")
    axes[0][0].set_ylabel("signed rho_n (theta = 0 / pi)")
    if image is not None:
        cb = fig.colorbar(image, ax=shared_axes, label=label, location="bottom", shrink=0.6, aspect=40)
        cb.locator = MaxNLocator(5)
        cb.update_ticks()
    if note:
        fig.text(0.01, 0.01, note, fontsize=7)
    return fig


_LABELS = {
    "U": "|U| (m/s)",
    "p": "p (Pa)",
    "WSS": "|WSS| (Pa)",
    "TAWSS": "TAWSS (Pa)",
    "OSI": "OSI",
    "log10_RRT": "log10 RRT (RRT in 1/Pa)",
    "ECAP": "ECAP (1/Pa)",
}


def field_title(name: str) -> str:
    """A flow field's name in panel titles: ``U``, ``TAWSS``, ``U at peak_systole``."""
    phase = field_phase(name)
    return f"{field_quantity(name)} at {phase}" if phase else name


def field_label(name: str) -> str:
    """A flow field's colour-bar title with its unit: ``|U| (m/s)``, ``|U| (m/s) at peak_systole``."""
    phase = field_phase(name)
    label = _LABELS.get(field_quantity(name), field_quantity(name))
    return f"{label} at {phase}" if phase else label


def wall_map_figure(
    tau: np.ndarray,
    theta: np.ndarray,
    panels: list[tuple[str, np.ndarray, str]],
    *,
    label: str,
    clim: tuple[float, float],
    note: str = "",
) -> Any:
    """matplotlib Figure of a scalar wall field as (tau, theta) maps, one per panel.

    The panels whose colour map is the first panel's share ``clim`` and one colour bar titled
    ``label`` (at most 5 ticks); the others (the top-20 % mask) are drawn on (0, 1) without one.
    NaN values (wall cells left out of the field's PCA, :data:`vcs.atlas.cohort.NON_FINITE_RULE`)
    are drawn grey, and the note (a small line above the panels) says so.

    Parameters
    ----------
    tau : (n_tau,) float
    theta : (n_theta,) float, rad
    panels : list of (title, (n_tau, n_theta) float array, colour map name)
    label : str
        Name (with units) of the values: the colour bar's title.
    clim : (float, float)
        Colour limits of the shared panels.
    note : str
        A small line above the panels (the figure's suptitle).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.ticker import MaxNLocator

    plt = _plt()
    fig, axes = plt.subplots(
        1,
        len(panels),
        figsize=(3.2 * len(panels) + 1.2, 3.4),
        dpi=110,
        squeeze=False,
        sharey=True,
        layout="constrained",
    )
    shared_axes, image, left_out = [], None, False
    extent = (float(tau[0]), float(tau[-1]), 0.0, TWO_PI)
    for ax, (title, values, cmap) in zip(axes[0], panels):
        v = np.asarray(values, float)
        shared = cmap == panels[0][2]
        left_out |= shared and bool(np.isnan(v).any())
        lim = clim if shared else (0.0, 1.0)
        cm = plt.get_cmap(cmap).with_extremes(bad=NAN_COLOUR)
        im = ax.imshow(v.T, origin="lower", aspect="auto", cmap=cm, extent=extent, vmin=lim[0], vmax=lim[1])
        if shared:
            shared_axes.append(ax)
            image = im
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("tau")
    axes[0][0].set_ylabel("theta (rad)")
    if image is not None:
        cb = fig.colorbar(image, ax=shared_axes, label=label, location="bottom", shrink=0.6, aspect=40)
        cb.locator = MaxNLocator(5)
        cb.update_ticks()
    if left_out:
        note = (note + "; " if note else "") + LEFT_OUT_NOTE
    if note:  # above the panels: constrained layout makes room for it (a figure text would overlap the bar)
        fig.suptitle(note, fontsize=7, x=0.01, ha="left")
    return fig


def wall_map_png(
    tau: np.ndarray,
    theta: np.ndarray,
    panels: list[tuple[str, np.ndarray, str]],
    path: PathLike,
    *,
    label: str,
    clim: tuple[float, float] | None = None,
    note: str = "",
) -> None:
    """PNG of :func:`wall_map_figure` (``clim`` default: :func:`robust_limits` of the shared panels)."""
    if clim is None:
        clim = robust_limits([v for _, v, c in panels if c == panels[0][2]])
    plt = _plt()
    fig = wall_map_figure(tau, theta, panels, label=label, clim=clim, note=note)
    fig.savefig(path)
    plt.close(fig)


def field_limits(panels: dict[str, Any], *, on_wall: bool) -> tuple[float, float]:
    """Colour limits shared by every figure of one flow field (3-D and flat, its mean and each
    mode): the widest of the figures' own :func:`robust_limits` (2nd-98th percentile of a mode's
    mean - 2 sigma, mean and mean + 2 sigma values; magnitudes; of a wall field, its values on the
    wall), widened by :data:`FIELD_LIMIT_PAD` of its width at either end (not below 0 when the
    lower percentile is not). Each figure then has
    less than 2 % of its values beyond either end, and the figures of a field can be compared
    colour for colour. ``panels`` is a field's entry of :func:`flow_grid`'s
    ``panels``."""

    def shown(a: np.ndarray) -> np.ndarray:
        return _scalar(a)[:, :, -1] if on_wall else _scalar(a)

    mean = shown(panels["mean"])
    limits = [robust_limits([mean])]
    limits += [robust_limits([shown(minus), mean, shown(plus)]) for minus, plus, _ in panels["modes"]]
    lo, hi = min(lo for lo, _ in limits), max(hi for _, hi in limits)
    return _padded(lo, hi)  # the extreme cells, often facing a 3-D view, not at the end colours


def _padded(lo: float, hi: float) -> tuple[float, float]:
    """(lo, hi) widened by :data:`FIELD_LIMIT_PAD` of its width at either end, the lower end not
    below 0 when ``lo`` is not (a magnitude's scale read "-0.01" at its start)."""
    pad = FIELD_LIMIT_PAD * (hi - lo)
    return (lo - pad if lo < 0 else max(lo - pad, 0.0)), hi + pad


def mean_limits(panels: dict[str, Any], *, on_wall: bool) -> tuple[float, float]:
    """Colour limits of a flow field's mean figure alone: the :data:`MEAN_PERCENTILES` of the mean
    (magnitudes; of a wall field, its values on the wall; of a volume field, its values with its
    wall layer counted twice) widened by :data:`FIELD_LIMIT_PAD` at either end (not below 0 when
    the lower percentile is not). The modes' +-2 sigma panels of a varied cohort reach far beyond
    the mean; on :func:`field_limits` the mean would use a small part of the colour map."""
    mean = _scalar(panels["mean"])
    # a wall field: its wall values; a volume field: its values, its wall values once more (the
    # figures show the wall, where p peaks on an arch's outer curve, as much as the cut)
    lo, hi = robust_limits([mean[:, :, -1]] if on_wall else [mean, mean[:, :, -1]], MEAN_PERCENTILES)
    return _padded(lo, hi)


def write_flow_files(
    atlas: Atlas,
    mean_model: VesselModel,
    out_dir: PathLike,
    *,
    png_dir: PathLike | None = None,
    grid: tuple[pyvista.UnstructuredGrid, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """flow_mean.vtu (:func:`flow_grid`) and the flat PNG of every field and mode: a clipped lumen
    view of a volume field (:func:`clipped_view_png`), a (tau, theta) map of a wall field (WSS
    magnitude, the wall markers: :func:`wall_map_png`). Every figure of a field has the field's
    colour limits (:func:`field_limits`).

    Parameters
    ----------
    atlas : Atlas
    mean_model : VesselModel
        The mean shape.
    out_dir : str or Path
        Existing output directory (the VTU).
    png_dir : str or Path, optional
        Existing directory of the PNGs (default ``out_dir``).
    grid : tuple, optional
        :func:`flow_grid` of the atlas and mean shape (computed when missing).

    Returns
    -------
    dict
        {what: file name relative to ``out_dir``}: ``flow_mean`` and ``flow_{field}_mode{k}``
        (``{field}`` the :func:`vcs.atlas.pca.field_slug`), plus (not files) ``renderer``: the
        sorted list of 3-D renderers used, and ``colour_limits``: {figure key: [lo, hi]} of the
        shared panels (:func:`robust_limits`; for a wall field, of its values on the wall).
    """
    out = Path(out_dir)
    pngs = Path(png_dir) if png_dir is not None else out
    vtu, info = grid if grid is not None else flow_grid(atlas, mean_model)
    files: dict[str, Any] = {"flow_mean": "flow_mean.vtu"}
    vtu.save(str(out / files["flow_mean"]))
    theta = atlas.grid["theta"]
    # look at the cut planes from the removed side (theta = 3 pi / 2 at mid tau)
    _, v1, v2 = mean_model.vcs.frame(np.array([0.5]))
    view = -v2[0]
    renderers = set()
    limits: dict[str, list[float]] = {}
    lo_pc, hi_pc = COLOUR_PERCENTILES
    note = f"colour scale: {lo_pc:g}-{hi_pc:g} % of the field's figures' values, widest"
    tau = atlas.grid["tau"]
    for f, d in info["panels"].items():
        cmap = "coolwarm" if field_quantity(f) == "p" else "viridis"
        label, title = field_label(f), field_title(f)
        mask_title = "" if field_phase(f) else title  # a phase's name makes the title overflow the panel
        shape = atlas.field_shapes[f]
        on_wall = len(shape) - (1 if is_vector_field(f) else 0) == 2  # (n_tau, n_theta[, 3])
        clim = field_limits(d, on_wall=on_wall)
        for k, (minus, plus, mask) in enumerate(d["modes"]):
            panels = [
                (f"{title} mean - 2 sigma (mode {k + 1})", _scalar(minus), cmap),
                (f"{title} mean", _scalar(d["mean"]), cmap),
                (f"{title} mean + 2 sigma (mode {k + 1})", _scalar(plus), cmap),
                (f"{mask_title} mode {k + 1}: top 20 % variation (red)".lstrip(), mask.astype(float), "Reds"),
            ]
            values = [v[:, :, -1] if on_wall else v for _, v, _ in panels[:3]]  # inside a wall field: zeros
            left_out = any(bool(np.isnan(v).any()) for v in values)
            key = f"flow_{field_slug(f)}_mode{k + 1}"
            png = pngs / f"{key}.png"
            if on_wall:  # a wall field (WSS, the wall markers): drawn over (tau, theta)
                maps = [(t, v[:, :, -1], c) for t, v, c in panels]
                wall_map_png(tau, theta, maps, png, label=label, clim=clim, note=note)
            else:
                shown = f"{note}\n{LEFT_OUT_NOTE}" if left_out else note
                renderers.add(
                    clipped_view_png(
                        info["points"], theta, panels, png, label=label, clim=clim, view_normal=view, note=shown
                    )
                )
            files[key] = _relative(png, out)
            limits[key] = [clim[0], clim[1]]
    files["renderer"] = sorted(renderers)
    files["colour_limits"] = limits
    return files


def write_atlas_figures(atlas: Atlas, out_dir: PathLike, *, png_dir: PathLike | None = None) -> dict[str, Any]:
    """Write all atlas VTP/VTU/PNG files (see the module doc).

    Parameters
    ----------
    atlas : Atlas
    out_dir : str or Path
        Existing output directory (VTP/VTU).
    png_dir : str or Path, optional
        Directory of the PNGs (default ``out_dir/figures``; created), each written once.

    Returns
    -------
    dict
        ``files``: {what: file name relative to ``out_dir``}; ``renderer``: list of the 3-D
        renderer(s) used (``"pyvista"``, ``"matplotlib"``), empty without flow figures;
        ``colour_limits``: {flow figure: [lo, hi]} (see :func:`write_flow_files`);
        ``mean_model``, ``grid`` and ``png_dir``: what :func:`vcs.atlas.plots3d.write_listed_3d`
        draws the 3-D figures from (:func:`vcs.atlas.build.build_atlas` calls it).
    """
    from vcs.vessel import VesselModel

    out = Path(out_dir)
    pngs = Path(png_dir) if png_dir is not None else out / "figures"
    pngs.mkdir(parents=True, exist_ok=True)
    template = atlas.aligned_models[0]
    files: dict[str, Any] = write_shape_files(
        atlas.shape, template, out, n_modes=atlas.options["n_modes"], png_dir=pngs
    )
    explained_variance_png(atlas, pngs / "explained_variance.png")
    files["explained_variance"] = _relative(pngs / "explained_variance.png", out)
    mean_model = VesselModel.from_feature_vector(atlas.shape.mean, template)
    grid = flow_grid(atlas, mean_model) if atlas.flow and atlas.grid else None
    if grid is not None:
        files.update(write_flow_files(atlas, mean_model, out, png_dir=pngs, grid=grid))
    renderer = files.pop("renderer", [])
    limits = files.pop("colour_limits", {})
    # the 3-D figures (vcs.atlas.plots3d, which imports this module) are drawn by the caller
    # (vcs.atlas.build) from ``mean_model`` and ``grid``
    return {
        "files": files,
        "renderer": renderer,
        "colour_limits": limits,
        "mean_model": mean_model,
        "grid": grid,
        "png_dir": pngs,
    }
