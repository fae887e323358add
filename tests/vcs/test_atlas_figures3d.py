"""The 3-D atlas figures (vcs.atlas.plots3d, issue 26 items 1 and 4) judged by their pixels, as a
reader would: each figure is not blank, its colour range is not saturated, two views of the same
data differ, the wall-field panels have coloured pixels on the wall and background around it.

One small synthetic atlas (6 bent tubes, a 9 x 8 x 5 grid, WSS with an ostium left out of the PCA)
is rendered once for the module (~10 s). Render times are measured by bench/render_figures.py."""

from __future__ import annotations

import numpy as np
import pytest
from test_atlas_ostium import cohort, with_ostium

from vcs.atlas import compute_atlas
from vcs.atlas.figure_checks import coloured, end_fractions, foreground, panel
from vcs.vessel import VesselModel

pv = pytest.importorskip("pyvista")


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    """{figure name: (H, W, 3) uint8 image} of every 3-D figure of the synthetic atlas, and the
    write_3d_figures result."""
    from matplotlib.image import imread

    from vcs.atlas.plots3d import write_3d_figures

    try:  # skip only without any off-screen render window; errors of the figure code fail
        probe = pv.Plotter(off_screen=True, window_size=[32, 32])
        probe.add_mesh(pv.Sphere())
        probe.screenshot(return_img=True)
        probe.close()
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no off-screen render window: {exc}")
    models, fields = cohort(6)
    fields, _ = with_ostium(fields)
    atlas = compute_atlas(models, fields, {}, n_modes=2)
    mean = VesselModel.from_feature_vector(atlas.shape.mean, atlas.aligned_models[0])
    out = tmp_path_factory.mktemp("figures3d")
    written = write_3d_figures(atlas, mean, out)
    images = {k: (255 * imread(v)[..., :3]).round().astype(np.uint8) for k, v in written["files"].items()}
    return images, written, atlas, mean


def test_every_figure_is_written_and_not_blank(figures):
    images, written, atlas, _ = figures
    expected = {"shape_mean_3d", "shape_mode1_3d", "shape_mode2_3d"}
    expected |= {f"flow_{f}_{what}_3d" for f in ("U", "p", "WSS") for what in ("mean", "mode1", "mode2")}
    assert set(images) == expected
    for name, img in images.items():
        assert foreground(img).mean() > 0.03, name
        assert coloured(img).mean() > 0.01, name
    for f in ("U", "p", "WSS"):  # one colour scale for the mode figures of a field; the mean its own
        lims = {tuple(written["colour_limits"][k]) for k in written["colour_limits"] if k.startswith(f"flow_{f}_mode")}
        assert len(lims) == 1, lims
        mean = written["colour_limits"][f"flow_{f}_mean_3d"]
        assert lims.pop()[0] <= mean[0] < mean[1]  # inside the modes' (mean +- 2 sigma reach further)


@pytest.mark.parametrize(
    ("name", "cmap", "cols", "rows", "field_panels"),
    [
        ("shape_mean_3d", "viridis", 2, 1, [0, 1]),
        ("shape_mode1_3d", "RdBu_r", 3, 2, [0, 1, 3, 4]),  # the walls, not the centerlines
        ("shape_mode2_3d", "RdBu_r", 3, 2, [0, 1, 3, 4]),
        ("flow_U_mean_3d", "viridis", 1, 1, [0]),
        ("flow_p_mean_3d", "coolwarm", 2, 1, [0, 1]),
        ("flow_WSS_mean_3d", "viridis", 2, 1, [0, 1]),
        ("flow_WSS_mode1_3d", "viridis", 4, 2, [0, 1, 2, 4, 5, 6]),  # not the top-20 % mask
        ("flow_U_mode1_3d", "viridis", 4, 1, [0, 1, 2]),
    ],
)
def test_colour_range_is_not_saturated(figures, name, cmap, cols, rows, field_panels):
    """Less than 3 % of the coloured pixels at either end of the colour map (the 2nd-98th
    percentile limits: a few cells beyond, not a saturated picture)."""
    img = figures[0][name]
    shown = np.concatenate([panel(img, i, cols, rows).reshape(-1, 3) for i in field_panels])[:, None]
    lo, hi = end_fractions(shown, cmap)
    assert lo < 0.03 and hi < 0.03, (name, lo, hi)


def test_the_saturation_check_fails_on_narrow_limits(figures, tmp_path):
    """The check above can fail: the WSS mean drawn on its 30th-70th percentile is saturated."""
    from matplotlib.image import imread

    from vcs.atlas.plots import robust_limits
    from vcs.atlas.plots3d import ViewFrame, flow_mean_png
    from vcs.grid import grid_points

    _, _, atlas, mean = figures
    from vcs.atlas.plots import flow_grid

    info = flow_grid(atlas, mean)[1]
    d = info["panels"]["WSS"]
    wall = np.linalg.norm(d["mean"][:, :, -1], axis=-1)
    narrow = robust_limits([wall], (30.0, 70.0))
    path = tmp_path / "narrow.png"
    pts, _ = grid_points(mean, atlas.grid["tau"], atlas.grid["theta"], atlas.grid["rho_n"])
    flow_mean_png("WSS", d, pts, mean, ViewFrame.from_model(mean), path, on_wall=True, clim=narrow)
    img = (255 * imread(path)[..., :3]).round().astype(np.uint8)
    assert max(end_fractions(img, "viridis")) > 0.1


