"""The workflow on a REAL one-node SLURM cluster (markers ``slurm`` and ``openfoam``).

The CI cohort -- three CI-resolution aorta phantoms (config/ci.yaml merged over
config/config.yaml, the sheet of config/ci_patients.tsv); three because vcs.atlas refuses an
atlas of fewer than 3 included patients -- runs twice from scratch in separate throw-away
working directories:

* through the shipped ``profiles/slurm`` with the test cluster's overrides
  (``SlurmCluster.snakemake_profile``: partition, squeue status, no account) against the test
  cluster of tests/slurm_cluster.py: each patient's chain (phantom, fit, wall, case, solve,
  sampling) is ONE sbatch job (the profile's ``groups``), the atlas one more, and
* through ``--profile profiles/local`` on this machine.

Checks that the SLURM run submitted exactly one job per patient plus the atlas, that each
patient's job ran exactly that patient's jobs of the DAG (read from the job's own log, the inner
Snakemake's ``rule ...:`` / ``wildcards:`` lines) and completed with exit status 0 in
slurmctld's log, that the jobs got cfd.ranks CPUs, and
that the results are the same as the local run's: byte-identical model.json, status.json with
the same cells/iterations, bit-identical resampled fields (np.array_equal on every array of
fields.npz except the sampler's wall-clock timings *_time_s: serial simpleFoam and the rest of
the chain are deterministic) and an identical atlas.json (patient lists, scores, regression).

Needs root, slurm-wlm + munge (else the ``slurm_cluster`` fixture skips) and OpenFOAM.
The SLURM run submits 4 jobs (one per patient, the atlas); with the smoke tests 17 min at load
8-10 (2026-12-02).
"""

from __future__ import annotations

import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ci_workdir, parse_jobs
from slurm_cluster import missing_requirements

HAVE_FOAM = shutil.which("simpleFoam") is not None
SLURM_MISSING = missing_requirements()
SEEDS = (0, 1, 2)  # an atlas needs >= 3 included patients (vcs.atlas.compute_atlas)
IDS = [f"demo_aorta_{s}" for s in SEEDS]

pytestmark = [
    pytest.mark.slurm,
    pytest.mark.openfoam,
    pytest.mark.skipif(not HAVE_FOAM, reason="OpenFOAM (simpleFoam) not installed; run scripts/install.sh"),
    pytest.mark.skipif(SLURM_MISSING is not None, reason=f"no SLURM test cluster: {SLURM_MISSING}"),
]


_SUBMITTED = re.compile(r"Job \S+ has been submitted with SLURM jobid (\d+) \(log: (\S+)\)")
# rules that never go to SLURM: a target without a body, a localrule (runs in this Snakemake)
LOCAL_RULES = ("all", "atlas_complete")
_RULE_LINE = re.compile(r"^\s+((?:local)?rule \w+:\s*)$", re.M)


def _expected_jobs(wd) -> dict[str, set[tuple[str, str | None]]]:
    """{SLURM job: {(rule, id)}} expected from a dry-run of the DAG without groups (the local
    profile): one job per patient holding its phantom (aorta_seed<N> of demo_aorta_<N>) and its
    chain, and one for the atlas."""
    expected: dict[str, set[tuple[str, str | None]]] = {}
    for rule, pid in wd.planned_jobs("--forceall"):
        if rule in LOCAL_RULES:
            continue
        owner = f"demo_aorta_{pid.removeprefix('aorta_seed')}" if rule == "vcs_phantom" else pid or rule
        expected.setdefault(owner, set()).add((rule, pid))
    return expected


