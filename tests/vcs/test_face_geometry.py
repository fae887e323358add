"""Face centres and area vectors of polyMesh faces (vcs.cfd.foamfiles.face_geometry) against
hand-computed polygons: OpenFOAM's triangle fan about the corner average, area-weighted."""

from __future__ import annotations

import numpy as np
import pytest

from vcs.cfd.foamfiles import face_geometry


def test_polygons_of_several_corner_counts_in_one_call():
    hexagon = [(np.cos(a), np.sin(a), 2.0) for a in np.linspace(0.0, 2 * np.pi, 7)[:-1]]
    points = np.array(
        [(0, 0, 0), (2, 0, 0), (0, 1, 0)]  # right triangle, legs 2 and 1, in z = 0
        + [(0, 0, 1), (0, 3, 1), (0, 3, 4), (0, 0, 4)]  # 3 x 3 square in x = 0, normal +x
        + hexagon  # unit regular hexagon in z = 2
        + [(0, 0, 5), (4, 0, 5), (4, 1, 5), (0, 1, 5)],  # 4 x 1 rectangle: not a square, same centre rule
        float,
    )
    faces = [np.array([0, 1, 2]), np.array([3, 4, 5, 6]), np.arange(7, 13), np.array([13, 14, 15, 16])]
    centres, areas = face_geometry(points, faces)
    assert centres[0] == pytest.approx([2 / 3, 1 / 3, 0])  # a triangle's centroid: its corner mean
    assert areas[0] == pytest.approx([0, 0, 1.0])  # half of 2 x 1, normal +z by the corner order
    assert centres[1] == pytest.approx([0, 1.5, 2.5])
    assert areas[1] == pytest.approx([9.0, 0, 0])  # +x by the corner order, area 9
    assert centres[2] == pytest.approx([0, 0, 2], abs=1e-12)
    assert areas[2] == pytest.approx([0, 0, 1.5 * np.sqrt(3)])  # regular hexagon, side 1
    assert centres[3] == pytest.approx([2.0, 0.5, 5.0])
    assert areas[3] == pytest.approx([0, 0, 4.0])


def test_an_irregular_quad_has_its_area_centroid_not_its_corner_mean():
    """A trapezoid: corners (0,0), (4,0), (3,1), (1,1): area 3, centroid y = (1/3)(b1 + 2 b2)/(b1 + b2)
    = (4 + 4) / (3 * 6) = 4/9 (the corner mean would give 1/2)."""
    points = np.array([(0, 0, 0), (4, 0, 0), (3, 1, 0), (1, 1, 0)], float)
    centres, areas = face_geometry(points, [np.arange(4)])
    assert areas[0] == pytest.approx([0, 0, 3.0])
    assert centres[0] == pytest.approx([2.0, 4 / 9, 0.0])


def test_no_faces_and_faces_as_lists():
    points = np.array([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)], float)
    centres, areas = face_geometry(points, [])
    assert centres.shape == (0, 3) and areas.shape == (0, 3)
    centres, areas = face_geometry(points, [[0, 1, 3, 2], [0, 1, 2]])
    assert centres[0] == pytest.approx([0.5, 0.5, 0]) and areas[0] == pytest.approx([0, 0, 1.0])
    assert areas[1] == pytest.approx([0, 0, 0.5])
