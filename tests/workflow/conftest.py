"""Helpers for the workflow tests: a throw-away working directory with its own patients sheet,
config and results, driven through the `snakemake` CLI of this venv."""
from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

# the real one-node SLURM cluster fixture `slurm_cluster` (tests/ is not a package)
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from slurm_cluster import slurm_cluster  # noqa: E402,F401

REPO = Path(__file__).resolve().parents[2]
SNAKEFILE = REPO / "Snakefile"
SNAKEMAKE = Path(sys.executable).parent / "snakemake"
# outputs declared with directory() (created as folders when faking a finished run)
DIRECTORY_OUTPUTS = re.compile(r"(^|/)(case|case_setup|figures)$")


@dataclass
class Workdir:
    """A working directory for `snakemake -d`: config.yaml, patients.tsv, meshes, results/."""

    path: Path

    @property
    def config_file(self) -> Path:
        return self.path / "config.yaml"

    def config(self) -> dict:
        return yaml.safe_load(self.config_file.read_text())

    def write_config(self, cfg: dict) -> None:
        self.config_file.write_text(yaml.safe_dump(cfg, sort_keys=False))

    def update_config(self, *keys_and_value) -> None:
        """update_config("cfd", "solver", "max_iterations", 10)"""
        *keys, value = keys_and_value
        cfg = self.config()
        node = cfg
        for k in keys[:-1]:
            node = node.setdefault(k, {})
        node[keys[-1]] = value
        self.write_config(cfg)

    def write_sheet(self, rows: list[dict], name: str = "patients.tsv") -> Path:
        cols = ["id", "mesh", "units", "inlet", "outlet", "inlet_cap", "outlet_cap"]
        lines = ["\t".join(cols)] + ["\t".join(str(r.get(c, "")) for c in cols) for r in rows]
        sheet = self.path / name
        sheet.write_text("# test sheet\n" + "\n".join(lines) + "\n")
        return sheet

    def snakemake(self, *args: str, check: bool = True, timeout: float = 600,
                  env: dict | None = None) -> subprocess.CompletedProcess:
        cmd = [str(SNAKEMAKE), "-s", str(SNAKEFILE), "-d", str(self.path),
               "--configfile", str(self.config_file), *args]
        r = subprocess.run(cmd, cwd=self.path, capture_output=True, text=True, timeout=timeout,
                           env={**os.environ, **(env or {})})
        if check and r.returncode != 0:
            raise AssertionError(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stdout[-4000:]}\n{r.stderr[-4000:]}")
        return r

    def planned_jobs(self, *args: str) -> set[tuple[str, str | None]]:
        """{(rule, id wildcard or None)} of a dry-run (`snakemake -n`)."""
        r = self.snakemake("-n", *args)
        return parse_jobs(r.stdout + r.stderr)

    def summary(self) -> list[dict]:
        r = self.snakemake("--summary")
        lines = [ln for ln in r.stdout.splitlines() if "\t" in ln]
        head = lines[0].split("\t")
        return [dict(zip(head, ln.split("\t"))) for ln in lines[1:]]

    def fake_finished_run(self) -> None:
        """Create every output as an empty file/folder and register Snakemake's metadata (params,
        code, input) as if the whole workflow had run: `--touch --forceall` touches the outputs in
        DAG order and records the provenance used by the rerun triggers."""
        for row in self.summary():
            p = self.path / row["output_file"]
            if DIRECTORY_OUTPUTS.search(row["output_file"]):
                p.mkdir(parents=True, exist_ok=True)
            else:
                p.parent.mkdir(parents=True, exist_ok=True)
                p.touch()
        self.snakemake("--touch", "--forceall", "-c1", "--quiet")
        time.sleep(0.05)  # later edits must be strictly newer than the touched outputs


_JOB_START = re.compile(r"^(?:local)?(?:checkpoint|rule) (\w+):\s*$")
_WILDCARDS = re.compile(r"^\s+wildcards: (.*)$")


def parse_jobs(text: str) -> set[tuple[str, str | None]]:
    jobs: list[list] = []
    for line in text.splitlines():
        m = _JOB_START.match(line)
        if m:
            jobs.append([m.group(1), None])
            continue
        m = _WILDCARDS.match(line)
        if m and jobs:
            wc = dict(kv.split("=", 1) for kv in m.group(1).split(", ") if "=" in kv)
            jobs[-1][1] = wc.get("id") or (f"{wc['kind']}_seed{wc['seed']}" if "seed" in wc else None)
    return {(rule, pid) for rule, pid in jobs}


def make_workdir(path: Path, rows: list[dict]) -> Workdir:
    wd = Workdir(path)
    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    cfg["patients"] = "patients.tsv"
    wd.write_config(cfg)
    wd.write_sheet(rows)
    return wd


@pytest.fixture
def workdir_factory():
    """make_workdir(path, rows) -> Workdir (config from config/config.yaml, sheet from rows)."""
    return make_workdir


@pytest.fixture
def repo() -> Path:
    return REPO


@pytest.fixture
def cohort(tmp_path) -> Workdir:
    """Three patients with (fake) meshes, one of them with spaces in its path."""
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    for name in ("p1.stl", "p 2 scan.stl", "p3.stl"):
        (meshes / name).write_text("solid empty\nendsolid empty\n")
    return make_workdir(tmp_path, [
        {"id": "P1", "mesh": "meshes/p1.stl", "units": "mm"},
        {"id": "P2", "mesh": "meshes/p 2 scan.stl", "units": "mm", "inlet": "0,0,0", "outlet": "0,0,100"},
        {"id": "P3", "mesh": "meshes/p3.stl"},
    ])
