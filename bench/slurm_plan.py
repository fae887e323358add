"""Planning a big cohort: Snakemake's dry-run of an N-patient sheet (issue 23: 1,000 patients plan
in <= 60 s; on SLURM at most ~2 jobs per patient).

Writes a sheet of N demo rows (results/demo/aorta_seed<i>.stl: no files needed) into a scratch
directory outside the repository and times `snakemake -n` with profiles/local (every job) and with
profiles/slurm (its `groups`: one SLURM job per patient), printing the jobs planned, the SLURM
jobs that would be submitted and the seconds each plan took (wall clock, and the CPU time, which
a busy machine changes less), with the load (`uptime`).

    .venv/bin/python bench/slurm_plan.py                 # 1,000 patients
    .venv/bin/python bench/slurm_plan.py --n 200
"""

from __future__ import annotations

import argparse
import datetime
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
SNAKEMAKE = Path(sys.executable).parent / "snakemake"
# top-level entries of a dry-run: a group job, or a single job (its time stamp alone on a line)
ENTRY = re.compile(r"^\[[^\]]+\] Group job \w+ |^\[[^\]]+\]\s*$", re.M)
RULE = re.compile(r"^(?:local)?rule (\w+):\s*$", re.M)
LOCAL = ("all", "atlas_complete")  # never submitted: a target without a body, a localrule


def plan(work: Path, profile: str) -> tuple[float, float, int, int, int]:
    """(wall-clock s, CPU s, jobs planned, SLURM jobs submitted, group jobs) of `snakemake -n`."""
    cmd = [
        str(SNAKEMAKE),
        "-s",
        str(REPO / "Snakefile"),
        "-d",
        str(work),
        "--profile",
        str(REPO / "profiles" / profile),
    ]
    cmd += ["--configfile", str(REPO / "config" / "config.yaml"), str(work / "sheet.yaml"), "-n"]
    t0, c0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    r = subprocess.run(cmd, cwd=work, capture_output=True, text=True)
    seconds, c1 = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime
    text = r.stdout + r.stderr
    if r.returncode != 0:
        sys.exit(f"bench/slurm_plan.py: snakemake -n failed ({r.returncode}): {text[-2000:]}")
    total = int(re.search(r"^total\s+(\d+)$", text, re.M).group(1))
    entries = ENTRY.findall(text)
    groups = sum("Group job" in e for e in entries)
    singles = [m.group(1) for m in RULE.finditer(text)]  # top-level rules are not indented
    return seconds, cpu, total, groups + sum(rule not in LOCAL for rule in singles), groups


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="patients (default 1000)")
    ap.add_argument("--workdir", type=Path, help="scratch directory (default: a new temporary one)")
    args = ap.parse_args(argv)
    work = (args.workdir or Path(tempfile.mkdtemp(prefix="slurm_plan_"))).resolve()
    if work.is_relative_to(REPO):
        ap.error(f"--workdir {work} is inside the repository; give a scratch directory outside it")
    work.mkdir(parents=True, exist_ok=True)
    rows = [f"P{i}\tresults/demo/aorta_seed{i}.stl\tmm" for i in range(args.n)]
    (work / "patients.tsv").write_text("id\tmesh\tunits\n" + "\n".join(rows) + "\n")
    (work / "sheet.yaml").write_text(yaml.safe_dump({"patients": str(work / "patients.tsv")}))
    commit = subprocess.run(["git", "-C", str(REPO), "describe", "--always", "--dirty"], capture_output=True, text=True)
    print(f"{args.n} patients, workflow at {commit.stdout.strip()}, in {work}")
    for profile in ("local", "slurm"):
        load = subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()
        seconds, cpu, total, submitted, groups = plan(work, profile)
        print(
            f"{datetime.datetime.now().isoformat(timespec='seconds')} profiles/{profile:5s}: {total} jobs planned, "
            f"{submitted if profile == 'slurm' else '-'} SLURM jobs ({groups} group jobs), "
            f"dry-run {seconds:.1f} s ({cpu:.1f} s CPU)  [{load}]"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
