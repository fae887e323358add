"""The wheel built by `pip wheel .` is complete: it holds the OpenFOAM templates, and a case renders
from a non-editable install of it (no source tree on the path)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
# what a copy of the source tree leaves out (pip builds in the source folder, which must stay clean)
_SKIP = shutil.ignore_patterns(
    ".git", ".venv", "results", "build", "dist", "*.egg-info", "__pycache__", ".snakemake", "test-artifacts", ".*_cache"
)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    # build from a copy: pip builds in the source folder (build/, *.egg-info), which must stay clean
    src = out / "src"
    shutil.copytree(REPO, src, ignore=_SKIP)
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", ".", "-w", str(out)],
        cwd=src,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    (whl,) = out.glob("vcs_atlas-*.whl")
    return whl


def test_wheel_from_the_sdist_has_the_templates(tmp_path):
    """The other install route: sdist (MANIFEST.in grafts templates/openfoam) -> wheel."""
    src = tmp_path / "src"
    shutil.copytree(REPO, src, ignore=_SKIP)
    r = subprocess.run(
        [sys.executable, "-c", "import setuptools.build_meta as b; print(b.build_sdist('sdist'))"],
        cwd=src,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    (sdist,) = (src / "sdist").glob("*.tar.gz")
    r = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", str(sdist), "-w", str(tmp_path / "w")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    (whl,) = (tmp_path / "w").glob("vcs_atlas-*.whl")
    names = zipfile.ZipFile(whl).namelist()
    assert "vcs/cfd/templates/openfoam/common/system/snappyHexMeshDict" in names
    assert "vcs/cfd/templates/openfoam/org10/constant/physicalProperties" in names
    assert "vcs/data/waveforms/ascending_aorta.csv" in names  # package data (pyproject.toml)


def test_wheel_contains_templates_and_every_package(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    templates = sorted(
        p.relative_to(REPO / "templates" / "openfoam").as_posix()
        for p in (REPO / "templates" / "openfoam").rglob("*")
        if p.is_file()
    )
    assert templates, "no templates in the source tree"
    missing = [t for t in templates if f"vcs/cfd/templates/openfoam/{t}" not in names]
    assert not missing, f"templates missing from the wheel: {missing}"
    packages = sorted(p.parent.relative_to(REPO).as_posix() for p in (REPO / "vcs").rglob("__init__.py"))
    assert all(f"{p}/__init__.py" in names for p in packages), packages
    waveforms = sorted(p.relative_to(REPO).as_posix() for p in (REPO / "vcs" / "data").rglob("*.csv"))
    assert waveforms and all(w in names for w in waveforms), waveforms


def test_case_renders_from_a_non_editable_install(wheel, tmp_path):
    site = tmp_path / "site"
    r = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    script = f"""
import vcs, vcs.cfd.openfoam as o
from vcs.cfd import render_case
from vcs.phantoms.analytic import write_closed_tube_stl
assert vcs.__file__.startswith({str(site)!r}), vcs.__file__
assert str(o.template_dir()).startswith({str(site)!r}), o.template_dir()
from vcs.cfd.waveform import default_waveform_path, load_waveform
assert str(default_waveform_path()).startswith({str(site)!r}), default_waveform_path()
assert load_waveform(default_waveform_path()).n_samples >= 50
stl = write_closed_tube_stl("tube.stl", radius=0.005, length=0.05, n_theta=24, n_z=10)
state = render_case("case", stl, {{"mesh": {{"cell_size": 1e-3}}}}, flavour="esi")
print(sorted(state["files"]))
"""
    env = {"PYTHONPATH": str(site), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    r = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, env=env, timeout=300
    )
    assert r.returncode == 0, r.stderr
    for rel in (
        "system/controlDict",
        "system/snappyHexMeshDict",
        "system/fvSchemes",
        "0/U",
        "0/p",
        "constant/transportProperties",
    ):
        text = (tmp_path / "case" / rel).read_text()
        assert "FoamFile" in text, rel
    assert "locationInMesh" in (tmp_path / "case" / "system" / "snappyHexMeshDict").read_text()
