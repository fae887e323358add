"""The workflow on a REAL one-node SLURM cluster (markers ``slurm`` and ``openfoam``).

The CI cohort -- three CI-resolution aorta phantoms (config/ci.yaml merged over
config/config.yaml, the sheet of config/ci_patients.tsv); three because vcs.atlas refuses an
atlas of fewer than 3 included patients -- runs twice from scratch in separate throw-away
working directories:

* through ``--profile profiles/slurm`` against the test cluster of tests/slurm_cluster.py
  (every job -- phantom, fit, wall, case, solve, sampling, atlas -- is an sbatch job), and
* through ``--profile profiles/local`` on this machine.

Checks that every job of the DAG went through sbatch as its own SLURM job (Snakemake's
per-job SLURM log ``.snakemake/slurm_logs/rule_<rule>/<wildcards>/<jobid>.log``, and the job id
completed with exit status 0 in slurmctld's log), that the solve jobs got cfd.ranks CPUs, and
that the results are the same as the local run's: byte-identical model.json, status.json with
the same cells/iterations, bit-identical resampled fields (np.array_equal on every array of
fields.npz except the sampler's wall-clock timings *_time_s: serial simpleFoam and the rest of
the chain are deterministic) and an identical atlas.json (patient lists, scores, regression).

Needs root, slurm-wlm + munge (else the ``slurm_cluster`` fixture skips) and OpenFOAM.
About 3 minutes on 2 cores (local run ~35 s, SLURM run ~140 s: 19 sbatch jobs).
"""

from __future__ import annotations

import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import ci_workdir
from slurm_cluster import SNAKEMAKE_SLURM_ARGS, missing_requirements

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


def _slurm_jobs(wd) -> dict[tuple[str, str], list[str]]:
    """{(rule, wildcards string): [SLURM job ids]} from the plugin's per-job log files
    .snakemake/slurm_logs/rule_<rule>/<wildcards joined by _>/<jobid>.log (no wildcards: no
    middle folder)."""
    jobs: dict[tuple[str, str], list[str]] = {}
    root = wd.path / ".snakemake" / "slurm_logs"
    for log in root.rglob("*.log"):
        rule_dir, *wc = log.relative_to(root).parent.parts
        jobs.setdefault((rule_dir.removeprefix("rule_"), "/".join(wc)), []).append(log.stem)
    return jobs


_SUBMITTED = re.compile(r"Job \d+ has been submitted with SLURM jobid (\d+) \(log: (\S+)\)")


