"""Fault tolerance of the CFD part of the workflow with the real OpenFOAM (marker ``openfoam``;
GitHub issue 'Reliability', item 3). One coarse synthetic aorta with the CI settings
(config/ci.yaml), about one minute on 2 cores for the whole file:

* a hard crash (SIGKILL of Snakemake and the solver) in the middle of simpleFoam, then a rerun:
  the partial case is detected as incomplete, re-solved from a fresh copy of the rendered case,
  and the result equals an uninterrupted run;
* a snappyHexMesh failure (inside point outside the mesh) ends as status.json converged: false
  with the utility's error and log path, not as a job failure; the atlas leaves the patient out;
* a diverging simpleFoam (classic SIMPLE without under-relaxation: floating point exception,
  non-zero exit) likewise.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import with_ci_config

REPO = Path(__file__).resolve().parents[2]
SNAKEFILE = REPO / "Snakefile"
SNAKEMAKE = Path(sys.executable).parent / "snakemake"
PROFILE = str(REPO / "profiles" / "local")
HAVE_FOAM = shutil.which("simpleFoam") is not None
PID = "demo_aorta_0"
STARTUP = 30  # solver.startup_iterations of config/ci.yaml
FOAM_PROCESSES = ("simpleFoam", "mpirun", "orterun", "prterun", "orted")

pytestmark = [
    pytest.mark.openfoam,
    pytest.mark.skipif(not HAVE_FOAM, reason="OpenFOAM (simpleFoam) not installed; run scripts/install.sh"),
]


def _ci_config() -> dict:
    """config/config.yaml overlaid with config/ci.yaml (as test_demo does); patients.tsv."""
    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    cfg["patients"] = "patients.tsv"
    return with_ci_config(cfg)


ROWS = [{"id": PID, "mesh": "results/demo/aorta_seed0.stl", "units": "mm"}]


@pytest.fixture(scope="module")
def prepared(tmp_path_factory) -> Path:
    """A working directory with the phantom, fit, wall STL and rendered case of PID (made once)."""
    path = tmp_path_factory.mktemp("faults_prepared")
    (path / "config.yaml").write_text(yaml.safe_dump(_ci_config(), sort_keys=False))
    (path / "patients.tsv").write_text(
        "id\tmesh\tunits\n" + "".join(f"{r['id']}\t{r['mesh']}\t{r['units']}\n" for r in ROWS)
    )
    r = subprocess.run(
        [
            str(SNAKEMAKE),
            "-s",
            str(SNAKEFILE),
            "-d",
            str(path),
            "--configfile",
            str(path / "config.yaml"),
            "--profile",
            PROFILE,
            "--cores",
            "2",
            f"results/patients/{PID}/case_setup",
        ],
        cwd=path,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    return path


@pytest.fixture
def wd(prepared, tmp_path, workdir_factory):
    """A private copy of the prepared directory (Snakemake's metadata and the mtimes included),
    as a conftest Workdir with the same configuration."""
    dest = tmp_path / "wd"
    shutil.copytree(prepared, dest, symlinks=True)
    shutil.rmtree(dest / ".snakemake" / "locks", ignore_errors=True)
    wd = workdir_factory(dest, ROWS)
    wd.write_config(_ci_config())
    return wd


_JOB_START = re.compile(r"^(?:local)?(?:checkpoint|rule) (\w+):\s*$")
_WILDCARDS = re.compile(r"^\s+wildcards: .*\bid=([^,\s]+)")


def _jobs(r: subprocess.CompletedProcess) -> set[tuple[str, str | None]]:
    """{(rule, id or None)} of the jobs a Snakemake run printed."""
    jobs: list[list] = []
    for line in (r.stdout + r.stderr).splitlines():
        m = _JOB_START.match(line)
        if m:
            jobs.append([m.group(1), None])
        elif (m := _WILDCARDS.match(line)) and jobs:
            jobs[-1][1] = m.group(1)
    return {(rule, pid) for rule, pid in jobs}


def _foam_pids(root: Path) -> list[int]:
    """OpenFOAM/MPI processes running inside `root` (by their working directory: other people's
    simpleFoam runs on this machine are never touched)."""
    pids = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            if (d / "comm").read_text().strip() not in FOAM_PROCESSES:
                continue
            cwd = os.readlink(d / "cwd")
        except OSError:
            continue
        if cwd == str(root) or cwd.startswith(str(root) + os.sep):
            pids.append(int(d.name))
    return pids


def _iterations(log: Path) -> int:
    """Last SIMPLE iteration ('Time = N') written to an OpenFOAM solver log so far."""
    try:
        times = re.findall(r"^Time = (\d+)\s*$", log.read_text(errors="replace"), re.M)
    except OSError:
        return 0
    return int(times[-1]) if times else 0


def _status(wd) -> dict:
    return json.loads((wd.path / "results" / "patients" / PID / "status.json").read_text())


def _rule_errors(r: subprocess.CompletedProcess) -> set[str]:
    return set(re.findall(r"Error in rule (\w+):", r.stdout + r.stderr))


# ------------------------------------------------------------------------------------ 1: crash


def test_killed_solver_rerun_restarts_from_a_clean_case_and_matches_an_uninterrupted_run(wd):
    wd.update_config("cfd", "ranks", 2)  # decomposed: the crash leaves processor* dirs behind
    target = f"results/patients/{PID}/fields.npz"
    res = wd.path / "results" / "patients" / PID
    case = res / "case"
    main_log = case / "logs" / "log.simpleFoam"

    cmd = [
        str(SNAKEMAKE),
        "-s",
        str(SNAKEFILE),
        "-d",
        str(wd.path),
        "--configfile",
        str(wd.config_file),
        "--profile",
        PROFILE,
        "--cores",
        "2",
        target,
    ]
    with open(wd.path / "killed_run.log", "w") as out:
        proc = subprocess.Popen(cmd, cwd=wd.path, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        deadline = time.monotonic() + 600
        while not (_iterations(main_log) >= STARTUP + 5 and _foam_pids(case)):
            assert proc.poll() is None, (
                "snakemake ended before simpleFoam's main stage could be killed:\n"
                + (wd.path / "killed_run.log").read_text()[-3000:]
            )
            assert not (res / "status.json").exists(), "the solve finished before it could be killed"
            assert time.monotonic() < deadline, "simpleFoam's main stage did not start within 600 s"
            time.sleep(0.05)
    finally:  # a crash: SIGKILL for Snakemake, its jobs and every solver process of this case
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        for _ in range(100):
            pids = _foam_pids(wd.path)
            if not pids:
                break
            for pid in pids:
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
            time.sleep(0.1)
    assert not _foam_pids(wd.path)
    killed_at = _iterations(main_log)
    assert STARTUP + 5 <= killed_at, killed_at

    # the crash left a partial case: decomposed, start-up time written, no status
    assert not (res / "status.json").exists()
    assert (case / "processor0" / str(STARTUP)).is_dir() and (case / "processor1").is_dir()
    # plant stale state that a rerun must not trust or keep
    (case / "STALE_FROM_KILLED_RUN").write_text("must not survive the rerun\n")
    stale_time = case / "processor0" / "999"
    shutil.copytree(case / "processor0" / str(STARTUP), stale_time)  # startFrom latestTime would pick it
    (case / "processor7").mkdir()

    # without --rerun-incomplete the partial case is refused as incomplete ...
    r = wd.snakemake("-n", target, check=False)
    assert r.returncode != 0, r.stdout
    assert re.search(rf"Incomplete files:\s+results/patients/{PID}/case\s*$", r.stdout + r.stderr), r.stdout
    # after a hard kill Snakemake's lock stays: a real run refuses to start; the recovery is --unlock
    r = wd.snakemake("--profile", PROFILE, "--cores", "2", target, check=False)
    assert r.returncode != 0 and "Directory cannot be locked" in r.stdout + r.stderr, r.stdout[-2000:]
    assert (case / "STALE_FROM_KILLED_RUN").exists()  # refused before touching anything
    wd.snakemake("--unlock")
    # ... the local profile (rerun-incomplete: true) re-runs the solve
    r = wd.snakemake("--profile", PROFILE, "--cores", "2", target, timeout=900)
    jobs = _jobs(r)
    assert ("openfoam_solve", PID) in jobs and ("fields_sample", PID) in jobs, jobs
    assert ("openfoam_case", PID) not in jobs, jobs  # the rendered case is reused, not the solved one

    # a fresh case: nothing of the killed run left
    assert not (case / "STALE_FROM_KILLED_RUN").exists()
    assert not stale_time.exists() and not (case / "processor7").exists()
    resumed = _status(wd)
    assert resumed["converged"] is True, resumed["reason"]
    assert resumed["ranks"] == 2 and resumed["stage_iterations"]["simpleFoam.startup"] == STARTUP
    assert resumed["iterations"] > killed_at
    # each log holds a single run (a restart would append or start at a later time)
    startup_log = (case / "logs" / "log.simpleFoam.startup").read_text()
    assert len(re.findall(r"^Time = 1\s*$", startup_log, re.M)) == 1
    assert re.findall(r"^Time = (\d+)\s*$", main_log.read_text(), re.M)[0] == str(STARTUP + 1)
    with np.load(res / "fields.npz") as z:
        resumed_fields = {k: z[k] for k in z.files}
    assert "excluded" not in resumed_fields and len(resumed_fields) > 3

    # the reference: the same solve, uninterrupted
    r = wd.snakemake("--profile", PROFILE, "--cores", "2", target, "--forcerun", "openfoam_solve", timeout=900)
    assert ("openfoam_solve", PID) in _jobs(r)
    reference = _status(wd)
    for key in (
        "converged",
        "iterations",
        "stage_iterations",
        "final_residuals",
        "cells",
        "mass_imbalance",
        "continuity_errors",
        "flow_rates",
        "patch_pressure",
        "wall_shear_stress_Pa",
    ):
        assert resumed[key] == reference[key], key
    # exactly equal: the same binary solving the same case with the same decomposition is
    # deterministic, so ANY difference would be state leaking from the killed run
    with np.load(res / "fields.npz") as z:
        assert sorted(z.files) == sorted(resumed_fields)
        for k in z.files:
            if not k.endswith("_time_s"):  # wall-clock timings of the resampling
                np.testing.assert_array_equal(z[k], resumed_fields[k], err_msg=k)
        assert z["time"] == resumed["iterations"] and np.isfinite(z["U"]).all() and np.isfinite(z["p"]).all()


# ------------------------------------------------------------------------------ 2: mesh failure


def _assert_kept_out_of_the_atlas(wd, r: subprocess.CompletedProcess, words: str) -> None:
    """The patient's failure is data: solve and sampling succeed, only the atlas (no included
    patient left) fails, with one error line naming the patient and the reason."""
    assert r.returncode != 0
    assert _rule_errors(r) == {"atlas_build"}, r.stdout[-3000:] + r.stderr[-3000:]
    with np.load(wd.path / "results" / "patients" / PID / "fields.npz") as z:
        assert sorted(z.files) == ["excluded", "stage"] and words in str(z["excluded"])
    log = (wd.path / "results" / "logs" / "atlas_build" / "atlas.log").read_text()
    errors = [ln for ln in log.splitlines() if " ERROR " in ln]
    assert len(errors) == 1 and "Traceback" not in log, log
    assert "an atlas needs at least 3 included patients, got 0" in errors[0]
    assert PID in errors[0] and words in errors[0]


def test_snappyhexmesh_failure_marks_the_patient_failed_with_the_log(wd):
    wd.update_config("cfd", "mesh", "inside_point", [1.0, 1.0, 1.0])  # 1 m away: outside the background mesh
    r = wd.snakemake("--profile", PROFILE, "--cores", "2", check=False, timeout=900)
    st = _status(wd)
    case = wd.path / "results" / "patients" / PID / "case"
    assert st["converged"] is False and st["patient"] == PID
    assert st["reason"].startswith("snappyHexMesh failed: Point (1 1 1) is not inside the mesh"), st["reason"]
    assert st["failed_log"] == str(case / "logs" / "log.snappyHexMesh")
    assert "FOAM FATAL ERROR" in Path(st["failed_log"]).read_text()
    assert st["cells"] is None and "simpleFoam" not in st["timings_s"]
    _assert_kept_out_of_the_atlas(wd, r, "snappyHexMesh failed")


def test_case_setup_failure_is_recorded_not_a_job_failure(wd):
    """A background cell larger than the vessel: render_case finds no point inside the lumen.
    The openfoam_case job still succeeds; the patient's status says why, and it is excluded."""
    wd.update_config("cfd", "mesh", "cell_size", 0.5)  # 0.5 m cells around a ~0.3 m aorta
    r = wd.snakemake("--profile", PROFILE, "--cores", "2", check=False, timeout=900)
    st = _status(wd)
    assert st["converged"] is False and st["reason"].startswith("case set-up failed:"), st["reason"]
    log = Path(st["failed_log"])
    assert log.name == f"{PID}.log" and log.parent.name == "openfoam_case" and "case set-up failed" in log.read_text()
    assert "openfoam_case" not in _rule_errors(r)
    _assert_kept_out_of_the_atlas(wd, r, "case set-up failed")


