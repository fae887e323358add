"""Candidate ends (issue 10): `vcs ends`, choosing listed ends in `vcs fit` (end:N, NAME=VALUE),
flat unlabelled caps and blunt closed ends of closed surfaces, labelled caps among many face groups."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh

from vcs.ends import EndSelector, find_ends, list_ends, parse_end_option
from vcs.errors import VCSInputError

SHIFT = np.array([-312.0, -45.5, -1180.0])  # scanner coordinates: mostly negative


def run(*args):
    return subprocess.run([sys.executable, "-m", "vcs.cli", *map(str, args)], capture_output=True, text=True)


def one_line_error(r, *words):
    assert r.returncode == 2, r.stdout + r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for w in words:
        assert w in lines[0], lines[0]
    return lines[0]


def capped_cylinder(radius=10.0, height=100.0, shift=SHIFT):
    """Closed cylinder along z with flat caps (trimesh), moved to negative coordinates (mm)."""
    m = trimesh.creation.cylinder(radius=radius, height=height, sections=48).subdivide_to_size(2.0)
    m.apply_translation(shift)
    return m


@pytest.fixture(scope="module")
def closed_stl(tmp_path_factory):
    path = tmp_path_factory.mktemp("closed") / "closed tube.stl"
    capped_cylinder().export(path)
    return path


@pytest.fixture(scope="module")
def labelled_vtp(tmp_path_factory):
    """A closed tube whose faces form 17 labelled groups (ModelFaceID): 15 wall patches (strips
    around the axis, not flat) and the two flat caps (labels 16 and 17), as SimVascular writes a
    vessel whose wall is split in faces."""
    import pyvista as pv

    m = capped_cylinder()
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    c = v[f].mean(axis=1) - SHIFT
    n = m.face_normals
    label = 1 + (np.floor((np.arctan2(c[:, 1], c[:, 0]) + np.pi) / (2 * np.pi) * 15) % 15).astype(np.int32)
    label[n[:, 2] < -0.99] = 16
    label[n[:, 2] > 0.99] = 17
    assert len(np.unique(label)) == 17
    poly = pv.PolyData(v, np.hstack([np.full((len(f), 1), 3), f]).ravel())
    poly.cell_data["ModelFaceID"] = label
    path = tmp_path_factory.mktemp("labelled") / "aorta17.vtp"
    poly.save(path)
    return path


# ------------------------------------------------------------------ parsing


@pytest.mark.parametrize(
    "text, expected",
    [
        ("-40,0,0", [-40, 0, 0]),
        ("-40, 0, 0", [-40, 0, 0]),
        (" -40,0,0 ", [-40, 0, 0]),
        ("-.5,1e-3,-2E1", [-0.5, 1e-3, -20]),
        ("end:3", EndSelector("end:3", index=3)),
        (" END: 3", EndSelector(" END: 3", index=3)),
        ("ModelFaceID=2", EndSelector("ModelFaceID=2", array="ModelFaceID", value=2)),
        ("CapID = -1", EndSelector("CapID = -1", array="CapID", value=-1)),
    ],
)
def test_parse_end_option(text, expected):
    got = parse_end_option(text, "inlet")
    if isinstance(expected, EndSelector):
        assert got == expected
    else:
        np.testing.assert_allclose(got, expected)


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "nan,0,0", "3", "end:", "end:-1", "=2", "1,2,3,4"])
def test_parse_end_option_refuses_anything_else(text):
    with pytest.raises(VCSInputError, match="--outlet .* is not a point") as exc:
        parse_end_option(text, "outlet")
    assert "end:N" in str(exc.value)
    if text == "3":
        assert "write end:3" in str(exc.value)


# ------------------------------------------------------------------ candidate lists


def test_closed_tube_has_two_flat_caps_and_fits_with_no_end_given(closed_stl, tmp_path):
    m = capped_cylinder()
    ends = list_ends(np.asarray(m.vertices), np.asarray(m.faces))
    assert [c.kind for c in ends.candidates] == ["flat cap", "flat cap"]
    for c in ends.candidates:
        assert abs(c.radius - 10.0) < 0.1 and abs(abs(c.normal[2]) - 1) < 1e-6
        assert abs(abs(c.end.center[2] - SHIFT[2]) - 50.0) < 1e-6  # the caps' centres
        assert np.dot(c.normal, SHIFT - c.end.center) > 0  # normals into the lumen
    assert not ends.wall_mask[ends.candidates[0].faces].any()  # caps are not wall
    r = run("fit", closed_stl, "-o", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "f" / "fit_report.json").read_text())
    assert rep["ends_method"] == "flat_caps" and rep["units"] == "mm"
    assert abs(rep["centerline_length_mm"] - 100.0) < 0.5 and rep["residual_mean_mm"] < 0.05


def test_vcs_ends_lists_and_writes_json(closed_stl, tmp_path):
    r = run("ends", closed_stl, "-o", tmp_path / "ends.json")
    assert r.returncode == 0, r.stderr
    assert "end:0  flat cap" in r.stdout and "end:1  flat cap" in r.stdout
    assert "--inlet end:0 --outlet end:1" in r.stdout and "finds these two ends by itself" in r.stdout
    table = json.loads((tmp_path / "ends.json").read_text())
    assert table["units"] == "mm" and len(table["candidates"]) == 2 and table["suggested"]["automatic"]
    c0 = table["candidates"][0]
    assert c0["select"] == "end:0" and c0["kind"] == "flat cap" and abs(c0["radius"] - 10) < 0.1
    # the printed point options work as they are (minus signs after '=')
    pts = table["suggested"]["point_options"].split()
    assert pts[0].startswith("--inlet=-") and pts[1].startswith("--outlet=-")
    r = run("fit", closed_stl, "-o", tmp_path / "p", *pts)
    assert r.returncode == 0, r.stderr
    # the same ends chosen by index, by point after a space, or automatically: the same model
    r = run("fit", closed_stl, "-o", tmp_path / "i", "--inlet", "end:0", "--outlet", "end:1")
    assert r.returncode == 0, r.stderr
    r = run("fit", closed_stl, "-o", tmp_path / "a")
    assert r.returncode == 0, r.stderr
    ref = (tmp_path / "i" / "model.json").read_bytes()
    assert (tmp_path / "p" / "model.json").read_bytes() == ref == (tmp_path / "a" / "model.json").read_bytes()
    # never overwrites the input
    one_line_error(run("ends", closed_stl, "-o", closed_stl), "also an input")


def test_choosing_the_outlet_first_reverses_tau(closed_stl, tmp_path):
    r = run("fit", closed_stl, "-o", tmp_path / "r", "--inlet", "end:1", "--outlet", "end:0")
    assert r.returncode == 0, r.stderr
    rev = json.loads((tmp_path / "r" / "fit_report.json").read_text())
    table = json.loads(
        run("ends", closed_stl, "-o", tmp_path / "e.json").returncode == 0 and (tmp_path / "e.json").read_text()
    )
    np.testing.assert_allclose(rev["inlet"]["center_mm"], table["candidates"][1]["center"], atol=1e-3)


@pytest.mark.parametrize(
    "args, words",
    [
        (["--inlet", "end:7", "--outlet", "end:0"], ["--inlet end:7", "end:0 to end:1", "vcs ends"]),
        (["--inlet", "end:1", "--outlet", "end:1"], ["both choose end:1"]),
        (["--inlet", "ModelFaceID=2", "--outlet", "end:0"], ["no cap labelled ModelFaceID=2", "no labelled caps"]),
        (["--inlet", "2", "--outlet", "end:0"], ["write end:2"]),
    ],
)
def test_bad_end_choices_give_one_line(closed_stl, tmp_path, args, words):
    one_line_error(run("fit", closed_stl, "-o", tmp_path / "o", *args), *words)
    assert not (tmp_path / "o" / "model.json").exists()


def test_seventeen_labelled_face_groups(labelled_vtp, tmp_path):
    """Only the two flat groups are caps; the 15 wall patches stay wall. With no end given the two
    caps are the ends; points written with a space and a minus sign pick them too."""
    import pyvista as pv

    mesh = pv.read(labelled_vtp)
    labels = np.asarray(mesh.cell_data["ModelFaceID"])
    faces = np.asarray(mesh.faces).reshape(-1, 4)[:, 1:]
    ends = list_ends(np.asarray(mesh.points), faces, {"ModelFaceID": labels})
    assert [c.label for c in ends.candidates] == ["ModelFaceID=16", "ModelFaceID=17"]
    assert ends.wall_mask.sum() == (labels <= 15).sum()
    r = run("ends", labelled_vtp)
    assert r.returncode == 0 and "ModelFaceID=16" in r.stdout, r.stderr
    bottom = ", ".join(f"{x:g}" for x in SHIFT - [0, 0, 50])  # "-312, -45.5, -1230"
    top = ",".join(f"{x:g}" for x in SHIFT + [0.5, -0.5, 49.0])
    r = run("fit", labelled_vtp, "-o", tmp_path / "p", "--inlet", top, "--outlet", bottom)
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "p" / "fit_report.json").read_text())
    assert rep["ends_method"] == "labelled_caps" and rep["inlet"]["source"] == "ModelFaceID=17"
    assert rep["outlet"]["source"] == "ModelFaceID=16"
    r = run("fit", labelled_vtp, "-o", tmp_path / "l", "--inlet", "ModelFaceID=17", "--outlet", "ModelFaceID=16")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "l" / "model.json").read_bytes() == (tmp_path / "p" / "model.json").read_bytes()
    r = run("fit", labelled_vtp, "-o", tmp_path / "a")
    assert r.returncode == 0, r.stderr
    one_line_error(
        run("fit", labelled_vtp, "-o", tmp_path / "x", "--inlet", "ModelFaceID=3", "--outlet", "end:0"),
        "no cap labelled ModelFaceID=3",
        "ModelFaceID=16, ModelFaceID=17",
    )


def test_any_integer_cell_array_with_few_labels_labels_caps():
    m = capped_cylinder()
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    group = np.where(m.face_normals[:, 2] < -0.99, 7, np.where(m.face_normals[:, 2] > 0.99, 9, 0)).astype(float)
    ends = list_ends(v, f, {"GroupIds": group, "Quality": np.linspace(0, 1, len(f))})
    assert ends.cap_array == "GroupIds" and [c.label for c in ends.candidates] == ["GroupIds=7", "GroupIds=9"]
    # an array whose groups are not flat discs is not a cap labelling: the caps are found as flat caps
    walls = (np.arange(len(f)) % 5).astype(np.int32)
    ends = list_ends(v, f, {"ModelFaceID": walls})
    assert ends.cap_array is None and [c.kind for c in ends.candidates] == ["flat cap", "flat cap"]
    # nor is an array numbering the cells (every single triangle is a flat disc)
    small = trimesh.creation.cylinder(radius=10, height=40, sections=8)
    sv, sf = np.asarray(small.vertices), np.asarray(small.faces)
    ends = list_ends(sv, sf, {"GlobalElementID": np.arange(len(sf))})
    assert ends.cap_array is None


def test_caps_written_as_separate_solids_of_an_ascii_stl_are_labelled(tmp_path):
    from vcs.mesh import write_stl_ascii

    m = capped_cylinder()
    tris = np.asarray(m.vertices)[np.asarray(m.faces)]
    nz = m.face_normals[:, 2]
    path = tmp_path / "solids.stl"
    write_stl_ascii(path, {"wall": tris[np.abs(nz) < 0.99], "inlet": tris[nz < -0.99], "outlet": tris[nz > 0.99]})
    r = run("ends", path)
    assert r.returncode == 0 and "STLSolidLabeling=1" in r.stdout and "STLSolidLabeling=2" in r.stdout, r.stdout
    r = run("fit", path, "-o", tmp_path / "f", "--inlet", "STLSolidLabeling=2", "--outlet", "STLSolidLabeling=1")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "f" / "fit_report.json").read_text())
    assert rep["ends_method"] == "labelled_caps" and rep["inlet"]["center_mm"][2] > rep["outlet"]["center_mm"][2]


def test_blunt_closed_ends_of_a_capsule(tmp_path):
    """Rounded ends (no flat cap, no loop): the geodesic extremities are the ends; the fit needs no option."""
    m = trimesh.creation.capsule(height=120.0, radius=9.0, count=[48, 48])
    m.apply_translation(SHIFT)
    ends = list_ends(np.asarray(m.vertices), np.asarray(m.faces))
    assert [c.kind for c in ends.candidates] == ["closed end", "closed end"]
    for c in ends.candidates:
        z = c.end.center[2] - SHIFT[2]
        assert 50 < abs(z) < 66 and np.linalg.norm((c.end.center - SHIFT)[:2]) < 1.0
        assert c.end.normal is None and 6.0 < c.radius < 10.0
    path = tmp_path / "capsule.stl"
    m.export(path)
    r = run("fit", path, "-o", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "f" / "fit_report.json").read_text())
    # spheres' centres 120 mm apart, tips 138 mm apart: the section lies between the rounded ends
    assert rep["ends_method"] == "closed_ends" and 105 < rep["centerline_length_mm"] < 138


def test_points_on_rounded_caps_take_the_last_full_section(tmp_path):
    """Issue 10 (vmtk segment, rho_w 32 % of the radius at tau = 0): a point on a rounded cap put
    the end plane across the cap, whose cut is a small ring. Such a point stands for the closed
    end (its last full cross-section); a point deeper in the lumen is kept as the user's plane."""
    from vcs.vessel import fit_vessel

    m = trimesh.creation.capsule(height=120.0, radius=9.0, count=[48, 48]).subdivide_to_size(2.0)
    m.apply_translation(SHIFT)
    path = tmp_path / "capsule.stl"
    m.export(path)
    tips = [SHIFT + [0.5, -0.3, 66.5], SHIFT + [-0.4, 0.2, -66.5]]  # on the caps, 2.5 mm inside the tips
    model, rep, _ = fit_vessel(path, units="mm", inlet=tips[0], outlet=tips[1])
    assert rep["ends_method"] == "closed_ends" and rep["quality"] == "ok", rep["quality_reasons"]
    theta = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    # the end sections are (nearly) full sections of the radius-9 cylinder: the closed end's last
    # full section lies where the hemisphere begins (measured 8.49 mm); the cap cut at the given
    # points is a ring of radius sqrt(9^2 - 6.5^2) = 6.2 mm
    for tau in (0.0, 1.0):
        assert np.all(np.abs(model.wall(np.full(64, tau), theta) - 9.0) < 0.75)
    assert 120 < rep["centerline_length_mm"] < 130  # from where the hemispheres begin (+-60 mm), not +-66.5
    deeper = SHIFT + [0.0, 0.0, 40.0]
    _, rep2, _ = fit_vessel(path, units="mm", inlet=deeper, outlet=tips[1])
    assert rep2["ends_method"] == "points+closed_ends" and rep2["quality"] == "ok"
    assert abs(rep2["inlet"]["center_mm"][2] - deeper[2]) < 0.5