def test_ci_cohort_on_slurm_matches_the_local_run(tmp_path, workdir_factory, repo, slurm_cluster):
    if slurm_cluster.nested_srun_problem:
        pytest.skip(slurm_cluster.nested_srun_problem)
    ranks = 1
    t0 = time.monotonic()

    # ---- local reference run
    local = ci_workdir(tmp_path / "local", SEEDS)
    local.snakemake("--profile", str(repo / "profiles" / "local"), "--cores", "2", timeout=1200)
    t_local = time.monotonic() - t0

    # ---- the same on SLURM (every job through sbatch)
    slurm = ci_workdir(tmp_path / "slurm", SEEDS)
    assert slurm.config()["cfd"]["ranks"] == ranks
    expected = _expected_jobs(slurm)
    assert sorted(expected) == sorted([*IDS, "atlas_build"]), expected
    assert all(len(expected[pid]) == 7 for pid in IDS), expected  # phantom + 6 rules per patient
    r = slurm.snakemake(
        "--profile",  # the shipped profiles/slurm with the test cluster's partition, status, account
        str(slurm_cluster.snakemake_profile(tmp_path / "profile")),
        "--latency-wait",
        "5",
        "--retries",
        "0",
        "--slurm-keep-successful-logs",
        check=False,
        timeout=1500,
        env=slurm_cluster.env,
    )
    t_slurm = time.monotonic() - t0 - t_local
    (slurm.path / "snakemake.out").write_text(r.stdout + "\n----- stderr -----\n" + r.stderr)  # for post-mortems
    assert r.returncode == 0, (
        f"SLURM run failed ({t_slurm:.0f} s):\n{r.stdout[-4000:]}\n{r.stderr[-6000:]}\n" + slurm_cluster.log_tails()
    )

    # ---- (1) one SLURM job per patient (its whole chain) and one for the atlas, each completed
    # as reported by the submitting Snakemake ("Job <uuid> has been submitted with SLURM jobid 1 (log:
    # .../group_patient_.../1.log)"); --retries 0: one submission each
    submitted = {jid: Path(log) for jid, log in _SUBMITTED.findall(r.stdout + r.stderr)}
    assert len(submitted) == len(IDS) + 1, submitted
    ran: dict[str, str] = {}  # owner (patient id or atlas_build) -> SLURM job id
    for jid, log in submitted.items():
        # the job's own log is the inner (jobstep) Snakemake running exactly its jobs of the DAG
        text = log.read_text(errors="replace")
        text = _RULE_LINE.sub(r"\1", text)  # a group's jobs may be printed indented
        jobs = {job for job in parse_jobs(text) if job[0] not in LOCAL_RULES}
        owners = [owner for owner, want in expected.items() if want == jobs]
        assert len(owners) == 1 and owners[0] not in ran, (jid, sorted(jobs), ran)
        ran[owners[0]] = jid
    assert sorted(ran) == sorted(expected), (ran, submitted)
    for pid in IDS:  # the plugin names a group job's log folder after the group
        assert submitted[ran[pid]].parent.name.startswith("group_patient"), submitted
    ctld_log = (slurm_cluster.workdir / "slurmctld.log").read_text(errors="replace")
    for jid in submitted:
        assert re.search(rf"_job_complete: JobId={jid} WEXITSTATUS 0\b", ctld_log), (
            f"job {jid} not completed in slurmctld.log"
        )
    # CPUs of the patients' jobs = cfd.ranks (profile: cpus_per_task = threads = cfd.ranks for the
    # solve, 1 for the rest; a group job asks for the most); only visible while slurmctld still
    # keeps the finished job (MinJobAge 300 s)
    visible = slurm_cluster.run("squeue", "--states=all", "-h", "-o", "%i|%C", check=False).stdout
    cpus = dict(line.split("|") for line in visible.splitlines() if line.count("|") == 1)
    for pid in IDS:
        if ran[pid] in cpus:
            assert int(cpus[ran[pid]]) == ranks, (pid, cpus[ran[pid]])

    # ---- (2) identical results
    for pid in IDS:
        a, b = (w.path / "results" / "patients" / pid for w in (local, slurm))
        assert (a / "fit" / "model.json").read_bytes() == (b / "fit" / "model.json").read_bytes(), pid
        sa, sb = (json.loads((p / "status.json").read_text()) for p in (a, b))
        assert sa["converged"] is True and sb["converged"] is True, (sa.get("reason"), sb.get("reason"))
        for key in ("cells", "iterations", "mass_imbalance"):
            assert sa.get(key) == sb.get(key), (pid, key, sa.get(key), sb.get(key))
        # fields.npz: every array bit-identical (serial OpenFOAM, same mesh -> same numbers; the
        # sampler's wall-clock timings are in fields.json, not in the npz)
        with np.load(a / "fields.npz") as fa, np.load(b / "fields.npz") as fb:
            assert sorted(fa.files) == sorted(fb.files) and "U" in fa.files and "WSS" in fa.files, (fa.files, fb.files)
            assert not [name for name in fa.files if name.endswith("_time_s")]
            for name in fa.files:
                assert fa[name].dtype == fb[name].dtype and fa[name].shape == fb[name].shape, (pid, name)
                assert np.array_equal(fa[name], fb[name], equal_nan=fa[name].dtype.kind == "f"), (pid, name)
    atlas_a, atlas_b = (json.loads((w.path / "results" / "atlas" / "atlas.json").read_text()) for w in (local, slurm))
    assert sorted(atlas_a["patients_included"]) == sorted(atlas_b["patients_included"]) == IDS
    assert atlas_a["patients_excluded"] == atlas_b["patients_excluded"] == []
    assert atlas_a == atlas_b  # PCA scores, regression, ... too (atlas.json holds no timings or paths)
    print(f"local run {t_local:.0f} s, SLURM run {t_slurm:.0f} s, {len(submitted)} SLURM jobs")