# --------------------------------------------------------------------------------- 3: divergence


def test_diverging_solver_is_recorded_not_a_job_failure(wd):
    from vcs.atlas import status_exclusion

    cfg = wd.config()  # classic SIMPLE without under-relaxation: blows up within ~40 iterations
    cfg["cfd"]["solver"].update(consistent=False, relax_U=1.0, relax_p=1.0)
    wd.write_config(cfg)
    r = wd.snakemake("--profile", PROFILE, "--cores", "2", check=False, timeout=900)
    st = _status(wd)
    case = wd.path / "results" / "patients" / PID / "case"
    assert st["converged"] is False and st["mesh_ok"] is True
    assert st["reason"] == "simpleFoam (main) diverged: floating point exception (see logs/log.simpleFoam)"
    assert st["failed_log"] == str(case / "logs" / "log.simpleFoam")
    assert "Floating point exception" in Path(st["failed_log"]).read_text()
    assert STARTUP < st["iterations"] < int(wd.config()["cfd"]["solver"]["max_iterations"])
    assert status_exclusion(st).startswith("not converged: simpleFoam (main) diverged")
    assert "converged False" in (wd.path / "results" / "logs" / "openfoam_solve" / f"{PID}.log").read_text()
    _assert_kept_out_of_the_atlas(wd, r, "floating point exception")