def test_one_end_given_takes_the_other_of_a_pair():
    m = capped_cylinder()
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    ends = find_ends(v, f, outlet=EndSelector("end:0", index=0))
    assert ends.method == "flat_caps" and ends.outlet.center[2] < ends.inlet.center[2]


# ------------------------------------------------------------------ the shared real meshes


@pytest.mark.realdata
def test_vmr0154_fits_from_vcs_ends_without_hand_computed_points(shared_data, tmp_path):
    """Closed aorta, six flat unlabelled caps (4 branch stubs): `vcs ends` lists them, the root cap
    (~(-0.98, 4.61, 3.01) cm, normal ~(0.10, 0.17, 0.98)) first; the user picks two and fits."""
    mesh = shared_data / "sphinxsys_vmr0154_aorta_capped.stl"
    r = run("ends", mesh, "-o", tmp_path / "ends.json")
    assert r.returncode == 0, r.stderr
    table = json.loads((tmp_path / "ends.json").read_text())
    assert table["units"] == "cm" and [c["kind"] for c in table["candidates"]] == ["flat cap"] * 6
    root = table["candidates"][0]
    assert np.linalg.norm(np.array(root["center"]) - [-0.98, 4.61, 3.01]) < 0.2
    assert np.dot(root["normal"], [0.10, 0.17, 0.98]) > 0.99
    descending = table["candidates"][1]
    assert descending["radius"] > 2 * max(c["radius"] for c in table["candidates"][2:])  # the 4 stubs
    # no choice: one line listing the six ends and the options
    msg = one_line_error(run("fit", mesh, "-o", tmp_path / "x"), "6 ends", "end:5", "--inlet end:I --outlet end:J")
    assert "(cm)" in msg
    r = run("fit", mesh, "-o", tmp_path / "f", "--inlet", "end:0", "--outlet", "end:1")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "f" / "fit_report.json").read_text())
    assert rep["ends_method"] == "flat_caps" and rep["units"] == "cm"
    np.testing.assert_allclose(np.array(rep["inlet"]["center_mm"]) / 10, root["center"], atol=1e-3)
    # the root point from the data README (after a space, with a minus sign) picks the same cap
    r = run("fit", mesh, "-o", tmp_path / "p", "--inlet", "-0.98, 4.61, 3.01", "--outlet", "end:1")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "p" / "model.json").read_bytes() == (tmp_path / "f" / "model.json").read_bytes()


