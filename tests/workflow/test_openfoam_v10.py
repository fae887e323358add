"""openfoam.org 10 output (issue #12): the solver-log parser (time units, both banners, the v10
convergence line), detection of the installation without a sourced environment (fake
``simpleFoam`` / ``dpkg-query`` scripts on PATH), and real runs of Debian's ESI solver wrapped by a
script that rewrites its output to what OpenFOAM-10 prints (marker ``openfoam``).

Every v10 line written here names the OpenFOAM-10 source that prints it (paths in the
OpenFOAM/OpenFOAM-10 repository).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from vcs.cfd import detect_openfoam, render_case, run_case
from vcs.cfd.foamfiles import parse_banner, parse_solver_log
from vcs.cfd.openfoam import openfoam_installation
from vcs.cfd.run import _pyfoam_check
from vcs.phantoms.analytic import write_closed_tube_stl

REAL_SIMPLEFOAM = shutil.which("simpleFoam")


def _have_esi() -> bool:
    openfoam_installation.cache_clear()
    try:
        return REAL_SIMPLEFOAM is not None and detect_openfoam()[0] == "esi"
    finally:
        openfoam_installation.cache_clear()


HAVE_FOAM = _have_esi()
needs_foam = pytest.mark.skipif(not HAVE_FOAM, reason="Debian's ESI OpenFOAM (simpleFoam) not installed")

# ------------------------------------------------------------------ v10 log text

# src/OpenFOAM/db/IOobject/IOobjectI.H, IOobject::writeBanner(Info, noHint=true), then
# src/OpenFOAM/global/argList/argList.C (argList::parse: Build/Exec/Date/Time/Host/PID, Case/nProcs,
# fileModificationChecking, allowSystemOperations, writeDivider);
# uncollatedFileOperation.C ("I/O    : uncollated"); src/OSspecific/POSIX/signals/sigFpe.C.
# hostName() is a Foam::string, written quoted.
V10_HEADER = r"""/*---------------------------------------------------------------------------*\
  =========                 |
  \\      /  F ield         | OpenFOAM: The Open Source CFD Toolbox
   \\    /   O peration     | Website:  https://openfoam.org
    \\  /    A nd           | Version:  10
     \\/     M anipulation  |
\*---------------------------------------------------------------------------*/
Build  : 10-c4cf895ad8fa
Exec   : simpleFoam
Date   : Jan 12 2024
Time   : 15:22:46
Host   : "node1"
PID    : 4242
I/O    : uncollated
Case   : /scratch/p01/case
nProcs : 1
sigFpe : Enabling floating point exception trapping (FOAM_SIGFPE).
fileModificationChecking : Monitoring run-time modified files using timeStampMaster (fileModificationSkew 10)
allowSystemOperations : Allowing user-supplied system call operations

// * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * * //
Create time

Create mesh for time = 100


SIMPLE: Convergence criteria found
        p: tolerance 1e-05
        U: tolerance 1e-05

Reading field p

Reading field U

Reading/calculating face flux field phi

Selecting viscosity model constant
Selecting turbulence model type laminar
Selecting laminar stress model Stokes
No MRF models present

No fvModels present
No fvConstraints present

Starting time loop

