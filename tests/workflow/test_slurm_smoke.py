"""Smoke test: a REAL one-node SLURM cluster + Snakemake's SLURM executor.

Starts slurmctld/slurmd/munged (tests/slurm_cluster.py, needs root and the
Debian packages slurm-wlm + munge, skipped otherwise), runs a plain
`sbatch --wrap` job, then a tiny two-job Snakefile through the shipped
profiles/slurm with the test cluster's overrides
(`SlurmCluster.snakemake_profile`) and checks that both jobs ran as
distinct SLURM jobs.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

TESTS_DIR = Path(__file__).resolve().parents[1]
if str(TESTS_DIR) not in sys.path:
    sys.path.insert(0, str(TESTS_DIR))

# The session fixture is reference counted in slurm_cluster, so importing it here
# as well as in a conftest.py starts only one cluster.
from slurm_cluster import slurm_cluster  # noqa: E402,F401

pytestmark = pytest.mark.slurm

SNAKEFILE = """\
localrules: all

rule all:
    input:
        expand("out/{i}.txt", i=[1, 2]),

rule write_jobid:
    output:
        "out/{i}.txt",
    resources:
        mem_mb=100,
        runtime=5,
        cpus_per_task=1,
    shell:
        'echo "${{SLURM_JOB_ID:-none}}" > {output}'
"""


def _snakemake_exe() -> list[str]:
    return [sys.executable, "-m", "snakemake"]


def _wait_job(cluster, jobid: str, timeout: float = 60) -> str:
    """Poll squeue (no accounting -> no sacct) until the job reached a final state."""
    deadline = time.monotonic() + timeout
    state = ""
    while time.monotonic() < deadline:
        r = cluster.run("squeue", "--states=all", "-h", "-j", jobid, "-o", "%T", check=False)
        state = r.stdout.strip()
        if state in ("COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY"):
            return state
        time.sleep(0.5)
    raise AssertionError(f"job {jobid} not finished after {timeout}s (state {state!r})\n" + cluster.log_tails())


def test_sbatch_wrap(slurm_cluster, tmp_path):  # noqa: F811 (the fixture imported above)
    out = tmp_path / "wrap.out"
    r = slurm_cluster.run(
        "sbatch",
        "--parsable",
        "-p",
        slurm_cluster.partition,
        "-o",
        str(out),
        "--wrap",
        'echo "job=$SLURM_JOB_ID node=$SLURMD_NODENAME"',
    )
    jobid = r.stdout.strip().split(";")[0]
    assert jobid.isdigit(), r
    assert _wait_job(slurm_cluster, jobid) == "COMPLETED"
    text = out.read_text()
    assert f"job={jobid}" in text
    assert f"node={slurm_cluster.nodename}" in text


def test_snakemake_slurm_executor(slurm_cluster, tmp_path):  # noqa: F811
    if slurm_cluster.nested_srun_problem:
        pytest.skip(slurm_cluster.nested_srun_problem)
    (tmp_path / "Snakefile").write_text(SNAKEFILE)
    cmd = _snakemake_exe() + [
        "--profile",  # profiles/slurm with the test cluster's partition, squeue status, no account
        str(slurm_cluster.snakemake_profile(tmp_path / "profile")),
        "--snakefile",
        str(tmp_path / "Snakefile"),
        "--directory",
        str(tmp_path),
        "--latency-wait",
        "5",
        "--retries",
        "0",
        "--slurm-keep-successful-logs",
    ]
    t0 = time.monotonic()
    r = subprocess.run(cmd, cwd=tmp_path, env=slurm_cluster.env, capture_output=True, text=True, timeout=150)
    took = time.monotonic() - t0
    assert r.returncode == 0, f"snakemake failed ({took:.0f}s):\n{r.stdout}\n{r.stderr}\n" + slurm_cluster.log_tails()
    ids = []
    for i in (1, 2):
        f = tmp_path / "out" / f"{i}.txt"
        assert f.exists(), r.stderr
        ids.append(f.read_text().strip())
    assert all(i.isdigit() for i in ids), ids  # "none" would mean: not run under SLURM
    assert len(set(ids)) == 2, ids
    # the submission really went through sbatch of *this* cluster
    seen = slurm_cluster.run("squeue", "--states=all", "-h", "-o", "%i", check=False).stdout.split()
    assert set(ids) <= set(seen), (ids, seen)
