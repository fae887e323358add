"""Cohort throughput of the workflow: N synthetic aortas with the local profile.

Prints the wall time of the Snakemake run against the ideal given by Snakemake's benchmark files
(sum of all job times / cores), the time spent in OpenFOAM (openfoam_solve benchmark and the
OpenFOAM utility timings of each status.json), and the share of job time spent outside OpenFOAM.
Target: parallel efficiency >= 0.9 on 2 cores (one serial case per core).

    .venv/bin/python bench/bench_cohort.py --n 4 --cores 2                 # CI-sized cases
    .venv/bin/python bench/bench_cohort.py --n 8 --configfile config/config.yaml

The phantoms (vcs_phantom) are generated before the timed run, so that the timed run is the
per-patient chain + atlas only. Runs in a fresh directory (default: a temporary one). ``--json
PATH`` also writes the per-patient table in the docs' format, with each patient's cell size and
prism-layer coverage (docs/data/bench/demo_cohort.json: the demo cohort, ``--n 8 --configfile
config/config.yaml``).
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from _table import save  # bench/ is on sys.path when this runs as a script

REPO = Path(__file__).resolve().parents[1]
SNAKEMAKE = Path(sys.executable).parent / "snakemake"


def read_benchmarks(results: Path) -> dict[str, dict[str, float]]:
    """{rule: {job: seconds}} from results/benchmarks/<rule>/<job>.tsv (Snakemake's `s` column)."""
    out: dict[str, dict[str, float]] = {}
    for tsv in sorted((results / "benchmarks").glob("*/*.tsv")):
        with open(tsv) as fh:
            rows = list(csv.DictReader(fh, delimiter="\t"))
        if rows:
            out.setdefault(tsv.parent.name, {})[tsv.stem] = float(rows[-1]["s"])
    return out


def read_statuses(results: Path) -> dict[str, dict]:
    return {p.parent.name: json.loads(p.read_text()) for p in sorted((results / "patients").glob("*/status.json"))}


#: the docs table's columns (docs/data/bench/demo_cohort.json)
JSON_COLUMNS = [
    "patient",
    "cell mm (auto)",
    "cells",
    "layer coverage",
    "snappyHexMesh s",
    "SIMPLE iterations",
    "simpleFoam s",
    "converged",
    "resampling s",
    "resampling / solver",
]


def json_cells(pid: str, st: dict, sample: float | None) -> list[str]:
    """One patient's row of :data:`JSON_COLUMNS` from its status.json and its resampling job's
    seconds (the fields_sample benchmark; None: none)."""
    t = st.get("timings_s", {})
    mesh = st.get("mesh") or {}
    size = ((mesh.get("sizing") or {}).get("cell_size") or {}).get("cell_size_m")
    coverage = (mesh.get("layers") or {}).get("coverage")
    solver = sum(float(v) for k, v in t.items() if k.startswith("simpleFoam"))
    return [
        pid,
        "-" if size is None else f"{size * 1e3:.3g}",
        f"{st.get('cells') or 0:,}",
        "-" if coverage is None else f"{coverage:.2f}",
        f"{float(t.get('snappyHexMesh') or 0.0):.1f}",
        str(st.get("iterations")),
        f"{solver:.1f}",
        "yes" if st.get("converged") else "NO: " + str(st.get("reason")),
        "-" if sample is None else f"{sample:.1f}",
        f"{100 * sample / solver:.0f} %" if sample is not None and solver > 0 else "-",
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4, help="patients (aorta phantoms, seeds 0..n-1)")
    ap.add_argument("--cores", type=int, default=2, help="snakemake --cores")
    ap.add_argument(
        "--configfile",
        default=str(REPO / "config" / "ci.yaml"),
        help="config merged over config/config.yaml (default: the CI-sized config/ci.yaml)",
    )
    ap.add_argument("--workdir", help="run here instead of a temporary directory (kept)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the per-patient table as docs JSON")
    args = ap.parse_args(argv)

    work = Path(args.workdir or tempfile.mkdtemp(prefix="bench_cohort_")).resolve()
    work.mkdir(parents=True, exist_ok=True)
    sheet = work / "patients.tsv"
    rows = ["id\tmesh\tunits"] + [f"aorta_{s}\tresults/demo/aorta_seed{s}.stl\tmm" for s in range(args.n)]
    sheet.write_text("\n".join(rows) + "\n")
    override = work / "bench.yaml"
    override.write_text(yaml.safe_dump({"patients": str(sheet)}))
    base = [
        "-s",
        str(REPO / "Snakefile"),
        "-d",
        str(work),
        "--profile",
        str(REPO / "profiles" / "local"),
        "--cores",
        str(args.cores),
        "--configfile",
        str(REPO / "config" / "config.yaml"),
        str(Path(args.configfile).resolve()),
        str(override),
    ]
    phantoms = [f"results/demo/aorta_seed{s}.stl" for s in range(args.n)]
    # targets before the options: `--quiet` takes optional values
    subprocess.run([str(SNAKEMAKE), *phantoms, *base, "--quiet"], check=True, cwd=work)

    t0 = time.perf_counter()
    r = subprocess.run([str(SNAKEMAKE), "all", *base, "--quiet"], cwd=work)
    wall = time.perf_counter() - t0
    results = work / "results"
    bench = read_benchmarks(results)
    statuses = read_statuses(results)

    jobs_s = sum(sum(v.values()) for v in bench.values())
    solve_s = sum(bench.get("openfoam_solve", {}).values())
    foam_s = sum(float(s.get("timings_s", {}).get("total") or 0.0) for s in statuses.values())
    ideal = jobs_s / args.cores
    converged = sum(bool(s.get("converged")) for s in statuses.values())

    print(f"cohort: {args.n} patients, {args.cores} cores, config {args.configfile}, in {work}")
    print(f"snakemake exit code {r.returncode}; {converged}/{len(statuses)} cases converged")
    print("job time per rule (sum of benchmark s):")
    for rule, times in sorted(bench.items(), key=lambda kv: -sum(kv[1].values())):
        print(f"  {rule:16s} {sum(times.values()):9.1f} s  over {len(times)} job(s)")
    print(f"wall time                       {wall:9.1f} s")
    print(f"sum of solver job times         {solve_s:9.1f} s  (openfoam_solve benchmarks)")
    print(f"ideal wall (all jobs / cores)   {ideal:9.1f} s")
    print(f"parallel efficiency             {ideal / wall:9.2f}   (target >= 0.90)")
    print(f"solver jobs / cores / wall      {solve_s / args.cores / wall:9.2f}")
    print(f"time inside OpenFOAM utilities  {foam_s:9.1f} s  (status.json timings_s.total)")
    if jobs_s > 0:
        print(f"share of job time outside OpenFOAM {1 - foam_s / jobs_s:6.1%}")
    print(f"scheduler/idle share of core time  {max(0.0, 1 - jobs_s / (args.cores * wall)):6.1%}")
    print("\nper patient (status.json timings, Snakemake benchmarks):")
    print(
        "| patient | cells | snappyHexMesh s | iterations | simpleFoam s | converged | resampling s "
        "| resampling / solver |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for pid, st in statuses.items():
        t = st.get("timings_s", {})
        snappy = float(t.get("snappyHexMesh") or 0.0)
        solver = sum(float(v) for k, v in t.items() if k.startswith("simpleFoam"))
        sample = bench.get("fields_sample", {}).get(pid)
        ratio = f"{sample / solver:.1%}" if sample is not None and solver > 0 else "-"
        print(
            f"| {pid} | {st.get('cells')} | {snappy:.1f} | {st.get('iterations')} | {solver:.1f} | "
            f"{st.get('converged')} | {sample if sample is None else round(sample, 1)} | {ratio} |"
        )
    config_name = Path(args.configfile).resolve()
    if config_name.is_relative_to(REPO):
        config_name = config_name.relative_to(REPO)
    save(
        args.json,
        measured=f"one run, {args.n} patients, {args.cores} cores, config/config.yaml + {config_name}; "
        f"{wall:.0f} s wall, parallel efficiency {ideal / wall:.2f}",
        columns=JSON_COLUMNS,
        rows=[json_cells(pid, st, bench.get("fields_sample", {}).get(pid)) for pid, st in statuses.items()],
    )
    return r.returncode


if __name__ == "__main__":
    sys.exit(main())