"""
# Create time: src/OpenFOAM/include/createTime.H; "Create mesh for time = " + runTime.timeName()
# (no unit): src/OpenFOAM/include/createMesh.H; "SIMPLE: Convergence criteria found" and
# "<algorithmSpace>  p: tolerance 1e-05": singleRegionConvergenceControl.C
# printResidualControls(); "Reading field p/U": applications/solvers/incompressible/simpleFoam/
# createFields.H; "Reading/calculating face flux field phi": createPhi.H; viscosityModelNew.C,
# momentumTransportModelTemplates.C, laminarModel.C, IOMRFZoneList.C, createFvModels.H,
# createFvConstraints.H; "Starting time loop": simpleFoam.C.


def _v10_iteration(t: int, r: float, cumulative: float) -> str:
    """One SIMPLE iteration as OpenFOAM-10's simpleFoam prints it.

    "Time = <t>s": simpleFoam.C prints runTime.userTimeName() = timeName(userTimeValue()) +
    userTime_->unit() (src/OpenFOAM/db/Time/Time.C; unit "s": userTime/realTime/realTime.C).
    Solver lines: src/OpenFOAM/matrices/LduMatrix/LduMatrix/SolverPerformance.C (one per
    component; p twice: 1 non-orthogonal corrector). Continuity: src/finiteVolume/cfdTools/
    incompressible/continuityErrs.H. ExecutionTime/ClockTime: simpleFoam.C.
    """
    return (
        f"Time = {t}s\n\n"
        f"smoothSolver:  Solving for Ux, Initial residual = {0.5 * r:.10g}, Final residual = {0.05 * r:.10g}, "
        "No Iterations 2\n"
        f"smoothSolver:  Solving for Uy, Initial residual = {r:.10g}, Final residual = {0.1 * r:.10g}, "
        "No Iterations 1\n"
        f"smoothSolver:  Solving for Uz, Initial residual = {0.2 * r:.10g}, Final residual = {0.02 * r:.10g}, "
        "No Iterations 1\n"
        f"GAMG:  Solving for p, Initial residual = {0.8 * r:.10g}, Final residual = {0.04 * r:.10g}, "
        "No Iterations 3\n"
        f"GAMG:  Solving for p, Initial residual = {0.3 * r:.10g}, Final residual = {0.01 * r:.10g}, "
        "No Iterations 2\n"
        f"time step continuity errors : sum local = {1e-3 * r:.10g}, global = {-1e-5 * r:.10g}, "
        f"cumulative = {cumulative:.10g}\n"
        f"ExecutionTime = {0.01 * t:.3g} s  ClockTime = {t // 50} s\n\n"
    )


def v10_log(start: int = 100, converged_at: int = 129) -> str:
    """A main-stage simpleFoam log of OpenFOAM-10 that converges at ``converged_at``.

    The end: convergenceControl::converged() (src/finiteVolume/cfdTools/general/solutionControl/
    convergenceControl/convergenceControl/convergenceControl.C) prints nl + "SIMPLE solution
    converged in " + time().timeName() + " iterations" + nl (timeName: no unit), at the start of
    the next simpleControl::loop (simpleControl.C); then simpleFoam.C prints "End".
    """
    parts = [V10_HEADER]
    for i, t in enumerate(range(start + 1, converged_at + 1)):
        r = 1e-3 * 0.82**i  # 0.82**28 * 1e-3 = 3.9e-6 < 1e-5 at t = 129
        parts.append(_v10_iteration(t, r, 1e-6 * (i + 1)))
    parts.append(f"\nSIMPLE solution converged in {converged_at} iterations\n\nEnd\n\n")
    return "".join(parts)


def test_v10_log_is_parsed(tmp_path):
    log = tmp_path / "log.simpleFoam"
    log.write_text(v10_log())
    out = parse_solver_log(log)
    rows = out["rows"]
    assert len(rows) == 29 and rows[0]["time"] == 101.0 and rows[-1]["time"] == 129.0
    assert out["time_unit"] == "s" and out["time_lines"] == 29
    assert out["converged_message"] and out["converged_iterations"] == 129.0
    assert out["ended"] and out["execution_time_s"] == pytest.approx(1.29) and out["clock_time_s"] == 2.0
    r_last = 1e-3 * 0.82**28
    assert rows[-1]["U"] == pytest.approx(r_last, rel=1e-8)  # max over Ux, Uy, Uz
    assert rows[-1]["p"] == pytest.approx(0.8 * r_last, rel=1e-8)  # first p solve only
    assert rows[-1]["cont_cumulative"] == pytest.approx(29e-6)
    b = out["banner"]
    assert (b["family"], b["version"], b["build"]) == ("org", "10", "10-c4cf895ad8fa")


def test_v10_log_pyfoam_cross_check(tmp_path):
    log = tmp_path / "log.simpleFoam"
    log.write_text(v10_log())
    rows = parse_solver_log(log)["rows"]
    pf = _pyfoam_check(log, rows[-1])
    # PyFoam's timeRegExp "^(Time =|Iteration:) ([^s]+)s?$" accepts the "s" unit
    assert pf["last_iteration"] == 129.0 and pf["agrees_with_parser"] is True
    assert pf["initial_residuals"]["p"] == pytest.approx(rows[-1]["p"])


@pytest.mark.parametrize(
    "line, time, unit",
    [
        ("Time = 12", 12.0, ""),  # ESI, openfoam.org <= 9: runTime.timeName()
        ("Time = 1s", 1.0, "s"),  # openfoam.org 10+: userTimeName(), realTime unit "s"
        ("Time = 0.001s", 0.001, "s"),
        ("Time = 1e-05s", 1e-5, "s"),
        ("Time = 5ms", 5.0, "ms"),
        ("Time = 12CAD", 12.0, "CAD"),  # engineTime unit (userTime/engineTime/engineTime.C)
    ],
)
def test_time_line_units(tmp_path, line, time, unit):
    log = tmp_path / "log"
    log.write_text(
        f"{line}\n\nGAMG:  Solving for p, Initial residual = 0.5, Final residual = 0.01, No Iterations 3\n"
        "ExecutionTime = 0.1 s  ClockTime = 0 s\n\nEnd\n"
    )
    out = parse_solver_log(log)
    assert [r["time"] for r in out["rows"]] == [pytest.approx(time)]
    assert out["rows"][0]["p"] == 0.5 and out["time_unit"] == unit and out["ended"]


def v10_pimple_log(start: float = 20.0, steps: int = 4) -> str:
    """A transient stage of OpenFOAM-10's pimpleFoam restarted at ``start``.

    pimpleFoam.C: CourantNo.H ("Courant Number mean: ... max: ...",
    src/finiteVolume/cfdTools/incompressible/CourantNo.H) and setInitialDeltaT.H before the time
    loop (the restart's time step, no deltaT line); in the loop CourantNo.H, setDeltaT.H
    ("deltaT = ...", src/finiteVolume/cfdTools/general/include/setDeltaT.H), then "Time = " +
    runTime.userTimeName() (unit "s"), the solver lines, ExecutionTime/ClockTime; "End".
    """
    parts = [V10_HEADER.replace("Create mesh for time = 100", f"Create mesh for time = {start:g}")]
    parts.append("Courant Number mean: 50.1 max: 2500.5\n\nStarting time loop\n\n")
    t, dt = start, 4e-4
    for i in range(steps):
        dt *= 1.1 if i else 1.0
        t += dt
        parts.append(f"Courant Number mean: 0.08 max: {0.9 + 0.02 * i:.3f}\ndeltaT = {dt:.10g}\n")
        parts.append(_v10_iteration(0, 1e-3, 1e-6).replace("Time = 0s", f"Time = {t:.10g}s"))
    parts.append("End\n\n")
    return "".join(parts)


def test_v10_pimple_log_courant_and_time_steps(tmp_path):
    log = tmp_path / "log.pimpleFoam.average"
    log.write_text(v10_pimple_log())
    out = parse_solver_log(log)
    assert out["time_unit"] == "s" and len(out["rows"]) == 4 and out["ended"]
    assert out["rows"][0]["time"] == pytest.approx(20.0004) and out["rows"][-1]["p"] == pytest.approx(0.8e-3)
    # the Courant number before the loop is the restart's time step (none was taken with it)
    assert out["courant_max"] == pytest.approx(0.96)
    assert out["delta_t_min"] == pytest.approx(4e-4) and out["delta_t_max"] == pytest.approx(4e-4 * 1.1**3)


def test_banner_time_line_is_not_an_iteration(tmp_path):
    # argList.C prints "Time   : 15:22:46" in the header: not a solver time line
    log = tmp_path / "log"
    log.write_text(V10_HEADER)
    out = parse_solver_log(log)
    assert out["rows"] == [] and out["time_lines"] == 0 and out["time_unit"] is None and not out["ended"]


# Debian's ESI v1912 (as run here), an upstream ESI v1912 build, openfoam.com's newer banners, and
# openfoam.org's (argList.C printUsage: "Using: OpenFOAM-" FOAMversion " (see https://openfoam.org)")
BANNERS = {
    "esi_debian_log": (
        "/*---------------------------------------------------------------------------*\\\n"
        "| =========                 |                                                 |\n"
        "| \\\\      /  F ield         | OpenFOAM: The Open Source CFD Toolbox           |\n"
        "|  \\\\    /   O peration     | Version:                                        |\n"
        "|   \\\\  /    A nd           | Website:  www.openfoam.com                      |\n"
        "|    \\\\/     M anipulation  |                                                 |\n"
        "\\*---------------------------------------------------------------------------*/\n"
        "Build  : OPENFOAM=1912 patch=200626\n"
        'Arch   : "LSB;label=32;scalar=64"\n',
        ("com", "v1912"),
    ),
    "esi_upstream_log": (
        "|  \\\\    /   O peration     | Version:  v1912                                 |\n"
        "|   \\\\  /    A nd           | Website:  www.openfoam.com                      |\n"
        "Build  : _9f29a8da7a-20191219 OPENFOAM=1912\n",
        ("com", "v1912"),
    ),
    "esi_debian_help": (
        "Using: OpenFOAM- (1912) - visit www.openfoam.com\nBuild:  (patch=200626)\nArch:  LSB;label=32;scalar=64\n",
        ("com", "v1912"),
    ),
    "esi_upstream_help": (
        "Using: OpenFOAM-v1912 (1912) - visit www.openfoam.com\nBuild: _9f29a8da7a-20191219 OPENFOAM=1912\n",
        ("com", "v1912"),
    ),
    "esi_develop_help": ("Using: OpenFOAM-com (2012) - visit www.openfoam.com\n", ("com", "v2012")),
    "esi_2512_help": (
        "Using: OpenFOAM-2512 (2512) - visit www.openfoam.com\nBuild: _bd2b6720-20260127\n",
        ("com", "v2512"),
    ),
    "org10_help": ("Using: OpenFOAM-10 (see https://openfoam.org)\nBuild: 10-c4cf895ad8fa\n", ("org", "10")),
    "org10_log": (V10_HEADER, ("org", "10")),
    "orgdev_help": ("Using: OpenFOAM-dev (see https://openfoam.org)\nBuild: dev-a1b2c3d4e5f6\n", ("org", "dev")),
    "garbage": ("segmentation fault\n\x00\x01", (None, None)),
}


@pytest.mark.parametrize("name", sorted(BANNERS))
def test_parse_banner(name):
    text, (family, version) = BANNERS[name]
    b = parse_banner(text)
    assert (b["family"], b["version"]) == (family, version)


# ------------------------------------------------------------------ detection with fake scripts

# OpenFOAM-11/12 bin/simpleFoam: a script printing this, then `exec env foamRun -solver
# incompressibleFluid "$@"`, whose -help ends with argList.C's "Using:" line
V11_STUB = (
    "\nsimpleFoam has been superseded and replaced by the more general\n"
    "incompressibleFluid solver module executed by the foamRun application:\n\n"
    "    foamRun -solver incompressibleFluid\n\n"
    "Usage: foamRun [OPTIONS]\n\nUsing: OpenFOAM-11 (see https://openfoam.org)\nBuild: 11-7b1e2c8f0d3a\n"
)


def _script(path: Path, stdout: str, code: int = 0) -> None:
    """An executable /bin/sh script printing ``stdout`` and exiting with ``code``."""
    body = stdout.replace("'", "'\"'\"'")
    path.write_text(f"#!/bin/sh\nprintf '%s' '{body}'\nexit {code}\n")
    path.chmod(0o755)


@pytest.fixture
def fake_foam(tmp_path, monkeypatch) -> Iterator[Path]:
    """PATH = only a folder for fake scripts; no sourced environment (WM_PROJECT_VERSION unset,
    WM_PROJECT_DIR an empty folder); the detection cache cleared before and after."""
    bindir = tmp_path / "bin"
    bindir.mkdir()
    (tmp_path / "foam").mkdir()
    monkeypatch.setenv("PATH", str(bindir))
    monkeypatch.delenv("WM_PROJECT_VERSION", raising=False)
    monkeypatch.delenv("VCSFLOW_OPENFOAM_FLAVOUR", raising=False)
    monkeypatch.setenv("WM_PROJECT_DIR", str(tmp_path / "foam"))
    openfoam_installation.cache_clear()
    yield bindir
    openfoam_installation.cache_clear()


@pytest.mark.parametrize(
    "banner, code, expected",
    [
        (BANNERS["org10_help"][0], 0, ("org10", "10")),
        (BANNERS["esi_debian_help"][0], 0, ("esi", "v1912")),
        (BANNERS["esi_upstream_help"][0], 0, ("esi", "v1912")),
        (BANNERS["orgdev_help"][0], 0, ("orgdev", "dev")),  # was an AttributeError
        (V11_STUB, 0, ("org11", "11")),
        ("FOAM FATAL ERROR: cannot open libOpenFOAM.so\n", 1, (None, None)),
        ("", 127, (None, None)),
    ],
    ids=["org10", "esi1912-debian", "esi1912", "org-dev", "org11-stub", "broken", "silent"],
)
def test_detect_from_simplefoam_banner(fake_foam, banner, code, expected):
    _script(fake_foam / "simpleFoam", banner, code)
    _script(fake_foam / "dpkg-query", "", 1)  # no package installed
    assert detect_openfoam() == expected
    info = openfoam_installation()
    assert info["executable"] == str(fake_foam / "simpleFoam") and not info["forced"]
    if expected[0] == "org11":
        assert any("foamRun" in n for n in info["notes"])


def test_detect_forced_flavour_keeps_version(fake_foam, monkeypatch):
    _script(fake_foam / "simpleFoam", BANNERS["org10_help"][0])
    monkeypatch.setenv("VCSFLOW_OPENFOAM_FLAVOUR", "esi")
    assert detect_openfoam() == ("esi", "10")
    assert openfoam_installation()["forced"]


def test_detect_from_wm_project_version(fake_foam, monkeypatch):
    monkeypatch.setenv("WM_PROJECT_VERSION", "10")  # a sourced v10, simpleFoam not on PATH
    assert detect_openfoam() == ("org10", "10")


@pytest.mark.parametrize(
    "files, expected",
    [
        (  # openfoam.org: etc/bashrc header and WM_PROJECT_VERSION (OpenFOAM-10/etc/bashrc)
            {"etc/bashrc": "# \\\\      /  F ield  | Website:  https://openfoam.org\nexport WM_PROJECT_VERSION=10\n"},
            ("org10", "10"),
        ),
        ({"META-INFO/api-info": "api=2312\npatch=240220\n"}, ("esi", "v2312")),  # ESI v2006+
        (  # Debian's /usr/share/openfoam/etc/bashrc
            {"etc/bashrc": "#   \\\\  /    A nd           | www.openfoam.com\nexport WM_PROJECT_VERSION=v1912\n"},
            ("esi", "v1912"),
        ),
    ],
    ids=["org10-bashrc", "esi-api-info", "esi-debian-bashrc"],
)
def test_detect_from_installation_files(fake_foam, tmp_path, files, expected):
    for rel, text in files.items():
        f = tmp_path / "foam" / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_text(text)
    assert detect_openfoam() == expected


@pytest.mark.parametrize(
    "dpkg, expected",
    [
        ("openfoam\t1912.200626-1+b1\tii \n", ("esi", "v1912")),  # Debian bookworm
        ("openfoam-examples\t1912.200626-1\tii \nopenfoam10\t20230119\tii \n", ("org10", "10")),  # openfoam.org deb
        ("openfoam2312\t2312.240220\tii \n", ("esi", "v2312")),  # openfoam.com deb
        ("openfoam10\t20230119\trc \n", (None, None)),  # removed, config files left
    ],
    ids=["debian", "org10-deb", "esi2312-deb", "removed"],
)
def test_detect_from_dpkg(fake_foam, dpkg, expected):
    _script(fake_foam / "dpkg-query", dpkg)
    assert detect_openfoam() == expected


def test_detect_nothing(fake_foam):
    assert detect_openfoam() == (None, None)


# ------------------------------------------------------------------ real runs, v10-wrapped solver

# the rewrite of the real (ESI v1912) solver's output into OpenFOAM-10's; each target line is
# the one the OpenFOAM-10 source named prints
FILTER = r"""
import re
import sys

mode = sys.argv[1]
BOX = {  # src/OpenFOAM/db/IOobject/IOobjectI.H, writeBanner
    "=========": "  =========                 |",
    "F ield": "  \\\\      /  F ield         | OpenFOAM: The Open Source CFD Toolbox",
    "O peration": "   \\\\    /   O peration     | Website:  https://openfoam.org",
    "A nd": "    \\\\  /    A nd           | Version:  10",
    "M anipulation": "     \\\\/     M anipulation  |",
}
for line in sys.stdin:
    s = line.rstrip("\n")
    m = re.match(r"^Time = ([-+.0-9eE]+)$", s)
    if m:  # simpleFoam.C: runTime.userTimeName() (realTime unit "s")
        if mode == "garble":
            continue
        s = f"Time = {m.group(1)}s"
    elif s.startswith("|") and any(k in s for k in BOX):
        s = next(v for k, v in BOX.items() if k in s)
    elif s.startswith("Build  :"):  # argList.C
        s = "Build  : 10-c4cf895ad8fa"
    elif s.startswith("Host   : ") and not s.endswith('"'):  # argList.C: hostName() is a quoted string
        s = 'Host   : "' + s[9:] + '"'
    elif s.startswith(("Arch   :", "Arch:")):  # openfoam.org prints no Arch line
        continue
    elif s.startswith("Using: OpenFOAM-"):  # argList.C printUsage
        s = "Using: OpenFOAM-10 (see https://openfoam.org)"
    elif s.startswith("Build:"):
        s = "Build: 10-c4cf895ad8fa"
    elif s.startswith("trapFpe:"):  # src/OSspecific/POSIX/signals/sigFpe.C
        s = "sigFpe : Enabling floating point exception trapping (FOAM_SIGFPE)."
    elif s == "SIMPLE: convergence criteria":  # singleRegionConvergenceControl.C
        s = "SIMPLE: Convergence criteria found"
    else:
        m = re.match(r"^    field (\w+)\t tolerance (\S+)$", s)
        if m:
            s = f"        {m.group(1)}: tolerance {m.group(2)}"
    sys.stdout.write(s + "\n")
    sys.stdout.flush()
"""


def _wrap_solver(bindir: Path, mode: str = "v10", solver: str = "simpleFoam") -> Path:
    """A ``solver`` (simpleFoam, pimpleFoam) in ``bindir`` that runs the real one and rewrites its
    output (mode ``"v10"``: as OpenFOAM-10 prints it; ``"garble"``: v10 without any time line)."""
    bindir.mkdir(parents=True, exist_ok=True)
    filt = bindir / "v10filter.py"
    filt.write_text(FILTER)
    w = bindir / solver
    pipe = f'"{shutil.which(solver)}" "$@" 2>&1 | "{sys.executable}" -u "{filt}" {mode}'
    w.write_text(f'#!/bin/bash\n{pipe}\nexit "${{PIPESTATUS[0]}}"\n')
    w.chmod(0o755)
    return w


TINY_AXIS = np.array([0.3, 0.2, 1.0])  # tilted: no axis-aligned round-off residual floor
TINY_CFG = {
    "mesh": {"cell_size": 0.6e-3},  # ~9,400 cells (3 prism layers, the default; ~5,500 without)
    "inlet": {"type": "parabolic", "flow_rate": 2.0e-6},  # Re ~ 95
    "solver": {"max_iterations": 400, "startup_iterations": 10},  # fallback: transient (default)
}


@pytest.fixture(scope="module")
def tiny_tube(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("v10tube")
    return write_closed_tube_stl(tmp / "tube.stl", radius=0.004, length=0.024, n_theta=64, n_z=24, axis=TINY_AXIS)


@pytest.fixture(scope="module")
def tiny_reference(tiny_tube) -> dict:
    """The tiny tube solved by the real solver, unwrapped."""
    case = tiny_tube.parent / "reference"
    render_case(case, tiny_tube, TINY_CFG, flavour="esi")
    return run_case(case, ranks=1)


@pytest.fixture
def v10_solver(tmp_path, monkeypatch) -> Iterator[Path]:
    """The v10-wrapped simpleFoam first on PATH; the flavour forced to esi (the dictionaries are
    ESI's, whatever the wrapper's banner says); detection cache cleared around the test."""
    bindir = tmp_path / "v10bin"
    _wrap_solver(bindir)
    monkeypatch.setenv("PATH", f"{bindir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("VCSFLOW_OPENFOAM_FLAVOUR", "esi")
    openfoam_installation.cache_clear()
    yield bindir
    openfoam_installation.cache_clear()


def _latest_time(case: Path) -> float:
    return max(float(p.name) for p in case.iterdir() if p.is_dir() and re.fullmatch(r"[0-9.]+", p.name))


@pytest.mark.openfoam
@needs_foam
def test_v10_wrapped_solver_converges(tiny_tube, tiny_reference, v10_solver, tmp_path):
    ref = tiny_reference
    assert ref["converged"] and ref["iterations"] > 10, ref["reason"]
    assert detect_openfoam() == ("esi", "10")  # the wrapper's banner, the forced flavour
    case = tmp_path / "v10"
    render_case(case, tiny_tube, TINY_CFG, flavour="esi")
    st = run_case(case, ranks=1)
    log = (case / "logs" / "log.simpleFoam").read_text()
    assert re.search(r"^Time = \d+s$", log, re.M) and not re.search(r"^Time = \d+$", log, re.M)
    assert "Version:  10" in log and "Using:" not in log
    # converged with the real iteration count (was: converged false, iterations 0, TypeError)
    assert st["converged"] is True, st["reason"]
    assert st["iterations"] == ref["iterations"] > 0
    assert st["stage_iterations"] == ref["stage_iterations"]
    assert st["final_residuals"] == pytest.approx(ref["final_residuals"])
    assert st["criterion_used"] == "residualControl" and st["reason"] is None
    sl = st["solver_log"]
    assert sl["time_unit"] == "s" and sl["ended"] and sl["converged_iterations"] == st["iterations"]
    assert (sl["banner"]["family"], sl["banner"]["version"]) == ("org", "10")
    assert ref["solver_log"]["time_unit"] == "" and ref["solver_log"]["banner"]["version"] == "v1912"
    pf = st["pyfoam_log_analysis"]
    assert pf["last_iteration"] == st["iterations"] and pf["agrees_with_parser"] is True
    assert _latest_time(case) == st["iterations"]
    assert json.loads((case / "status.json").read_text())["converged"] is True


@pytest.mark.openfoam
@needs_foam
def test_v10_wrapped_solver_parallel(tiny_tube, v10_solver, tmp_path):
    case = tmp_path / "v10par"
    render_case(case, tiny_tube, TINY_CFG, flavour="esi")
    st = run_case(case, ranks=2)
    assert (case / "processor1").is_dir() and "reconstructPar" in st["timings_s"]
    assert re.search(r"^Time = \d+s$", (case / "logs" / "log.simpleFoam").read_text(), re.M)
    assert st["converged"] is True, st["reason"]
    assert st["iterations"] > 10 and st["solver_log"]["converged_iterations"] == st["iterations"]
    assert _latest_time(case) == st["iterations"]


@pytest.mark.openfoam
@needs_foam
def test_v10_wrapped_transient_fallback(tiny_tube, v10_solver, tmp_path):
    """SIMPLE stopped early, then the transient fallback with a pimpleFoam that prints as
    OpenFOAM-10 (``Time = 20.0123s``; pimpleFoam.C prints runTime.userTimeName() too): the time
    steps are read, the window is judged, the laminar tube flow is stationary."""
    _wrap_solver(v10_solver, solver="pimpleFoam")
    cfg = {
        **TINY_CFG,
        "solver": {
            "max_iterations": 20,
            "startup_iterations": 5,
            "fallback": "transient",
            "transient": {"min_flow_throughs": 0.2, "max_flow_throughs": 0.2, "washout_flow_throughs": 0.1},
        },
    }
    case = tmp_path / "v10tr"
    render_case(case, tiny_tube, cfg, flavour="esi")
    st = run_case(case, ranks=1)  # must not raise
    log = (case / "logs" / "log.pimpleFoam.average").read_text()
    assert re.search(r"^Time = 20\.[0-9]+s$", log, re.M) and "Version:  10" in log
    assert st["iterations"] == 20 and "did not reach" in st["transient"]["steady_not_converged"]
    tr = st["transient"]
    assert tr["solver_log"]["time_unit"] == "s" and tr["solver_log"]["ended"]
    assert tr["time_steps"]["washout"] > 5 and tr["time_steps"]["average"] > 5
    assert tr["courant_max"] is not None and tr["courant_max"] <= 1.02 * tr["courant"]["pimple_max_co"]
    assert tr["evaluated"] and st["criterion_used"] == "time_average_stationary"
    assert st["converged"] is True and st["reason"] is None, st["reason"]
    assert tr["window_flow_throughs"] >= 0.2 and float(tr["end_time_folder"]) == pytest.approx(tr["end_time"])
    assert json.loads((case / "status.json").read_text())["converged"] is True


@pytest.mark.openfoam
@needs_foam
def test_unreadable_solver_log_never_raises(tiny_tube, tmp_path, monkeypatch):
    """A solver whose time lines cannot be read: a reason, no fallback, no exception."""
    bindir = tmp_path / "garblebin"
    _wrap_solver(bindir, mode="garble")
    monkeypatch.setenv("PATH", f"{bindir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.setenv("VCSFLOW_OPENFOAM_FLAVOUR", "esi")
    openfoam_installation.cache_clear()
    try:
        cfg = {**TINY_CFG, "solver": {"max_iterations": 30, "startup_iterations": 0}}
        case = tmp_path / "garbled"
        render_case(case, tiny_tube, cfg, flavour="esi")
        st = run_case(case, ranks=1)
    finally:
        openfoam_installation.cache_clear()
    assert st["converged"] is False and "no SIMPLE iteration could be read" in st["reason"]
    assert not list((case / "logs").glob("log.pimpleFoam*")) and "transient" not in st
    assert st["pyfoam_log_analysis"]["last_iteration"] is None and "note" in st["pyfoam_log_analysis"]


@pytest.mark.openfoam
@needs_foam
def test_v10_banner_without_override_is_a_flavour_mismatch(tiny_tube, tmp_path, monkeypatch):
    """Detected from the (wrapped) v10 banner: org10; an esi case is refused with a reason."""
    bindir = tmp_path / "v10bin"
    _wrap_solver(bindir)
    monkeypatch.setenv("PATH", f"{bindir}{os.pathsep}{os.environ['PATH']}")
    monkeypatch.delenv("VCSFLOW_OPENFOAM_FLAVOUR", raising=False)
    monkeypatch.delenv("WM_PROJECT_VERSION", raising=False)
    openfoam_installation.cache_clear()
    try:
        assert detect_openfoam() == ("org10", "10")
        case = tmp_path / "mismatch"
        render_case(case, tiny_tube, TINY_CFG, flavour="esi")
        st = run_case(case, ranks=1)
    finally:
        openfoam_installation.cache_clear()
    assert st["converged"] is False and "'org10'" in st["reason"] and st["openfoam_version"] == "10"


# ------------------------------------------------------------------ pulsatile case (issue 24), rendered for v10

# Every check below names the OpenFOAM-10 source that reads the entry (paths in the
# OpenFOAM/OpenFOAM-10 repository; $TVM = src/finiteVolume/fields/fvPatchFields/derived/
# timeVaryingMappedFixedValue).
SWITCH_WORDS = {"false", "true", "off", "on", "no", "yes", "n", "y", "f", "t", "none", "any"}  # Switch.C names


def _pulsatile_org10(tmp: Path, stl: Path) -> tuple[Path, dict]:
    """A pulsatile org10 case: one 0.8 s cycle, 5 +- 3 L/min (no backflow), 24 intervals; its
    last row repeats the first flow (a closed cycle)."""
    rows = [(0.8 * i / 24, 5.0 + 3.0 * np.sin(2 * np.pi * i / 24)) for i in range(24)] + [(0.8, 5.0)]
    csv = tmp / "wave.csv"
    csv.write_text("time_s,flow_rate_l_min\n" + "".join(f"{t:.6g},{q:.6g}\n" for t, q in rows))
    case = tmp / "pulsatile"
    state = render_case(case, stl, {"inlet": {"waveform": str(csv)}}, flavour="org10")
    return case, state


def _block(text: str, name: str) -> dict[str, str]:
    """The entries (keyword -> rest of the line, without the ';') of the sub-dictionary ``name``
    of a boundaryField, comments left out."""
    m = re.search(rf"^    {name}\n    \{{\n(.*?)^    \}}", text, re.M | re.S)
    assert m, name
    out = {}
    for ln in m.group(1).splitlines():
        s = ln.split("//")[0].strip()
        if s:
            k, _, v = s.partition(" ")
            out[k] = v.strip().rstrip(";").strip()
    return out


def _v10_function_name(include_func: str) -> str:
    """The name OpenFOAM-10 gives an ``#includeFunc`` function object: its ``funcName`` argument,
    else the call with the characters word::valid rejects (whitespace, quotes, / $ ; { }) removed
    (src/OpenFOAM/db/functionObjects/functionObjectList/functionObjectList.C readFunctionObject:
    funcDict.lookupOrDefault("funcName", string::validate<word>(funcArgs));
    src/OpenFOAM/primitives/strings/word/wordI.H word::valid)."""
    m = re.search(r"[(,]\s*funcName\s*=\s*([^,)\s]+)", include_func)
    return m.group(1) if m else re.sub(r"[\s\"'/$;{}]", "", include_func)


class _Stages:
    """Stands in for pimpleFoam in :func:`vcs.cfd.pulsatile._run_cycle`: keeps each stage's
    dictionaries, writes a v10 pimpleFoam log and the time folders the run writes.

    ``anchor``: how the write times of ``writeControl adjustableRunTime`` are placed.
    ``"end"``: a folder at endTime (the stage reaches its end and writes there). ``"v10"``:
    OpenFOAM-10's src/OpenFOAM/db/Time/Time.C: setControls reads ``beginTime`` from
    ``<start>/uniform/time`` (absent: the start time) and sets writeTimeIndex_ =
    label((t - beginTime + 0.5 deltaT)/writeInterval); every step setDeltaT -> adjustDeltaT
    (timeToNextWrite = (writeTimeIndex_ + 1) writeInterval - (t - beginTime)), operator++ writes
    when label((t - beginTime + 0.5 deltaT)/writeInterval) grows, running(): t < endTime -
    0.5 deltaT; no write at endTime otherwise; TimeIO.C writeTimeDict keeps beginTime.
    ``"esi"``: the same with writes counted from the start time (ESI v1812/v1912 Time.C
    adjustDeltaT: (writeTimeIndex_ + 1) writeInterval - (value() - startTime_)). The time step
    asked for is maxDeltaT, growing by at most 1.2 per step (setDeltaT.H).
    """

    def __init__(self, case: Path, anchor: str = "end") -> None:
        self.case, self.anchor, self.stages = case, anchor, []

    def __call__(self, args, log, ranks=1, watch=None):
        if args[0] != "pimpleFoam":  # postProcess (the end-plane Courant plan): writes nothing here, so the
            return subprocess.CompletedProcess(args, 0)  # run keeps its Courant limit (a logged warning)
        ctl = (self.case / "system/controlDict").read_text()

        def entry(key: str) -> float:
            return float(re.search(rf"^{key}\s+(\S+);", ctl, re.M).group(1))

        start, start_name = max(
            (float(p.name), p.name) for p in self.case.iterdir() if re.fullmatch(r"[0-9.e+-]+", p.name)
        )
        end, interval, max_dt = entry("endTime"), entry("writeInterval"), entry("maxDeltaT")
        tdict = self.case / start_name / "uniform" / "time"
        stored = dict(re.findall(r"^(\w+)\s+(\S+);", tdict.read_text(), re.M)) if tdict.exists() else {}
        begin = float(stored.get("beginTime", start)) if self.anchor == "v10" else start
        dt = float(stored.get("deltaT", entry("deltaT")))
        self.stages.append(
            {
                "start": start,
                "controlDict": ctl,
                "fvSolution": (self.case / "system/fvSolution").read_text(),
                "fvSchemes": (self.case / "system/fvSchemes").read_text(),
            }
        )
        writes, t, index = [], start, int((start - begin + 0.5 * dt) / interval)
        steps = []
        if self.anchor == "end":
            steps, writes = [(end, end - start)], [end]
        else:
            while t < end - 0.5 * dt and len(steps) < 100000:
                dt = min(1.2 * dt, max_dt)
                to_next = max(0.0, (index + 1) * interval - (t - begin))
                dt = to_next / int(max(to_next / dt, 1) + 0.99)
                t += dt
                steps.append((t, dt))
                if int((t - begin + 0.5 * dt) / interval) > index:
                    index = int((t - begin + 0.5 * dt) / interval)
                    writes.append(t)
        for tw in writes:
            d = self.case / f"{tw:.10g}" / "uniform"
            d.mkdir(parents=True, exist_ok=True)
            (d / "time").write_text(f"beginTime {begin:.10g};\nvalue {tw:.10g};\ndeltaT {steps[-1][1]:.10g};\n")
        text = V10_HEADER.replace("Create mesh for time = 100", f"Create mesh for time = {start:g}")
        text += "Courant Number mean: 0 max: 0\n\nStarting time loop\n\n"
        for tk, dk in steps:
            text += f"Courant Number mean: 0.1 max: 0.5\ndeltaT = {dk:.10g}\n"
            text += _v10_iteration(0, 1e-3, 1e-6).replace("Time = 0s", f"Time = {tk:.10g}s")
        (self.case / "logs").mkdir(exist_ok=True)
        (self.case / "logs" / f"log.{log}").write_text(text + "End\n\n")
        return subprocess.CompletedProcess(args, 0)


def _cycle(case: Path, state: dict, anchor: str) -> tuple[_Stages, dict]:
    """Cycle 1 of :func:`vcs.cfd.pulsatile.pulsatile_solve` (its stage settings) run by :class:`_Stages`."""
    from vcs.cfd.pulsatile import _run_cycle, pulsatile_plan
    from vcs.cfd.transient import _Pimple
    from vcs.cfd.utilities import _fmt_time

    plan = pulsatile_plan(state)
    common = {  # pulsatile_solve's stage settings
        "transient": True,
        "residual_control": False,
        "delta_t": _fmt_time(plan["delta_t_initial_s"]),
        "max_delta_t": _fmt_time(plan["max_delta_t_s"]),
        "max_co": plan["max_co"],
        "outer_correctors": plan["outer_correctors"],
        "probe_points": None,
    }
    stages = _Stages(case, anchor)
    cycle = _run_cycle(_Pimple(case, state, stages, 1, case, common, {}), plan, 1)
    return stages, cycle


def test_pulsatile_org10_inlet_and_stages_read_by_v10(tiny_tube, tmp_path):
    """A pulsatile org10 case: the mapped inlet, the outlet and the dictionaries of a cycle's
    pimpleFoam stages are what OpenFOAM-10 reads (no OpenFOAM needed)."""
    from PyFoam.RunDictionary.ParsedParameterFile import ParsedParameterFile

    from vcs.cfd.pulsatile import _vector_list
    from vcs.cfd.utilities import _fmt_time

    case, state = _pulsatile_org10(tmp_path, tiny_tube)
    assert state["flavour"] == "org10" and state["waveform"]["period_s"] == pytest.approx(0.8)
    u_text = (case / "0/U").read_text()
    ParsedParameterFile(str(case / "0/U"))
    inlet = _block(u_text, "inlet")
    # $TVM/timeVaryingMappedFixedValueFvPatchField.C: fixedValueFvPatchField(p, iF, dict, false) and
    # "value" read when found; $TVM/timeVaryingMappedFvPatchField/timeVaryingMappedFvPatchField.C
    # reads fieldTable, dataDir, points, sample, setAverage, perturb, mapMethod (lookupOrDefault)
    # and offset (Function1<Type>::New when found): nothing else, nothing required
    assert set(inlet) == {"type", "mapMethod", "offset", "setAverage", "value"}, inlet
    assert inlet["type"] == "timeVaryingMappedFixedValue"  # TypeName in timeVaryingMappedFixedValueFvPatchField.H
    # FatalIOError unless mapMethod is planarInterpolation or nearest (nearestOnly interpolation)
    assert inlet["mapMethod"] == "nearest"
    # src/OpenFOAM/primitives/functions/Function1/Function1/Function1New.C: an entry whose first
    # token is not a word is a Function1s::Constant read from the stream (Constant.C:
    # pTraits<Type>(is)): "offset (0 0 0)" is the constant zero vector, no "constant" keyword needed
    assert re.fullmatch(r"\(0 0 0\)", inlet["offset"])
    # setAverage: lookupOrDefault bool, read as a Switch (src/OpenFOAM/primitives/bools/bool/boolIO.C)
    assert inlet["setAverage"] in SWITCH_WORDS and inlet["setAverage"] in ("off", "false", "no")
    assert inlet["value"] == "uniform (0 0 0)"
    # no dataDir/points/sample: constant/boundaryData/<patch>/points and <time>/U (findFieldFile),
    # both read by a plain IFstream (checkTable): headerless lists
    block = _vector_list(np.array([[0.0, 1e-3, -2.5e-3], [1.0, 2.0, 3.0]]))
    assert "FoamFile" not in block and block.split("\n")[:2] == ["2", "("] and block.rstrip().endswith(")")
    assert re.findall(r"\(([^()]*)\)", block) == ["0 0.001 -0.0025", "1 2 3"]
    # Time::findTimes on constant/boundaryData/<patch>: folder names that read as scalars
    for t in (0.0, 0.004, 0.8 / 3):
        assert float(_fmt_time(t)) == pytest.approx(t, rel=1e-11)
    outlet = _block(u_text, "outlet")
    assert outlet == {"type": "inletOutlet", "inletValue": "uniform (0 0 0)", "value": "uniform (0 0 0)"}
    p_out = _block((case / "0/p").read_text(), "outlet")
    assert p_out["type"] == "fixedValue" and p_out["value"] == "uniform 0"

    stages, cycle = _cycle(case, state, "end")
    assert len(stages.stages) == 4 and cycle["cut_names"] == ["0.2", "0.6", "0.7"]  # sine: peak, trough, midway
    for i, st in enumerate(stages.stages):
        ctl = st["controlDict"]
        assert re.search(r"^application\s+pimpleFoam;", ctl, re.M)
        # readTimeControls.H (src/finiteVolume/cfdTools/general/include): adjustTimeStep, maxCo, maxDeltaT
        assert re.search(r"^adjustTimeStep\s+yes;", ctl, re.M) and re.search(r"^maxDeltaT\s+0\.004;", ctl, re.M)
        assert re.search(r"^writeControl\s+adjustableRunTime;", ctl, re.M)
        funcs = [ln.strip() for ln in ctl.splitlines() if ln.strip().startswith("#includeFunc")]
        # etc/caseDicts/postProcessing/fields/{wallShearStress,mag,fieldAverage}; each executed in
        # the order of the functions dictionary: the averaged fields exist before fieldAverage runs
        i_wss = funcs.index("#includeFunc wallShearStress(executeControl=timeStep)")
        i_mag = funcs.index("#includeFunc mag(wallShearStress, result=magWallShearStress, executeControl=timeStep)")
        (fa,) = [f for f in funcs if f.startswith("#includeFunc fieldAverage(")]
        assert i_wss < i_mag < funcs.index(fa)
        # fieldAverage.cfg: writeControl writeTime; fieldAverage: mean yes, fields (<fieldNames>)
        # replaced by the positional arguments (functionObjectList.C readFunctionObject); named
        # arguments set as entries: restartOnRestart, read by fieldAverage.C read() as a bool
        call = fa[len("#includeFunc ") :]
        args = [a.strip() for a in call[call.index("(") + 1 : call.rindex(")")].split(",")]
        named = dict(a.split("=", 1) for a in args if "=" in a)
        assert [a for a in args if "=" not in a] == ["U", "p", "wallShearStress", "magWallShearStress"]
        assert set(named) <= {"restartOnRestart", "funcName"} and named["restartOnRestart"] in SWITCH_WORDS
        # restarted at the cycle's first part, continued across its cuts (fieldAverage.C
        # readAveragingProperties: totalIter/totalTime from <start>/uniform/<name>Properties)
        assert named["restartOnRestart"] == ("yes" if i == 0 else "no")
        sol = st["fvSolution"]
        # pimpleLoop.C nOuterCorrectors; pisoControl.C nCorrectors; nonOrthogonalSolutionControl.C
        # nNonOrthogonalCorrectors; fluidSolutionControl.C momentumPredictor
        pimple = re.search(r"^PIMPLE\n\{\n(.*?)^\}", sol, re.M | re.S).group(1)
        keys = {ln.split()[0] for ln in pimple.splitlines() if ln.strip()}
        assert keys == {"nOuterCorrectors", "nCorrectors", "nNonOrthogonalCorrectors", "momentumPredictor"}
        assert "pFinal" in sol and '"(U|UFinal)"' in sol and "SIMPLE" not in sol
        assert re.search(r"default\s+backward;", st["fvSchemes"])


def test_pulsatile_org10_average_continues_across_cuts(tiny_tube, tmp_path):
    """fieldAverage's properties (totalIter, totalTime) are found by the name of the function
    object: the parts of a cycle must give it one name for v10 to continue the average."""
    case, state = _pulsatile_org10(tmp_path, tiny_tube)
    stages, _ = _cycle(case, state, "end")
    names = set()
    for st in stages.stages:
        lines = [ln.strip() for ln in st["controlDict"].splitlines()]
        (fa,) = [ln for ln in lines if ln.startswith("#includeFunc fieldAverage(")]
        names.add(_v10_function_name(fa[len("#includeFunc ") :]))
    assert len(names) == 1, names


def test_pulsatile_stage_writes_model(tiny_tube, tmp_path):
    """Control of the write-time model of :class:`_Stages`: written from the start time (ESI
    v1912, whose writeInterval the stages count from their start: vcs.cfd.transient.write_origin),
    every cut of the cycle gets its folder and no other time is written."""
    case, state = _pulsatile_org10(tmp_path, tiny_tube)
    _, cycle = _cycle(case, {**state, "flavour": "esi"}, "esi")
    assert cycle["cut_names"] == ["0.2", "0.6", "0.7"] and cycle["end_name"] == "0.8"
    written = sorted(p.name for p in case.iterdir() if re.fullmatch(r"[0-9.]+", p.name))
    assert written == ["0", "0.2", "0.6", "0.7", "0.8"]


def test_pulsatile_org10_stages_write_their_ends_under_v10(tiny_tube, tmp_path):
    """Each part of a cycle, restarted by pimpleFoam of OpenFOAM-10 (write times as its Time.C
    places them), ends with its time folder at its cut."""
    case, state = _pulsatile_org10(tmp_path, tiny_tube)
    _, cycle = _cycle(case, state, "v10")
    assert cycle["cut_names"] == ["0.2", "0.6", "0.7"] and cycle["end_name"] == "0.8"
