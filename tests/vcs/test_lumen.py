"""`cfd.geometry: surface`: the patient's own surface closed into a lumen with every end a patch
(vcs.lumen, `vcs lumen`), and the branch ends in the mesh sizing (vcs.cfd.sizing)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import sweep, vcs_in_process

from vcs.errors import VCSInputError
from vcs.io import Surface, read_surface
from vcs.lumen import build_lumen, read_lumen_surface, write_lumen
from vcs.mesh import edge_topology, read_stl_solids


def _straight_tube(r: float = 5.0, length: float = 60.0, n_phi: int = 48) -> Surface:
    """Open straight tube along z (mm): rings of regular n_phi-gons, open ends at z = 0 and length."""
    e = np.eye(3)
    v, f = sweep(
        lambda s: np.outer(s, [0.0, 0.0, length]),
        lambda s: np.tile(e[0], (len(s), 1)),
        lambda s: np.tile(e[1], (len(s), 1)),
        r,
        31,
        n_phi,
    )
    return Surface(v, f, {}, "mm", "given", "tube")


def _watertight(solids: dict[str, np.ndarray]) -> bool:
    """Every edge of the union of the solids used by exactly two triangles (vertices merged)."""
    tri = np.concatenate(list(solids.values())).reshape(-1, 3)
    _, inv = np.unique(np.round(tri, 9), axis=0, return_inverse=True)
    _, counts = edge_topology(inv.reshape(-1, 3))
    return bool((counts == 2).all())


def test_straight_tube_lumen_is_the_polygonal_prism():
    r, length, n = 5.0, 60.0, 48
    lumen = build_lumen(_straight_tube(r, length, n), np.zeros(3), np.array([0.0, 0.0, length]))
    polygon = 0.5 * n * r**2 * np.sin(2 * np.pi / n)  # area of the regular n-gon: the fan caps
    assert lumen.volume_mm3 == pytest.approx(polygon * length, rel=1e-9)
    assert [e.name for e in lumen.ends] == ["inlet", "outlet"]
    assert [e.role for e in lumen.ends] == ["inlet", "outlet"]
    for e, z, nz in zip(lumen.ends, (0.0, length), (1.0, -1.0)):
        assert e.area == pytest.approx(polygon, rel=1e-9)
        np.testing.assert_allclose(e.center, [0, 0, z], atol=1e-9)
        np.testing.assert_allclose(e.normal, [0, 0, nz], atol=1e-9)  # into the lumen
    assert list(lumen.solids) == ["wall", "inlet", "outlet"]
    assert _watertight(lumen.solids)


def test_the_ends_follow_the_fit_not_the_size():
    # the smaller end as the section's inlet: the names follow the fit's end centres
    lumen = build_lumen(_straight_tube(), np.array([0.0, 0.0, 60.0]), np.zeros(3))
    np.testing.assert_allclose(lumen.ends[0].center, [0, 0, 60.0], atol=1e-9)
    assert lumen.ends[0].name == "inlet"


def test_inlet_and_outlet_at_the_same_end_are_refused():
    with pytest.raises(VCSInputError, match="the same end of the surface"):
        build_lumen(_straight_tube(), np.zeros(3), np.array([0.5, 0.0, 0.0]))


def test_an_end_plane_inside_the_vessel_is_refused_in_one_line():
    with pytest.raises(VCSInputError, match=r"section's outlet .* not an opening or a flat cap") as exc:
        build_lumen(_straight_tube(), np.zeros(3), np.array([0.0, 0.0, 30.0]))
    assert "\n" not in str(exc.value) and "cfd_geometry model" in str(exc.value)


@pytest.mark.realdata
def test_vmr0154_six_caps_inlet_outlet_and_four_branches(shared_data, tmp_path):
    mesh = shared_data / "sphinxsys_vmr0154_aorta_capped.stl"
    c_in, c_out = np.array([-9.91, 45.55, 28.63]), np.array([-16.13, -8.21, 3.96])  # `vcs ends`: end:0, end:1 (mm)
    lumen = build_lumen(read_lumen_surface(mesh, "cm", c_in, c_out), c_in, c_out)
    names = [e.name for e in lumen.ends]
    assert names == ["inlet", "outlet", "branch_1", "branch_2", "branch_3", "branch_4"]
    assert {e.source for e in lumen.ends} == {"flat cap"}
    areas = [e.area for e in lumen.ends[2:]]
    assert areas == sorted(areas, reverse=True)
    # radii as `vcs ends` lists them (cm): 1.379, 0.922, then the stubs 0.404 ... 0.266
    np.testing.assert_allclose(
        [np.sqrt(e.area / np.pi) for e in lumen.ends], [13.79, 9.22, 4.04, 3.55, 2.93, 2.66], atol=0.02
    )
    # the caps keep their own triangles: the whole input is used, nothing added
    assert sum(len(t) for t in lumen.solids.values()) == len(read_surface(mesh, "cm").faces)
    assert _watertight(lumen.solids)
    info = write_lumen(lumen, tmp_path / "l.stl", tmp_path / "l.json")
    solids = read_stl_solids(tmp_path / "l.stl")
    assert list(solids) == ["wall", *names]
    np.testing.assert_allclose(
        np.concatenate(list(solids.values())) * 1e3, np.concatenate(list(lumen.solids.values())), atol=1e-6
    )
    assert json.loads((tmp_path / "l.json").read_text()) == json.loads(json.dumps(info))
    assert info["ends"][0]["center"] == pytest.approx(c_in * 1e-3, abs=2e-4)


@pytest.mark.realdata
def test_bifurcation_volume_matches_vtk(shared_data):
    import pyvista as pv

    mesh = shared_data / "vmtk_aorta_bifurcation_open.stl"
    c_in, c_out = np.array([221.03, 177.80, 21.30]), np.array([235.24, 101.57, 29.16])
    lumen = build_lumen(read_lumen_surface(mesh, "mm", c_in, c_out), c_in, c_out)
    assert [(e.name, e.source) for e in lumen.ends] == [
        ("inlet", "open loop"),
        ("outlet", "open loop"),
        ("branch_1", "open loop"),
    ]
    np.testing.assert_allclose(lumen.ends[2].center, [210.19, 102.87, 30.82], atol=0.01)
    # an independent volume: VTK's hole filling, normals made consistent, and mass properties
    filled = pv.read(str(mesh)).clean().fill_holes(1e3)
    filled = filled.compute_normals(auto_orient_normals=True, consistent_normals=True, split_vertices=False)
    assert filled.n_open_edges == 0
    assert lumen.volume_mm3 == pytest.approx(filled.volume, rel=1e-4)
    assert _watertight(lumen.solids)


@pytest.mark.realdata
def test_rounded_ends_are_refused_with_what_to_do(shared_data, tmp_path):
    mesh = shared_data / "sphinxsys_tah_aorta_capped_coarse.stl"
    c_in, c_out = np.array([-27.31, -203.48, -1173.99]), np.array([4.00, -120.90, -1246.75])
    with pytest.raises(VCSInputError, match=r"section's inlet is a rounded \(closed\) end.*cut the end flat"):
        build_lumen(read_lumen_surface(mesh, "mm", c_in, c_out), c_in, c_out)


@pytest.mark.realdata
def test_vcs_lumen_command(shared_data, tmp_path):
    mesh = shared_data / "vmtk_aorta_bifurcation_open.stl"
    fit = vcs_in_process("fit", mesh, "-o", tmp_path / "fit", "--inlet", "end:0", "--outlet", "end:1")
    assert fit.returncode == 0, fit.stderr
    model = tmp_path / "fit" / "model.json"
    r = vcs_in_process("lumen", mesh, "--model", model, "-o", tmp_path / "lumen.stl", "--ends", tmp_path / "ends.json")
    assert r.returncode == 0, r.stderr
    ends = json.loads((tmp_path / "ends.json").read_text())["ends"]
    assert [e["name"] for e in ends] == ["inlet", "outlet", "branch_1"]
    assert ends[0]["equivalent_radius"] == pytest.approx(7.69e-3, abs=1e-5)  # metres
    bad = vcs_in_process("lumen", mesh, "--model", model, "-o", tmp_path / "lumen.vtp")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


def test_branch_ends_are_refined_to_the_cells_asked_for():
    from vcs.cfd.case import branch_levels

    hb = 0.004  # background cell: 4 mm; outlets at level 1 (2 mm)
    got = branch_levels({"branch_1": 0.008, "branch_2": 0.0036}, hb, [1, 1], 8.0)
    # 8 across 8 mm needs 1 mm: level 2; 8 across 3.6 mm needs 0.45 mm: level 4 (0.25 mm)
    assert got["branch_1"]["level"] == [2, 2] and got["branch_1"]["cells_across"] == pytest.approx(8.0)
    assert got["branch_2"]["level"] == [4, 4] and got["branch_2"]["cells_across"] == pytest.approx(14.4)
    # a branch already resolved at the outlet level keeps it
    assert branch_levels({"branch_1": 0.05}, hb, [1, 2], 8.0)["branch_1"]["level"] == [1, 2]


# --------------------------------------------------------------------------- planar ends, extensions


def _wavy_tube() -> Surface:
    """The straight tube (r 5 mm, z 0..60) with its z = 60 end tilted (0.4 mm/mm) and wavy (+-1 mm, 3 waves)."""
    s = _straight_tube()
    v = s.vertices.copy()
    w = (v[:, 2] / 60.0) ** 6
    v[:, 2] += w * (0.4 * v[:, 0] + np.cos(3 * np.arctan2(v[:, 1], v[:, 0])))
    return Surface(v, s.faces, {}, "mm", "given", "wavy tube")


def _off_plane(tris: np.ndarray) -> tuple[float, float]:
    """(largest distance of the triangles' vertices from their best-fit plane, their diameter)."""
    from vcs.lumen import end_plane

    _, _, dev, diam = end_plane(np.unique(tris.reshape(-1, 3), axis=0))
    return dev, diam


def test_wavy_tilted_end_is_cut_planar_and_extended():
    surf = _wavy_tube()
    ring = surf.vertices[np.isclose(_straight_tube().vertices[:, 2], 60.0)]  # the wavy end loop
    lumen = build_lumen(surf, np.zeros(3), np.array([0.0, 0.0, 60.0]), extend_outlet=1.0)
    assert _watertight(lumen.solids)
    out = lumen.ends[1]
    assert out.name == "outlet" and any("cut flat" in n for n in lumen.notes)
    dev, diam = _off_plane(lumen.solids["outlet"])
    assert dev < 1e-6 * diam, (dev, diam)
    # the cut is inside the vessel: every vertex of the wavy end beyond it (0.02 diameters beyond the innermost)
    n_out = -out.normal
    assert n_out @ [-0.4, 0.0, 1.0] / np.hypot(0.4, 1.0) > 0.999  # the tilt's plane
    # the extension: one equivalent diameter along the outward normal, a prism of the cut end's shape
    d = 2.0 * np.sqrt(out.area / np.pi)
    assert out.extension == pytest.approx(d, rel=1e-9)
    cut = out.center - out.extension * n_out  # the cut end's centre, where the extension starts
    assert ((ring - cut) @ n_out > 0).all()  # the cut is inside the vessel: the whole wavy loop beyond it
    np.testing.assert_allclose(out.opening_center, [0.0, 0.0, 60.0], atol=0.1)  # matched where it was
    # the untouched inlet keeps its fan, and no extension was asked for it
    assert lumen.ends[0].extension == 0.0
    np.testing.assert_allclose(lumen.ends[0].center, [0.0, 0.0, 0.0], atol=1e-9)


def test_far_faces_turned_to_the_grid_and_extension_refused_when_crossing():
    # a planar end tilted 20 degrees: its far face on the grid plane z = const (a wedge, >= 1 edge long)
    s = _straight_tube()
    v = s.vertices.copy()
    v[:, 2] += (v[:, 2] / 60.0) ** 6 * np.tan(np.radians(20)) * v[:, 0]
    lumen = build_lumen(
        Surface(v, s.faces, {}, "mm", "given", "tilted"), np.zeros(3), np.array([0.0, 0.0, 60.0]), grid="axes"
    )
    assert _watertight(lumen.solids)
    np.testing.assert_allclose(lumen.ends[1].normal, [0.0, 0.0, -1.0], atol=1e-12)
    tri = lumen.solids["outlet"].reshape(-1, 3)
    assert np.ptp(tri[:, 2]) < 1e-9 and tri[:, 2].min() > v[:, 2].max()
    with pytest.raises(VCSInputError, match="must be a length >= 0"):
        build_lumen(_straight_tube(), np.zeros(3), np.array([0.0, 0.0, 60.0]), extend_outlet=-1.0)


@pytest.mark.realdata
def test_bifurcation_ends_planar_extended_on_the_grid(shared_data):
    mesh = shared_data / "vmtk_aorta_bifurcation_open.stl"
    c_in, c_out = np.array([221.03, 177.80, 21.30]), np.array([235.24, 101.57, 29.16])
    surf = read_lumen_surface(mesh, "mm", c_in, c_out)
    plain = build_lumen(surf, c_in, c_out)
    lumen = build_lumen(surf, c_in, c_out, extend_outlet=1.0, grid="axes")
    assert _watertight(lumen.solids)
    assert lumen.volume_mm3 > plain.volume_mm3
    for e, e0 in zip(lumen.ends, plain.ends):
        assert e.name == e0.name
        dev, diam = _off_plane(lumen.solids[e.name])
        assert dev < 1e-6 * diam, (e.name, dev, diam)
        # the far face on a plane of the grid (the ends are ~8 degrees off y), matched at the opening
        np.testing.assert_allclose(np.abs(e.normal), [0.0, 1.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(e.opening_center, e0.center, atol=1e-9)
        d = 2.0 * np.sqrt(e0.area / np.pi)
        if e.role == "inlet":  # extend_inlet 0: only the wedge to the grid plane
            assert 0 < e.extension < 0.25 * d
        else:
            assert e.extension == pytest.approx(d, rel=0.05)
