"""CLI: outputs of `vcs fit/coords/cartesian/wall/grid`, and bad input -> one line, exit code 2."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import sweep


def run(*args):
    return subprocess.run([sys.executable, "-m", "vcs.cli", *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def tube_stl(tmp_path_factory):
    """Gently curved open tube (mm) written as STL with trimesh (independent writer)."""
    import trimesh

    c = lambda s: np.stack([10 * np.sin(2 * s), 0 * s, 100 * s], -1)  # noqa: E731
    ex = lambda s: np.tile([1.0, 0, 0], (len(s), 1))  # noqa: E731
    ey = lambda s: np.tile([0, 1.0, 0], (len(s), 1))  # noqa: E731
    V, F = sweep(c, ex, ey, 8.0, 80, 40)
    path = tmp_path_factory.mktemp("tube") / "tube.stl"
    trimesh.Trimesh(V, F, process=False).export(path)
    return path


def test_fit_coords_cartesian_round_trip(tube_stl, tmp_path):
    out = tmp_path / "fit"
    r = run("fit", tube_stl, "-o", out, "--units", "mm")
    assert r.returncode == 0, r.stderr
    rep = json.loads((out / "fit_report.json").read_text())
    assert rep["ends_method"] == "open_loops" and rep["units"] == "mm"
    assert (out / "centerline.vtp").is_file() and (out / "wall_residuals.vtp").is_file()
    pts = np.array([[0.5, 1.0, 30.0], [2.0, -3.0, 60.0]])
    np.savetxt(tmp_path / "p.csv", pts, delimiter=",", header="x,y,z", comments="")
    assert run("coords", out / "model.json", tmp_path / "p.csv", "-o", tmp_path / "c.csv").returncode == 0
    assert run("cartesian", out / "model.json", tmp_path / "c.csv", "-o", tmp_path / "x.csv").returncode == 0
    back = np.loadtxt(tmp_path / "x.csv", delimiter=",", skiprows=1)
    assert np.abs(back - pts).max() < 1e-6
    # same input, same bytes
    out2 = tmp_path / "fit2"
    run("fit", tube_stl, "-o", out2, "--units", "mm")
    assert (out / "model.json").read_bytes() == (out2 / "model.json").read_bytes()


def test_units_cm_reported_and_outputs_in_input_units(tube_stl, tmp_path):
    import trimesh

    m = trimesh.load(tube_stl)
    m.apply_scale(0.1)  # now in cm
    cm = tmp_path / "tube_cm.stl"
    m.export(cm)
    r = run("fit", cm, "-o", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "f" / "fit_report.json").read_text())
    assert rep["units"] == "cm" and rep["units_source"].startswith("auto")
    assert abs(rep["centerline_length_mm"] - 102.0) < 3.0


@pytest.mark.parametrize("kind", ["missing", "empty", "extension", "garbage", "nan"])
def test_bad_mesh_files_give_one_line(tmp_path, kind):
    path = tmp_path / ("m.stl" if kind != "extension" else "m.xyz")
    if kind == "empty":
        path.write_bytes(b"")
    elif kind in ("garbage", "extension"):
        path.write_text("this is not a mesh\n")
    elif kind == "nan":
        path.write_text(
            "solid s\nfacet normal 0 0 1\nouter loop\nvertex nan 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
            "endloop\nendfacet\nendsolid s\n"
        )
    r = run("fit", path, "-o", tmp_path / "out")
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "out" / "model.json").exists()


def test_closed_surface_without_ends(tmp_path):
    """A closed tube with two flat caps fits with no end given (the larger cap is the inlet), or
    with points; a closed blob with no ends to find is one line asking for them."""
    import trimesh

    path = tmp_path / "closed.stl"
    trimesh.creation.cylinder(radius=10, height=100, sections=48).subdivide_to_size(2.0).export(path)
    r = run("fit", path, "-o", tmp_path / "a", "--units", "mm")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "a" / "fit_report.json").read_text())
    assert rep["ends_method"] == "flat_caps" and abs(rep["centerline_length_mm"] - 100.0) < 0.5
    r = run("fit", path, "-o", tmp_path / "o", "--units", "mm", "--inlet", "0,0,49", "--outlet", "0,0,-49")
    assert r.returncode == 0, r.stderr
    blob = tmp_path / "blob.stl"
    trimesh.creation.icosphere(4, radius=10).export(blob)
    r = run("fit", blob, "-o", tmp_path / "b", "--units", "mm")
    assert r.returncode == 2 and "--inlet" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "b" / "model.json").exists()


def test_three_openings_need_a_choice_and_points_outside(shared_data, tmp_path):
    mesh = shared_data / "vmtk_aorta_bifurcation_open.stl"
    r = run("fit", mesh, "-o", tmp_path / "o")
    assert r.returncode == 2 and "3 ends" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    r = run("fit", mesh, "-o", tmp_path / "o", "--inlet", "0,0,0", "--outlet", "500,500,500")
    assert r.returncode == 2 and "outside the lumen" in r.stderr, r.stderr


def test_wall_stl_and_grid(tube_stl, tmp_path):
    import pyvista as pv
    import trimesh

    run("fit", tube_stl, "-o", tmp_path / "f", "--units", "mm")
    r = run("wall", tmp_path / "f" / "model.json", "-o", tmp_path / "wall.stl", "--units", "m", "--extend-outlet", "2")
    assert r.returncode == 0, r.stderr
    text = (tmp_path / "wall.stl").read_text()
    assert [ln.split()[1] for ln in text.splitlines() if ln.startswith("solid")] == ["wall", "inlet", "outlet"]
    tm = trimesh.load(tmp_path / "wall.stl", force="mesh")
    tm.merge_vertices()  # the three solids are loaded as separate parts
    assert tm.is_watertight and tm.volume > 0
    for scheme in ("cylindrical", "ogrid"):
        r = run(
            "grid",
            tmp_path / "f" / "model.json",
            "-o",
            tmp_path / f"{scheme}.vtu",
            "--scheme",
            scheme,
            "--n-tau",
            10,
            "--n-theta",
            16,
            "--n-rho",
            4,
        )
        assert r.returncode == 0, r.stderr
        g = pv.read(tmp_path / f"{scheme}.vtu")
        vol = g.compute_cell_sizes()["Volume"]
        assert {"tau", "theta", "rho_n"} <= set(g.point_data.keys())
        if scheme == "ogrid":
            assert vol.min() > 0  # no degenerate cell at the axis
        else:
            # node counts as given (the resampling's definition): 10 x 16 x 4 nodes, 9 x 16 x 3 cells;
            # cells of the radial layers k = 0, 1, 2 (k = 0: wedges at the axis) have volumes in the
            # ratio of the annuli areas, (k+1)^2 - k^2 = 1 : 3 : 5
            assert g.n_points == 10 * 16 * 4 and g.n_cells == 9 * 16 * 3
            layer_vol = np.asarray(vol).reshape(9, 16, 3).sum(axis=(0, 1))
            np.testing.assert_allclose(layer_vol / layer_vol[0], [1, 3, 5], rtol=0.05)
            assert np.allclose(np.unique(np.round(g.point_data["rho_n"], 12)), [0, 1 / 3, 2 / 3, 1])
            assert np.allclose(np.unique(np.round(g.point_data["tau"], 12)), np.linspace(0, 1, 10))


def test_inputs_are_never_overwritten(tube_stl, tmp_path):
    run("fit", tube_stl, "-o", tmp_path / "f", "--units", "mm")
    pts = tmp_path / "p.csv"
    pts.write_text("x,y,z\n0,0,30\n")
    r = run("coords", tmp_path / "f" / "model.json", pts, "-o", pts)
    assert r.returncode == 2 and "also an input" in r.stderr
    assert pts.read_text() == "x,y,z\n0,0,30\n"


def test_output_checks_of_grid_sensitivity_phantom(tube_stl, tmp_path):
    """Bad -o for `vcs grid`, `vcs sensitivity` and `vcs phantom`: one line, exit 2, nothing written
    (regressions: an internal error after the whole sweep; --params overwriting the STL)."""
    run("fit", tube_stl, "-o", tmp_path / "f", "--units", "mm")
    model = tmp_path / "f" / "model.json"
    r = run("grid", model, "-o", tmp_path / "g.json")
    assert r.returncode == 2 and "must end in .vtu" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "g.json").exists()
    r = run("grid", model, "-o", model)
    assert r.returncode == 2 and "also an input" in r.stderr
    (tmp_path / "file").write_text("x")
    r = run("sensitivity", tube_stl, "--L", "9:9:1", "--K", "7:7:1", "--R", "7:7:1", "-o", tmp_path / "file")
    assert r.returncode == 2 and "not a directory" in r.stderr, r.stderr
    assert (tmp_path / "file").read_text() == "x"
    stl = tmp_path / "p.stl"
    r = run("phantom", "--kind", "tube", "-o", stl, "--params", stl)
    assert r.returncode == 2 and "--params" in r.stderr and not stl.exists()
