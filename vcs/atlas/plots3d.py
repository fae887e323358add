"""3-D atlas figures (paper Figs. 6-9), rendered off-screen with pyvista.

Every view is set in the mean shape's own frame (:class:`ViewFrame`): the plane that best fits
the mean centerline, its long axis up (the outlet at the bottom), its in-plane cross axis
"anterior" (the inlet's side: the ascending aorta lies in front of the descending one), its
normal the sagittal direction. Views: ``sagittal`` (from +normal: the whole centerline in the
picture plane), ``coronal`` (from +anterior), and for the wall fields ``front`` (+normal) and
``back`` (-normal): the two sides of the mean plane, which together show the whole wall (seen
from +-anterior, an arch's ascending part would hide its descending part).

Figures (PNG, written by :func:`write_3d_figures`; ``{field}`` a :func:`vcs.atlas.pca.field_slug`):

* ``shape_mean_3d.png``: the mean wall coloured by its radius rho_w, sagittal and coronal;
* ``shape_mode{k}_3d.png``: the mean - 2 sigma and mean + 2 sigma walls of shape mode k coloured
  by the radius change against the mean (the mean as a grey ghost), and the three centerlines;
  one row per view (sagittal, coronal);
* ``flow_{field}_mean_3d.png``: a wall field (WSS, TAWSS, OSI, log10 RRT, ECAP) on the wall,
  front and back (the two sides of the mean plane); p on the wall from the back and in the
  clipped lumen; |U| in the clipped
  lumen with streamlines;
* ``flow_{field}_mode{k}_3d.png``: mean - 2 sigma, mean, mean + 2 sigma and the top-20 % region of
  flow mode k, on the wall (front and back rows) or in the clipped lumen; not of the
  phase fields of a pulsatile cohort (their modes have the flat figures of :mod:`vcs.atlas.plots`
  only: 27 renders fewer for 3 phases and 3 modes).

The clipped lumen is the measurement grid with the half of its theta range that faces the camera
removed (:func:`facing_half`), so the cut shows the field inside. The mode figures of one field
share its colour limits (:func:`vcs.atlas.plots.field_limits`: the widest of the figures' 2nd-98th
percentiles), the mean figure has its own (:func:`vcs.atlas.plots.mean_limits`: readable when a
varied cohort's modes reach far); NaN (wall cells left out of a PCA, e.g. at an ostium) is grey.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vcs.atlas.pca import field_phase, field_quantity, field_slug, is_vector_field, mode_deformation
from vcs.atlas.plots import (
    BAR_HEIGHT,
    BAR_Y,
    FIELD_LIMIT_PAD,
    LABEL_FONT_PX,
    LEFT_OUT_NOTE,
    NAN_COLOUR,
    NOTE_FONT_PT,
    TITLE_FONT_PT,
    PathLike,
    _relative,
    _scalar,
    colour_bar_labels,
    field_label,
    field_limits,
    field_title,
    mean_limits,
    robust_limits,
    text_font_file,
    vtk_text,
)
from vcs.grid import grid_to_vtk

if TYPE_CHECKING:
    import pyvista

    from vcs.atlas.cohort import Atlas
    from vcs.atlas.pca import PCA
    from vcs.vessel import VesselModel

log = logging.getLogger(__name__)

#: Width, height (pixels) of one panel of a 3-D figure.
PANEL_3D_PX = (340, 400)
#: Background, text and ghost colours; the top-20 % mask's two colours.
BACKGROUND, TEXT_COLOUR, GHOST_COLOUR = "white", "black", "#808080"
MASK_COLOURS = ("#d9d9d9", "#d62728")
#: Surface lighting: one headlight; a face seen head-on shows its colour-map colour exactly.
SURFACE_LOOK = {"ambient": 0.35, "diffuse": 0.65, "specular": 0.0, "smooth_shading": True}


@dataclass(frozen=True)
class ViewFrame:
    """The mean shape's own frame, from which every 3-D figure is seen.

    Attributes
    ----------
    centre : (3,) float, mm
        Centroid of the centerline.
    up : (3,) float
        Long axis of the centerline's best-fit plane, pointing away from the outlet c(1).
    anterior : (3,) float
        In-plane axis across ``up``, towards the inlet c(0).
    normal : (3,) float
        ``up`` x ``anterior``: the plane's normal.
    size : float, mm
        Largest extent of the wall's bounding box.
    wall : (n, 3) float, mm
        Points of the wall, which the cameras frame.
    """

    centre: np.ndarray
    up: np.ndarray
    anterior: np.ndarray
    normal: np.ndarray
    size: float
    wall: np.ndarray

    @classmethod
    def from_model(cls, model: VesselModel) -> ViewFrame:
        """The frame of a vessel model's centerline (principal axes of c(tau) on 101 samples)."""
        c = model.vcs.curve(np.linspace(0.0, 1.0, 101))
        centre = c.mean(axis=0)
        _, _, axes = np.linalg.svd(c - centre)
        up, ant = axes[0], axes[1]
        if (c[-1] - centre) @ up > 0:
            up = -up
        if (c[0] - centre) @ ant < 0:
            ant = -ant
        T, TH = np.meshgrid(np.linspace(0, 1, 41), np.linspace(0, 2 * np.pi, 16), indexing="ij")
        wall = model.surface_points(T, TH).reshape(-1, 3)
        return cls(centre, up, ant, np.cross(up, ant), float(np.ptp(wall, axis=0).max()), wall)

    def direction(self, view: str) -> np.ndarray:
        """Unit vector from the centre towards the camera of ``view``."""
        return {"sagittal": self.normal, "coronal": self.anterior, "front": self.normal, "back": -self.normal}[view]

    def set_camera(self, camera: Any, view: str, *, aspect: float) -> None:
        """Point a pyvista camera at the mean wall from ``view`` (parallel projection): the same
        scale in every panel of ``view``, the wall inside the band between the title (top 8 %)
        and the colour bar (bottom 20 %) of a panel of width / height ``aspect``."""
        d = self.direction(view)
        right = np.cross(self.up, d)
        x, y = (self.wall - self.centre) @ right, (self.wall - self.centre) @ self.up
        band, middle = 0.72, 0.56  # height fraction and centre of the band
        scale = 1.08 * max(np.ptp(y) / (2 * band), np.ptp(x) / (2 * 0.95 * aspect))
        focal = self.centre + 0.5 * (x.max() + x.min()) * right + 0.5 * (y.max() + y.min()) * self.up
        focal = focal - (middle - 0.5) * 2 * scale * self.up
        camera.focal_point = tuple(focal)
        camera.position = tuple(focal + 4.0 * self.size * d)
        camera.up = tuple(self.up)
        camera.parallel_projection = True
        camera.parallel_scale = scale
        camera.clipping_range = (0.1 * self.size, 10.0 * self.size)


