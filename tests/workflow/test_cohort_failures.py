"""A patient that fails at any stage does not stop the atlas of the others, and the run says so
(GitHub issue 11, item 4). No OpenFOAM runs here:

* the four good patients' fits are real (`vcs fit` on aorta phantoms, through the workflow), their
  CFD results are synthetic (status.json converged, Poiseuille-like fields.npz on the CI grid),
  and the whole run is registered as finished (conftest's ``fake_finished_run``);
* then one patient's mesh is replaced by garbage (a real failing `vcs fit`), one patient's model
  has a wall that `vcs wall` refuses, one patient's wall STL cannot be set up as a case, and one
  patient's case cannot be resampled; the next run builds the atlas of the remaining three, lists
  the four under ``patients_excluded`` with their stage and reason, and exits non-zero after
  the atlas with one line naming them;
* a rerun after fixing the mesh (real fit and wall; its CFD faked again) includes the patient and
  exits 0;
* a run that leaves the atlas older than a patient's result (here: only the broken patient's fit
  is run) removes the atlas, so it can never list a failed patient as included.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import REPO, Workdir, make_workdir, with_ci_config

GOOD = ["g0", "g1", "g2"]
FIT, WALL, CASE, SAMPLE = "pfit", "pwall", "pcase", "psample"
IDS = sorted(GOOD + [FIT, WALL, CASE, SAMPLE])
PROFILE = str(REPO / "profiles" / "local")
SUMMARY = re.compile(r"^vcs-atlas: (\d+) of (\d+) patients not in the atlas .*$", re.M)


def synthetic_fields(q: float, n=(24, 16, 6)) -> dict:
    """Poiseuille-like fields on the CI grid (mean axial velocity q), as fields.npz holds them."""
    nt, nth, nr = n
    tau, theta, rho_n = np.linspace(0, 1, nt), 2 * np.pi * np.arange(nth) / nth, np.linspace(0, 1, nr)
    T, _, RN = np.meshgrid(tau, theta, rho_n, indexing="ij")
    u = np.zeros((nt, nth, nr, 3))
    u[..., 0] = 2 * q * (1 - RN**2)
    w = np.zeros((nt, nth, 3))
    w[..., 0] = 4 * q
    p = 100 * q * (1 - T)
    return {"tau": tau, "theta": theta, "rho_n": rho_n, "U_vcs": u, "U": u, "p": p, "WSS_vcs": w, "WSS": w}


def fake_cfd(wd: Workdir, pid: str, q: float) -> None:
    """A converged status.json and synthetic fields for ``pid`` (in place of OpenFOAM)."""
    res = wd.path / "results" / "patients" / pid
    (res / "status.json").write_text(json.dumps({"converged": True, "patient": pid, "reason": None}))
    np.savez_compressed(res / "fields.npz", **synthetic_fields(q))


@pytest.fixture(scope="module")
def prepared(tmp_path_factory) -> Path:
    """Seven patients, all 'finished': real fits of aorta phantoms (pfit's from a mesh file of its
    own), synthetic CFD, every output registered by `snakemake --touch`."""
    path = tmp_path_factory.mktemp("cohort_failures")
    rows = [{"id": pid, "mesh": f"results/demo/aorta_seed{i}.stl", "units": "mm"} for i, pid in enumerate(IDS)]
    rows[IDS.index(FIT)]["mesh"] = "meshes/pfit.stl"
    (path / "meshes").mkdir()
    vcs = Path(sys.executable).parent / "vcs"
    mesh = str(path / "meshes" / "pfit.stl")
    subprocess.run([str(vcs), "phantom", "--kind", "aorta", "--seed", "9", "--resolution", "3", "-o", mesh], check=True)
    wd = make_workdir(path, rows)
    cfg = with_ci_config(wd.config())
    cfg["demo"]["resolution"] = 3.0  # coarse phantoms: quick fits
    cfg["atlas"]["figures"] = False  # the figures have their own tests (tests/vcs/test_atlas.py)
    wd.write_config(cfg)
    wd.snakemake("-c2", *[f"results/patients/{pid}/fit/model.json" for pid in IDS], timeout=900)
    # pwall: a model whose wall radius is negative somewhere (vcs wall refuses it)
    model_path = path / "results" / "patients" / WALL / "fit" / "model.json"
    model = json.loads(model_path.read_text())
    rows = model["wall"]["coefficients"]
    rows[len(rows) // 2] = [-20.0] * len(rows[0])  # a ring of negative radius mid-vessel
    model_path.write_text(json.dumps(model))
    for i, pid in enumerate(IDS):
        (path / "results" / "patients" / pid).mkdir(parents=True, exist_ok=True)
        fake_cfd(wd, pid, 0.2 + 0.05 * i)
    wd.fake_finished_run()  # keeps the content written above, registers every job as done
    r = wd.snakemake("-n")
    assert "Nothing to be done" in r.stdout + r.stderr
    return path


@pytest.fixture
def wd(prepared, tmp_path) -> Workdir:
    dest = tmp_path / "wd"
    shutil.copytree(prepared, dest, symlinks=True)
    shutil.rmtree(dest / ".snakemake" / "locks", ignore_errors=True)
    return Workdir(dest)


def _atlas(wd: Workdir) -> dict:
    return json.loads((wd.path / "results" / "atlas" / "atlas.json").read_text())


def _run(wd: Workdir, *args: str):
    return wd.snakemake("--profile", PROFILE, "--cores", "2", *args, check=False, timeout=900)


def test_a_failure_at_any_stage_leaves_an_atlas_of_the_others_and_a_failed_run(wd):
    (wd.path / "meshes" / "pfit.stl").write_text("this is not an STL file\n")
    (wd.path / "results" / "patients" / CASE / "wall" / "wall.stl").write_text("solid wall\nendsolid wall\n")
    r = _run(
        wd,
        "--forcerun",
        f"results/patients/{WALL}/wall/wall.stl",
        f"results/patients/{CASE}/case_setup",
        f"results/patients/{SAMPLE}/fields.npz",
    )
    out = r.stdout + r.stderr
    assert r.returncode != 0, out[-3000:]
    # every job but the verdict succeeded: the failures are data
    assert set(re.findall(r"Error in rule (\w+):", out)) == {"atlas_complete"}, out[-3000:]

    atlas = _atlas(wd)
    assert atlas["patients_included"] == GOOD
    excluded = {e["id"]: e for e in atlas["patients_excluded"]}
    assert sorted(excluded) == sorted([CASE, FIT, SAMPLE, WALL])
    assert excluded[FIT]["stage"] == "fit"
    assert (
        excluded[FIT]["reason"]
        == "fit failed: 'meshes/pfit.stl' contains no surface triangles; export the surface again"
    )
    assert excluded[WALL]["stage"] == "wall" and excluded[WALL]["reason"].startswith("wall failed: ")
    assert excluded[CASE]["stage"] == "case" and excluded[CASE]["reason"].startswith("case set-up failed: ")
    assert excluded[SAMPLE]["stage"] == "sampling" and excluded[SAMPLE]["reason"].startswith("sampling failed: ")
    assert atlas["shape_to_flow_regression"]["status"] == "insufficient_patients"

    # one line, after the atlas, naming each patient and its stage
    lines = {m.group(0) for m in SUMMARY.finditer(out)}  # on stderr (and again from the log)
    assert len(lines) == 1, out[-3000:]
    line = lines.pop()
    assert line.startswith("vcs-atlas: 4 of 7 patients not in the atlas (built from the other 3")
    for pid in (CASE, FIT, SAMPLE, WALL):
        assert f"{pid} at {excluded[pid]['stage']} (" in line
    log = (wd.path / "results" / "logs" / "atlas_complete" / "atlas.log").read_text()
    assert line in log
    assert not (wd.path / "results" / "atlas" / "complete.txt").exists()

    # the failed stages wrote failure records, not results; the logs keep the one-line errors
    res = wd.path / "results" / "patients"
    record = json.loads((res / FIT / "fit" / "model.json").read_text())
    assert record["failed"] is True and record["stage"] == "fit" and record["exit_code"] == 2
    assert json.loads((res / FIT / "wall" / "wall.stl").read_text())["stage"] == "fit"  # passed on
    fit_log = (wd.path / "results" / "logs" / "vcs_fit" / f"{FIT}.log").read_text().splitlines()
    assert fit_log[0].startswith("vcs fit: error:") and "recorded as a failure of pfit" in fit_log[-1]
    status = json.loads((res / FIT / "status.json").read_text())
    assert status["converged"] is False and status["stage"] == "fit" and status["failed_log"] == record["log"]
    with np.load(res / SAMPLE / "fields.npz") as z:
        assert sorted(z.files) == ["excluded", "stage"] and str(z["stage"]) == "sampling"

    # a rerun without a fix repeats only the verdict
    r2 = _run(wd)
    assert r2.returncode != 0
    assert SUMMARY.search(r2.stdout + r2.stderr)
    jobs = set(re.findall(r"^(?:local)?rule (\w+):", r2.stdout + r2.stderr, re.M))
    assert jobs == {"atlas_complete"}, jobs


def test_fixing_the_mesh_brings_the_patient_back_into_the_atlas(wd, prepared):
    good_mesh = (wd.path / "meshes" / "pfit.stl").read_bytes()
    (wd.path / "meshes" / "pfit.stl").write_text("this is not an STL file\n")
    r = _run(wd)
    assert r.returncode != 0 and SUMMARY.search(r.stdout + r.stderr)
    assert FIT not in _atlas(wd)["patients_included"]

    (wd.path / "meshes" / "pfit.stl").write_bytes(good_mesh)
    # the real fit, wall and case set-up; OpenFOAM is replaced by synthetic results again
    r = _run(wd, f"results/patients/{FIT}/case_setup")
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    assert "failed" not in json.loads((wd.path / "results" / "patients" / FIT / "fit" / "model.json").read_text())
    fake_cfd(wd, FIT, 0.33)
    wd.snakemake("--touch", "-c1", f"results/patients/{FIT}/fields.npz")
    fake_cfd(wd, FIT, 0.33)  # --touch re-creates nothing: keep the synthetic content newest
    r = _run(wd)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    atlas = _atlas(wd)
    assert atlas["patients_included"] == IDS and atlas["patients_excluded"] == []
    assert not SUMMARY.search(r.stdout + r.stderr)
    assert (wd.path / "results" / "atlas" / "complete.txt").read_text().startswith("all 7 patients")


def test_an_atlas_older_than_a_patient_result_is_moved_aside(wd):
    r = _run(wd, "--forcerun", "atlas_build")  # a real atlas of all seven
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    assert _atlas(wd)["patients_included"] == IDS
    (wd.path / "meshes" / "pfit.stl").write_text("this is not an STL file\n")
    r = _run(wd, f"results/patients/{FIT}/fit/model.json")  # only the fit: exit 0, the failure is data
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    atlas_dir = wd.path / "results" / "atlas"
    assert not (atlas_dir / "atlas.json").exists() and not (atlas_dir / "figures").exists()
    assert not (atlas_dir / "patients.html").exists()  # the old cohort table goes with its atlas
    assert (wd.path / "results" / "previous" / "atlas" / "patients.html").is_file()
    assert "vcs-atlas: moved the atlas in results/atlas/ to results/previous/atlas/" in r.stdout + r.stderr
    # nothing lost (issue 22): the old atlas and the patient's earlier fit are kept aside
    assert (
        json.loads((wd.path / "results" / "previous" / "atlas" / "atlas.json").read_text())["patients_included"] == IDS
    )
    earlier = wd.path / "results" / "patients" / FIT / "previous" / "fit" / "model.json"
    assert "wall" in json.loads(earlier.read_text()) and f"failed: {FIT} (" in r.stderr
    assert json.loads((wd.path / "results" / "patients" / FIT / "fit" / "model.json").read_text())["failed"] is True
    r = _run(wd)  # the next full run builds it again, without the failed patient
    assert r.returncode != 0 and FIT not in _atlas(wd)["patients_included"]


def test_failure_records_of_the_shell_rules(tmp_path):
    """workflow/scripts/_failure.py: a failed command's outputs become the record (reason: the log's
    last line), an interrupted or missing command stays a job failure, a record is passed on."""
    sys.path.insert(0, str(REPO / "workflow" / "scripts"))
    import _failure

    log = tmp_path / "fit.log"
    log.write_text("vcs fit: error: mesh file 'x.stl' is empty; export the surface again\n")
    outs = [str(tmp_path / "fit" / "model.json"), str(tmp_path / "fit" / "centerline.vtp")]
    assert _failure.main(["record", "fit", "2", "--patient", "P1", "--log", str(log), "--", *outs]) == 0
    for out in outs:
        record = _failure.read_record(out)
        assert record["reason"] == "fit failed: mesh file 'x.stl' is empty; export the surface again"
        assert record["stage"] == "fit" and record["patient"] == "P1" and record["exit_code"] == 2
    assert log.read_text().splitlines()[-1] == "recorded as a failure of P1 at the fit stage (exit code 2)"
    for code in (127, 130, 137):  # command not found, interrupted, killed: not this patient's failure
        other = tmp_path / f"other{code}.json"
        assert (
            _failure.main(["record", "fit", str(code), "--patient", "P1", "--log", str(log), "--", str(other)]) == code
        )
        assert not other.exists()
    wall = str(tmp_path / "wall.stl")
    args = ["propagate", "--patient", "P1", "--log", str(log), "--upstream"]
    assert _failure.main([*args, str(log), "--", wall]) == 1  # nothing to pass on: run the stage
    assert _failure.main([*args, outs[0], "--", wall]) == 0
    assert _failure.read_record(wall) == _failure.read_record(outs[0])
    np.savez_compressed(tmp_path / "f.npz", a=np.zeros(3))
    (tmp_path / "result.json").write_text('{"failed": false}')
    assert _failure.read_record(tmp_path / "f.npz") is None and _failure.read_record(tmp_path / "result.json") is None
