"""The `vcs` command line on bad arguments and bad output paths (issue 14, part B): no abbreviated
options, -v anywhere, range-checked numbers, output paths checked before any work (exit 2, one
line, nothing written), out of memory exit 3, atomic outputs, earlier outputs kept whole through
a failed or interrupted rerun (with a failure record), inputs never overwritten, wall/grid in
the model's units.

The large matrices of argument and path errors run `vcs` in this process (vcs_in_process); what
needs a real process (resource limits, a crash, the console script's exit) runs it as one."""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import vcs_in_process

REPO = Path(__file__).resolve().parents[2]


def run(*args, **kwargs):
    return subprocess.run([sys.executable, "-m", "vcs.cli", *map(str, args)], capture_output=True, text=True, **kwargs)


def one_line_error(r, *fragments, code=2):
    """Exit ``code``, exactly one line on stderr holding every fragment, no traceback."""
    lines = r.stderr.strip().splitlines()
    assert r.returncode == code, (r.returncode, r.stderr)
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    for f in fragments:
        assert f in lines[0], lines[0]
    return lines[0]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (hidden ones too) with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """The tube phantom (r = 10 mm, 100 mm long along z) written in cm and fitted: (folder, mesh,
    model.json)."""
    import trimesh

    from vcs.phantoms import make_phantom

    d = tmp_path_factory.mktemp("fitted")
    ph = make_phantom("tube", resolution=2.0)
    mesh = d / "tube_cm.stl"
    trimesh.Trimesh(ph.vertices * 0.1, ph.faces, process=False).export(mesh)
    r = run("fit", mesh, "-o", d / "fit", "--units", "cm", "--K", "7", "--R", "7")
    assert r.returncode == 0, r.stderr
    assert np.ptp(ph.vertices, axis=0) == pytest.approx([20.0, 20.0, 100.0], abs=0.01)  # mm
    return d, mesh, d / "fit" / "model.json"


# ---------------------------------------------------------------------------------------------
# 1. the parser


def test_every_parser_refuses_abbreviations():
    """allow_abbrev=False on the parser and each subparser; `--outp`, `--rec`, `--verb` are errors
    naming the command, not silently `--output`, `--recentre`, `--verbose`."""
    import argparse

    from vcs.cli import build_parser

    p = build_parser()
    sub = next(a for a in p._actions if isinstance(a, argparse._SubParsersAction))
    assert p.allow_abbrev is False
    assert len(sub.choices) == 9 and all(sp.allow_abbrev is False for sp in sub.choices.values())
    one_line_error(run("phantom", "--kind", "tube", "--outp", "x.stl"), "vcs phantom: error:", "--outp")
    one_line_error(run("fit", "m.stl", "-o", "f", "--rec", "2"), "vcs fit: error:", "unrecognized arguments: --rec 2")
    one_line_error(run("--verb", "phantom", "-o", "x.stl"), "--verb")
    assert not Path("x.stl").exists()


@pytest.mark.parametrize(
    "argv",
    [
        ["fit", "m.stl", "-o", "f"],
        ["ends", "m.stl"],
        ["coords", "m.json", "p.csv", "-o", "c.csv"],
        ["cartesian", "m.json", "c.csv", "-o", "x.csv"],
        ["phantom", "-o", "p.stl"],
        ["wall", "m.json", "-o", "w.stl"],
        ["grid", "m.json", "-o", "g.vtu"],
        ["sensitivity", "m.stl", "-o", "s"],
    ],
)
def test_verbose_anywhere_on_the_line(argv):
    from vcs.cli.main import parse_args

    assert parse_args(argv).verbose is False
    assert parse_args(["-v", *argv]).verbose is True
    assert parse_args([*argv, "-v"]).verbose is True
    assert parse_args([argv[0], "--verbose", *argv[1:]]).verbose is True
    assert parse_args(["-v", *argv, "-v"]).verbose is True


