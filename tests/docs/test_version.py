"""One version: pyproject.toml's, shown by the package (vcs.__version__), by results/provenance.json
(vcs_version) and by the documentation (docs/conf.py reads the installed package's metadata)."""

import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import yaml

import vcs

ROOT = Path(__file__).resolve().parents[2]
PYPROJECT_VERSION = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


def test_package_version_is_pyprojects():
    assert vcs.__version__ == PYPROJECT_VERSION


def test_changelog_has_the_version():
    assert f"## [{PYPROJECT_VERSION}]" in (ROOT / "CHANGELOG.md").read_text()


def test_docs_show_the_package_version():
    conf = (ROOT / "docs" / "conf.py").read_text()
    assert 'release = importlib.metadata.version("vcs-atlas")' in conf


def test_provenance_records_the_package_version(tmp_path):
    """A one-job run (a tube phantom) writes results/provenance.json with vcs_version."""
    cfg = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    cfg["patients"] = "patients.tsv"
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(cfg))
    (tmp_path / "patients.tsv").write_text("id\tmesh\tunits\ntube\tresults/demo/tube_seed0.stl\tmm\n")
    snakemake = Path(sys.executable).parent / "snakemake"
    cmd = [str(snakemake), "-s", str(ROOT / "Snakefile"), "-d", str(tmp_path), "--configfile"]
    cmd += [str(tmp_path / "config.yaml"), "--cores", "1", "results/demo/tube_seed0.stl"]
    r = subprocess.run(cmd, cwd=tmp_path, capture_output=True, text=True, timeout=600, env=dict(os.environ))
    assert r.returncode == 0, r.stderr[-3000:]
    prov = json.loads((tmp_path / "results" / "provenance.json").read_text())
    assert prov["vcs_version"] == PYPROJECT_VERSION == prov["packages"]["vcs-atlas"]
