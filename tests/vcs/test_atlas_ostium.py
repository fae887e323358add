"""Atlas of a cohort whose wall fields miss cells (issue 25 item 4): a patient resampled from a lumen
with a side branch has NaN wall values at the ostium (vcs.cfd.resample marks them). Those cells are
left out of every wall field's PCA and recorded; the PCA of the other cells is the one of the cohort
without them (checked against numpy's SVD of the hand-reduced matrix); the outputs carry NaN there,
never zeros."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
import pyvista as pv
from test_atlas import random_rigid, synthetic_fields, synthetic_model
from test_atlas_pulsatile import pulsatile_cohort

from vcs.atlas import atlas_summary, build_atlas, compute_atlas, is_wall_field, pulsatile_fields, transform_model
from vcs.atlas.pca import is_vector_field

GRID = (9, 8, 5)
OSTIUM = [(4, 1), (4, 2), (5, 1), (5, 2)]  # P2's ostium: 4 wall cells
ONE_COMPONENT = (2, 6)  # P4: one component of one cell not finite -> the whole cell is out


def cohort(n: int = 6, seed: int = 0):
    """n moved tubes with U, p of synthetic_fields and a WSS map varying by patient (two patterns
    with random amplitudes, and noise: a full-rank PCA)."""
    rng = np.random.default_rng(seed)
    radii = 8.0 + 4.0 * rng.random(n)
    models = {
        f"P{i}": transform_model(synthetic_model(radius=r, bend=50 + 3 * i), random_rigid(20 + i))
        for i, r in enumerate(radii)
    }
    fields = {}
    for i, pid in enumerate(models):
        q = 0.5 + 0.01 * radii[i] ** 2
        f = synthetic_fields(None, q, n=GRID)
        T, TH = np.meshgrid(f["tau"], f["theta"], indexing="ij")
        w = np.zeros((*GRID[:2], 3))
        a, b, c = rng.normal(size=3)
        w[..., 0] = 4 * q + a * np.sin(np.pi * T) * np.cos(TH) + 0.5 * b * np.cos(2 * TH)
        w[..., 1] = 0.3 * c * np.sin(TH)
        w += 0.05 * rng.normal(size=w.shape)
        f["WSS_vcs"] = f["WSS"] = w
        fields[pid] = f
    return models, fields


def with_ostium(fields):
    """P2 with NaN WSS (all components) at its ostium cells and the resampling's mask; P4 with one
    NaN component. Returns the fields and the (n_tau, n_theta) cells missing for some patient."""
    out = {p: dict(f) for p, f in fields.items()}
    missing = np.zeros(GRID[:2], bool)
    w = out["P2"]["WSS_vcs"].copy()
    mask = np.zeros(GRID[:2], bool)
    for c in OSTIUM:
        w[c] = np.nan
        mask[c] = missing[c] = True
    out["P2"].update(WSS_vcs=w, WSS=w, ostium=mask)
    w = out["P4"]["WSS_vcs"].copy()
    w[ONE_COMPONENT][1] = np.nan
    missing[ONE_COMPONENT] = True
    out["P4"].update(WSS_vcs=w, WSS=w)
    return out, missing


def svd_pca(X):
    """The PCA by hand: mean, components (k, d), sigma, explained variance ratio, scores."""
    mean = X.mean(axis=0)
    U, S, Vt = np.linalg.svd(X - mean, full_matrices=False)
    k = len(X) - 1
    return mean, Vt[:k], S[:k] / np.sqrt(len(X) - 1), S[:k] ** 2 / np.sum(S**2), U[:, :k] * S[:k]


def test_missing_wall_cells_are_left_out_and_the_rest_is_the_reduced_cohorts_pca():
    models, clean = cohort()
    fields, missing = with_ostium(clean)
    atlas = compute_atlas(models, fields, {}, n_modes=5)
    pca = atlas.flow["WSS"]
    keep = ~np.repeat(missing.ravel(), 3)  # every component of a missing cell is out
    np.testing.assert_array_equal(pca.support, keep)
    # the truth: numpy's SVD of the matrix without those columns
    X = np.array([fields[p]["WSS_vcs"].ravel() for p in atlas.patients])[:, keep]
    assert np.isfinite(X).all()
    mean, comps, sigma, ratio, scores = svd_pca(X)
    np.testing.assert_allclose(pca.mean[keep], mean, rtol=1e-12)
    np.testing.assert_allclose(pca.sigma, sigma, rtol=1e-9)
    np.testing.assert_allclose(pca.explained_variance_ratio, ratio, rtol=1e-9)
    sign = np.sign(np.sum(pca.components[:, keep] * comps, axis=1))
    np.testing.assert_allclose(pca.components[:, keep], comps * sign[:, None], atol=1e-9)
    np.testing.assert_allclose(pca.scores, scores * sign, atol=1e-9)
    # a kept cell's mean by hand
    j = int(np.flatnonzero(keep)[0])
    assert pca.mean[j] == pytest.approx(sum(fields[p]["WSS_vcs"].ravel()[j] for p in atlas.patients) / 6)
    # NaN where left out, never a number standing in (no zeros)
    assert np.isnan(pca.mean[~keep]).all() and np.isnan(pca.components[:, ~keep]).all()
    assert np.isnan(pca.mode_sample(0, 2.0)[~keep]).all() and np.isfinite(pca.mode_sample(0, 2.0)[keep]).all()
    # U and p are untouched: identical to the atlas of the cohort without missing cells
    ref = compute_atlas(models, clean, {}, n_modes=5)
    for f in ("U", "p"):
        np.testing.assert_array_equal(atlas.flow[f].mean, ref.flow[f].mean)
        np.testing.assert_array_equal(atlas.flow[f].scores, ref.flow[f].scores)
        assert atlas.flow[f].support is None
    assert ref.flow["WSS"].support is None and ref.wall_fields["WSS"]["n_left_out"] == 0
    # recorded: how many, which fraction, who caused them, who had an ostium
    rec = atlas.wall_fields["WSS"]
    n_cells = GRID[0] * GRID[1]
    assert rec["n_cells"] == n_cells and rec["n_left_out"] == len(OSTIUM) + 1
    assert rec["fraction_left_out"] == pytest.approx((len(OSTIUM) + 1) / n_cells)
    assert rec["non_finite_by_patient"] == {"P2": len(OSTIUM), "P4": 1}
    assert rec["ostium_by_patient"] == {"P2": len(OSTIUM)}
    s = atlas_summary(atlas)
    json.dumps(s, allow_nan=False)  # strict JSON
    assert s["wall_fields"]["fields"]["WSS"] == rec and "ostium" in s["wall_fields"]["non_finite_rule"]
    assert s["wall_markers"] is None  # a steady cohort has no markers


def test_atlas_files_carry_nan_at_the_left_out_cells(tmp_path, caplog):
    models, clean = cohort()
    fields, missing = with_ostium(clean)
    out = tmp_path / "atlas"
    with caplog.at_level(logging.WARNING, logger="vcs.atlas.plots"):
        build_atlas(models, fields, {p: {"converged": True} for p in models}, out, n_modes=1)
    # the NaN colour is one pyvista takes (else the 3-D views fall back to matplotlib)
    assert not [r for r in caplog.records if "color" in r.getMessage()]
    with np.load(out / "atlas.npz") as z:
        mean = z["flow_WSS_mean"].reshape(*GRID[:2], 3)
        comps = z["flow_WSS_components"].reshape(-1, *GRID[:2], 3)
        support = z["flow_WSS_support"].reshape(*GRID[:2], 3)
    assert np.isnan(mean[missing]).all() and np.isfinite(mean[~missing]).all()
    assert np.isnan(comps[:, missing]).all() and not support[missing].any()
    grid = pv.read(out / "flow_mean.vtu")
    on_wall = np.asarray(grid.point_data["rho_n"]) == 1.0
    for name in ("WSS_mean", "WSS_mode1_plus2sigma", "WSS_mode1_minus2sigma"):
        v = np.linalg.norm(np.asarray(grid.point_data[name]), axis=-1)
        # the missing cells (none on theta = 0, which the VTU repeats to close the grid) are NaN;
        # every other wall value is a WSS (> 0), the inside is the zero of a wall field
        assert np.isnan(v[on_wall]).sum() == missing.sum(), name
        assert (v[on_wall][~np.isnan(v[on_wall])] > 0).all() and (v[~on_wall] == 0).all(), name
    s = json.loads((out / "atlas.json").read_text())
    assert s["wall_fields"]["fields"]["WSS"]["n_left_out"] == int(missing.sum())
    assert (out / s["files"]["flow_WSS_mode1"]).is_file()


def test_a_wall_field_missing_everywhere_for_one_patient_has_no_pca_and_says_so(caplog):
    models, fields = cohort()
    fields["P3"] = dict(fields["P3"], WSS_vcs=np.full((*GRID[:2], 3), np.nan))
    with caplog.at_level(logging.WARNING, logger="vcs.atlas"):
        atlas = compute_atlas(models, fields, {}, n_modes=2)
    assert list(atlas.flow) == ["U", "p"] and "WSS" not in atlas.regression
    rec = atlas.wall_fields["WSS"]
    assert rec["excluded"] == "no wall cell where every included patient's WSS_vcs is finite (missing for P3)"
    lines = [r.getMessage() for r in caplog.records if "WSS" in r.getMessage()]
    assert lines == ["WSS has no PCA: " + rec["excluded"]]


def test_every_wall_field_of_a_pulsatile_cohort_leaves_the_ostium_out():
    models, fields, _, _ = pulsatile_cohort(5, seed=4, rrt_modes=True)
    f = dict(fields["P1"])
    mask = np.zeros(GRID[:2], bool)
    for c in OSTIUM:
        mask[c] = True
    for key in list(f):
        if key.endswith(("WSS", "WSS_vcs")) or key in ("TAWSS", "OSI", "RRT", "ECAP"):
            a = np.array(f[key], float)
            a[mask] = np.nan
            f[key] = a
    fields["P1"] = dict(f, ostium=mask)
    atlas = compute_atlas(models, fields, {}, n_modes=2)
    walls = [n for n in pulsatile_fields(atlas.phase_names) if is_wall_field(n)]
    assert sorted(atlas.wall_fields) == sorted(walls) and len(walls) == 4 + 1 + 3
    for name in walls:
        rec = atlas.wall_fields[name]
        assert rec["n_left_out"] == len(OSTIUM) and rec["non_finite_by_patient"] == {"P1": len(OSTIUM)}, name
        pca = atlas.flow[name]
        per_cell = 3 if is_vector_field(name) else 1
        support = pca.support.reshape(*GRID[:2], per_cell).all(axis=-1)
        np.testing.assert_array_equal(support, ~mask)
    for name in ("U", "p", "phase/peak_systole/U", "phase/mid_diastole/p"):
        assert atlas.flow[name].support is None and name not in atlas.wall_fields
    assert set(atlas.wall_markers) == {"TAWSS", "OSI", "log10_RRT", "ECAP"}