def test_usage_errors_are_one_line_even_with_line_breaks_in_values(tmp_path):
    r = run("wall", "m.json", "-o", "w.stl", "--n-theta", "1\n2")
    one_line_error(r, "argument --n-theta", "1\\n2", "see vcs wall --help")
    r = run("coords", "m.json", "p.csv", "-o", tmp_path / "a\nb" / "c.csv")
    one_line_error(r, "a\\nb")


@pytest.mark.parametrize(
    "argv, option",
    [
        (["wall", "MODEL", "-o", "OUT/w.stl", "--extend-inlet", "-1"], "--extend-inlet"),
        (["wall", "MODEL", "-o", "OUT/w.stl", "--extend-outlet", "-0.5"], "--extend-outlet"),
        (["wall", "MODEL", "-o", "OUT/w.stl", "--extend-inlet", "nan"], "--extend-inlet"),
        (["wall", "MODEL", "-o", "OUT/w.stl", "--extend-outlet", "inf"], "--extend-outlet"),
        (["wall", "MODEL", "-o", "OUT/w.stl", "--n-theta", "7"], "--n-theta"),
        (["wall", "MODEL", "-o", "OUT/w.stl", "--n-tau", "0"], "--n-tau"),
        (["grid", "MODEL", "-o", "OUT/g.vtu", "--n-tau", "1"], "--n-tau"),
        (["grid", "MODEL", "-o", "OUT/g.vtu", "--n-theta", "3"], "--n-theta"),
        (["grid", "MODEL", "-o", "OUT/g.vtu", "--n-rho", "1"], "--n-rho"),
        (["fit", "MESH", "-o", "OUT/f", "--K", "0"], "--K"),
        (["fit", "MESH", "-o", "OUT/f", "--R", "-2"], "--R"),
        (["fit", "MESH", "-o", "OUT/f", "--L", "0"], "--L"),
        (["fit", "MESH", "-o", "OUT/f", "--recentre", "-1"], "--recentre"),
        (["fit", "MESH", "-o", "OUT/f", "--K", "1.5"], "--K"),
        (["phantom", "-o", "OUT/p.stl", "--seed", "-1"], "--seed"),
        (["phantom", "-o", "OUT/p.stl", "--resolution", "0"], "--resolution"),
        (["phantom", "-o", "OUT/p.stl", "--resolution", "-1"], "--resolution"),
        (["phantom", "-o", "OUT/p.stl", "--resolution", "nan"], "--resolution"),
    ],
)
def test_numbers_out_of_range_are_usage_errors(fitted, tmp_path, argv, option):
    """Every numeric option is range-checked by its argparse type: exit 2, one line naming the
    option, nothing written (before: `--extend-inlet -1` silently became 0, a negative seed was an
    internal error)."""
    _, mesh, model = fitted
    argv = [a.replace("MODEL", str(model)).replace("MESH", str(mesh)).replace("OUT", str(tmp_path)) for a in argv]
    one_line_error(vcs_in_process(*argv), f"argument {option}")
    assert list(tmp_path.iterdir()) == []


def test_wall_mesh_refuses_a_negative_extension(fitted):
    from vcs.errors import VCSInputError
    from vcs.surface import wall_mesh
    from vcs.vessel import VesselModel

    model = VesselModel.load(fitted[2])
    with pytest.raises(VCSInputError, match="extend-inlet"):
        wall_mesh(model, extend_inlet=-1.0)
    with pytest.raises(VCSInputError, match="extend-outlet"):
        wall_mesh(model, extend_outlet=float("nan"))


