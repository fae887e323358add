""".snakemake-workflow-catalog.yml against the Snakemake workflow catalog's documented format.

The truth is written out by hand from the catalog's documentation, "Standardized usage workflows"
in the README of https://github.com/snakemake/snakemake-workflow-catalog (also its
``source/docs/about/adding_workflows.md``), and from the generator that reads the file
(``scripts/generate-catalog.py``, ``source/build_wf_pages.py``):

* a YAML mapping with one key, ``usage``, holding
* ``mandatory-flags``: ``desc`` (a few sentences, shown below the run commands) and ``flags``
  (a single string ``'--a --b'`` or a list of strings);
* ``software-stack-deployment``: booleans ``conda`` (``--sdm conda``), ``apptainer`` (``--sdm
  apptainer``) and ``apptainer+conda`` (``--sdm conda apptainer``); the catalog's earlier names
  ``singularity`` and ``singularity+conda`` are read as the apptainer ones;
* ``report``: a boolean, whether ``snakemake --report report.zip`` works. The README's example
  indents it under ``software-stack-deployment``, but the generator reads ``usage.report``
  (``settings.get("usage", {}).get("report", False)``), which is where this file has it.

"Standardized usage" (a usage page with snakedeploy instructions) also needs ``config/README.md``
and the workflow at ``workflow/Snakefile``.
"""

from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
CATALOG = ROOT / ".snakemake-workflow-catalog.yml"

USAGE_KEYS = {"mandatory-flags", "software-stack-deployment", "report"}
FLAG_KEYS = {"desc", "flags"}
DEPLOYMENT_KEYS = {"conda", "apptainer", "apptainer+conda"}


def _usage() -> dict:
    settings = yaml.safe_load(CATALOG.read_text())
    assert isinstance(settings, dict) and set(settings) == {"usage"}, settings
    assert isinstance(settings["usage"], dict)
    return settings["usage"]


def test_catalog_file_has_only_the_documented_keys():
    usage = _usage()
    assert set(usage) <= USAGE_KEYS, set(usage) - USAGE_KEYS
    flags = usage["mandatory-flags"]
    assert set(flags) <= FLAG_KEYS, set(flags) - FLAG_KEYS
    assert isinstance(flags["desc"], str) and flags["desc"].strip()
    value = flags["flags"]
    assert isinstance(value, str) or (isinstance(value, list) and all(isinstance(f, str) for f in value))
    deployment = usage["software-stack-deployment"]
    assert set(deployment) <= DEPLOYMENT_KEYS, set(deployment) - DEPLOYMENT_KEYS
    assert all(isinstance(v, bool) for v in deployment.values()), deployment
    assert isinstance(usage["report"], bool)


def test_catalog_file_points_at_what_exists():
    """The profile of the mandatory flags, config/README.md, and the report the file promises."""
    usage = _usage()
    flags = usage["mandatory-flags"]["flags"]
    words = flags.split() if isinstance(flags, str) else flags
    profile = words[words.index("--profile") + 1]
    assert (ROOT / profile / "config.yaml").is_file(), profile
    assert (ROOT / "config" / "README.md").is_file()
    if usage["report"]:
        assert any(line.startswith("report:") for line in (ROOT / "Snakefile").read_text().splitlines())


def _planned_jobs(snakefile: Path, workdir: Path) -> dict[str, int]:
    """Job counts per rule of a dry run of the demo (the default config) through ``snakefile``."""
    import subprocess
    import sys

    snakemake = Path(sys.executable).parent / "snakemake"
    cmd = [str(snakemake), "-s", str(snakefile), "-d", str(workdir), "-n", "--cores", "1"]
    cmd += ["--configfile", str(ROOT / "config" / "config.yaml")]
    cmd += ["--config", f"patients={ROOT / 'config' / 'patients.tsv'}"]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    counts = {}
    for line in (out.stdout + out.stderr).splitlines():
        words = line.split()
        if len(words) == 2 and words[1].isdigit():
            counts[words[0]] = int(words[1])
    assert counts.get("total", 0) > 0, out.stdout
    return counts


def test_workflow_is_where_the_catalog_looks(tmp_path):
    """The catalog's generator and snakedeploy run workflow/Snakefile (the repository has a workflow/
    folder): the same workflow as ./Snakefile, planning the same jobs from a working directory that
    is not the repository."""
    assert (ROOT / "workflow" / "Snakefile").is_file()
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    root_plan = _planned_jobs(ROOT / "Snakefile", a)
    catalog_plan = _planned_jobs(ROOT / "workflow" / "Snakefile", b)
    # its target rule (catalog_all) asks for what rule all asks for
    assert root_plan.pop("all") == catalog_plan.pop("catalog_all") == 1
    assert root_plan == catalog_plan
    # the demo: 8 patients, each through the fit, wall, case, solve, sampling and QC, then the atlas
    assert root_plan["vcs_fit"] == 8 and root_plan["atlas_build"] == 1
