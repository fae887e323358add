"""Resampling a lumen with a side branch (issue 25 item 4): the wall grid points at the ostium are
marked and carry no wall value; a lumen without branches gets no mask.

The truth is built independently of the resampling: a straight tube of radius R (the model's
wall, exactly) with a circular hole where a perpendicular branch of radius r_b leaves, the branch's
wall starting on the hole's rim (the saddle curve where the two cylinders meet). A model wall
point is inside the ostium when its distance to the branch's axis is below r_b (the ostium
"disc"); its distance to the CFD wall is then r_b minus that distance. The main wall carries a
smooth WSS f(x) along the axis (and TAWSS = f, OSI = 0.1), the branch a distinct WSS (B = 50 f's
scale, along the branch, TAWSS = B, OSI = 0.45) from its first ring of vertices above the rim on.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import pyvista as pv

from vcs.cfd.markers import ecap, rrt
from vcs.cfd.resample import OSTIUM_GAP, OSTIUM_NORMAL_COS, load_fields, ostium_mask, sample_mesh, summary, write_fields
from vcs.grid import grid_to_vtk

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from model_phantoms import narrowed_model  # noqa: E402

R, LENGTH, RB = 10.0, 120.0, 5.0  # mm
AXIS = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
TAU_B, THETA_B = 0.5, np.pi / 2  # where the branch's axis meets the main axis at right angles
B = 50.0  # the branch's WSS magnitude (kinematic, m^2/s^2; f is 1-1.7 on the main wall)
GRID = (61, 64, 3)  # wall grid: 2 mm along tau, 1 mm around theta


def model():
    return narrowed_model(R, R, R, length=LENGTH, axis=AXIS)


def branch_frame(m):
    """Centre of the branch's axis on the main axis, its direction nb (radial at theta_b) and eb."""
    _, v1, v2 = (a[0] for a in m.vcs.frame(np.array([TAU_B])))
    nb = np.cos(THETA_B) * v1 + np.sin(THETA_B) * v2
    return TAU_B * LENGTH * AXIS, nb, np.cross(AXIS, nb)


def main_field(x_mm):
    """The main wall's WSS magnitude: smooth, varying along and around the tube."""
    return 1.0 + 0.5 * (x_mm @ AXIS) / LENGTH + 0.2 * x_mm[:, 0] / R


def disc_offset(m, x_mm):
    """Distance of points from the branch's axis line (mm); inf on the tube's far side."""
    cb, nb, _ = branch_frame(m)
    x = x_mm - cb
    s = np.linalg.norm(x - np.outer(x @ nb, nb), axis=1)
    return np.where(x @ nb > 0, s, np.inf)


def _with_fields(surf, tawss, osi, direction):
    surf.point_data["wallShearStress"] = tawss[:, None] * direction
    surf.point_data["TAWSS"] = tawss
    surf.point_data["OSI"] = osi
    return surf


def wall_patch(*, branch: bool, bumps: float = 0.0):
    """The CFD wall patch in metres (point data wallShearStress, TAWSS, OSI). ``bumps``: a relative
    radius perturbation of the main wall (a fit residual: the model stays the perfect tube)."""
    m = model()
    T, TH = np.meshgrid(np.linspace(0, 1, 241), 2 * np.pi * np.arange(192) / 192, indexing="ij")
    c = m.vcs.curve(T)
    pts = c + (m.surface_points(T, TH) - c) * (1 + bumps * np.sin(3 * TH) * np.sin(9 * np.pi * T))[..., None]
    main = grid_to_vtk(pts, close_theta=True).extract_surface(algorithm="dataset_surface").triangulate()
    if branch:  # cut the hole exactly on the branch's cylinder
        main.point_data["off"] = np.nan_to_num(disc_offset(m, main.points), posinf=1e3) - RB
        main = main.clip_scalar(scalars="off", value=0.0, invert=False)
        main = main.extract_surface(algorithm="dataset_surface").triangulate()
    f = main_field(main.points)
    main = _with_fields(main, f, np.full(main.n_points, 0.1), AXIS)
    if not branch:
        return m, main.scale(1e-3)
    cb, nb, eb = branch_frame(m)
    phi = 2 * np.pi * np.arange(96) / 96
    h0 = np.sqrt(R**2 - (RB * np.sin(phi)) ** 2)  # the rim: on the main cylinder
    H = h0 + np.linspace(0.0, 30.0, 40)[:, None]
    P = cb + (RB * np.cos(phi))[:, None] * AXIS + (RB * np.sin(phi))[:, None] * eb + H[..., None] * nb
    tube = grid_to_vtk(P[:, :, None], close_theta=True).extract_surface(algorithm="dataset_surface").triangulate()
    rim = np.arange(tube.n_points) < len(phi)  # the first ring: the main wall's values
    x = np.asarray(tube.points)
    tawss = np.where(rim, main_field(x), B)
    tube = _with_fields(tube, tawss, np.where(rim, 0.1, 0.45), np.where(rim[:, None], AXIS, nb))
    return m, (main + tube).extract_surface(algorithm="dataset_surface").triangulate().scale(1e-3)


@pytest.fixture(scope="module")
def interior():
    """A coarse tetrahedral lumen with U = 0, p = 0 (only the probe needs it)."""
    m = model()
    T, TH, RN = np.meshgrid(np.linspace(0, 1, 13), 2 * np.pi * np.arange(12) / 12, [0.0, 0.5, 1.0], indexing="ij")
    c = m.vcs.curve(T)
    pts = (c + (m.surface_points(T, TH) - c) * RN[..., None]).reshape(-1, 3) * 1e-3
    vol = pv.PolyData(np.unique(pts.round(12), axis=0)).delaunay_3d()
    vol.cell_data["U"] = np.zeros((vol.n_cells, 3))
    vol.cell_data["p"] = np.zeros(vol.n_cells)
    return vol


