"""Resampling CFD fields on the VCS grid: analytic Poiseuille tube (VTK mesh, and OpenFOAM when installed)."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
import pyvista as pv  # a dependency of vcs: a broken install must fail, not skip
from scipy.interpolate import BSpline

from vcs.centerline import uniform_knots
from vcs.cfd.resample import load_fields, sample_mesh, write_fields
from vcs.grid import from_vcs_components, grid_axes, grid_to_vtk, local_frame, measurement_grid, to_vcs_components
from vcs.model import VesselCoordinateSystem
from vcs.vessel import VesselModel
from vcs.wall import WallModel

RADIUS_MM = 10.0
LENGTH_MM = 120.0
AXIS = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])  # as tests/workflow/test_openfoam.py
U_MEAN = 0.064  # m/s
NU = 3.37e-6
RHO = 1060.0


def straight_model(radius_mm=RADIUS_MM, length_mm=LENGTH_MM, axis=AXIS, origin_mm=(0.0, 0.0, 0.0), L=5, K=7, R=7):
    """A straight tube model: arc-length line c(tau) = origin + tau * length * axis, rho_w = radius."""
    t = uniform_knots(L)
    greville = np.array([t[i + 1 : i + 4].mean() for i in range(L + 4)])
    c = np.asarray(origin_mm) + greville[:, None] * length_mm * np.asarray(axis)
    curve = BSpline(t, c, 3)
    v1 = np.cross(axis, [1.0, 0.0, 0.0])
    vcs = VesselCoordinateSystem(curve, v1 / np.linalg.norm(v1))
    return VesselModel(vcs, WallModel(K, R, np.full((K + 4, R + 1), radius_mm)))


def poiseuille(points_m, axis=AXIS, radius_m=RADIUS_MM * 1e-3):
    x = np.asarray(points_m)
    along = x @ axis
    r = np.linalg.norm(x - along[:, None] * axis, axis=1)
    u = 2 * U_MEAN * np.clip(1 - (r / radius_m) ** 2, 0, None)
    dpdx = 8 * NU * U_MEAN / radius_m**2  # kinematic pressure gradient
    return u[:, None] * axis, -dpdx * along, r


def wall_shear(points_m, tau_w, axis=AXIS, length_m=LENGTH_MM * 1e-3):
    """A non-constant analytic wall-shear field (kinematic), so that the resampling is checked
    for place, orientation and components, not only for unit scaling: axial part
    -tau_w (1 + 0.3 cos theta + 0.4 s / L) t, circumferential part 0.2 tau_w sin(2 theta) e_theta,
    with s along the axis and theta about it from v1 = axis x x_hat (the straight model's frame).

    Returns the (N, 3) vectors and, per point, the exact (axial, circumferential, radial)
    components."""
    x = np.asarray(points_m)
    s = x @ axis
    v1 = np.cross(axis, [1.0, 0.0, 0.0])
    v1 /= np.linalg.norm(v1)
    v2 = np.cross(axis, v1)
    th = np.arctan2(x @ v2, x @ v1)
    e_th = -np.sin(th)[:, None] * v1 + np.cos(th)[:, None] * v2
    ax = -tau_w * (1 + 0.3 * np.cos(th) + 0.4 * s / length_m)
    circ = 0.2 * tau_w * np.sin(2 * th)
    return ax[:, None] * axis + circ[:, None] * e_th, np.column_stack([ax, circ, 0 * ax])


@pytest.fixture(scope="module")
def tube_mesh():
    """Tetrahedral tube (Delaunay of a cylindrical point cloud, polygonal wall of 48 sides) with
    the analytic Hagen-Poiseuille U, p as point and cell data, and the wall with the analytic,
    non-constant WSS of :func:`wall_shear`."""
    nz, nth, nr = 41, 48, 7
    z = np.linspace(0, LENGTH_MM * 1e-3, nz)
    th = 2 * np.pi * np.arange(nth) / nth
    r = np.linspace(0, RADIUS_MM * 1e-3, nr)[1:]
    e1 = np.cross(AXIS, [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(AXIS, e1)
    Z, TH, RR = np.meshgrid(z, th, r, indexing="ij")
    ring = (RR[..., None] * (np.cos(TH)[..., None] * e1 + np.sin(TH)[..., None] * e2) + Z[..., None] * AXIS).reshape(
        -1, 3
    )
    pts = np.vstack([ring, z[:, None] * AXIS])
    vol = pv.PolyData(pts).delaunay_3d()
    for data, x in ((vol.point_data, vol.points), (vol.cell_data, vol.cell_centers().points)):
        u, p, _ = poiseuille(x)
        data["U"], data["p"] = u, p
    wall_pts = ring.reshape(nz, nth, nr - 1, 3)[:, :, -1]
    wall = grid_to_vtk(wall_pts, close_theta=True).triangulate()
    tau_w = 4 * NU * U_MEAN / (RADIUS_MM * 1e-3)  # kinematic |WSS|
    wall.point_data["wallShearStress"] = wall_shear(wall.points, tau_w)[0]
    wall.cell_data["U"] = np.zeros((wall.n_cells, 3))
    wall.cell_data["p"] = poiseuille(wall.cell_centers().points)[1]
    return vol, wall, tau_w


def test_grid_and_frame_components_round_trip():
    m = straight_model()
    tau, theta, rho_n = grid_axes(5, 8, 3)
    assert tau[0] == 0 and tau[-1] == 1 and rho_n[-1] == 1 and theta[-1] < 2 * np.pi
    F = local_frame(m, tau, theta)
    np.testing.assert_allclose(np.einsum("ijab,ijcb->ijac", F, F), np.broadcast_to(np.eye(3), F.shape), atol=1e-12)
    v = np.random.default_rng(0).normal(size=(5, 8, 3, 3))
    np.testing.assert_allclose(from_vcs_components(to_vcs_components(v, F), F), v, atol=1e-12)
    np.testing.assert_allclose(F[..., 0, :], np.broadcast_to(AXIS, (5, 8, 3)), atol=1e-12)


def test_vcs_grid_and_fields_npz_share_one_grid(tube_mesh):
    """`vcs grid` (measurement_grid) and the resampling (fields.npz) give the same nodes for the same
    numbers: n_tau x n_theta x n_rho nodes, tau/theta/rho_n from one definition, same points."""
    vol, wall, _ = tube_mesh
    m = straight_model()
    f = sample_mesh(vol, {"wall": wall}, m, n_tau=7, n_theta=8, n_rho=4)
    g = measurement_grid(m, n_tau=7, n_theta=8, n_rho=4)
    assert f["points"].shape == (7, 8, 4, 3) and g.points.shape == (7 * 8 * 4, 3)
    np.testing.assert_array_equal(g.points * f["rho_scale"], f["points"].reshape(-1, 3))
    T, TH, RN = np.meshgrid(f["tau"], f["theta"], f["rho_n"], indexing="ij")
    np.testing.assert_array_equal(g.tau, T.ravel())
    np.testing.assert_array_equal(g.theta, TH.ravel())
    np.testing.assert_array_equal(g.rho_n, RN.ravel())
    # analytic truth on the straight tube: rho = rho_n * R around the axis
    r = np.linalg.norm(np.cross(g.points, AXIS), axis=1)
    np.testing.assert_allclose(r, g.rho_n * RADIUS_MM, atol=1e-6)


def check_poiseuille(f, tau_w, *, inner=(0.1, 0.9)):
    """Axial velocity vs 2 U_mean (1 - rho_n^2): RMS error / U_mean; |WSS| relative error."""
    sel = (f["tau"] >= inner[0]) & (f["tau"] <= inner[1])
    u_ax = f["U_vcs"][sel][..., 0]
    exact = 2 * U_MEAN * (1 - f["rho_n"] ** 2)
    rms = np.sqrt(np.mean((u_ax - exact) ** 2)) / U_MEAN
    wss = np.linalg.norm(f["WSS"][sel], axis=-1)
    wss_err = np.abs(wss.mean() / (RHO * tau_w) - 1)
    return rms, wss_err


def test_sample_mesh_poiseuille_analytic(tube_mesh, tmp_path):
    vol, wall, tau_w = tube_mesh
    m = straight_model()
    f = sample_mesh(vol, {"wall": wall}, m, n_tau=21, n_theta=16, n_rho=9)
    assert f["U"].shape == (21, 16, 9, 3) and f["p"].shape == (21, 16, 9) and f["WSS"].shape == (21, 16, 3)
    rms, _ = check_poiseuille(f, tau_w)
    assert rms < 0.03, rms
    # WSS node by node against the analytic field at the grid's (tau, theta): in Pa, Cartesian
    # and in the local frame (axial, circumferential, radial). On a grid whose nodes are not the
    # wall's vertices (17 x 20; the 48-gon has 41 rings), between them: the grid points project
    # onto flat faces, where the barycentric interpolation of this smooth field is within 0.2 %
    # of tau_w (theta mirrored or tau reversed would be off by up to 40 %).
    g = sample_mesh(vol, {"wall": wall}, m, n_tau=17, n_theta=20, n_rho=3)
    T, TH = np.meshgrid(g["tau"], g["theta"], indexing="ij")
    v1 = np.cross(AXIS, [1.0, 0.0, 0.0])
    v1 /= np.linalg.norm(v1)
    at = (T * LENGTH_MM * 1e-3)[..., None] * AXIS + RADIUS_MM * 1e-3 * (
        np.cos(TH)[..., None] * v1 + np.sin(TH)[..., None] * np.cross(AXIS, v1)
    )
    vec, comp = wall_shear(at.reshape(-1, 3), tau_w)
    np.testing.assert_allclose(g["WSS"], RHO * vec.reshape(17, 20, 3), rtol=0, atol=0.005 * RHO * tau_w)
    np.testing.assert_allclose(g["WSS_vcs"], RHO * comp.reshape(17, 20, 3), rtol=0, atol=0.005 * RHO * tau_w)
    assert np.ptp(g["WSS_vcs"][..., 0]) > 0.9 * RHO * tau_w  # the field does vary over the map
    # no-slip on the wall layer, whether or not the probe found the point in the mesh
    assert f["n_wall_noslip"] == 21 * 16
    np.testing.assert_array_equal(f["U"][:, :, -1], 0.0)
    assert f["n_interior_nearest"] < 0.02 * f["n_points"]
    # pressure in Pa, linear along tau; within 1 % of the drop: near the axis the 27 nearest cell
    # centres of this lattice (0.2 mm apart around the axis, 3 mm along it) lie in one axial layer
    dpdx = 8 * NU * U_MEAN / (RADIUS_MM * 1e-3) ** 2
    drop = RHO * dpdx * LENGTH_MM * 1e-3
    np.testing.assert_allclose(f["p"][:, 0, 0], -drop * f["tau"], atol=0.01 * drop)
    np.testing.assert_allclose(f["p"], f["p_kinematic"] * RHO)
    write_fields(f, tmp_path / "fields.npz", vtu_path=tmp_path / "fields.vtu")
    g = load_fields(tmp_path / "fields.npz")
    np.testing.assert_array_equal(g["U"], f["U"])
    assert (tmp_path / "fields.json").is_file()
    vtu = pv.read(tmp_path / "fields.vtu")
    assert vtu.n_points == 21 * 17 * 9 and "U_vcs" in vtu.point_data


def test_sample_mesh_far_outside_counts_nearest(tube_mesh):
    """A model 20 % wider than the mesh: the outer grid points are outside the CFD mesh and get the
    nearest cell's values, counted."""
    vol, wall, _ = tube_mesh
    f = sample_mesh(vol, {"wall": wall}, straight_model(radius_mm=12.0), n_tau=9, n_theta=8, n_rho=7)
    assert f["n_interior_nearest"] > 0
    assert np.all(np.isfinite(f["U"])) and np.all(np.isfinite(f["p"]))
    assert f["interior_nearest_max_distance"] > 1e-3


# --------------------------------------------------------------- real OpenFOAM (colleague's runner)
def _foam_api():
    from vcs.cfd import detect_openfoam, render_case, run_case  # the project's own: never a skip
    from vcs.phantoms.analytic import write_closed_tube_stl

    if shutil.which("simpleFoam") is None or detect_openfoam()[0] != "esi":
        pytest.skip("Debian's ESI OpenFOAM (simpleFoam) not installed")
    return write_closed_tube_stl, render_case, run_case


@pytest.fixture(scope="module")
def poiseuille_case(tmp_path_factory):
    """The Hagen-Poiseuille tube of tests/workflow/test_openfoam.py, solved by vcs.cfd."""
    write_closed_tube_stl, render_case, run_case = _foam_api()
    tmp = tmp_path_factory.mktemp("pois_resample")
    stl = write_closed_tube_stl(
        tmp / "tube.stl", radius=RADIUS_MM * 1e-3, length=LENGTH_MM * 1e-3, n_theta=96, n_z=60, axis=AXIS
    )
    q = U_MEAN * np.pi * (RADIUS_MM * 1e-3) ** 2
    cfg = {
        "mesh": {"cell_size": 1.25e-3},
        "inlet": {"type": "parabolic", "flow_rate": q},
        "solver": {"max_iterations": 800, "startup_iterations": 50, "fallback": "none"},
    }
    render_case(tmp / "case", stl, cfg, flavour="esi")
    status = run_case(tmp / "case", ranks=1)
    return tmp / "case", status


@pytest.mark.openfoam
def test_sample_case_hagen_poiseuille(poiseuille_case, tmp_path):
    from vcs.cfd import sample_case

    case, status = poiseuille_case
    assert status["converged"], status.get("reason")
    f = sample_case(case, straight_model(), n_tau=41, n_theta=24, n_rho=11)
    rms, wss_err = check_poiseuille(f, 4 * NU * U_MEAN / (RADIUS_MM * 1e-3), inner=(0.2, 0.8))
    write_fields(f, tmp_path / "fields.npz", vtu_path=tmp_path / "fields.vtu")
    assert f["n_interior_nearest"] < 0.01 * f["n_points"]
    assert rms <= 0.03, rms  # 0.015 with the MLS interpolation (0.034 with the VTK cell-to-point probe)
    assert wss_err <= 0.05, wss_err
    # the snapped wall of the model tube has no ostium (gap <= 0.008 rho_w, normals within 4 deg
    # away from the ends; the outlet rim's snapped faces are turned up to 61 deg: not an ostium)
    assert f["n_ostium"] == 0 and np.isfinite(f["WSS"]).all()