def test_two_views_of_the_same_data_differ(figures):
    images = figures[0]
    for name, cols, rows, a, b in (
        ("shape_mean_3d", 2, 1, 0, 1),  # sagittal, coronal
        ("flow_WSS_mean_3d", 2, 1, 0, 1),  # front, back
        ("flow_WSS_mode1_3d", 4, 2, 1, 5),  # the mean, front and back
        ("shape_mode1_3d", 3, 2, 0, 1),  # -2 sigma and +2 sigma walls
    ):
        pa, pb = panel(images[name], a, cols, rows), panel(images[name], b, cols, rows)
        h = int(0.1 * pa.shape[0])  # below the titles
        changed = np.any(np.abs(pa[h:].astype(int) - pb[h:].astype(int)) > 30, axis=-1)
        assert changed.mean() > 0.02, (name, changed.mean())


def test_wall_field_panels_are_coloured_walls_on_a_background(figures):
    """WSS on the wall: each panel has coloured pixels (the wall), and its margins, left and right
    of the vessel and between the title and the colour bar, are background."""
    img = figures[0]["flow_WSS_mode1_3d"]
    for i in range(8):
        p = panel(img, i, 4, 2)
        h, w = p.shape[:2]
        band = p[int(0.1 * h) : int(0.78 * h)]
        assert coloured(band).mean() > 0.01 or i in (3, 7), i  # the mask panels: red only where marked
        margins = np.concatenate([band[:, : int(0.05 * w)], band[:, -int(0.05 * w) :]], axis=1)
        assert not foreground(margins[:, 2:-2]).any(), i  # (panel borders excluded)
        fg = foreground(band)
        assert 0.01 < fg.mean() < 0.9, i
    # the ostium cells left out of the WSS PCA are grey on the mean wall: grey pixels in colour-free shades
    mean = panel(figures[0]["flow_WSS_mean_3d"], 0, 2), panel(figures[0]["flow_WSS_mean_3d"], 1, 2)
    grey = [np.sum(foreground(p) & ~coloured(p) & (p.astype(int).sum(-1) > 300)) for p in mean]
    assert max(grey) > 50, grey


def test_a_figure_for_print_has_scale_times_the_pixels(figures, tmp_path):
    """atlas.figure_scale: the same figure at 2x the panel size (text and lines with it), the
    same picture: its 2x2-pixel blocks averaged give back the 1x figure within anti-aliasing."""
    from matplotlib.image import imread

    from vcs.atlas.plots3d import PANEL_3D_PX, ViewFrame, shape_mean_png

    _, _, atlas, mean = figures
    frame = ViewFrame.from_model(mean)
    shape_mean_png(mean, frame, tmp_path / "x1.png")
    shape_mean_png(mean, frame, tmp_path / "x2.png", scale=2)
    one, two = (imread(tmp_path / f"x{k}.png")[..., :3] for k in (1, 2))
    assert one.shape[:2] == (PANEL_3D_PX[1], 2 * PANEL_3D_PX[0])
    assert two.shape[:2] == (2 * one.shape[0], 2 * one.shape[1])
    down = two.reshape(one.shape[0], 2, one.shape[1], 2, 3).mean(axis=(1, 3))
    assert np.mean(np.abs(down - one) > 0.25) < 0.03  # the same picture, sharper


def test_a_pipe_in_a_3d_title_is_drawn():
    """VTK's text renderer takes '|' for a MathText column separator: ``|U| (m/s)`` came out as
    ``U``. :func:`vtk_text` draws it with the divides sign: a title of pipes alone leaves ink."""
    import pyvista as pv

    from vcs.atlas.plots import text_font_file, vtk_text

    def ink(text: str) -> int:
        pl = pv.Plotter(off_screen=True, window_size=[120, 60])
        try:
            pl.set_background("white")
            pl.add_text(
                text, position=(0.1, 0.3), viewport=True, font_size=14, color="black", font_file=text_font_file()
            )
            img = np.asarray(pl.screenshot(return_img=True))
        finally:
            pl.close()
        return int((img[..., :3].max(axis=2) < 128).sum())

    assert ink("|||") == 0  # VTK's own handling: nothing drawn (a VTK that draws it makes this fail: drop vtk_text)
    assert ink(vtk_text("|||")) > 30


@pytest.mark.parametrize(
    "lo, hi, expected", [(0.01, 1.01, (0.0, 1.06)), (0.2, 1.2, (0.15, 1.25)), (-1.0, 1.0, (-1.1, 1.1))]
)
def test_colour_limits_of_a_magnitude_do_not_go_below_zero(lo, hi, expected):
    """The 5 % margin at either end stops at 0 for a field that is not negative (a |U| scale read
    "-0.01" at its start); a signed field (p) keeps it."""
    from vcs.atlas.plots import _padded

    assert _padded(lo, hi) == pytest.approx(expected)
