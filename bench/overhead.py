"""Time outside OpenFOAM per rule of the workflow (issue 23: <= 10 % of all job time on the demo).

Runs the workflow with the local profile in a scratch directory outside the repository (default:
a new temporary one), then reads Snakemake's ``benchmark:`` files (results/benchmarks/<rule>/*.tsv,
the ``s`` column: wall time of the job's process) and each case's status.json ``timings_s`` (the
OpenFOAM utilities: blockMesh, snappyHexMesh, checkMesh, simpleFoam, ...), and prints per rule the
jobs, their wall time, the time inside OpenFOAM and the share outside it, the longest job and the
largest peak memory (max_rss: what profiles/slurm's per-rule resources are sized from), then the
whole run.

    .venv/bin/python bench/overhead.py                              # the demo (config/config.yaml)
    .venv/bin/python bench/overhead.py --configfile config/ci.yaml  # 3 CI-sized patients
    .venv/bin/python bench/overhead.py --read /tmp/overhead_xyz     # figures of an earlier run

The demo phantoms (vcs_phantom, not benchmarked) are made first, so that the timed run is the
patients' chains and the atlas. The load (``uptime``) is printed before and after: timings on a
shared machine are noisy.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
SNAKEMAKE = Path(sys.executable).parent / "snakemake"


def read_benchmarks(results: Path, column: str = "s") -> dict[str, dict[str, float]]:
    """{rule: {job: value}} from results/benchmarks/<rule>/<job>.tsv (the last row's ``column``:
    ``s`` wall-clock seconds, ``max_rss`` peak memory MB, ...)."""
    out: dict[str, dict[str, float]] = {}
    for tsv in sorted((results / "benchmarks").glob("*/*.tsv")):
        with open(tsv) as fh:
            rows = list(csv.DictReader(fh, delimiter="\t"))
        if rows:
            value = rows[-1].get(column, "NA")
            out.setdefault(tsv.parent.name, {})[tsv.stem] = float(value) if value not in ("", "NA", "-") else 0.0
    return out


def openfoam_seconds(results: Path) -> dict[str, float]:
    """{patient: seconds in OpenFOAM utilities} from status.json ``timings_s`` (``total``, else the sum)."""
    out = {}
    for path in sorted((results / "patients").glob("*/status.json")):
        timings = json.loads(path.read_text()).get("timings_s") or {}
        total = timings.get("total")
        out[path.parent.name] = float(total if total is not None else sum(timings.values()))
    return out


# the rule whose jobs run OpenFOAM (its benchmark holds the status.json timings)
SOLVE_RULES = ("openfoam_solve",)


def table(results: Path) -> tuple[list[tuple], float, float]:
    """Rows (rule, jobs, wall s, OpenFOAM s, outside s, outside share, longest job s, peak MB),
    the job total and the OpenFOAM total."""
    bench = read_benchmarks(results)
    rss = read_benchmarks(results, "max_rss")
    foam = openfoam_seconds(results)
    rows = []
    for rule, jobs in sorted(bench.items(), key=lambda kv: -sum(kv[1].values())):
        wall = sum(jobs.values())
        inside = sum(foam.get(job, 0.0) for job in jobs) if rule in SOLVE_RULES else 0.0
        share = (wall - inside) / wall if wall else 0.0
        rows.append((rule, len(jobs), wall, inside, wall - inside, share, max(jobs.values()), max(rss[rule].values())))
    total = sum(r[2] for r in rows)
    inside = sum(r[3] for r in rows)
    return rows, total, inside


def print_table(results: Path) -> None:
    """The per-rule table; the last two columns (the longest job, the largest peak memory) are what
    profiles/slurm's per-rule runtime and mem_mb are sized from."""
    rows, total, inside = table(results)
    head = ("jobs", "wall s", "OpenFOAM s", "outside s", "per job", "outside", "max s", "max MB")
    print(f"{'rule':16s} " + " ".join(f"{h:>{w}s}" for h, w in zip(head, (4, 8, 10, 9, 7, 7, 7, 7))))
    for rule, n, wall, foam, out, share, longest, peak in rows:
        print(f"{rule:16s} {n:4d} {wall:8.1f} {foam:10.1f} {out:9.1f} {out / n:7.2f} {share:7.1%}", end=" ")
        print(f"{longest:7.1f} {peak:7.0f}")
    if total:
        print(
            f"{'all jobs':16s} {sum(r[1] for r in rows):4d} {total:8.1f} {inside:10.1f} {total - inside:9.1f}"
            f" {'':7s} {(total - inside) / total:7.1%}"
        )


def load() -> str:
    return subprocess.run(["uptime"], capture_output=True, text=True).stdout.strip()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--configfile", help="config merged over config/config.yaml (default: none, the demo)")
    ap.add_argument("--cores", type=int, default=2, help="snakemake --cores (default 2)")
    ap.add_argument("--workdir", type=Path, help="run here (kept; must be outside the repository)")
    ap.add_argument("--read", type=Path, metavar="DIR", help="only print the figures of an earlier run in DIR")
    args = ap.parse_args(argv)

    if args.read:
        print_table(args.read / "results")
        return 0
    work = (args.workdir or Path(tempfile.mkdtemp(prefix="overhead_"))).resolve()
    if work.is_relative_to(REPO):
        ap.error(f"--workdir {work} is inside the repository; give a scratch directory outside it")
    work.mkdir(parents=True, exist_ok=True)
    configs = [REPO / "config" / "config.yaml"] + ([Path(args.configfile).resolve()] if args.configfile else [])
    merged: dict = {}
    for path in configs:
        merged.update({k: v for k, v in yaml.safe_load(path.read_text()).items() if k == "patients"})
    sheet = (REPO / merged["patients"]).resolve()
    override = work / "overhead.yaml"
    override.write_text(yaml.safe_dump({"patients": str(sheet)}))
    base = [
        "-s", str(REPO / "Snakefile"), "-d", str(work), "--profile", str(REPO / "profiles" / "local"),
        "--cores", str(args.cores), "--configfile", *map(str, configs), str(override),
    ]  # fmt: skip
    env = {**os.environ, "WM_PROJECT_DIR": os.environ.get("WM_PROJECT_DIR", "/usr/share/openfoam")}
    log = work / "snakemake.log"
    with open(log, "w") as fh:  # the phantoms first: the timed run is the chains and the atlas
        subprocess.run([str(SNAKEMAKE), "--until", "vcs_phantom", *base], cwd=work, env=env, stdout=fh, stderr=fh)
        print(f"{datetime.datetime.now().isoformat(timespec='seconds')}  {load()}")
        t0 = time.perf_counter()
        r = subprocess.run([str(SNAKEMAKE), *base], cwd=work, env=env, stdout=fh, stderr=fh)
        wall = time.perf_counter() - t0
    print(f"{datetime.datetime.now().isoformat(timespec='seconds')}  {load()}")
    commit = subprocess.run(["git", "-C", str(REPO), "describe", "--always", "--dirty"], capture_output=True, text=True)
    where = commit.stdout.strip() or REPO
    configs_text = " + ".join(p.name for p in configs)
    print(f"workflow at {where}, config {configs_text}, sheet {sheet.name}, {args.cores} cores, in {work}")
    print(f"snakemake exit {r.returncode}, {wall:.0f} s (log: {log})")
    print_table(work / "results")
    return r.returncode


if __name__ == "__main__":
    sys.exit(main())