def test_phantom_never_replaces_a_file_without_overwrite(tmp_path):
    mine = tmp_path / "patient.stl"
    mine.write_bytes(b"solid mine\nendsolid mine\n")
    params = tmp_path / "params.json"
    params.write_text("{}\n")
    one_line_error(run("phantom", "--kind", "tube", "-o", mine), "exists", "--overwrite")
    assert mine.read_bytes() == b"solid mine\nendsolid mine\n"
    r = run("phantom", "--kind", "tube", "-o", tmp_path / "new.stl", "--params", params)
    one_line_error(r, "--params", "exists")
    assert params.read_text() == "{}\n" and not (tmp_path / "new.stl").exists()
    r = run("phantom", "--kind", "tube", "--resolution", "4", "-o", mine, "--params", params, "--overwrite")
    assert r.returncode == 0, r.stderr
    assert mine.read_bytes()[:80].startswith(b"vcs phantom kind=tube")
    assert json.loads(params.read_text())["kind"] == "tube"


@pytest.mark.parametrize("command", ["wall", "grid"])
def test_wall_and_grid_default_to_the_units_of_the_fitted_mesh(fitted, tmp_path, command):
    """A mesh in cm gives a wall STL / grid VTU in cm (the 100 mm tube is 10 long, as in the mesh),
    not in mm; --units overrides."""
    import pyvista as pv

    _, _, model = fitted
    ext = ".stl" if command == "wall" else ".vtu"
    r = run(command, model, "-o", tmp_path / f"a{ext}", *(["--n-tau", "8"] if command == "grid" else []))
    assert r.returncode == 0, r.stderr
    assert "in cm" in r.stdout
    r = run(command, model, "-o", tmp_path / f"b{ext}", "--units", "mm")
    assert r.returncode == 0, r.stderr
    za, zb = (np.ptp(np.asarray(pv.read(tmp_path / f"{n}{ext}").points)[:, 2]) for n in "ab")
    assert za == pytest.approx(10.0, abs=0.05) and zb == pytest.approx(100.0, abs=0.5)


# ---------------------------------------------------------------------------------------------
# 2. output paths


def _commands(d: Path, mesh: Path, model: Path, out: str):
    """Every command with output ``out`` (``{ext}`` replaced by its extension)."""
    pts = d / "p.csv"
    return {
        "fit": ["fit", mesh, "-o", out.format(ext="")],
        "ends": ["ends", mesh, "-o", out.format(ext=".json")],
        "coords": ["coords", model, pts, "-o", out.format(ext=".csv")],
        "cartesian": ["cartesian", model, d / "c.csv", "-o", out.format(ext=".csv")],
        "wall": ["wall", model, "-o", out.format(ext=".stl")],
        "lumen": ["lumen", mesh, "--model", model, "-o", out.format(ext=".stl")],
        "grid": ["grid", model, "-o", out.format(ext=".vtu"), "--n-tau", "4", "--n-theta", "8", "--n-rho", "2"],
        "phantom": ["phantom", "--kind", "tube", "-o", out.format(ext=".stl")],
        "sensitivity": ["sensitivity", mesh, "--L", "5", "--K", "5", "--R", "5", "-o", out.format(ext="")],
    }


@pytest.fixture()
def workdir(fitted, tmp_path):
    """A folder with the inputs of every command: m.stl, model.json, p.csv, c.csv, a regular file
    'afile' and a directory 'adir'."""
    _, mesh, model = fitted
    shutil.copy(mesh, tmp_path / "m.stl")
    shutil.copy(model, tmp_path / "model.json")
    (tmp_path / "p.csv").write_text("x,y,z\n0,0,5\n")
    (tmp_path / "c.csv").write_text("tau,theta,rho\n0.5,0,0.2\n")
    (tmp_path / "afile").write_text("x")
    (tmp_path / "adir").mkdir()
    return tmp_path


