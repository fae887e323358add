"""Dry-run tests of the Snakemake workflow: which jobs an edit reruns, sheet validation, lint.

No OpenFOAM or VCS code runs: the outputs of a finished run are faked (empty files +
`snakemake --touch`, which records the params/code metadata the rerun triggers compare).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import parse_jobs

PER_PATIENT = ["vcs_fit", "vcs_wall", "openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"]
IDS = ["P1", "P2", "P3"]


def chain(rules, ids=IDS):
    return {(r, i) for r in rules for i in ids}


COHORT = {("atlas_build", None), ("atlas_complete", None), ("all", None)}


def _cohort_rows() -> list[dict]:
    """The sheet rows of the `cohort` fixture (to edit one patient's columns)."""
    return [
        {"id": "P1", "mesh": "meshes/p1.stl", "units": "mm"},
        {"id": "P2", "mesh": "meshes/p 2 scan.stl", "units": "mm", "inlet": "0,0,0", "outlet": "0,0,100"},
        {"id": "P3", "mesh": "meshes/p3.stl"},
    ]


def test_fresh_cohort_plans_every_stage_once_per_patient(cohort):
    assert cohort.planned_jobs() == chain(PER_PATIENT) | COHORT


def test_finished_run_is_up_to_date(cohort):
    cohort.fake_finished_run()
    r = cohort.snakemake("-n")
    assert "Nothing to be done" in r.stdout + r.stderr


def test_editing_one_mesh_reruns_only_that_patient_and_the_atlas(cohort):
    cohort.fake_finished_run()
    with open(cohort.path / "meshes" / "p 2 scan.stl", "a") as fh:  # an edit, not just a touch:
        fh.write("solid edited\nendsolid edited\n")  # same bytes + newer mtime is no change
    assert cohort.planned_jobs() == chain(PER_PATIENT, ["P2"]) | COHORT


def test_cfd_parameter_reruns_cfd_and_downstream_but_not_the_fit(cohort):
    cohort.fake_finished_run()
    cohort.update_config("cfd", "solver", "max_iterations", 777)
    assert cohort.planned_jobs() == chain(["openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"]) | COHORT


def test_mesh_size_reruns_cfd_and_downstream_but_not_the_fit(cohort):
    cohort.fake_finished_run()
    current = cohort.config().get("cfd", {}).get("mesh", {}).get("cell_size", "auto")
    new = 3.0e-3 if current == "auto" else 1.5 * current  # a real change, whatever the default
    cohort.update_config("cfd", "mesh", "cell_size", new)
    planned = cohort.planned_jobs()
    assert planned == chain(["openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"]) | COHORT
    assert not {job for job in planned if job[0] in ("vcs_fit", "vcs_wall")}


def test_auto_sizing_parameter_reruns_cfd_and_downstream_but_not_the_fit(cohort):
    cohort.fake_finished_run()
    cohort.update_config("cfd", "mesh", "cells_across_end", 16)
    assert cohort.planned_jobs() == chain(["openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"]) | COHORT


def test_one_patients_own_cfd_values_rerun_only_that_patients_cfd(cohort):
    """A flow rate (or cell size) in one row of the sheet is a param of that patient's case:
    its CFD, sampling and the atlas rerun, nobody's fit, nobody else's CFD."""
    cohort.fake_finished_run()
    rows = _cohort_rows()
    rows[1]["flow_rate_l_min"] = "2.5"
    cohort.write_sheet(rows)
    assert (
        cohort.planned_jobs()
        == chain(["openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"], ["P2"]) | COHORT
    )
    cohort.fake_finished_run()
    rows[0]["cell_size_mm"] = "auto"  # the config's value, spelled out: no change
    cohort.write_sheet(rows)
    assert "Nothing to be done" in (lambda r: r.stdout + r.stderr)(cohort.snakemake("-n"))
    rows[2]["cell_size_mm"] = "0.8"
    cohort.write_sheet(rows)
    assert (
        cohort.planned_jobs()
        == chain(["openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"], ["P3"]) | COHORT
    )


def test_one_patients_geometry_and_outlets_rerun_only_that_patients_cfd(cohort):
    """cfd_geometry surface in one row: that patient's lumen (not its fit, nobody's wall) and its
    CFD; then its outlets / Windkessel totals: its CFD only."""
    cohort.fake_finished_run()
    rows = _cohort_rows()
    rows[1]["cfd_geometry"] = "surface"
    cohort.write_sheet(rows)
    cfd = ["openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"]
    assert cohort.planned_jobs() == chain(["vcs_lumen", *cfd], ["P2"]) | COHORT
    cohort.fake_finished_run()
    rows[2] |= {"outlets": "rcr", "rcr_compliance_ml_mmhg": "1.5"}
    cohort.write_sheet(rows)
    assert cohort.planned_jobs() == chain(cfd, ["P3"]) | COHORT


def test_knots_rerun_everything_downstream_of_the_fit(cohort):
    cohort.fake_finished_run()
    cohort.update_config("vcs", "K", 15)
    assert cohort.planned_jobs() == chain(PER_PATIENT) | COHORT


def test_wall_resolution_reruns_from_the_wall_stl(cohort):
    cohort.fake_finished_run()
    cohort.update_config("wall", "n_theta", 48)
    assert cohort.planned_jobs() == chain(PER_PATIENT[1:]) | COHORT


def test_grid_size_reruns_sampling_and_atlas_only(cohort):
    cohort.fake_finished_run()
    cohort.update_config("grid", "n_rho", 5)
    assert cohort.planned_jobs() == chain(["fields_sample", "patient_qc"]) | COHORT


def test_atlas_option_reruns_the_atlas_only(cohort):
    cohort.fake_finished_run()
    cohort.update_config("atlas", "n_modes", 2)
    assert cohort.planned_jobs() == COHORT


def test_changing_how_one_patients_ends_are_given_reruns_that_patient(cohort):
    cohort.fake_finished_run()
    cohort.write_sheet(
        [
            {"id": "P1", "mesh": "meshes/p1.stl", "units": "mm"},
            {"id": "P2", "mesh": "meshes/p 2 scan.stl", "units": "mm", "inlet": "0,0,0", "outlet": "0,0,90"},
            {"id": "P3", "mesh": "meshes/p3.stl"},
        ]
    )
    assert cohort.planned_jobs() == chain(PER_PATIENT, ["P2"]) | COHORT


def test_adding_a_patient_runs_its_chain_and_the_atlas(cohort):
    cohort.fake_finished_run()
    (cohort.path / "meshes" / "p4.stl").write_text("solid empty\nendsolid empty\n")
    cohort.write_sheet(
        [
            {"id": "P1", "mesh": "meshes/p1.stl", "units": "mm"},
            {"id": "P2", "mesh": "meshes/p 2 scan.stl", "units": "mm", "inlet": "0,0,0", "outlet": "0,0,100"},
            {"id": "P3", "mesh": "meshes/p3.stl"},
            {"id": "P4", "mesh": "meshes/p4.stl"},
        ]
    )
    assert cohort.planned_jobs() == chain(PER_PATIENT, ["P4"]) | COHORT


def test_sheet_saved_with_a_utf8_bom_is_read(cohort):
    """Excel's "UTF-8 CSV" starts the file with a byte-order mark: it is not part of the header."""
    sheet = cohort.write_sheet([{"id": "P1", "mesh": "meshes/p1.stl", "units": "mm"}])
    body = sheet.read_text().split("\n", 1)[1]  # no comment line: the BOM sits right before `id`
    sheet.write_bytes(b"\xef\xbb\xbf" + body.encode())
    assert cohort.planned_jobs() == chain(PER_PATIENT, ["P1"]) | COHORT


def test_mesh_path_with_spaces_is_quoted(cohort):
    r = cohort.snakemake("-n", "-p", "--forcerun", "vcs_fit")
    fit_cmds = [
        ln for ln in (r.stdout + r.stderr).splitlines() if ln.lstrip().startswith("vcs fit") or "vcs fit " in ln
    ]
    p2 = [c for c in fit_cmds if "p 2 scan" in c]
    assert p2 and "'meshes/p 2 scan.stl'" in p2[0], fit_cmds
    assert "--inlet=0,0,0 --outlet=0,0,100" in p2[0]


def test_fit_runs_with_sheet_points_with_minus_signs_and_spaces(tmp_path, workdir_factory):
    """Sheet points as scanners give them (negative, written with spaces) reach `vcs fit` as one
    argument each that argparse cannot mistake for an option, and the fit itself runs (a torus
    phantom moved to negative coordinates; the points pick its two open ends, outlet first)."""
    import json

    import numpy as np

    from vcs.mesh import write_stl_binary
    from vcs.phantoms.factory import make_phantom

    ph = make_phantom("torus", resolution=2.5)
    shift = np.array([-150.0, -75.5, -1200.0])
    (tmp_path / "meshes").mkdir()
    write_stl_binary(tmp_path / "meshes" / "neg torus.stl", ph.vertices + shift, ph.faces)
    inlet = ", ".join(f"{v:.2f}" for v in ph.outlet_center + shift)  # "-190.00, -75.50, -1200.00"
    outlet = " " + ",".join(f"{v:.2f}" for v in ph.inlet_center + shift)  # " -110.00,-75.50,-1200.00"
    wd = workdir_factory(tmp_path, [{"id": "N1", "mesh": "meshes/neg torus.stl", "inlet": inlet, "outlet": outlet}])
    r = wd.snakemake("-n", "-p", "results/patients/N1/fit/model.json")
    assert "--inlet='-190.00, -75.50, -1200.00' --outlet=-110.00,-75.50,-1200.00" in r.stdout + r.stderr
    wd.snakemake("-c1", "results/patients/N1/fit/model.json")
    rep = json.loads((tmp_path / "results/patients/N1/fit/fit_report.json").read_text())
    assert rep["units"] == "mm" and rep["ends_method"] == "open_loops"
    assert np.linalg.norm(np.array(rep["inlet"]["center_mm"]) - (ph.outlet_center + shift)) < 0.5
    assert np.linalg.norm(np.array(rep["outlet"]["center_mm"]) - (ph.inlet_center + shift)) < 0.5


def test_sheet_ends_listed_by_vcs_ends_reach_the_fit(cohort):
    """inlet/outlet cells may name ends of `vcs ends` (end:N, NAME=VALUE) instead of points."""
    cohort.write_sheet(
        [
            {"id": "P1", "mesh": "meshes/p1.stl", "inlet": "end:2", "outlet": " end:0"},
            {"id": "P2", "mesh": "meshes/p 2 scan.stl", "inlet": "ModelFaceID=3", "outlet": "ModelFaceID=-1"},
            {"id": "P3", "mesh": "meshes/p3.stl", "inlet": "-1.5e1, -2, -3.25", "outlet": "-4,5,-6"},
        ]
    )
    r = cohort.snakemake("-n", "-p", "--forcerun", "vcs_fit")
    text = r.stdout + r.stderr
    assert "--inlet=end:2 --outlet=end:0" in text
    assert "--inlet=ModelFaceID=3 --outlet=ModelFaceID=-1" in text
    assert "--inlet='-1.5e1, -2, -3.25' --outlet=-4,5,-6" in text


def test_demo_rows_generate_their_phantoms(tmp_path, workdir_factory):
    wd = workdir_factory(
        tmp_path, [{"id": f"demo_{s}", "mesh": f"results/demo/aorta_seed{s}.stl", "units": "mm"} for s in (0, 1, 2)]
    )
    planned = wd.planned_jobs()
    assert {("vcs_phantom", f"aorta_seed{s}") for s in (0, 1, 2)} <= planned
    assert chain(PER_PATIENT, ["demo_0", "demo_1", "demo_2"]) | COHORT <= planned


def test_default_config_is_the_eight_phantom_demo(repo):
    r = subprocess.run(
        [
            str(Path(sys.executable).parent / "snakemake"),
            "-s",
            str(repo / "Snakefile"),
            "-d",
            str(repo),
            "-n",
            "--quiet",
            "rules",
            "--forceall",
        ],
        capture_output=True,
        text=True,
        cwd=repo,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    counts = dict(
        ln.split()[:2]
        for ln in r.stdout.splitlines()
        if ln.split()[:1] and ln.split()[0] in ("vcs_phantom", "vcs_fit", "openfoam_solve", "atlas_build")
    )
    assert counts == {"vcs_phantom": "8", "vcs_fit": "8", "openfoam_solve": "8", "atlas_build": "1"}


# ------------------------------------------------------------------ cohort scale on SLURM

_TOP_LEVEL = re.compile(r"^\[[^\]]+\]\s*$|^\[[^\]]+\] Group job (\w+) \(jobs in lexicogr\. order\):$", re.M)


def slurm_submissions(text: str) -> list[tuple[str | None, set]]:
    """The jobs a dry-run with profiles/slurm would submit: [(group or None, {(rule, id)})], one
    per top-level entry of the plan (a group job with its member jobs, or a single job)."""
    starts = list(_TOP_LEVEL.finditer(text))
    entries = []
    for m, nxt in zip(starts, [*starts[1:], None]):
        body = text[m.end() : nxt.start() if nxt else len(text)]
        if m.group(1):  # a group's member jobs are printed indented by 4
            body = re.sub(r"^ {4}", "", body, flags=re.M)
        entries.append((m.group(1), parse_jobs(body)))
    return entries


def test_a_thousand_patients_on_slurm_are_one_job_each_and_the_atlas(tmp_path, workdir_factory, repo):
    """profiles/slurm groups each patient's chain into one SLURM job: a 1,000-patient sheet of
    demo rows plans 7,003 jobs (phantom + 6 per patient, atlas, verdict, `all`) and submits 1,001:
    one per patient holding exactly that patient's seven jobs, and the atlas (atlas_complete and
    `all` run in Snakemake itself). A dry-run: nothing is submitted. (bench/slurm_plan.py prints
    how long the plan takes.)"""
    n = 1000
    wd = workdir_factory(
        tmp_path, [{"id": f"P{i}", "mesh": f"results/demo/aorta_seed{i}.stl", "units": "mm"} for i in range(n)]
    )
    r = wd.snakemake("-n", "--profile", str(repo / "profiles" / "slurm"), timeout=1800)
    text = r.stdout + r.stderr
    assert re.search(r"^total\s+7003$", text, re.M), text[-3000:]
    plan = slurm_submissions(text)
    singles = sorted(rule for group, jobs in plan if group is None for rule, _ in jobs)
    assert singles == ["all", "atlas_build", "atlas_complete"], singles
    groups = [frozenset(jobs) for group, jobs in plan if group is not None]
    assert {group for group, _ in plan} == {"patient", None}
    chains = {frozenset(chain(PER_PATIENT, [f"P{i}"]) | {("vcs_phantom", f"aorta_seed{i}")}) for i in range(n)}
    assert len(groups) == n and set(groups) == chains
    assert len(groups) + singles.count("atlas_build") == n + 1  # SLURM jobs


# ------------------------------------------------------------------ one-line errors


def _one_line_error(wd) -> str:
    r = wd.snakemake("-n", check=False)
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    return lines[0]


@pytest.mark.parametrize("bad_id", ["P 1", "P/1", "P.1", "P1;rm"])
def test_bad_patient_id_fails_with_one_line(cohort, bad_id):
    cohort.write_sheet([{"id": bad_id, "mesh": "meshes/p1.stl"}])
    msg = _one_line_error(cohort)
    assert f"id '{bad_id}'" in msg and "A-Za-z0-9_-" in msg and "line 3" in msg


def test_duplicate_patient_id_fails_with_one_line(cohort):
    cohort.write_sheet([{"id": "P1", "mesh": "meshes/p1.stl"}, {"id": "P1", "mesh": "meshes/p3.stl"}])
    assert "already used on line 3" in _one_line_error(cohort)


def test_missing_mesh_fails_with_one_line(cohort):
    cohort.write_sheet([{"id": "P1", "mesh": "meshes/nope.stl"}])
    assert "mesh 'meshes/nope.stl' not found" in _one_line_error(cohort)


def test_ends_given_twice_fail_with_one_line(cohort):
    cohort.write_sheet(
        [
            {
                "id": "P1",
                "mesh": "meshes/p1.stl",
                "inlet": "0,0,0",
                "outlet": "1,1,1",
                "inlet_cap": "meshes/p3.stl",
                "outlet_cap": "meshes/p3.stl",
            }
        ]
    )
    assert "not both" in _one_line_error(cohort)


def test_half_given_ends_fail_with_one_line(cohort):
    cohort.write_sheet([{"id": "P1", "mesh": "meshes/p1.stl", "inlet": "0,0,0"}])
    assert "both inlet and outlet" in _one_line_error(cohort)


@pytest.mark.parametrize(
    "cells, expected",
    [
        ({"cell_size_mm": "fine"}, "cell_size_mm 'fine' is not a number; give auto or a number in [0.05, 50] mm"),
        ({"cell_size_mm": "0.01"}, "cell_size_mm '0.01' is out of range; give auto or a number in [0.05, 50] mm"),
        ({"cell_size_mm": "nan"}, "cell_size_mm 'nan' is out of range"),
        ({"cell_size_mm": "inf"}, "cell_size_mm 'inf' is out of range"),
        ({"flow_rate_l_min": "-2"}, "flow_rate_l_min '-2' is out of range; give a number in (0, 50] L/min"),
        ({"flow_rate_l_min": "-1"}, "flow_rate_l_min '-1' is out of range"),
        ({"flow_rate_l_min": "0"}, "flow_rate_l_min '0' is out of range"),
        ({"flow_rate_l_min": "nan"}, "flow_rate_l_min 'nan' is out of range"),
        ({"flow_rate_l_min": "NaN"}, "flow_rate_l_min 'NaN' is out of range"),
        ({"flow_rate_l_min": "inf"}, "flow_rate_l_min 'inf' is out of range"),
        ({"flow_rate_l_min": "1e9"}, "flow_rate_l_min '1e9' is out of range"),
        ({"flow_rate_l_min": "abc"}, "flow_rate_l_min 'abc' is not a number; give a number in (0, 50] L/min"),
        ({"flow_rate_l_min": "5 L/min"}, "flow_rate_l_min '5 L/min' is not a number"),
        ({"flow_rate_l_min": "80"}, "flow_rate_l_min '80' is out of range"),
        (
            {"inlet_velocity_m_s": "nan", "valve_area_cm2": "1"},
            "inlet_velocity_m_s 'nan' is out of range; give a number in (0, 10] m/s",
        ),
        (
            {"inlet_velocity_m_s": "1.2", "valve_area_cm2": "-inf"},
            "valve_area_cm2 '-inf' is out of range; give a number in (0, 50] cm2",
        ),
        ({"inlet_velocity_m_s": "1e9", "valve_area_cm2": "1"}, "inlet_velocity_m_s '1e9' is out of range"),
        ({"inlet_velocity_m_s": "1.2", "valve_area_cm2": "abc"}, "valve_area_cm2 'abc' is not a number"),
        ({"inlet_velocity_m_s": "1.2"}, "the inflow needs both inlet_velocity_m_s and valve_area_cm2"),
        ({"valve_area_cm2": "1"}, "the inflow needs both inlet_velocity_m_s and valve_area_cm2"),
        (
            {"flow_rate_l_min": "4", "inlet_velocity_m_s": "1.2", "valve_area_cm2": "1"},
            "give the inflow either as flow_rate_l_min or as inlet_velocity_m_s + valve_area_cm2, not both",
        ),
        ({"cfd_geometry": "lumen"}, "cfd_geometry"),
        ({"outlets": "windkessel"}, "outlets"),
        ({"outlets": "rcr", "rcr_resistance_mmhg_s_ml": "-1"}, "rcr_resistance_mmhg_s_ml '-1' is out of range"),
        ({"outlets": "rcr", "rcr_compliance_ml_mmhg": "nan"}, "rcr_compliance_ml_mmhg 'nan' is out of range"),
        (
            {"outlets": "murray", "rcr_resistance_mmhg_s_ml": "1"},
            "rcr_resistance_mmhg_s_ml is given but this patient's outlets are murray",
        ),
    ],
)
def test_bad_patient_cfd_columns_fail_with_one_line(cohort, cells, expected):
    cohort.write_sheet([{"id": "P1", "mesh": "meshes/p1.stl"}, {"id": "P2", "mesh": "meshes/p3.stl", **cells}])
    msg = _one_line_error(cohort)
    assert "line 4 (id P2)" in msg and expected in msg, msg


@pytest.mark.parametrize("bad", ["e,e,e", "..,+,-", "1e999,0,0", "-1e400,2,3"])
def test_sheet_point_that_is_not_three_finite_numbers_fails_with_one_line(cohort, bad):
    cohort.write_sheet([{"id": "P1", "mesh": "meshes/p1.stl", "inlet": bad, "outlet": "0,0,1"}])
    msg = _one_line_error(cohort)
    assert f"inlet '{bad}' is not a point of three finite numbers" in msg and "(id P1)" in msg, msg


@pytest.mark.parametrize("bad", ["2", "end:", "1,2", "cap 3"])
def test_malformed_sheet_end_fails_with_one_line(cohort, bad):
    cohort.write_sheet([{"id": "P1", "mesh": "meshes/p1.stl", "inlet": bad, "outlet": "end:1"}])
    msg = _one_line_error(cohort)
    assert f"inlet '{bad}'" in msg and "x,y,z" in msg and "end:N" in msg


def test_bad_config_value_fails_with_one_line(cohort):
    cohort.update_config("cfd", "ranks", 0)
    msg = _one_line_error(cohort)
    assert "cfd > ranks" in msg and "minimum of 1" in msg


@pytest.mark.parametrize(
    ("keys", "value"),
    [
        (("grid", "n_theta"), 10**9),
        (("vcs", "K"), 10**9),
        (("cfd", "mesh", "max_cells"), 10**12),
        (("wall", "n_theta"), -1),
    ],
)
def test_huge_or_negative_config_number_fails_with_one_line(cohort, keys, value):
    cohort.update_config(*keys, value)
    msg = _one_line_error(cohort)
    assert " > ".join(keys) in msg and ("maximum" in msg or "minimum" in msg), msg


@pytest.mark.parametrize(
    ("keys", "value"),
    [
        (("cfd", "inlet", "flow_rate"), float("nan")),
        (("cfd", "mesh", "layer_expansion"), float("inf")),
        (("wall", "extend_outlet"), float("nan")),
    ],
)
def test_non_finite_config_number_fails_with_one_line(cohort, keys, value):
    """A YAML `.nan` passes every minimum and maximum of the schema: it is refused by name."""
    cohort.update_config(*keys, value)
    msg = _one_line_error(cohort)
    assert " > ".join(keys) in msg and "is not a finite number" in msg, msg


@pytest.mark.parametrize(
    ("keys", "value"),
    [
        (("cfd", "solver", "div_scheme"), 'linearUpwind grad(U); #codeStream { code #{ system("id"); #}; }'),
        (("cfd", "solver", "startup_scheme"), "upwind;\nfunctions {}"),
        (("cfd", "decomposition", "method"), "scotch"),
    ],
)
def test_config_text_for_openfoam_dictionaries_is_refused_unless_listed(cohort, keys, value):
    """A config string is written into system/fvSchemes etc.: anything but a listed word stops the
    run with one line before any dictionary is written (no #codeStream injection)."""
    cohort.update_config(*keys, value)
    msg = _one_line_error(cohort)
    assert " > ".join(keys) in msg and "is not one of" in msg, msg


def _waveform(path: Path, rows: list[str]) -> Path:
    path.write_text("# a test cycle\ntime_s,flow_rate_l_min\n" + "\n".join(rows) + "\n")
    return path


def _good_rows(n: int = 24) -> list[str]:
    return [f"{0.8 * i / (n - 1):.6g},{5 + (3 if 0 < i < n - 1 else 0)}" for i in range(n)]


def test_bad_config_waveform_fails_with_one_line_naming_file_and_row(cohort):
    rows = _good_rows()
    rows[5] = rows[5].split(",")[0] + ",lots"
    _waveform(cohort.path / "bad.csv", rows)
    cohort.update_config("cfd", "inlet", "waveform", "bad.csv")
    msg = _one_line_error(cohort)
    assert msg.count("cfd.inlet.waveform") == 1 and "bad.csv" in msg and "line 8" in msg, msg


def test_missing_config_waveform_fails_with_one_line(cohort):
    cohort.update_config("cfd", "inlet", "waveform", "nope.csv")
    assert "cfd.inlet.waveform 'nope.csv' not found" in _one_line_error(cohort)


def test_bad_sheet_waveform_fails_with_one_line(cohort):
    rows = _good_rows()
    rows[3], rows[4] = rows[4], rows[3]  # times not increasing
    _waveform(cohort.path / "p2.csv", rows)
    cohort.write_sheet(
        [{"id": "P1", "mesh": "meshes/p1.stl"}, {"id": "P2", "mesh": "meshes/p3.stl", "inflow_waveform": "p2.csv"}]
    )
    msg = _one_line_error(cohort)
    assert "line 4 (id P2): inflow_waveform" in msg and "p2.csv" in msg and "line 7" in msg, msg


def test_editing_a_patients_waveform_reruns_only_that_patients_cfd(cohort):
    _waveform(cohort.path / "p2.csv", _good_rows())
    rows = [{"id": "P1", "mesh": "meshes/p1.stl"}, {"id": "P2", "mesh": "meshes/p 2 scan.stl"}]
    rows.append({"id": "P3", "mesh": "meshes/p3.stl"})
    rows[1]["inflow_waveform"] = "p2.csv"
    cohort.write_sheet(rows)
    cohort.update_config("cfd", "inlet", "waveform", str(_waveform(cohort.path / "cohort.csv", _good_rows())))
    cohort.fake_finished_run()
    assert cohort.planned_jobs() == set()
    _waveform(cohort.path / "p2.csv", _good_rows(30))  # same file, new content
    cfd = ["openfoam_case", "openfoam_solve", "fields_sample", "patient_qc"]
    assert cohort.planned_jobs() == chain(cfd, ["P2"]) | COHORT


def test_a_sheet_mixing_steady_and_pulsatile_patients_fails_with_one_line(cohort):
    _waveform(cohort.path / "p2.csv", _good_rows())
    rows = [{"id": "P1", "mesh": "meshes/p1.stl"}, {"id": "P2", "mesh": "meshes/p3.stl", "inflow_waveform": "p2.csv"}]
    cohort.write_sheet(rows)
    msg = _one_line_error(cohort)
    assert "P2 have an inflow_waveform (pulsatile) but P1 would be steady" in msg and "never mixes" in msg, msg


def test_a_waveform_with_a_flow_rate_fails_with_one_line(cohort):
    _waveform(cohort.path / "p2.csv", _good_rows())
    cohort.update_config("cfd", "inlet", "waveform", "p2.csv")
    row = {"id": "P2", "mesh": "meshes/p3.stl", "inflow_waveform": "p2.csv", "flow_rate_l_min": "4"}
    cohort.write_sheet([{"id": "P1", "mesh": "meshes/p1.stl"}, row])
    msg = _one_line_error(cohort)
    assert "line 4 (id P2): inflow_waveform is applied as given" in msg, msg


def test_every_config_string_is_an_enum_or_a_pattern():
    """Every string of the config schema is constrained (enum or pattern), except the sheet's path,
    which never reaches an OpenFOAM dictionary."""
    import yaml

    schema = yaml.safe_load((Path(__file__).resolve().parents[2] / "workflow/schemas/config.schema.yaml").read_text())
    free = []

    def walk(node, path):
        if not isinstance(node, dict):
            return
        types = node.get("type") if isinstance(node.get("type"), list) else [node.get("type")]
        if "string" in types and "enum" not in node and "pattern" not in node:
            free.append(path)
        for key, value in node.items():
            if key == "properties":
                for name, sub in value.items():
                    walk(sub, f"{path}/{name}")
            elif key in ("oneOf", "anyOf", "allOf"):
                for sub in value:
                    walk(sub, path)
            elif key in ("items", "additionalProperties"):
                walk(value, f"{path}/{key}")

    walk(schema, "")
    assert free == ["/patients"], free


def test_unknown_config_key_fails_with_one_line(cohort):
    cohort.update_config("cfd", "mesh", "cellsize", 1.0)
    assert "'cellsize' was unexpected" in _one_line_error(cohort)


# ------------------------------------------------------------------ lint


def test_lint_reports_nothing(cohort):
    """`snakemake --lint` finds nothing to fix (every rule names workflow/envs/vcs.yaml for
    --use-conda; the default software stack is the pinned venv + Debian OpenFOAM)."""
    r = cohort.snakemake("--lint", check=False)  # (snakemake 9.27's CLI ignores `--lint json`)
    text = r.stdout + r.stderr
    assert "Lints for" not in text, text
    assert "Congratulations, your workflow is in a good condition!" in text, text


AORTACFD = Path(__file__).resolve().parents[3] / "shared" / "data" / "vessels" / "aortacfd_patient1"


def test_bad_outlet_bc_table_fails_with_one_line(cohort):
    (cohort.path / "p2_rcr.csv").write_text("end,R_p,C,R_d,units\nend:1,1,0,1,SI\n")
    cohort.write_sheet(
        [{"id": "P1", "mesh": "meshes/p1.stl"}, {"id": "P2", "mesh": "meshes/p3.stl", "outlet_bc": "p2_rcr.csv"}]
    )
    msg = _one_line_error(cohort)
    assert "line 4 (id P2): outlet_bc" in msg and "p2_rcr.csv: line 2" in msg and "C 0" in msg, msg


@pytest.mark.skipif(not (AORTACFD / "wall_aorta.stl").is_file(), reason="shared data aortacfd_patient1 absent")
def test_outlet_bc_row_on_the_inlet_fails_at_planning_naming_patient_row_and_ends(cohort):
    """The table's rows are matched to the surface's ends when the workflow plans."""
    caps = {n: str(AORTACFD / f"{n}.stl") for n in ("inlet", "outlet1", "outlet4")}
    (cohort.path / "rcr.csv").write_text(f"end,R_p,C,R_d,units\n{caps['outlet1']},1,1,1,SI\n{caps['inlet']},1,1,1,SI\n")
    row = {"id": "A1", "mesh": str(AORTACFD / "wall_aorta.stl"), "units": "mm", "inlet_cap": caps["inlet"]}
    row.update(outlet_cap=caps["outlet4"], outlet_bc="rcr.csv")
    cohort.write_sheet([row])
    msg = _one_line_error(cohort)
    assert "(id A1): outlet_bc" in msg and "rcr.csv: line 3" in msg and "is the inlet (end:0)" in msg, msg
    assert "end:4 at" in msg, msg
    (cohort.path / "rcr.csv").write_text(
        "end,R_p,C,R_d,units\n" + "".join(f"{AORTACFD / f'outlet{k}.stl'},1,1,1,SI\n" for k in (1, 2, 3, 4))
    )
    assert ("openfoam_case", "A1") in cohort.planned_jobs()
