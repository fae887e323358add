"""Issue 10: --L auto, tau = arc length, quality in fit_report.json, one L per atlas (phantoms)."""

from __future__ import annotations

import numpy as np
import pytest

from vcs.io import Surface
from vcs.phantoms import make_phantom
from vcs.phantoms.sweep import sweep_tube
from vcs.vessel import fit_vessel


def tortuous_vessel() -> Surface:
    """A long tortuous branch-free vessel: 434 mm meandering in 3-D, radius tapering 12 -> 5 mm
    (radius of curvature >= 20 mm), rings every 1.5 mm, open ends."""
    s = np.linspace(0, 1, 4000)
    P = np.stack([340 * s, 24 * np.sin(2 * np.pi * 2.4 * s), 16 * np.sin(2 * np.pi * 1.6 * s + 0.7)], -1)
    arc = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    t = np.linspace(0, arc[-1], int(arc[-1] / 1.5) + 1)
    P = np.stack([np.interp(t, arc, P[:, k]) for k in range(3)], -1)
    V, F = sweep_tube(P, lambda ss, phi: 12.0 - 7.0 * ss + 0 * phi, edge=1.5)
    return Surface(V, F, {}, "mm", "given", "tortuous phantom")


@pytest.fixture(scope="module")
def tortuous():
    return tortuous_vessel()


def test_tortuous_vessel_gets_the_knots_it_needs(tortuous):
    model, r, wf = fit_vessel(tortuous)
    assert 430 < r["centerline_length_mm"] < 440
    assert r["L_source"] == "auto" and r["L"] > 15 and r["L_auto"]["criteria_met"]
    assert r["arc_length_speed_deviation"] <= 0.02
    assert r["centerline_inside_lumen"] and r["centerline_min_wall_distance_ratio"] > 0.5
    assert r["fraction_points_used"] >= 0.98 and r["points_not_used"]["branch"] == 0
    assert r["residual_mean_mm"] <= 0.2 and r["model_radius_min_mm"] > 4.0
    assert r["quality"] == "ok", r["quality_reasons"]
    assert model.meta["quality"] == "ok" and model.meta["L_source"] == "auto"


def test_paper_L_on_the_tortuous_vessel_is_reported_poor(tortuous):
    _, r, _ = fit_vessel(tortuous, L=9)
    assert r["L_source"] == "given" and r["L"] == 9
    assert r["arc_length_speed_deviation"] > 0.05
    assert r["quality"] == "poor"
    assert any("arc length" in why for why in r["quality_reasons"])


@pytest.mark.parametrize("seed", [0, 2])
def test_aorta_phantom_tau_is_arc_length(seed):
    ph = make_phantom("aorta", seed=seed, resolution=1.5)
    _, r, _ = fit_vessel(Surface(ph.vertices, ph.faces, {}, "mm", "given", "phantom"), K=None, R=None)
    assert r["arc_length_speed_deviation"] <= 0.02 and r["L"] >= 9
    assert r["quality"] == "ok"


def test_atlas_refits_to_one_L_and_excludes_poor_fits():
    from vcs.atlas.cohort import fit_exclusion

    ph = make_phantom("aorta", seed=1, resolution=1.5)
    model, r, _ = fit_vessel(Surface(ph.vertices, ph.faces, {}, "mm", "given", "phantom"))
    up = model.with_n_knots(model.n_knots + 7)
    assert up.n_knots == model.n_knots + 7 and up.meta["L_fitted"] == model.n_knots
    tau = np.linspace(0, 1, 501)
    assert np.abs(up.vcs.curve(tau) - model.vcs.curve(tau)).max() < 0.1  # mm, same tau (measured 0.06)
    assert r["arc_length_speed_deviation"] <= 0.02
    assert fit_exclusion(model) is None
    poor = type(model)(model.vcs, model.wall, model.units, {**model.meta, "quality": "poor", "quality_reasons": ["x"]})
    assert fit_exclusion(poor) == "fit quality poor: x"