@dataclass
class Panel:
    """One subplot: meshes with their ``add_mesh`` keywords, seen from ``view``, under ``title``."""

    title: str
    view: str
    meshes: list[tuple[Any, dict[str, Any]]]


@dataclass(frozen=True)
class ColourBar:
    """The one colour bar of a figure: title (with units), limits, colour map, and its panel."""

    label: str
    clim: tuple[float, float]
    cmap: str
    panel: int = 0


def render_panels(
    panels: list[Panel],
    frame: ViewFrame,
    path: PathLike,
    *,
    n_cols: int | None = None,
    bar: ColourBar | None = None,
    note: str = "",
    scale: int = 1,
) -> None:
    """Render ``panels`` (row-major, ``n_cols`` per row; default one row) off-screen to a PNG of
    ``scale`` times :data:`PANEL_3D_PX` per panel (text and lines scaled with it: 2-4 for print).

    White background, black text, one headlight; each panel's camera from ``frame``, zoomed to
    fit. ``bar`` is drawn horizontally at the bottom of its panel (labels above it, its title
    above them: VTK draws a horizontal bar's title over its middle label, and labels below a bar
    this thin over the bar itself); ``note`` at the bottom of the first panel.

    Raises
    ------
    Exception
        Whatever VTK raises when no off-screen render window can be opened.
    """
    import pyvista as pv

    cols = n_cols or len(panels)
    rows = -(-len(panels) // cols)
    w, h = PANEL_3D_PX
    pl = pv.Plotter(off_screen=True, shape=(rows, cols), window_size=[w * cols, h * rows], lighting="none")
    try:
        for i, p in enumerate(panels):
            pl.subplot(i // cols, i % cols)
            pl.set_background(BACKGROUND)  # type: ignore[arg-type]  # a colour name
            pl.add_light(pv.Light(light_type="headlight"), only_active=True)
            for mesh, kw in p.meshes:
                pl.add_mesh(mesh, show_scalar_bar=False, **kw)
            if bar is not None and i == bar.panel:
                _add_colour_bar(pl, bar)
            font = text_font_file()
            pl.add_text(
                vtk_text(p.title), position=(0.03, 0.93), font_size=TITLE_FONT_PT, color=TEXT_COLOUR,
                viewport=True, font_file=font,
            )  # fmt: skip
            if note and i == 0:
                pl.add_text(
                    vtk_text(note), position=(0.03, 0.01), font_size=NOTE_FONT_PT, color=TEXT_COLOUR,
                    viewport=True, font_file=font,
                )  # fmt: skip
            frame.set_camera(pl.camera, p.view, aspect=w / h)
        pl.screenshot(str(path), scale=scale)
    finally:
        pl.close()


def _add_colour_bar(pl: pyvista.Plotter, bar: ColourBar) -> None:
    """A horizontal colour bar of ``bar`` in the active subplot (an invisible point carries it)."""
    import pyvista as pv

    width = 0.8
    fmt, n_labels = colour_bar_labels(*bar.clim, width_px=width * PANEL_3D_PX[0])
    carrier = pv.PolyData(np.zeros((1, 3)))
    carrier.point_data[bar.label] = [bar.clim[0]]
    pl.add_mesh(
        carrier,
        scalars=bar.label,
        cmap=bar.cmap,  # type: ignore[arg-type]  # any matplotlib colour-map name
        clim=bar.clim,
        opacity=0.0,
        scalar_bar_args={
            "title": bar.label,
            "vertical": False,
            "width": width,
            "position_x": (1.0 - width) / 2,
            "position_y": BAR_Y,
            "height": BAR_HEIGHT,
            "n_labels": n_labels,
            "fmt": fmt,
            "label_font_size": LABEL_FONT_PX,
            "color": TEXT_COLOUR,
        },
    )
    actor = pl.scalar_bars[bar.label]
    actor.SetTitle("")
    actor.SetTextPositionToSucceedScalarBar()
    text = pl.add_text(
        vtk_text(bar.label),
        position=(0.5, BAR_Y + BAR_HEIGHT + 0.005),
        viewport=True,
        font_size=TITLE_FONT_PT,
        color=TEXT_COLOUR,
        name="colour_bar_title",
        font_file=text_font_file(),
    )
    text.prop.justification_horizontal = "center"


def coloured(name: str, clim: tuple[float, float], cmap: str) -> dict[str, Any]:
    """``add_mesh`` keywords of a surface coloured by point data ``name`` (NaN grey)."""
    return {"scalars": name, "clim": clim, "cmap": cmap, "nan_color": NAN_COLOUR, **SURFACE_LOOK}


def mask_look() -> dict[str, Any]:
    """``add_mesh`` keywords of a 0/1 mask surface (point data ``mask``): grey, the marked cells red."""
    from matplotlib.colors import ListedColormap

    return {"scalars": "mask", "clim": (0.0, 1.0), "cmap": ListedColormap(MASK_COLOURS), **SURFACE_LOOK}


def ghost_look() -> dict[str, Any]:
    """``add_mesh`` keywords of the mean wall drawn as a translucent grey ghost."""
    return {"color": GHOST_COLOUR, "opacity": 0.2, "smooth_shading": True}


# ---------------------------------------------------------------------------------------------
# Shape (paper Figs. 6-7)
# ---------------------------------------------------------------------------------------------
def wall_polydata(
    model: VesselModel, values: dict[str, np.ndarray] | None = None, *, n: tuple[int, int] = (101, 48)
) -> Any:
    """The wall x(tau, theta) = c(tau) + rho_w (v1 cos theta + v2 sin theta) (Eq. 8) on an
    (n_tau, n_theta) grid (seam closed), with point data ``values`` of shape (n_tau, n_theta)."""
    tau = np.linspace(0.0, 1.0, n[0])
    theta = 2 * np.pi * np.arange(n[1]) / n[1]
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    return grid_to_vtk(model.surface_points(T, TH), values or {})


def centerline_tube(model: VesselModel, radius: float) -> Any:
    """The centerline c(tau) as a tube of ``radius`` (mm)."""
    import pyvista as pv

    return pv.lines_from_points(model.vcs.curve(np.linspace(0.0, 1.0, 101))).tube(radius=radius, n_sides=10)


def shape_mean_png(mean: VesselModel, frame: ViewFrame, path: PathLike, *, scale: int = 1) -> tuple[float, float]:
    """Paper Fig. 6: the mean wall coloured by its radius rho_w (mm), sagittal and coronal views.

    Returns the colour limits (2nd-98th percentile of rho_w on the wall).
    """
    n = (101, 48)
    T, TH = np.meshgrid(np.linspace(0, 1, n[0]), 2 * np.pi * np.arange(n[1]) / n[1], indexing="ij")
    rho = np.asarray(mean.fitted_wall()(T, TH), float)
    lo, hi = robust_limits([rho])
    # padded as the flow fields (FIELD_LIMIT_PAD): the widest sections not all at the end colour
    half = max((0.5 + FIELD_LIMIT_PAD) * (hi - lo), 0.01 * float(np.mean(rho)))  # a tube: one colour
    clim = (0.5 * (lo + hi) - half, 0.5 * (lo + hi) + half)
    wall = wall_polydata(mean, {"rho_w": rho}, n=n)
    look = coloured("rho_w", clim, "viridis")
    panels = [Panel(f"mean shape, {v}", v, [(wall, look)]) for v in ("sagittal", "coronal")]
    render_panels(panels, frame, path, bar=ColourBar("rho_w (mm)", clim, "viridis", panel=1), scale=scale)
    return clim


def shape_mode_png(
    pca: PCA, template: VesselModel, mode: int, frame: ViewFrame, path: PathLike, *, scale: int = 1
) -> tuple[float, float]:
    """Paper Fig. 7: shape mode ``mode`` (0-based) as its mean - 2 sigma and mean + 2 sigma walls.

    Columns: the -2 sigma wall and the +2 sigma wall coloured by the radius change
    delta rho_w = rho_w(mode shape) - rho_w(mean) (mm; symmetric limits shared by both walls:
    1.05 max |delta rho_w|), each with the mean wall as a translucent grey ghost; then
    the centerlines (mean black, -2 sigma blue, +2 sigma red) inside the ghost. Rows: sagittal,
    coronal. Returns the colour limits.
    """
    d = {s: mode_deformation(pca, template, mode, n_sigma=s) for s in (-2.0, 2.0)}
    lim = 1.05 * float(max(np.abs(d[s]["radius_change"]).max() for s in d))  # smooth: no outliers to cut
    clim = (-max(lim, 1e-6), max(lim, 1e-6))
    mean = d[2.0]["mean_model"]
    ghost = (wall_polydata(mean, n=(51, 24)), ghost_look())
    r = 0.006 * frame.size
    lines = [(centerline_tube(mean, r), {"color": "black"})]
    walls = {}
    for s, colour in ((-2.0, "#2166ac"), (2.0, "#b2182b")):
        walls[s] = wall_polydata(d[s]["mode_model"], {"delta_rho": d[s]["radius_change"]})
        lines.append((centerline_tube(d[s]["mode_model"], r), {"color": colour}))
    look = coloured("delta_rho", clim, "RdBu_r")
    share = 100 * pca.explained_variance_ratio[mode]
    panels = []
    for view in ("sagittal", "coronal"):
        panels += [
            Panel(f"mode {mode + 1}: mean - 2 sigma, {view}", view, [(walls[-2.0], look), ghost]),
            Panel(f"mode {mode + 1}: mean + 2 sigma ({share:.0f} %)", view, [(walls[2.0], look), ghost]),
            Panel("centerlines: -2 sigma blue, +2 red", view, [ghost, *lines]),
        ]
    bar = ColourBar("radius change (mm)", clim, "RdBu_r", panel=1)
    # framed on every wall drawn (the +-2 sigma walls of a varied cohort reach beyond the mean's),
    # the same scale in every panel
    shown = np.vstack([frame.wall, *(np.asarray(walls[s].points) for s in walls)])
    render_panels(panels, replace(frame, wall=shown), path, n_cols=3, bar=bar, scale=scale)
    return clim


# ---------------------------------------------------------------------------------------------
# Flow (paper Figs. 8-9)
# ---------------------------------------------------------------------------------------------
def facing_half(model: VesselModel, theta: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """Indices of the theta half of the grid that faces away from a camera in ``direction``.

    The removed half is centred on the camera's angle in the (v1, v2) frame (circular mean over
    tau), so the cut planes at its edges face the camera. Returns n_theta / 2 + 1 contiguous
    indices (mod n_theta; both cut planes included) of a uniform theta grid.
    """
    tau = np.linspace(0.0, 1.0, 21)
    _, v1, v2 = model.vcs.frame(tau)
    phi = np.angle(np.sum(np.exp(1j * np.arctan2(v2 @ direction, v1 @ direction))))
    n = len(theta)
    start = int(np.rint((phi + np.pi / 2) / (2 * np.pi) * n)) % n
    return (start + np.arange(n // 2 + 1)) % n


def lumen_surface(points: np.ndarray, values: dict[str, np.ndarray], keep: np.ndarray) -> Any:
    """Outer surface (wall, cut planes, ends) of the measurement grid's theta columns ``keep``."""
    g = grid_to_vtk(points[:, keep], {k: v[:, keep] for k, v in values.items()}, close_theta=False)
    return g.extract_surface(algorithm="dataset_surface")


def wall_surface(points: np.ndarray, values: dict[str, np.ndarray]) -> Any:
    """The rho_n = 1 layer of the measurement grid (the wall) with point data ``values``
    of shape (n_tau, n_theta)."""
    return grid_to_vtk(points[:, :, -1], values)


def streamlines(points: np.ndarray, velocity: np.ndarray, size: float, *, n_seeds: int = 24) -> Any:
    """Streamlines of the mean velocity (Cartesian, (n_tau, n_theta, n_rho, 3)) from about
    ``n_seeds`` points of the second tau section (rho_n between 0.2 and 0.8), forward."""
    import pyvista as pv

    grid = grid_to_vtk(points, {"U": velocity})
    n_rho = points.shape[2]
    rows = np.unique(np.clip(np.rint(np.linspace(0.2, 0.8, 3) * (n_rho - 1)).astype(int), 1, n_rho - 1))
    cols = np.arange(0, points.shape[1], max(1, points.shape[1] * len(rows) // n_seeds))
    seeds = pv.PolyData(points[min(1, len(points) - 1)][np.ix_(cols, rows)].reshape(-1, 3))
    return grid.streamlines_from_source(
        seeds, vectors="U", integration_direction="forward", max_length=4.0 * size, max_steps=4000
    )


def field_cmap(name: str) -> str:
    """Colour map of a flow field: diverging for pressure, viridis for the others."""
    return "coolwarm" if field_quantity(name) == "p" else "viridis"


def flow_mean_png(
    name: str,
    panels: dict[str, Any],
    points: np.ndarray,
    model: VesselModel,
    frame: ViewFrame,
    path: PathLike,
    *,
    on_wall: bool,
    clim: tuple[float, float],
    scale: int = 1,
) -> tuple[float, float]:
    """Paper Fig. 8: the mean of flow field ``name`` on the mean shape.

    A wall field (WSS, TAWSS, OSI, log10 RRT, ECAP): on the wall, front and back. p: on
    the wall seen from the back, and in the lumen clipped along its sagittal plane. U:
    |U| in the clipped lumen with streamlines from the inlet (thin black lines, where they run in
    the removed half). ``panels`` is :func:`vcs.atlas.plots.flow_grid`'s entry of the field.
    """
    cmap, label, title = field_cmap(name), field_label(name), field_title(name)
    look = coloured("v", clim, cmap)
    mean = _scalar(panels["mean"])
    if on_wall:
        wall = wall_surface(points, {"v": mean[:, :, -1]})
        shown = [Panel(f"{title} mean, {v}", v, [(wall, look)]) for v in ("front", "back")]
    else:
        cut = lumen_surface(points, {"v": mean}, facing_half(model, _theta(points), frame.normal))
        shown = [Panel(f"{title} mean, sagittal cut", "sagittal", [(cut, look)])]
        if field_quantity(name) == "p":
            wall = wall_surface(points, {"v": mean[:, :, -1]})
            shown.insert(0, Panel(f"{title} mean on the wall, back", "back", [(wall, look)]))
        elif panels["mean"].ndim == 4:
            try:
                lines = streamlines(points, panels["mean"], frame.size)
                shown[0].meshes.append((lines, {"color": "black", "line_width": 1.0, "opacity": 0.6}))
            except Exception as exc:  # noqa: BLE001  # a figure without streamlines is still a figure
                log.warning("no streamlines in %s: %s", Path(path).name, exc)
    note = LEFT_OUT_NOTE if bool(np.isnan(mean).any()) else ""
    bar = ColourBar(label, clim, cmap, panel=len(shown) - 1)
    render_panels(shown, frame, path, bar=bar, note=note, scale=scale)
    return clim


def _theta(points: np.ndarray) -> np.ndarray:
    """The (uniform) theta samples of a measurement grid."""
    n = points.shape[1]
    return 2 * np.pi * np.arange(n) / n


def flow_mode_png(
    name: str,
    panels: dict[str, Any],
    mode: int,
    points: np.ndarray,
    model: VesselModel,
    frame: ViewFrame,
    path: PathLike,
    *,
    on_wall: bool,
    clim: tuple[float, float],
    share: float,
    scale: int = 1,
) -> tuple[float, float]:
    """Paper Fig. 9: flow mode ``mode`` (0-based) of field ``name`` as mean - 2 sigma, mean,
    mean + 2 sigma, and its top-20 % region (red: the cells with the largest |mode|
    contribution sigma_m |u_m|, :func:`vcs.atlas.pca.top_variation_mask`).

    A wall field on the wall, one row from the front and one from the back; a volume field (U, p) in the
    lumen clipped along its sagittal plane. ``share`` is the mode's explained variance (%).
    """
    cmap, label, title = field_cmap(name), field_label(name), field_title(name)
    minus, plus, mask = panels["modes"][mode]
    arrays = {"-": _scalar(minus), "0": _scalar(panels["mean"]), "+": _scalar(plus)}
    if on_wall:
        meshes = {k: wall_surface(points, {"v": v[:, :, -1]}) for k, v in arrays.items()}
        meshes["m"] = wall_surface(points, {"mask": mask[:, :, -1].astype(float)})
        views = ["front", "back"]
    else:
        keep = facing_half(model, _theta(points), frame.normal)
        meshes = {k: lumen_surface(points, {"v": v}, keep) for k, v in arrays.items()}
        meshes["m"] = lumen_surface(points, {"mask": mask.astype(float)}, keep)
        views = ["sagittal"]
    look = coloured("v", clim, cmap)
    shown = []
    for view in views:
        shown += [
            Panel(f"{title} mean - 2 sigma, {view}", view, [(meshes["-"], look)]),
            Panel(f"{title} mean", view, [(meshes["0"], look)]),
            Panel(f"{title} mean + 2 sigma", view, [(meshes["+"], look)]),
            Panel(f"mode {mode + 1} ({share:.0f} %): top 20 % red", view, [(meshes["m"], mask_look())]),
        ]
    note = LEFT_OUT_NOTE if any(bool(np.isnan(v).any()) for v in arrays.values()) else ""
    render_panels(shown, frame, path, n_cols=4, bar=ColourBar(label, clim, cmap, panel=1), note=note, scale=scale)
    return clim


def write_listed_3d(
    atlas: Atlas,
    mean_model: VesselModel,
    pngs: Path,
    out: Path,
    files: dict[str, Any],
    *,
    grid: Any,
    scale: int = 1,
) -> dict[str, float]:
    """The 3-D figures (:func:`write_3d_figures`, ``scale`` times the panel size), listed in
    ``files`` (relative to ``out``); their render seconds. Without an off-screen render window:
    none, and a warning."""
    try:
        written = write_3d_figures(atlas, mean_model, pngs, info=None if grid is None else grid[1], scale=scale)
    except Exception as exc:  # noqa: BLE001  # no off-screen render window: the flat figures remain
        log.warning("no 3-D atlas figures: pyvista off-screen rendering failed (%s)", exc)
        return {}
    files.update({k: _relative(Path(v), out) for k, v in written["files"].items()})
    return {k: round(v, 3) for k, v in written["seconds"].items()}


def write_3d_figures(
    atlas: Atlas, mean_model: VesselModel, png_dir: PathLike, *, info: dict[str, Any] | None = None, scale: int = 1
) -> dict[str, Any]:
    """Write every 3-D figure of the module doc into ``png_dir``, ``scale`` times
    :data:`PANEL_3D_PX` per panel (1 for the screen, 2-4 for print).

    Parameters
    ----------
    atlas : Atlas
    mean_model : VesselModel
        The mean shape.
    png_dir : str or Path
        Existing directory of the PNGs.
    info : dict, optional
        :func:`vcs.atlas.plots.flow_grid`'s second result (computed when missing and the atlas
        has flow fields).

    Returns
    -------
    dict
        ``files``: {figure name (the PNG's stem): path}; ``colour_limits``: {figure name: [lo, hi]};
        ``seconds``: {figure name: render time}.
    """
    import time

    from vcs.atlas.plots import flow_grid

    out = Path(png_dir)
    frame = ViewFrame.from_model(mean_model)
    jobs: list[tuple[str, Any]] = [("shape_mean_3d", partial(shape_mean_png, mean_model, frame))]
    template = atlas.aligned_models[0]
    for k in range(atlas.shape.n_modes):
        jobs.append((f"shape_mode{k + 1}_3d", partial(shape_mode_png, atlas.shape, template, k, frame)))
    if atlas.flow and atlas.grid:
        info = info if info is not None else flow_grid(atlas, mean_model)[1]
        pts = info["points"]
        for f, panels in info["panels"].items():
            shape = atlas.field_shapes[f]
            on_wall = len(shape) - (1 if is_vector_field(f) else 0) == 2
            clim = field_limits(panels, on_wall=on_wall)
            slug = field_slug(f)
            mean_clim = mean_limits(panels, on_wall=on_wall)  # the mean's own: readable next to wide modes
            mean_job = partial(flow_mean_png, f, panels, pts, mean_model, frame, on_wall=on_wall, clim=mean_clim)
            jobs.append((f"flow_{slug}_mean_3d", mean_job))
            for k in range(0 if field_phase(f) else len(panels["modes"])):  # a phase's modes: flat maps only
                share = 100 * float(atlas.flow[f].explained_variance_ratio[k])
                job = partial(
                    flow_mode_png, f, panels, k, pts, mean_model, frame, share=share, on_wall=on_wall, clim=clim
                )
                jobs.append((f"flow_{slug}_mode{k + 1}_3d", job))
    files, limits, seconds = {}, {}, {}
    for key, draw in jobs:
        t0 = time.perf_counter()
        clim = draw(path=out / f"{key}.png", scale=scale)
        seconds[key] = time.perf_counter() - t0
        files[key] = str(out / f"{key}.png")
        limits[key] = [float(clim[0]), float(clim[1])]
    return {"files": files, "colour_limits": limits, "seconds": seconds}
