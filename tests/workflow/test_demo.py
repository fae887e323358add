"""The CI configuration end to end with the real OpenFOAM (marker ``openfoam``): 4 synthetic
aortas -> VCS fit -> wall STL -> snappyHexMesh + simpleFoam -> resampled fields -> atlas; then one
patient's case is broken and the atlas must list it as excluded with the stage and reason while
the others stay in, the run exiting non-zero after the atlas with one line naming it; last, the
Snakemake report opened in headless Chromium (report_check.py). A few minutes on 2 cores."""

from __future__ import annotations

import csv
import json
import re
import shutil

import pytest
import report_check
from conftest import ci_workdir

HAVE_FOAM = shutil.which("simpleFoam") is not None
SEEDS = (0, 1, 2, 3)
IDS = [f"demo_aorta_{s}" for s in SEEDS]


@pytest.mark.openfoam
@pytest.mark.skipif(not HAVE_FOAM, reason="OpenFOAM (simpleFoam) not installed; run scripts/install.sh")
def test_ci_cohort_end_to_end_and_a_failing_patient_is_excluded(tmp_path, workdir_factory, repo):
    wd = ci_workdir(tmp_path, SEEDS)
    before = {p.name for p in wd.path.iterdir()}
    profile = str(repo / "profiles" / "local")
    wd.snakemake("--profile", profile, "--cores", "2", timeout=3600)
    res = wd.path / "results"
    # the workflow writes nothing outside results/ (and Snakemake's own .snakemake/)
    assert {p.name for p in wd.path.iterdir()} - before == {"results", ".snakemake"}

    for pid in IDS:
        st = json.loads((res / "patients" / pid / "status.json").read_text())
        assert st["converged"] is True, st.get("reason")
        assert st["cells"] > 1000 and st["mass_imbalance"] < 1e-3
        assert (res / "patients" / pid / "fields.npz").stat().st_size > 1000
        with open(res / "benchmarks" / "openfoam_solve" / f"{pid}.tsv") as fh:
            assert float(next(csv.DictReader(fh, delimiter="\t"))["s"]) > 0
    atlas = json.loads((res / "atlas" / "atlas.json").read_text())
    assert sorted(atlas["patients_included"]) == IDS and atlas["patients_excluded"] == []
    assert any((res / "atlas" / "figures").glob("*.png"))

    prov = json.loads((res / "provenance.json").read_text())
    assert prov["outcome"] == "success" and prov["patients"] == IDS
    assert prov["openfoam"]["flavour_installed"] in ("esi", "org10") and prov["openfoam"]["version"]
    assert prov["packages"]["snakemake"] and prov["python"]["version"] and prov["config_hash"]
    assert prov["start"] <= prov["end"]

    # a per-patient CFD failure: blockMesh cannot read its dictionary
    broken = IDS[-1]
    (res / "patients" / broken / "case_setup" / "system" / "blockMeshDict").write_text("not a dictionary\n")
    r = wd.snakemake(
        "--profile",
        profile,
        "--cores",
        "2",
        "--forcerun",
        f"results/patients/{broken}/status.json",
        check=False,
        timeout=3600,
    )  # the failure is data: every job succeeds but the verdict after the atlas
    out = r.stdout + r.stderr
    assert r.returncode != 0 and set(re.findall(r"Error in rule (\w+):", out)) == {"atlas_complete"}, out[-3000:]
    st = json.loads((res / "patients" / broken / "status.json").read_text())
    assert st["converged"] is False and "blockMesh" in st["reason"]
    atlas = json.loads((res / "atlas" / "atlas.json").read_text())
    assert sorted(atlas["patients_included"]) == IDS[:-1]
    (excluded,) = atlas["patients_excluded"]
    assert excluded["id"] == broken and excluded["stage"] == "mesh" and "blockMesh failed" in excluded["reason"]
    assert re.search(
        rf"^vcs-atlas: 1 of 4 patients not in the atlas .*: {broken} at mesh \(not converged: blockMesh", out, re.M
    )

    # the QC sheets: every panel of a converged patient drawn; the broken patient's fit panels
    # drawn, its CFD panels said missing (its blockMesh failed), nothing that could not be drawn
    for pid in IDS:
        lines = (res / "logs" / "patient_qc" / f"{pid}.log").read_text().splitlines()
        panels = dict(
            line.split("INFO patient_qc: ", 1)[1].split(": ", 1) for line in lines if "INFO patient_qc: " in line
        )
        assert len(panels) == 9 and not any(v.startswith("could not draw") for v in panels.values()), (pid, panels)
        if pid != broken:
            assert set(panels.values()) == {"drawn"}, (pid, panels)
    assert panels["fit_overlay"] == panels["verdict"] == "drawn", panels  # the broken patient (last)
    assert panels["mesh_slice"].startswith("not available"), panels

    r = wd.snakemake("--report", str(res / "report.html"))
    assert (res / "report.html").stat().st_size > 10_000, r.stderr
    # every figure in the report, captioned and not blank; the excluded patient in the cohort table
    report_check.check_report(res / "report.html", res, excluded={broken: "mesh"})
    if report_check.CHROMIUM is None:
        pytest.skip("report checked; chromium (Debian's package, scripts/install.sh) not installed to open it")
    # the report as a person opens it (headless Chromium): figures shown, the excluded patient red
    report_check.check_in_chromium(res / "report.html", tmp_path / "report_shots", excluded={broken: "mesh"})


def test_broken_mesh_is_a_failed_fit_with_one_line_in_the_log(tmp_path, workdir_factory):
    """Not a failed job (the rest of the cohort goes on): the log's one line, and a failure record
    in place of every output of the fit (tests/workflow/test_cohort_failures.py follows it to the
    atlas)."""
    (tmp_path / "bad.stl").write_text("this is not an STL file\n")
    wd = workdir_factory(tmp_path, [{"id": "bad", "mesh": "bad.stl", "units": "mm"}])
    wd.snakemake("--cores", "1", "results/patients/bad/fit/model.json", timeout=600)
    log = (tmp_path / "results" / "logs" / "vcs_fit" / "bad.log").read_text().strip().splitlines()
    assert len(log) == 2 and log[0].startswith("vcs fit: error:"), log
    assert log[1] == "recorded as a failure of bad at the fit stage (exit code 2)"
    for name in ("model.json", "fit_report.json", "centerline.vtp", "wall_residuals.vtp"):
        record = json.loads((tmp_path / "results" / "patients" / "bad" / "fit" / name).read_text())
        assert record["failed"] is True and record["stage"] == "fit", name
        assert record["reason"] == "fit failed: " + log[0].removeprefix("vcs fit: error: ")