@pytest.mark.realdata
@pytest.mark.parametrize("name", ["sphinxsys_tah_aorta_capped_coarse.stl", "vmtk_aorta_segment_closed.stl"])
def test_closed_aortas_with_two_ends_fit_with_no_end_given(shared_data, tmp_path, name):
    r = run("fit", shared_data / name, "-o", tmp_path / "f")
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "f" / "fit_report.json").read_text())
    assert rep["units"] == "mm" and rep["ends_method"] in ("flat_caps", "closed_ends")
    from vcs.io import read_surface

    extent = float(np.ptp(read_surface(shared_data / name).vertices, axis=0).max())
    assert rep["centerline_length_mm"] > 0.8 * extent  # from one end of the vessel to the other
    assert rep["residual_mean_mm"] < 0.3


@pytest.mark.realdata
@pytest.mark.parametrize(
    "name, kinds",
    [
        ("simvascular_aorta_segment_open.vtp", ["open loop"] * 2),
        ("simvascular_aorta_segment_capped.vtp", ["labelled cap"] * 2),
        ("vmtk_aorta_bifurcation_open.stl", ["open loop"] * 3),
        ("aortacfd_patient1/wall_aorta.stl", ["open loop"] * 5),
    ],
)
def test_shared_meshes_candidate_kinds(shared_data, name, kinds):
    from vcs.io import read_surface
    from vcs.vessel import vessel_component

    s = vessel_component(read_surface(shared_data / name))
    assert [c.kind for c in list_ends(s.vertices, s.faces, s.cell_data).candidates] == kinds


def test_vcs_ends_bad_input_is_one_line(tmp_path):
    one_line_error(run("ends", tmp_path / "missing.stl"), "does not exist")
    (tmp_path / "empty.stl").write_bytes(b"")
    one_line_error(run("ends", tmp_path / "empty.stl"), "is empty")
    m = capped_cylinder()
    m.export(tmp_path / "t.stl")
    one_line_error(run("ends", tmp_path / "t.stl", "--cap-array", "Nope"), "cell array 'Nope' not found")