@pytest.fixture(scope="module")
def branched(interior):
    m, wall = wall_patch(branch=True)
    n_tau, n_theta, n_rho = GRID
    f = sample_mesh(interior, {"wall": wall}, m, n_tau=n_tau, n_theta=n_theta, n_rho=n_rho, rho_density=1.0)
    T, TH = np.meshgrid(f["tau"], f["theta"], indexing="ij")
    x = m.surface_points(T, TH).reshape(-1, 3)
    return m, f, x, disc_offset(m, x).reshape(T.shape)


def test_ostium_marks_the_disc_and_nothing_else(branched):
    m, f, x, s = branched
    mask = f["ostium"]
    inside = s < RB
    assert mask.shape == GRID[:2] and mask.dtype == bool
    assert inside.sum() >= 20 and mask.sum() == f["n_ostium"]
    assert not (mask & ~inside).any(), "marked points outside the ostium"
    # every point farther than the gap threshold (+ 0.05 R for the polygonal rim) from the rim is marked
    deep = RB - s > (OSTIUM_GAP + 0.05) * R
    assert deep.sum() >= 8 and mask[deep].all()
    # the unmarked points inside the disc are within one grid cell (2 mm) of its rim
    assert (RB - s[inside & ~mask]).max(initial=0.0) <= OSTIUM_GAP * R + 2.0
    assert f["ostium_fraction"] == pytest.approx(mask.mean())
    assert "ostium" in str(f["ostium_criterion"]) and f["wall_gap"][mask].max() > 0.3


def test_ostium_wall_values_are_nan_and_no_branch_value_leaks(branched):
    m, f, x, s = branched
    mask = f["ostium"]
    for key in ("WSS", "WSS_vcs", "WSS_kinematic", "TAWSS", "OSI"):
        assert np.isnan(f[key][mask]).all(), key
        assert np.isfinite(f[key][~mask]).all(), key
    assert np.isnan(rrt(f["TAWSS"], f["OSI"])[mask]).all() and np.isnan(ecap(f["TAWSS"], f["OSI"])[mask]).all()
    # unmarked points: the main wall's field, never the branch's (B = 50). Outside the disc the
    # closest point is the grid point itself (barycentric on the fine wall: 1e-3); inside, up to
    # 0.15 R = 1.5 mm away on the rim, where f differs by up to |grad f| 1.5 mm = 0.04
    expected = main_field(x).reshape(mask.shape)
    keep, out = ~mask, s >= RB
    np.testing.assert_allclose(f["TAWSS"][out], expected[out], atol=1e-3)
    np.testing.assert_allclose(f["TAWSS"][keep], expected[keep], atol=0.04)
    np.testing.assert_allclose(f["OSI"][keep], 0.1, atol=1e-9)
    np.testing.assert_allclose(f["WSS_vcs"][keep][:, 0], expected[keep], atol=0.04)  # along t: the axis
    np.testing.assert_allclose(f["WSS_vcs"][keep][:, 1:], 0.0, atol=1e-9)
    # interior samples are not masked
    assert np.isfinite(f["U"]).all() and np.isfinite(f["p"]).all()


def test_ostium_mask_written_and_summarised(branched, tmp_path):
    _, f, _, _ = branched
    write_fields(f, tmp_path / "fields.npz", vtu_path=tmp_path / "fields.vtu")
    g = load_fields(tmp_path / "fields.npz")
    np.testing.assert_array_equal(g["ostium"], f["ostium"])
    s = json.loads((tmp_path / "fields.json").read_text())
    assert s == summary(f)
    assert s["n_ostium"] == int(f["ostium"].sum()) > 0 and "rho_w" in s["ostium_criterion"]
    assert 0 < s["wall_gap_max_kept"] < OSTIUM_GAP
    vtu = pv.read(tmp_path / "fields.vtu")
    assert vtu.point_data["ostium"].sum() == s["n_ostium"]


@pytest.mark.parametrize("bumps", [0.0, 0.06])
def test_lumen_without_branch_has_no_ostium(interior, bumps):
    """The tube without a branch, exact or with a 6 % radius residual (a fitted model's): no mask."""
    m, wall = wall_patch(branch=False, bumps=bumps)
    n_tau, n_theta, n_rho = GRID
    f = sample_mesh(interior, {"wall": wall}, m, n_tau=n_tau, n_theta=n_theta, n_rho=n_rho, rho_density=1.0)
    assert f["n_ostium"] == 0 and not f["ostium"].any()
    assert np.isfinite(f["WSS"]).all() and np.isfinite(f["TAWSS"]).all()
    assert f["wall_gap"].max() == pytest.approx(bumps, abs=0.01)


def test_ostium_mask_thresholds_and_end_rows():
    """Gap above OSTIUM_GAP or the CFD normal turned beyond 60 degrees: an ostium; a turned normal
    on the end rows (the wall patch's rim at the inlet or outlet) is not."""
    gap = np.zeros((5, 4))
    cos = np.ones((5, 4))
    gap[2, 1] = OSTIUM_GAP * 1.01
    cos[3, 2] = OSTIUM_NORMAL_COS * 0.99
    cos[0, 0] = cos[-1, 3] = 0.0
    expected = np.zeros((5, 4), bool)
    expected[2, 1] = expected[3, 2] = True
    np.testing.assert_array_equal(ostium_mask(gap, cos), expected)
    np.testing.assert_array_equal(ostium_mask(gap, cos, max_gap=np.inf, min_normal_cos=0.0), False)
