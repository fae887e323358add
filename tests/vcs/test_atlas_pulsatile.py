"""Atlas of a pulsatile cohort (issue 24, item 5): wall-marker and phase-field PCAs, non-finite RRT,
no mixing of pulsatile and steady patients. Synthetic fields dicts, as vcs.cfd.resample.sample_pulsatile
writes them."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_atlas import random_rigid, synthetic_fields, synthetic_model

from vcs.atlas import (
    PCA,
    WALL_MARKERS,
    atlas_summary,
    build_atlas,
    compute_atlas,
    pulsatile_fields,
    top_variation_mask,
    transform_model,
)
from vcs.errors import VCSInputError

PHASES = ("peak_systole", "end_systole", "mid_diastole")
PHASE_FACTORS = (2.0, 1.0, 0.3)  # each phase field = factor x the cycle average
GRID = (9, 8, 5)


def tawss_pattern(tau: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The one way the cohort's TAWSS maps vary: (n_tau, n_theta), zero mean around theta."""
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    return np.sin(np.pi * T) * np.cos(TH)


def rrt_pattern(tau: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """The one way the cohort's log10 RRT maps vary."""
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    return np.cos(np.pi * T) + 0.5 * np.sin(2 * TH)


def pulsatile_patient(q: float, a: float, *, b: float = 0.0, noise: float = 0.0, seed: int = 0) -> dict:
    """fields.npz of a pulsatile case: cycle averages (synthetic_fields), wall markers, phases.

    TAWSS = 1.5 + a * tawss_pattern (+ noise) Pa; OSI in [0.05, 0.25]; RRT and ECAP from them,
    unless ``b`` is given: then RRT = 10^(0.5 + b * rrt_pattern) (one known log10 RRT mode).
    """
    rng = np.random.default_rng(seed)
    f = synthetic_fields(None, q, n=GRID)
    tau, theta = f["tau"], f["theta"]
    T, TH = np.meshgrid(tau, theta, indexing="ij")
    tawss = 1.5 + a * tawss_pattern(tau, theta) + noise * rng.normal(size=T.shape)
    osi = 0.15 + 0.1 * np.sin(np.pi * T) * np.sin(TH)
    rrt = 1.0 / ((1.0 - 2.0 * osi) * tawss) if b == 0.0 else 10.0 ** (0.5 + b * rrt_pattern(tau, theta))
    f.update(
        TAWSS=tawss,
        OSI=osi,
        RRT=rrt,
        ECAP=osi / tawss,
        phase_names=np.array(PHASES, dtype=str),
        field_source=np.str_("pulsatile"),
    )
    for phase, factor in zip(PHASES, PHASE_FACTORS):
        for key in ("U", "U_vcs", "p", "p_kinematic", "WSS", "WSS_vcs"):
            f[f"phase/{phase}/{key}"] = factor * f[key]
    return f


def pulsatile_cohort(n: int, *, seed: int = 0, noise: float = 0.0, rrt_modes: bool = False):
    """n rigidly moved tubes of random radius; TAWSS amplitudes a (and log10 RRT amplitudes b)
    drawn independently of the shapes. Returns models, fields, a, b."""
    rng = np.random.default_rng(seed)
    radii = 8.0 + 4.0 * rng.random(n)
    a = rng.normal(0.0, 0.3, n)
    b = rng.normal(0.0, 0.4, n) if rrt_modes else np.zeros(n)
    models = {
        f"P{i}": transform_model(synthetic_model(radius=r, bend=50 + 3 * i), random_rigid(20 + i))
        for i, r in enumerate(radii)
    }
    fields = {
        pid: pulsatile_patient(0.5 + 0.01 * radii[i] ** 2, a[i], b=b[i], noise=noise, seed=seed + i)
        for i, pid in enumerate(models)
    }
    return models, fields, a, b


def test_first_tawss_mode_recovers_the_planted_pattern():
    models, fields, a, _ = pulsatile_cohort(8, noise=0.01, seed=1)
    atlas = compute_atlas(models, fields, {}, n_modes=3)
    assert atlas.flow_kind == "pulsatile" and atlas.phase_names == PHASES
    assert list(atlas.flow) == list(pulsatile_fields(PHASES))
    assert set(WALL_MARKERS) <= set(atlas.flow) and "phase/mid_diastole/WSS" in atlas.flow
    assert atlas.field_shapes["TAWSS"] == GRID[:2] and atlas.field_shapes["phase/peak_systole/U"] == (*GRID, 3)
    # the planted pattern, known independently of the PCA
    e = tawss_pattern(fields["P0"]["tau"], fields["P0"]["theta"]).ravel()
    e /= np.linalg.norm(e)
    tawss = atlas.flow["TAWSS"]
    assert abs(tawss.components[0] @ e) > 0.99
    assert abs(np.corrcoef(tawss.scores[:, 0], a)[0, 1]) > 0.99
    assert tawss.explained_variance_ratio[0] > 0.95
    assert tawss.sigma[0] == pytest.approx(np.std(a, ddof=1) * np.linalg.norm(tawss_pattern(*_grid(fields))), rel=0.05)
    # phase fields are the phases' arrays (factor x the cycle average), not the averages again
    for phase, factor in zip(PHASES, PHASE_FACTORS):
        for q in ("U", "p", "WSS"):
            pca = atlas.flow[f"phase/{phase}/{q}"]
            ref = factor * atlas.flow[q].sigma
            np.testing.assert_allclose(pca.sigma, ref, rtol=1e-9, atol=1e-9 * ref[0])
            np.testing.assert_allclose(pca.mean, factor * atlas.flow[q].mean, rtol=1e-12, atol=1e-15)
    # every PCA has its shape -> flow regression, with the cohort's status
    assert set(atlas.regression) == set(atlas.flow)
    assert {r["status"] for r in atlas.regression.values()} == {"ok"}
    s = atlas_summary(atlas)
    assert s["flow_kind"] == "pulsatile" and s["phase_names"] == list(PHASES)
    assert set(s["flow_explained_variance"]) == set(atlas.flow)
    assert s["flow_explained_variance"]["TAWSS"][0] > 0.95
    assert s["wall_markers"]["markers"]["TAWSS"] == {
        "data": "TAWSS",
        "transform": None,
        "units": "Pa",
        "n_cells": GRID[0] * GRID[1],
        "n_left_out": 0,
        "fraction_left_out": 0.0,
        "non_finite_by_patient": {},
        "ostium_by_patient": {},
    }
    assert s["wall_markers"]["markers"]["log10_RRT"]["transform"] == "log10"
    json.dumps(s, allow_nan=False)


def _grid(fields):
    return fields["P0"]["tau"], fields["P0"]["theta"]


def test_mixing_pulsatile_and_steady_patients_is_refused_in_one_line():
    models, fields, _, _ = pulsatile_cohort(5)
    steady = {pid: synthetic_fields(None, 0.5, n=GRID) for pid in ("P2", "P4")}
    steady["P2"]["field_source"] = np.str_("instantaneous")
    steady["P4"]["field_source"] = np.str_("time_average")
    mixed = fields | steady
    expected = (
        "an atlas cannot mix pulsatile and steady flows: pulsatile P0, P1, P3; steady P2 (instantaneous), "
        "P4 (time_average); run every patient with the same cfd.inlet.waveform setting"
    )
    with pytest.raises(VCSInputError) as err:
        compute_atlas(models, mixed, {}, n_modes=2)
    assert str(err.value) == expected and "\n" not in str(err.value)
    # judged on the included patients: a steady patient left out (its solve failed) mixes nothing
    models6, fields6, _, _ = pulsatile_cohort(4)
    models6["S"] = synthetic_model(radius=9.0)
    fields6["S"] = synthetic_fields(None, 0.5, n=GRID)
    atlas = compute_atlas(models6, fields6, {"S": {"converged": False, "reason": "diverged"}}, n_modes=2)
    assert atlas.patients == ["P0", "P1", "P2", "P3"] and atlas.flow_kind == "pulsatile"
    # pulsatile patients sampled at different phases cannot share the phase PCAs
    fields["P1"] = fields["P1"] | {"phase_names": np.array(PHASES[:2], dtype=str)}
    with pytest.raises(VCSInputError, match=r"sampled at different phases \(P0 peak_systole, end_systole, mid_"):
        compute_atlas(models, fields, {}, n_modes=2)


def test_non_finite_rrt_cells_are_left_out_of_the_log10_rrt_pca(tmp_path):
    models, fields, _, b = pulsatile_cohort(6, seed=2, rrt_modes=True)
    n_tau, n_theta = GRID[:2]
    bad = np.zeros((n_tau, n_theta), bool)
    for pid, cells, value in (
        ("P1", [(2, 3), (2, 4)], np.inf),  # OSI = 0.5
        ("P3", [(5, 0)], np.nan),  # 0/0
        ("P4", [(7, 7)], 0.0),  # not positive: no logarithm
    ):
        rrt = fields[pid]["RRT"].copy()
        for c in cells:
            rrt[c] = value
            bad[c] = True
        fields[pid]["RRT"] = rrt
    atlas = compute_atlas(models, fields, {}, n_modes=3)
    pca = atlas.flow["log10_RRT"]
    keep = ~bad.ravel()
    np.testing.assert_array_equal(pca.support, keep)
    # left out, never zero-filled: NaN mean (so NaN +-2 sigma maps), no mode weight there
    assert np.isnan(pca.mean[~keep]).all() and np.isfinite(pca.mean[keep]).all()
    assert np.isnan(pca.components[:, ~keep]).all() and np.isfinite(pca.components[:, keep]).all()
    assert np.isnan(pca.mode_sample(0, 2.0)[~keep]).all()
    # on the other cells: the planted log10 RRT pattern, with the planted amplitudes
    e = rrt_pattern(*_grid(fields)).ravel()[keep]
    assert abs(pca.components[0, keep] @ e) / np.linalg.norm(e) > 0.999
    assert abs(np.corrcoef(pca.scores[:, 0], b)[0, 1]) > 0.999
    assert pca.explained_variance_ratio[0] > 0.999
    np.testing.assert_allclose(pca.mean[keep], 0.5 + np.mean(b) * rrt_pattern(*_grid(fields)).ravel()[keep])
    # a cohort member projects onto its own scores
    x = np.log10(fields["P0"]["RRT"]).ravel()
    s, _, err = pca.project(x)
    np.testing.assert_allclose(s, pca.scores[0], atol=1e-9)
    assert err < 1e-9
    # the top-20 % region is ~20 % of the cells in the PCA (more with ties), never a left-out one
    mask = top_variation_mask(pca, 0, (n_tau, n_theta), vector=False)
    assert not mask[bad].any() and 0.2 * keep.sum() - 1 <= mask.sum() < 0.3 * keep.sum()
    # the other markers are finite: nothing left out
    assert all(atlas.flow[m].support is None for m in ("TAWSS", "OSI", "ECAP"))
    summary = atlas_summary(atlas)
    rec = summary["wall_markers"]["markers"]["log10_RRT"]
    assert rec["data"] == "RRT" and rec["units"] == "log10(1/Pa)"
    assert rec["n_left_out"] == 4 and rec["n_cells"] == n_tau * n_theta
    assert rec["non_finite_by_patient"] == {"P1": 2, "P3": 1, "P4": 1}
    assert "left out" in summary["wall_markers"]["non_finite_rule"]
    assert "log10" in summary["wall_markers"]["transforms"]["log10_RRT"]
    json.dumps(summary, allow_nan=False)  # strict JSON
    # one patient without a single finite RRT: that marker has no PCA, with the reason; the rest stays
    fields["P2"]["RRT"] = np.full((n_tau, n_theta), np.inf)
    atlas = compute_atlas(models, fields, {}, n_modes=3)
    assert "log10_RRT" not in atlas.flow and "log10_RRT" not in atlas.regression
    assert {"TAWSS", "OSI", "ECAP"} <= set(atlas.flow)
    rec = atlas_summary(atlas)["wall_markers"]["markers"]["log10_RRT"]
    assert rec["excluded"] == (
        "no wall cell where every included patient's RRT is finite and positive (missing for P1, P2, P3, P4)"
    )
    assert rec["non_finite_by_patient"]["P2"] == n_tau * n_theta
    # outside the wall markers a non-finite value is an error naming the patient and the field
    fields["P5"]["U_vcs"] = fields["P5"]["U_vcs"].copy()
    fields["P5"]["U_vcs"][0, 0, 0, 0] = np.nan
    with pytest.raises(VCSInputError, match=r"patient P5: field U_vcs has 1 non-finite values"):
        compute_atlas(models, fields, {}, n_modes=3)
    with pytest.raises(VCSInputError, match="non-finite"):
        PCA.from_data(np.array([[1.0, np.nan], [2.0, 3.0], [0.0, 1.0]]))


def test_steady_cohorts_get_no_marker_or_phase_pcas():
    """A time-averaged steady cohort has TAWSS and OSI in its fields, but its atlas stays U, p, WSS
    (wall markers of a cardiac cycle are a pulsatile cohort's); they can be asked for by name."""
    models, _, _, _ = pulsatile_cohort(5)
    fields = {}
    for i, pid in enumerate(models):
        f = synthetic_fields(None, 0.5 + 0.1 * i, n=GRID)
        f.update(TAWSS=np.full(GRID[:2], 1.0 + i), OSI=np.full(GRID[:2], 0.01 * i))
        f["field_source"] = np.str_("time_average")
        fields[pid] = f
    atlas = compute_atlas(models, fields, {}, n_modes=2)
    assert list(atlas.flow) == ["U", "p", "WSS"] and atlas.flow_kind == "steady" and atlas.phase_names == ()
    s = atlas_summary(atlas)
    assert s["wall_markers"] is None and s["phase_names"] == [] and s["flow_kind"] == "steady"
    assert s["options"]["flow_fields"] == ["U", "p", "WSS"]
    asked = compute_atlas(models, fields, {}, n_modes=2, flow_fields=("U", "TAWSS"))
    assert list(asked.flow) == ["U", "TAWSS"] and asked.flow["TAWSS"].explained_variance_ratio[0] > 0.999


def test_build_atlas_of_a_pulsatile_cohort_from_fields_npz(tmp_path):
    """As workflow/scripts/atlas_build.py calls it: paths of fields.npz written by
    vcs.cfd.resample.write_fields. Every PCA is in atlas.json and atlas.npz, the markers get
    (tau, theta) maps, the phase fields clipped views, named by the field's slug."""
    from vcs.cfd.resample import write_fields

    models, fields, _, _ = pulsatile_cohort(5, seed=3, rrt_modes=True)
    rrt = fields["P2"]["RRT"].copy()
    rrt[4, 2] = np.inf
    fields["P2"]["RRT"] = rrt
    paths = {}
    for pid, f in fields.items():
        paths[pid] = tmp_path / "patients" / pid / "fields.npz"
        paths[pid].parent.mkdir(parents=True)
        write_fields(f, paths[pid])
    out = tmp_path / "atlas"
    build_atlas(models, paths, {pid: {"converged": True} for pid in models}, out, n_modes=1)
    s = json.loads((out / "atlas.json").read_text())
    assert s["flow_kind"] == "pulsatile" and set(s["field_sources"].values()) == {"pulsatile"}
    names = list(pulsatile_fields(PHASES))
    assert sorted(s["flow_explained_variance"]) == sorted(names)
    assert sorted(s["shape_to_flow_regression"]["loo_r2"]) == sorted(names)
    assert s["wall_markers"]["markers"]["log10_RRT"]["non_finite_by_patient"] == {"P2": 1}
    files = s["files"]
    for key in ("flow_TAWSS_mode1", "flow_log10_RRT_mode1", "flow_phase_peak_systole_U_mode1", "flow_p_mode1"):
        assert files[key] == f"figures/{key}.png", files
    for f in files.values():
        assert (out / f).is_file(), f
    assert set(s["colour_limits"]["limits"]) == {f"flow_{n.replace('/', '_')}_mode1" for n in names}
    with np.load(out / "atlas.npz") as z:
        assert list(z["phase_names"]) == list(PHASES)
        assert "flow_phase_mid_diastole_WSS_mean" in z.files and "flow_TAWSS_support" not in z.files
        support = z["flow_log10_RRT_support"].reshape(GRID[:2])
        assert not support[4, 2] and support.sum() == GRID[0] * GRID[1] - 1
    import pyvista as pv

    grid = pv.read(out / "flow_mean.vtu")
    for name in ("TAWSS_mean", "log10_RRT_mode1_plus2sigma", "phase_end_systole_p_mean", "ECAP_mode1_top20"):
        assert name in grid.point_data, name
    assert np.isnan(grid.point_data["log10_RRT_mean"]).sum() == 1  # the one wall cell, nothing inside


def test_marker_map_and_explained_variance_panels():
    from matplotlib.colors import to_rgb

    from vcs.atlas.plots import LEFT_OUT_NOTE, NAN_COLOUR, _plt, variance_groups, wall_map_figure

    models, fields, _, _ = pulsatile_cohort(4)
    atlas = compute_atlas(models, fields, {}, n_modes=2)
    groups = variance_groups(atlas)
    assert [t for t, _ in groups] == [
        "shape and cycle-averaged flow",
        "wall markers",
        "phase peak_systole",
        "phase end_systole",
        "phase mid_diastole",
    ]
    assert list(groups[0][1]) == ["shape", "U", "p", "WSS"] and list(groups[1][1]) == list(WALL_MARKERS)
    assert list(groups[2][1]) == ["U", "p", "WSS"]
    tau, theta = _grid(fields)
    m = np.outer(tau, np.ones_like(theta))
    m[3, 2] = np.nan
    panels = [("a", m, "viridis"), ("b", m + 1, "viridis"), ("mask", m > 0.5, "Reds")]
    fig = wall_map_figure(tau, theta, panels, label="TAWSS (Pa)", clim=(0.0, 2.0), note="scale")
    try:
        images = [ax.images[0] for ax in fig.axes if ax.images]
        assert [im.get_clim() for im in images] == [(0.0, 2.0), (0.0, 2.0), (0.0, 1.0)]
        assert images[0].get_array().shape == (len(theta), len(tau))  # tau along x
        assert np.ma.is_masked(images[0].get_array()[2, 3])  # NaN drawn as 'bad' (grey), not a value
        assert images[0].cmap.get_bad()[:3] == pytest.approx(to_rgb(NAN_COLOUR))  # grey
        assert fig.get_suptitle() == f"scale; {LEFT_OUT_NOTE}"
        colour_bars = [ax for ax in fig.axes if not ax.images and ax.get_label() == "<colorbar>"]
        assert len(colour_bars) == 1 and colour_bars[0].get_xlabel() == "TAWSS (Pa)"
    finally:
        _plt().close(fig)


def _run_atlas_build_script(tmp_path, models, fields) -> tuple[int, str, dict | None]:
    """workflow/scripts/atlas_build.py in a subprocess (it takes over stderr for its log), with a
    stand-in for the snakemake object; returns its exit code, its log and atlas.json."""
    import subprocess
    import sys
    from pathlib import Path

    from vcs.cfd.resample import write_fields

    script = Path(__file__).resolve().parents[2] / "workflow" / "scripts" / "atlas_build.py"
    inputs: dict[str, list[str]] = {"reports": [], "models": [], "fields": [], "statuses": []}
    for pid, f in fields.items():
        d = tmp_path / "patients" / pid
        d.mkdir(parents=True)
        (d / "fit_report.json").write_text(json.dumps({"units": "mm"}))
        models[pid].save(d / "model.json")
        write_fields(f, d / "fields.npz")
        (d / "status.json").write_text(json.dumps({"converged": True}))
        for key, name in (("reports", "fit_report.json"), ("models", "model.json"), ("fields", "fields.npz")):
            inputs[key].append(str(d / name))
        inputs["statuses"].append(str(d / "status.json"))
    out = tmp_path / "atlas"
    out.mkdir()
    smk = {
        "input": inputs,
        "params": {"ids": list(fields), "options": {"n_modes": 1, "figures": False}},
        "output": {
            "json": str(out / "atlas.json"),
            "npz": str(out / "atlas.npz"),
            "figures": str(out / "figures"),
            "patients_html": str(out / "patients.html"),
            "patients_tsv": str(out / "patients.tsv"),
        },
        "log": [str(tmp_path / "atlas.log")],
        "scriptdir": str(script.parent),
    }
    driver = (
        "import json, runpy, sys\n"
        "from types import SimpleNamespace as NS\n"
        f"d = json.loads({json.dumps(json.dumps(smk))})\n"
        "smk = NS(input=NS(**d['input']), params=NS(**d['params']), output=NS(**d['output']),\n"
        "         log=d['log'], scriptdir=d['scriptdir'])\n"
        f"runpy.run_path({str(script)!r}, init_globals={{'snakemake': smk}}, run_name='__main__')\n"
    )
    r = subprocess.run([sys.executable, "-c", driver], capture_output=True, text=True, timeout=300)
    atlas_json = out / "atlas.json"
    summary = json.loads(atlas_json.read_text()) if atlas_json.is_file() else None
    return r.returncode, (tmp_path / "atlas.log").read_text(), summary


def test_atlas_build_script_passes_a_pulsatile_cohort_through_and_refuses_a_mixed_one(tmp_path):
    models, fields, _, _ = pulsatile_cohort(5, seed=4)
    rrt = fields["P3"]["RRT"].copy()
    rrt[1, 1] = np.inf
    fields["P3"]["RRT"] = rrt
    code, log, s = _run_atlas_build_script(tmp_path / "pulsatile", dict(models), fields)
    assert code == 0, log
    assert s["flow_kind"] == "pulsatile" and sorted(s["flow_explained_variance"]) == sorted(pulsatile_fields(PHASES))
    assert "flow: pulsatile (16 PCAs: U, p, WSS, TAWSS, OSI, log10_RRT, ECAP, phase/peak_systole/U," in log
    assert "wall marker log10_RRT: 1 of 72 wall cells left out of its PCA (not finite for P3)" in log
    mixed = fields | {"P1": synthetic_fields(None, 0.5, n=GRID)}
    code, log, s = _run_atlas_build_script(tmp_path / "mixed", dict(models), mixed)
    errors = [ln for ln in log.splitlines() if " ERROR " in ln]
    assert code == 2 and s is None and "Traceback" not in log, log
    assert len(errors) == 1 and errors[0].endswith(
        "an atlas cannot mix pulsatile and steady flows: pulsatile P0, P2, P3, P4; steady P1 (instantaneous); "
        "run every patient with the same cfd.inlet.waveform setting"
    ), errors