CASES = {
    "missing parent": ("nodir/deeper/out{ext}", "does not exist"),
    "under a regular file": ("afile/out{ext}", "which is a file"),
    "a directory": ("adir", "is a directory"),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize(
    "command", ["fit", "ends", "coords", "cartesian", "wall", "grid", "lumen", "phantom", "sensitivity"]
)
def test_bad_output_paths_are_one_line_and_write_nothing(workdir, command, case):
    """-o with a missing parent, under a regular file, or naming a directory (for file outputs):
    exit 2, one line, before any work; nothing created, every input unchanged."""
    out, fragment = CASES[case]
    if case == "a directory" and command in ("fit", "sensitivity"):
        out, fragment = "afile", "not a directory"  # these write into a directory: a file is the error
    before = snapshot(workdir)
    argv = _commands(workdir, workdir / "m.stl", workdir / "model.json", str(workdir / out))[command]
    one_line_error(vcs_in_process(*argv), f"vcs {command}: error:", fragment)
    assert snapshot(workdir) == before and sorted(p.name for p in workdir.iterdir()) == sorted(
        ["m.stl", "model.json", "p.csv", "c.csv", "afile", "adir"]
    )


@pytest.mark.parametrize(
    "command, name, expected",
    [
        ("grid", "g.xyz", ".vtu"),
        ("grid", "g", ".vtu"),
        ("wall", "w.vtu", ".stl"),
        ("lumen", "l.vtp", ".stl"),
        ("phantom", "p.obj", ".stl"),
        ("ends", "e.csv", ".json"),
        ("coords", "c.json", ".csv or .txt"),
    ],
)
def test_unknown_output_extension(workdir, command, name, expected):
    before = snapshot(workdir)
    argv = _commands(workdir, workdir / "m.stl", workdir / "model.json", str(workdir / name))[command]
    one_line_error(vcs_in_process(*argv), f"must end in {expected}")
    assert snapshot(workdir) == before


@pytest.fixture()
def read_only_dir(tmp_path):
    """An empty directory nobody here can write to: mode 0555, and for root (who ignores mode
    bits) also the immutable attribute (chattr +i); skipped where neither holds."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    immutable = False
    if os.geteuid() == 0:
        immutable = shutil.which("chattr") is not None and subprocess.run(["chattr", "+i", ro]).returncode == 0
        if not immutable:
            ro.chmod(0o755)
            pytest.skip("running as root and chattr +i is not available: no directory root cannot write to")
    try:
        yield ro
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", ro], check=True)
        ro.chmod(0o755)


@pytest.mark.parametrize("command", ["fit", "coords", "wall", "grid", "lumen", "phantom", "sensitivity"])
def test_output_directory_not_writable(workdir, read_only_dir, command):
    """-o in a directory that refuses new files: exit 2, one line naming the directory, before any
    work; nothing written."""
    argv = _commands(workdir, workdir / "m.stl", workdir / "model.json", str(read_only_dir / "out{ext}"))[command]
    one_line_error(vcs_in_process(*argv), "cannot write to directory", str(read_only_dir))
    assert list(read_only_dir.iterdir()) == []


def _limit_memory():
    """preexec_fn: 3 GB of address space, so that a large request fails as MemoryError whatever
    the kernel's overcommit policy, without touching the machine's memory."""
    resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))


def test_out_of_memory_is_exit_3_not_bad_input(fitted, tmp_path):
    """A grid of 6.4e9 nodes (150 GB of coordinates): exit 3 and one line, not 2 (the input is
    fine, the machine too small) nor an internal error; the same limit lets a small grid through."""
    _, _, model = fitted
    r = run("grid", model, "-o", tmp_path / "small.vtu", "--n-tau", "4", preexec_fn=_limit_memory)
    assert r.returncode == 0, r.stderr
    (tmp_path / "small.vtu").unlink()
    r = run(
        "grid",
        model,
        "-o",
        tmp_path / "g.vtu",
        "--n-tau",
        "4000",
        "--n-theta",
        "4000",
        "--n-rho",
        "400",
        preexec_fn=_limit_memory,
    )
    one_line_error(r, "vcs grid: out of memory", "exit code 3", code=3)
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------------------------------
# 3. atomic outputs, earlier outputs kept, inputs


def _limit_file_size():
    """preexec_fn: no file may grow beyond 16 kB (writes past it fail with EFBIG: Python ignores
    SIGXFSZ). The outputs below are far larger: a wall STL several MB, centerline.vtp ~57 kB."""
    resource.setrlimit(resource.RLIMIT_FSIZE, (16 << 10, 16 << 10))


def test_a_failed_write_leaves_the_old_output_whole(fitted, tmp_path):
    """The wall STL (several MB) cannot be written under a 16 kB file size limit: exit 2, one line,
    and the earlier wall.stl is still there byte for byte, with no temporary file beside it (a
    writer that wrote straight into wall.stl would have left 16 kB of a new one)."""
    _, _, model = fitted
    old = tmp_path / "wall.stl"
    assert run("wall", model, "-o", old, "--n-theta", "32").returncode == 0
    before = old.read_bytes()
    r = run("wall", model, "-o", old, "--n-theta", "256", preexec_fn=_limit_file_size)
    one_line_error(r, "cannot write", "wall.stl")
    assert old.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["wall.stl"]


def test_a_crash_while_writing_leaves_the_old_output_whole(fitted, tmp_path):
    """VTK aborts the process (double free) when its writer hits the file size limit: the earlier
    grid.vtu is untouched; the dead run's temporary file is removed by the next run."""
    _, _, model = fitted
    old = tmp_path / "grid.vtu"
    assert run("grid", model, "-o", old, "--n-tau", "4").returncode == 0
    before = old.read_bytes()
    r = run("grid", model, "-o", old, "--n-tau", "400", "--n-theta", "64", preexec_fn=_limit_file_size)
    assert r.returncode != 0
    assert old.read_bytes() == before
    leftovers = [p.name for p in tmp_path.iterdir() if p.name != "grid.vtu"]
    assert all(n.startswith(".grid.vtu.") and n.endswith(".tmp.vtu") for n in leftovers)
    assert run("grid", model, "-o", old, "--n-tau", "5").returncode == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["grid.vtu"] and old.read_bytes() != before


def test_a_crash_while_writing_a_fit_leaves_the_earlier_fit_whole(fitted, tmp_path):
    """`vcs fit` writes its files under temporary names and puts them in place together at the end:
    a refit killed while writing (VTK aborts at the file size limit) leaves the earlier fit's
    files as they were (not a new centerline.vtp beside an old model.json); the next run removes
    the dead run's temporary files."""
    _, mesh, _ = fitted
    out = tmp_path / "fit"
    assert run("fit", mesh, "-o", out, "--units", "cm", "--K", "7", "--R", "7").returncode == 0
    before = snapshot(out)
    r = run("fit", mesh, "-o", out, "--units", "cm", "--K", "5", "--R", "5", "--L", "12", preexec_fn=_limit_file_size)
    assert r.returncode != 0
    visible = {n: b for n, b in snapshot(out).items() if not n.startswith(".")}
    # VTK either aborts the process at the limit (no record) or reports the failed write, which
    # vcs fit then records as a failed refit (fit_failed.json, as a failed refit does): either
    # way every earlier file is there byte for byte
    record = visible.pop("fit_failed.json", None)
    if record is not None:
        rec = json.loads(record)
        kept = set(rec["kept_earlier_outputs"])
        assert "could not write" in rec["error"] and "model.json" in kept and kept <= set(before)
    assert visible == before
    assert run("fit", mesh, "-o", out, "--units", "cm", "--K", "5", "--R", "5").returncode == 0
    after = snapshot(out)
    assert sorted(after) == sorted(before) and after["model.json"] != before["model.json"]


def test_a_failed_refit_keeps_the_earlier_fit_and_says_so(fitted, tmp_path):
    """Issue 22: a fit, then a failed refit into the same folder: the earlier model.json & co. are
    kept byte for byte (still usable: `vcs wall` takes them) and fit_failed.json holds the error
    and what was kept; a later good fit removes the record. A file the earlier run wrote but the
    new run does not (residual_map.png) does not survive a successful run."""
    _, mesh, _ = fitted
    out = tmp_path / "fit"
    r = run("fit", mesh, "-o", out, "--units", "cm", "--K", "7", "--R", "7", "--residual-png")
    assert r.returncode == 0, r.stderr
    outputs = ["centerline.vtp", "fit_report.json", "model.json", "residual_map.png", "wall_residuals.vtp"]
    assert sorted(p.name for p in out.iterdir()) == outputs
    assert run("fit", mesh, "-o", out, "--units", "cm", "--K", "7", "--R", "7").returncode == 0
    assert sorted(p.name for p in out.iterdir()) == sorted(set(outputs) - {"residual_map.png"})
    r = run("fit", mesh, "-o", out, "--units", "cm", "--K", "7", "--R", "7", "--residual-png")
    assert r.returncode == 0, r.stderr
    before = snapshot(out)
    r = run("fit", mesh, "-o", out, "--units", "cm", "--inlet", "0,0,5", "--outlet", "0,0,5.01")
    msg = one_line_error(r, "vcs fit: error:")
    after = snapshot(out)
    assert {n: b for n, b in after.items() if n != "fit_failed.json"} == before
    record = json.loads(after["fit_failed.json"])
    assert record["error"] in msg and record["kept_earlier_outputs"] == outputs
    assert run("wall", out / "model.json", "-o", tmp_path / "w.stl").returncode == 0  # still usable
    r = run("fit", mesh, "-o", out, "--units", "cm", "--K", "7", "--R", "7")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == sorted(set(outputs) - {"residual_map.png"})


@pytest.mark.parametrize(("sig", "code"), [("SIGINT", 130), ("SIGTERM", 143), ("SIGKILL", -9)])
def test_an_interrupted_refit_keeps_the_earlier_fit_whole(tmp_path, sig, code):
    """Issue 22: Ctrl-C, SIGTERM (scancel, Snakemake) or SIGKILL (the out-of-memory killer) while
    a refit into a folder holding a good fit runs: every earlier file is still there byte for byte
    and `vcs wall` takes it; Ctrl-C and SIGTERM say so in one line and leave no temporary folder,
    a killed run's temporary folder is removed by the next run."""
    import signal
    import time

    from vcs.phantoms import make_phantom, write_stl

    write_stl(make_phantom("aorta", seed=0, resolution=1.0), tmp_path / "aorta.stl")  # ~2-4 s to fit
    out = tmp_path / "fit"
    assert run("fit", tmp_path / "aorta.stl", "-o", out, "--K", "11").returncode == 0
    before = snapshot(out)
    p = subprocess.Popen(
        [sys.executable, "-m", "vcs.cli", "fit", str(tmp_path / "aorta.stl"), "-o", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while not any(n.name.startswith(".fit.") for n in out.iterdir()) and p.poll() is None:
        assert time.monotonic() < deadline
        time.sleep(0.005)
    time.sleep(0.5)  # inside the fit
    assert p.poll() is None, "the refit ended before the signal"
    p.send_signal(getattr(signal, sig))
    _, err = p.communicate(timeout=120)
    assert p.returncode == code, (p.returncode, err)
    if sig != "SIGKILL":
        one_line_error(subprocess.CompletedProcess(p.args, p.returncode, "", err), "earlier outputs kept", code=code)
        assert snapshot(out) == before
    else:
        assert {n: b for n, b in snapshot(out).items() if not n.startswith(".")} == before
    assert run("wall", out / "model.json", "-o", tmp_path / "w.stl").returncode == 0
    assert run("fit", tmp_path / "aorta.stl", "-o", out, "--K", "11").returncode == 0
    assert sorted(snapshot(out)) == sorted(before)  # the dead run's temporary folder is gone


def test_a_failed_fit_into_a_new_folder_leaves_nothing(tmp_path):
    (tmp_path / "bad.stl").write_text("solid x\nendsolid x\n")
    one_line_error(run("fit", tmp_path / "bad.stl", "-o", tmp_path / "new"), "vcs fit: error:")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.stl"]


def test_a_failed_sweep_keeps_the_earlier_sweep(fitted, tmp_path):
    _, mesh, _ = fitted
    out = tmp_path / "s"
    argv = ["sensitivity", mesh, "--units", "cm", "--L", "5", "--K", "5", "--R", "5", "-o", out]
    assert run(*argv).returncode == 0
    before = snapshot(out)
    assert sorted(before) == ["sensitivity.csv", "sensitivity.png"]
    (tmp_path / "empty.stl").write_bytes(b"")
    one_line_error(run(*argv[:1], tmp_path / "empty.stl", *argv[2:]), "empty")
    after = snapshot(out)
    assert sorted(after) == ["sensitivity.csv", "sensitivity.png", "sensitivity_failed.json"]
    assert {n: after[n] for n in before} == before
    assert json.loads(after["sensitivity_failed.json"])["kept_earlier_outputs"] == sorted(before)


def test_an_input_inside_the_output_folder_is_never_removed(fitted, tmp_path):
    """`vcs fit` whose cap file is one of the folder's output names: refused before anything is
    touched (the output folder never holds an input)."""
    _, mesh, _ = fitted
    out = tmp_path / "fit"
    assert run("fit", mesh, "-o", out, "--units", "cm", "--K", "7", "--R", "7").returncode == 0
    before = snapshot(out)
    cap = out / "wall_residuals.vtp"
    r = run("fit", mesh, "-o", out, "--inlet-cap", cap, "--outlet-cap", cap)
    one_line_error(r, "also an input")
    assert snapshot(out) == before


def test_successful_runs_leave_no_temporary_files(fitted, tmp_path):
    _, mesh, model = fitted
    (tmp_path / "p.csv").write_text("x,y,z\n0,0,5\n")
    for argv in (
        ["fit", mesh, "-o", tmp_path / "f", "--units", "cm", "--K", "7", "--R", "7"],
        ["ends", mesh, "-o", tmp_path / "e.json"],
        ["coords", model, tmp_path / "p.csv", "-o", tmp_path / "c.csv"],
        ["cartesian", model, tmp_path / "c.csv", "-o", tmp_path / "x.csv"],
        ["wall", model, "-o", tmp_path / "w.stl"],
        ["grid", model, "-o", tmp_path / "g.vtu", "--n-tau", "4"],
        ["phantom", "--kind", "tube", "-o", tmp_path / "t.stl", "--params", tmp_path / "t.json"],
    ):
        r = run(*argv)
        assert r.returncode == 0, (argv, r.stderr)
    names = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert not [n for n in names if ".tmp" in n or Path(n).name.startswith(".")], names
    assert {"c.csv", "e.json", "f/model.json", "g.vtu", "t.json", "t.stl", "w.stl", "x.csv"} <= set(names)


def test_ctrl_c_during_a_fit_leaves_nothing_half_done(tmp_path):
    """SIGINT once `vcs fit` has created its (new) output folder, i.e. while it fits: exit 130, one
    line, and the folder is gone again (no temporary file, no partial fit)."""
    import signal
    import time

    from vcs.phantoms import make_phantom, write_stl

    write_stl(make_phantom("aorta", seed=0, resolution=1.0), tmp_path / "aorta.stl")  # ~1-2 s to fit
    out = tmp_path / "fit"
    p = subprocess.Popen(
        [sys.executable, "-m", "vcs.cli", "fit", str(tmp_path / "aorta.stl"), "-o", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # SIGINT at its default even when the suite runs as a background job (ignored there)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while not out.exists() and p.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    r = subprocess.CompletedProcess(p.args, p.returncode, "", err)
    one_line_error(r, "vcs fit: interrupted", code=130)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["aorta.stl"]