def _planned(wd) -> set[tuple[str, str]]:
    """(rule, wildcards string as the plugin names its log dir) of every job of a dry-run."""
    out = set()
    for rule, pid in wd.planned_jobs("--forceall"):
        if rule in ("all", "atlas_complete"):  # a target without a body; a localrule (runs in this Snakemake)
            continue
        if rule == "vcs_phantom":  # planned_jobs gives "aorta_seed0", the plugin "aorta_0"
            kind, seed = pid.split("_seed")
            pid = f"{kind}_{seed}"
        out.add((rule, pid or ""))
    return out


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
    profile = yaml.safe_load((repo / "profiles" / "slurm" / "config.yaml").read_text())
    assert profile["default-resources"]["slurm_partition"] == slurm_cluster.partition
    slurm = ci_workdir(tmp_path / "slurm", SEEDS)
    assert slurm.config()["cfd"]["ranks"] == ranks
    expected = _planned(slurm)
    assert len(expected) == 5 * len(IDS) + len(SEEDS) + 1, expected  # 5 per patient, phantoms, atlas
    r = slurm.snakemake(
        "--profile",
        str(repo / "profiles" / "slurm"),
        *SNAKEMAKE_SLURM_ARGS,  # no --set/--default-resources: they would replace the profile's
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

    # ---- (1) every job was its own sbatch job that completed
    jobs = _slurm_jobs(slurm)
    assert set(jobs) == expected, (sorted(jobs), sorted(expected))
    assert all(len(ids) == 1 for ids in jobs.values()), jobs  # --retries 0: one submission each
    job_ids = [ids[0] for ids in jobs.values()]
    assert all(j.isdigit() for j in job_ids) and len(set(job_ids)) == len(job_ids), jobs
    # ... as reported by the submitting Snakemake ("Job 3 has been submitted with SLURM jobid 1
    # (log: .../rule_vcs_phantom/aorta_0/1.log)") and completed with exit status 0 per slurmctld
    submitted = {Path(log): jid for jid, log in _SUBMITTED.findall(r.stdout + r.stderr)}
    root = slurm.path / ".snakemake" / "slurm_logs"
    assert submitted == {root / f"rule_{rule}" / wc / f"{jid}.log": jid for (rule, wc), (jid,) in jobs.items()}, (
        submitted,
        jobs,
    )
    ctld_log = (slurm_cluster.workdir / "slurmctld.log").read_text(errors="replace")
    for jid in job_ids:
        assert re.search(rf"_job_complete: JobId={jid} WEXITSTATUS 0\b", ctld_log), (
            f"job {jid} not completed in slurmctld.log"
        )
    # the job's own log is the inner (jobstep) Snakemake running exactly that rule
    for (rule, wc), (jid,) in jobs.items():
        text = (root / f"rule_{rule}" / wc / f"{jid}.log").read_text(errors="replace")
        assert f"--target-jobs {rule}:" in text and re.search(rf"^rule {rule}:$", text, re.M), (rule, wc, text[-2000:])
    # CPUs of the solve jobs = cfd.ranks (profile: cpus_per_task = threads = cfd.ranks); only
    # visible while slurmctld still keeps the finished job (MinJobAge 300 s)
    visible = slurm_cluster.run("squeue", "--states=all", "-h", "-o", "%i|%C|%k", check=False).stdout
    cpus = {line.split("|")[0]: line.split("|") for line in visible.splitlines() if line.count("|") == 2}
    for pid in IDS:
        (jid,) = jobs[("openfoam_solve", pid)]
        if jid in cpus:
            assert int(cpus[jid][1]) == ranks and cpus[jid][2] == f"rule_openfoam_solve_wildcards_{pid}", cpus[jid]

    # ---- (2) identical results
    for pid in IDS:
        a, b = (w.path / "results" / "patients" / pid for w in (local, slurm))
        assert (a / "fit" / "model.json").read_bytes() == (b / "fit" / "model.json").read_bytes(), pid
        sa, sb = (json.loads((p / "status.json").read_text()) for p in (a, b))
        assert sa["converged"] is True and sb["converged"] is True, (sa.get("reason"), sb.get("reason"))
        for key in ("cells", "iterations", "mass_imbalance"):
            assert sa.get(key) == sb.get(key), (pid, key, sa.get(key), sb.get(key))
        # fields.npz: every array bit-identical (serial OpenFOAM, same mesh -> same numbers),
        # except the wall-clock timings the sampler records (read/interpolation/sample_time_s)
        with np.load(a / "fields.npz") as fa, np.load(b / "fields.npz") as fb:
            assert sorted(fa.files) == sorted(fb.files) and "U" in fa.files and "WSS" in fa.files, (fa.files, fb.files)
            for name in fa.files:
                if name.endswith("_time_s"):
                    continue
                assert fa[name].dtype == fb[name].dtype and fa[name].shape == fb[name].shape, (pid, name)
                assert np.array_equal(fa[name], fb[name], equal_nan=fa[name].dtype.kind == "f"), (pid, name)
    atlas_a, atlas_b = (json.loads((w.path / "results" / "atlas" / "atlas.json").read_text()) for w in (local, slurm))
    assert sorted(atlas_a["patients_included"]) == sorted(atlas_b["patients_included"]) == IDS
    assert atlas_a["patients_excluded"] == atlas_b["patients_excluded"] == []
    assert atlas_a == atlas_b  # PCA scores, regression, ... too (atlas.json holds no timings or paths)
    print(f"local run {t_local:.0f} s, SLURM run {t_slurm:.0f} s, {len(job_ids)} SLURM jobs")
