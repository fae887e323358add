"""Regression tests named after defects found in review (issue 7: bad input never gives a wrong
result or a traceback)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from vcs.io import Surface
from vcs.phantoms import make_phantom, write_stl
from vcs.vessel import fit_vessel


def run(*args):
    return subprocess.run([sys.executable, "-m", "vcs.cli", *map(str, args)], capture_output=True, text=True)


@pytest.fixture(scope="module")
def capped_tube(tmp_path_factory):
    """Closed tube r = 5 mm, z in [0, 60], flat caps: ends must be given as points."""
    path = tmp_path_factory.mktemp("capped") / "capped.stl"
    m = trimesh.creation.cylinder(radius=5, height=60, sections=64).subdivide_to_size(1.0)
    m.apply_translation([0, 0, 30])
    m.export(path)
    return path


def test_stray_component_does_not_change_the_voxel_grid():
    ph = make_phantom("tube", resolution=2.0)
    ref, rep_ref, _ = fit_vessel(Surface(ph.vertices, ph.faces, {}, "mm", "given", "t"), K=None)
    V = np.vstack([ph.vertices, [[2000, 0, 0], [2001, 0, 0], [2000, 1, 0]]])
    F = np.vstack([ph.faces, [[len(ph.vertices), len(ph.vertices) + 1, len(ph.vertices) + 2]]])
    m, rep, _ = fit_vessel(Surface(V, F, {}, "mm", "given", "t"), K=None)
    assert rep["voxel_size_mm"] == pytest.approx(rep_ref["voxel_size_mm"])
    assert any("disconnected" in w for w in rep["warnings"])
    tau = np.linspace(0, 1, 50)
    assert np.abs(m.vcs.curve(tau) - ref.vcs.curve(tau)).max() < 1e-9


def test_small_cap_files_are_accepted(tmp_path):
    """Caps of a 3 mm-wide vessel: the whole-vessel size check must not apply to them."""
    z = np.linspace(0, 40, 81)
    from vcs.phantoms import sweep_tube

    V, F = sweep_tube(np.column_stack([0 * z, 0 * z, z]), 1.5, edge=0.3)
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "w.stl")
    for name, zc in (("in.stl", 0.0), ("out.stl", 40.0)):
        disc = trimesh.creation.cylinder(radius=1.5, height=0.01, sections=32)
        disc.apply_translation([0, 0, zc])
        disc.export(tmp_path / name)
    r = run(
        "fit",
        tmp_path / "w.stl",
        "-o",
        tmp_path / "o",
        "--units",
        "mm",
        "--K",
        "7",
        "--R",
        "7",
        "--inlet-cap",
        tmp_path / "in.stl",
        "--outlet-cap",
        tmp_path / "out.stl",
    )
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "o" / "fit_report.json").read_text())["ends_method"] == "cap_files"


def test_off_centre_point_on_a_closed_tube_gives_the_axial_end_plane(capped_tube, tmp_path):
    r = run("fit", capped_tube, "-o", tmp_path / "o", "--units", "mm", "--inlet", "1,1,0.5", "--outlet", "0,0,59.5")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "o" / "fit_report.json").read_text())
    n = np.array(rep["inlet"]["normal"])
    assert np.degrees(np.arccos(abs(n[2]))) < 2.0
    assert np.linalg.norm(np.array(rep["inlet"]["center_mm"])[:2]) < 0.2
    assert rep["residual_max_mm"] < 0.1


def test_points_on_the_caps_keep_the_caps_out_of_the_wall(capped_tube, tmp_path):
    r = run("fit", capped_tube, "-o", tmp_path / "o", "--units", "mm", "--inlet", "0,0,0", "--outlet", "0,0,60")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "o" / "fit_report.json").read_text())
    assert np.linalg.norm(np.array(rep["inlet"]["center_mm"]) - [0, 0, 0]) < 0.2
    assert rep["residual_mean_mm"] < 0.02 and rep["points_not_used"]["branch"] == 0


@pytest.mark.parametrize("args", [["--n-tau", "0"], ["--n-tau", "-3"], ["--n-theta", "0"]])
def test_wall_rejects_non_positive_sizes(tmp_path, args):
    write_stl(make_phantom("tube", resolution=2.0), tmp_path / "t.stl")
    assert run("fit", tmp_path / "t.stl", "-o", tmp_path / "f", "--units", "mm").returncode == 0
    r = run("wall", tmp_path / "f" / "model.json", "-o", tmp_path / "w.stl", *args)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert not (tmp_path / "w.stl").exists()


@pytest.mark.parametrize("content", ["tau,theta,rho\n0.5,abc,1\n", "tau,theta,rho\n", "x,y\n1,2\n"])
def test_bad_coordinate_tables_and_models_give_one_line(tmp_path, content):
    write_stl(make_phantom("tube", resolution=2.0), tmp_path / "t.stl")
    run("fit", tmp_path / "t.stl", "-o", tmp_path / "f", "--units", "mm")
    (tmp_path / "c.csv").write_text(content)
    r = run("cartesian", tmp_path / "f" / "model.json", tmp_path / "c.csv", "-o", tmp_path / "x.csv")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
    model = json.loads((tmp_path / "f" / "model.json").read_text())
    model["units"]["input"] = "inch"
    (tmp_path / "bad.json").write_text(json.dumps(model))
    r = run("wall", tmp_path / "bad.json", "-o", tmp_path / "w.stl")
    assert r.returncode == 2 and "not a valid model.json" in r.stderr


def test_absurd_L_is_named_in_the_error(tmp_path):
    write_stl(make_phantom("tube", resolution=2.0), tmp_path / "t.stl")
    r = run("fit", tmp_path / "t.stl", "-o", tmp_path / "o", "--units", "mm", "--L", "500")
    assert r.returncode == 2 and "L = 500" in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_a_closed_thin_disc_cap_file_gives_its_axis_and_radius():
    """Regression: a cap file that is a closed thin disc (both faces and the rim) has an area
    vector sum of ~0; its normal was that round-off's direction ([0, 1, 0] for a disc in the
    z = 0 plane: the centerline fit then failed, 'Singular matrix') and its radius sqrt(2) too big.
    Truth: the disc's axis z and the equivalent radius of its 32-gon face (1.5 mm circumradius)."""
    from vcs.ends import _end_from_faces

    disc = trimesh.creation.cylinder(radius=1.5, height=0.01, sections=32)
    end = _end_from_faces(np.asarray(disc.vertices), np.asarray(disc.faces), "cap")
    assert abs(abs(end.normal[2]) - 1.0) < 1e-9
    polygon = np.sqrt(0.5 * 32 * 1.5**2 * np.sin(2 * np.pi / 32) / np.pi)  # equivalent radius of the 32-gon
    assert end.radius == pytest.approx(polygon, rel=0.01)
