"""`--units auto` (issue 10): decided by the median lumen radius, the extent only as a tie-breaker.

A long aorta written in cm (35 cm extent) used to be read as mm because the old rule looked at the
bounding box alone; the radius (1.2 cm -> 12 mm, not 1.2 mm) is what tells cm from mm.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from vcs.io import guess_units, measure_units, read_surface
from vcs.mesh import lumen_chords, write_stl_binary
from vcs.phantoms.factory import make_phantom

# a 430 mm long helix whose bounding box spans ~350 mm (the 427 mm aorta spans 34.5 cm)
LONG_HELIX = {"helix_radius_mm": 24.0, "pitch_mm": 201.0, "turns": 1.71}


def run(*args):
    return subprocess.run([sys.executable, "-m", "vcs.cli", *map(str, args)], capture_output=True, text=True)


def test_lumen_chords_measure_the_diameter_whatever_the_winding():
    ph = make_phantom("tube", resolution=2.0, radius_mm=7.0, length_mm=120.0)
    for faces in (ph.faces, ph.faces[:, ::-1]):
        chords = lumen_chords(ph.vertices, faces)
        assert len(chords) > 200
        assert abs(0.5 * np.median(chords) - 7.0) < 0.15
    # the same mesh gives the same chords (fixed seed): byte-identical reports
    assert np.array_equal(lumen_chords(ph.vertices, ph.faces), lumen_chords(ph.vertices, ph.faces))


@pytest.mark.parametrize("kind", ["tube", "torus", "helix", "aorta"])
@pytest.mark.parametrize("unit", ["mm", "cm", "m"])
def test_phantoms_in_every_unit(kind, unit):
    ph = make_phantom(kind, resolution=2.0)
    scale = {"mm": 1.0, "cm": 0.1, "m": 0.001}[unit]
    guess = measure_units(ph.vertices * scale, ph.faces)
    assert guess.unit == unit, guess.reason
    assert guess.warning is None


@pytest.mark.parametrize("radius_mm", [5.0, 12.0])
def test_long_thin_vessel_written_in_cm_reads_as_cm(tmp_path, radius_mm):
    """~430 mm long, extent ~35 cm, radius 5 or 12 mm, written in cm: the old extent rule said mm."""
    ph = make_phantom("helix", resolution=2.5, tube_radius_mm=radius_mm, **LONG_HELIX)
    assert 425 < ph.params["length_mm"] < 435
    path = tmp_path / "long_cm.stl"
    write_stl_binary(path, ph.vertices / 10.0, ph.faces)
    surf = read_surface(path)
    extent = float(np.ptp(surf.vertices, axis=0).max())
    assert surf.units == "cm" and 340 < extent < 370
    ev = surf.units_evidence
    assert abs(ev["median_lumen_radius"] - radius_mm / 10) < 0.05 * radius_mm / 10
    assert ev["candidates"]["cm"]["plausible"] and abs(ev["candidates"]["cm"]["median_lumen_radius_mm"] - radius_mm) < 1
    assert not surf.warnings, surf.warnings


def test_fit_report_has_the_units_evidence(tmp_path):
    ph = make_phantom("helix", resolution=3.0, tube_radius_mm=10.0, **LONG_HELIX)
    path = tmp_path / "long_cm.stl"
    write_stl_binary(path, ph.vertices / 10.0, ph.faces)
    r = run("fit", path, "-o", tmp_path / "fit", "--K", 9, "--R", 7)
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "fit" / "fit_report.json").read_text())
    assert rep["units"] == "cm" and rep["units_source"].startswith("auto: median lumen radius")
    ev = rep["units_evidence"]
    assert set(ev["candidates"]) == {"mm", "cm", "m"} and ev["n_chords"] > 100
    assert abs(ev["candidates"]["cm"]["median_lumen_radius_mm"] - 10.0) < 0.5
    assert abs(rep["centerline_length_mm"] - ph.params["length_mm"]) < 0.02 * ph.params["length_mm"]


def test_guess_units_rule():
    assert guess_units(1.2, 34.5).unit == "cm"  # the aorta in cm: 12 mm radius, 345 mm extent
    assert guess_units(1.8, 35.0).unit == "cm"  # a dilated thoracic aorta in cm: 18 mm median radius
    assert guess_units(1.0, 45.0).unit == "cm"  # a whole aorta in cm, root to bifurcation
    assert guess_units(2.0, 60.0).unit == "mm"  # a carotid in mm: 2 mm radius, 60 mm extent
    assert guess_units(0.012, 0.3).unit == "m"
    assert guess_units(8.0, 100.0).unit == "mm"
    # no radius: the extent alone decides (the former rule)
    assert guess_units(None, 0.3).unit == "m" and guess_units(None, 30.0).unit == "mm"
    # a radius no unit makes human: the closest, with a warning
    g = guess_units(60.0, 500.0)
    assert g.unit == "mm" and g.warning and "no unit" in g.warning
    # nearly as plausible in another unit: a warning naming it
    g = guess_units(1.5, 40.0)
    assert g.warning and "--units" in g.warning


SHARED_UNITS = {
    "simvascular_aorta_segment_open.vtp": "cm",
    "simvascular_aorta_segment_capped.vtp": "cm",
    "sphinxsys_vmr0154_aorta_capped.stl": "cm",
    "vmtk_aorta_segment_closed.stl": "mm",
    "vmtk_aorta_bifurcation_open.stl": "mm",
    "aortacfd_patient1/wall_aorta.stl": "mm",
    "sphinxsys_tah_aorta_capped_coarse.stl": "mm",
}


@pytest.mark.realdata
@pytest.mark.parametrize("name", list(SHARED_UNITS))
def test_shared_meshes_units(shared_data, name):
    surf = read_surface(shared_data / name)
    assert surf.units == SHARED_UNITS[name], surf.units_source
    radius_mm = surf.units_evidence["candidates"][surf.units]["median_lumen_radius_mm"]
    assert 4.0 < radius_mm < 16.0  # aortas
    assert not any(w.startswith("units auto") for w in surf.warnings)
