"""Property-based tests of the `vcs` command line (hypothesis): random small meshes, random point
tables and random argument strings never give a traceback or an internal error (exit 1). Every run
ends with exit 0, or exit 2 and one line on stderr; the inputs are unchanged, and a failed run
leaves nothing behind in its working folder.

Runs `vcs` in this process (tests/vcs/conftest.py: vcs_in_process) so that an example costs
milliseconds, not an interpreter start-up; derandomised (the same examples on every run, no
example database), no deadline (a fit takes ~0.1-1 s), a modest number of examples per property.
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np
import pytest
from conftest import vcs_in_process

# hypothesis is in the test extra (scripts/install.sh installs it): a missing one is an error, not a skip
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

SETTINGS = {
    "deadline": None,
    "derandomize": True,
    "database": None,
    "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
    "print_blob": False,
}


def state(workdir: Path) -> tuple[dict[str, bytes], list[str]]:
    """Every file under ``workdir`` with its bytes, and every path (files and folders)."""
    paths = sorted(workdir.rglob("*"))
    files = {str(p.relative_to(workdir)): p.read_bytes() for p in paths if p.is_file()}
    return files, [str(p.relative_to(workdir)) for p in paths]


def check(r, workdir: Path, before: tuple[dict[str, bytes], list[str]], inputs: list[Path]) -> None:
    """The properties of one run: exit 0 or 2, one line for 2, no traceback, inputs unchanged,
    nothing left behind (not even a folder) by a failure."""
    event(f"exit {r.returncode}")
    assert r.returncode in (0, 2), (r.args, r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and "internal error" not in r.stderr, (r.args, r.stderr)
    after = state(workdir)
    if r.returncode == 2:
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "error" in lines[0], (r.args, r.stderr)
        assert after == before, (r.args, r.stderr, sorted(set(after[1]) ^ set(before[1])))
    else:
        assert r.stdout.strip(), r.args
    for p in inputs:
        name = str(p.relative_to(workdir))
        assert after[0].get(name) == before[0][name], (r.args, p)


# ---------------------------------------------------------------------------------------------
# strategies


@st.composite
def meshes(draw):
    """(kind, vertices (N, 3), faces (M, 3)) of a small surface, or raw bytes of a broken file."""
    kind = draw(st.sampled_from(["tube"] * 6 + ["soup", "bytes", "empty", "nan", "flat"]))
    if kind == "bytes":
        return kind, draw(st.binary(min_size=1, max_size=200)), None
    if kind == "empty":
        return kind, b"", None
    if kind == "soup":
        n = draw(st.integers(1, 12))
        v = np.array(draw(st.lists(st.tuples(*[st.floats(-50, 50)] * 3), min_size=3 * n, max_size=3 * n)))
        return kind, v, np.arange(3 * n).reshape(n, 3)
    n_s, n_phi = draw(st.one_of(st.integers(2, 6), st.integers(12, 40))), draw(st.integers(3, 32))
    radius = draw(st.floats(0.5, 20.0))
    length = draw(st.floats(1.0, 150.0))
    bend = draw(st.floats(0.0, 1.0))
    s = np.linspace(0.0, 1.0, n_s)
    phi = np.linspace(0, 2 * np.pi, n_phi, endpoint=False)
    c = np.stack([bend * length * np.sin(np.pi * s) / 2, 0 * s, length * s], -1)
    v = c[:, None] + radius * np.stack([np.cos(phi), np.sin(phi), 0 * phi], -1)[None]
    idx = np.arange(n_s * n_phi).reshape(n_s, n_phi)
    a, b = idx[:-1], idx[1:]
    a2, b2 = np.roll(a, -1, 1), np.roll(b, -1, 1)
    f = np.concatenate([np.stack([a, b, b2], -1).reshape(-1, 3), np.stack([a, b2, a2], -1).reshape(-1, 3)])
    v = v.reshape(-1, 3)
    if kind == "nan":
        v[draw(st.integers(0, len(v) - 1))] = np.nan
    if kind == "flat":
        v[:, 1] = 0.0  # every triangle degenerate or in one plane
    flip = draw(st.lists(st.integers(0, len(f) - 1), max_size=5))
    f[flip] = f[flip][:, ::-1]
    scale = draw(st.sampled_from([1.0, 1.0, 0.1, 0.001, 1000.0]))
    return kind, v * scale, f


def write_mesh(mesh, path: Path) -> None:
    import trimesh

    kind, v, f = mesh
    if f is None:
        path.write_bytes(v)
        return
    file_type = path.suffix[1:] if path.suffix in (".stl", ".ply", ".obj") else "stl"  # .xyz: STL inside
    trimesh.Trimesh(v, f, process=False).export(path, file_type=file_type)


@st.composite
def point_tables(draw):
    """A points file body for `vcs coords`/`vcs cartesian`: (suffix, bytes)."""
    n, k = draw(st.integers(0, 5)), draw(st.sampled_from([3, 3, 3, 1, 2, 4, 5]))
    values = draw(
        st.lists(
            st.one_of(st.floats(-100, 100), st.floats(-100, 100), st.sampled_from([np.nan, np.inf, -np.inf, 0.0])),
            min_size=n * k,
            max_size=n * k,
        )
    )
    a = np.array(values, dtype=float).reshape(n, k)
    form = draw(st.sampled_from(["csv_xyz", "csv_coords", "csv_xyz", "csv_coords", "csv_other", "npy", "text"]))
    if form == "npy":
        buf = io.BytesIO()
        np.save(buf, a)
        return ".npy", buf.getvalue()
    if form == "text":
        return ".csv", draw(st.text(max_size=60)).encode("utf-8", "surrogatepass")
    header = {"csv_xyz": "x,y,z,w,q", "csv_coords": "tau,theta,rho,a,b", "csv_other": "a,b,c,d,e"}[form]
    header = ",".join(header.split(",")[:k])
    body = "\n".join(",".join(repr(float(x)) for x in row) for row in a)
    return ".csv", (header + "\n" + body + ("\n" if n else "")).encode()


# values an option may get: in range, out of range, not a number, not finite, text
NUMBERS = st.one_of(
    st.sampled_from(["-1", "-3", "0", "1", "1.5", "nan", "inf", "-inf", "1e3", "", "abc", "2:4:1", "-0.5"]),
    st.integers(-3, 40).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
)
POINTS = st.one_of(
    st.sampled_from(["0,0,0", "0,0,50", "end:0", "end:1", "end:9", "ModelFaceID=1", "1,2", "a,b,c", "-5,0,0"]),
    st.lists(st.floats(-100, 100), min_size=3, max_size=3).map(lambda p: ",".join(f"{x:g}" for x in p)),
)
# words with line breaks of every kind (a message must stay one line), signs, and any other character
NASTY = ["a\nb", "x\ry", "\u2028", "\x85z", "tab\tword", "--", "-", "=", "-1", "--inlet", "é ü", "a b"]
TEXT = st.one_of(
    st.sampled_from(NASTY),
    st.text(
        alphabet=st.one_of(
            st.sampled_from("\n\r\x0b\x0c\x1c\x85\u2028 -=,:/."),
            st.characters(blacklist_characters="\x00", blacklist_categories=("Cs",)),
        ),
        max_size=12,
    ),
)

OPTIONS = {
    "fit": {
        "--units": st.sampled_from(["auto", "mm", "cm", "m", "inch"]),
        "--inlet": POINTS,
        "--outlet": POINTS,
        "--L": st.sampled_from(["auto", "9", "0", "-2", "30", "x"]),
        "--K": st.sampled_from(["3", "7", "19", "0", "x"]),
        "--R": st.sampled_from(["3", "7", "15", "0", "-1"]),
        "--recentre": st.sampled_from(["0", "1", "3", "-1"]),
        "--cap-array": st.sampled_from(["auto", "none", "ModelFaceID", "nope"]),
        "--residual-png": None,
    },
    "ends": {"--units": st.sampled_from(["auto", "mm", "cm", "m"]), "--cap-array": st.sampled_from(["auto", "none"])},
    "wall": {
        "--n-tau": NUMBERS,
        "--n-theta": NUMBERS,
        "--extend-inlet": NUMBERS,
        "--extend-outlet": NUMBERS,
        "--units": st.sampled_from(["mm", "cm", "m", "km"]),
    },
    "grid": {
        "--n-tau": NUMBERS,
        "--n-theta": NUMBERS,
        "--n-rho": NUMBERS,
        "--scheme": st.sampled_from(["cylindrical", "ogrid", "polar"]),
        "--units": st.sampled_from(["mm", "cm", "m"]),
    },
    "phantom": {
        "--kind": st.sampled_from(["aorta", "tube", "torus", "helix", "cube"]),
        "--seed": NUMBERS,
        "--resolution": st.sampled_from(["0", "-1", "nan", "inf", "0.05", "3", "8", "50", "1e9", "x"]),
        "--overwrite": None,
    },
    "coords": {},
    "cartesian": {},
}
COMMANDS = {"fit", "ends", "coords", "cartesian", "wall", "grid", "phantom", "sensitivity"}
# wall/grid sizes that are numbers are kept small (a property test is not a memory test)
SMALL = {"--n-tau", "--n-theta", "--n-rho"}


# values within range, for the "clean" half of the examples (which mostly succeed)
CLEAN = {
    "fit": {
        "--units": st.sampled_from(["auto", "mm"]),
        "--L": st.sampled_from(["auto", "9", "12"]),
        "--K": st.sampled_from(["4", "5", "7", "19"]),
        "--R": st.sampled_from(["4", "5", "7", "15"]),
        "--recentre": st.sampled_from(["0", "1", "3"]),
        "--cap-array": st.sampled_from(["auto", "none"]),
        "--residual-png": None,
        "-v": None,
    },
    "ends": {"--units": st.sampled_from(["auto", "mm"]), "-v": None},
    "wall": {
        "--n-tau": st.integers(1, 30).map(str),
        "--n-theta": st.integers(8, 40).map(str),
        "--extend-inlet": st.sampled_from(["0", "0.5", "2"]),
        "--extend-outlet": st.sampled_from(["0", "1", "3.5"]),
        "--units": st.sampled_from(["mm", "cm", "m"]),
    },
    "grid": {
        "--n-tau": st.integers(2, 30).map(str),
        "--n-theta": st.integers(4, 30).map(str),
        "--n-rho": st.integers(2, 8).map(str),
        "--scheme": st.sampled_from(["cylindrical", "ogrid"]),
        "--units": st.sampled_from(["mm", "cm", "m"]),
    },
    "phantom": {
        "--kind": st.sampled_from(["tube", "torus", "helix"]),
        "--seed": st.integers(0, 5).map(str),
        "--resolution": st.sampled_from(["3", "5", "8"]),
        "--overwrite": None,
    },
    "coords": {"-v": None},
    "cartesian": {"-v": None},
}


@st.composite
def option_tokens(draw, command: str):
    """Half the time a few options of ``command`` with values in range; otherwise also options
    of another command, abbreviated or misspelt ones, values out of range, stray words, -v."""
    tokens: list[str] = []
    clean = draw(st.booleans())
    table = CLEAN[command] if clean else OPTIONS[command]
    for _ in range(draw(st.integers(0, 4))):
        choice = "own" if clean else draw(st.sampled_from(["own", "own", "other", "abbrev", "stray", "verbose"]))
        if choice == "own" and table:
            opt = draw(st.sampled_from(sorted(table)))
            tokens.append(opt)
            if table[opt] is not None:
                value = draw(
                    table[opt] if clean or opt not in CLEAN[command] else st.one_of(table[opt], CLEAN[command][opt])
                )
                if opt in SMALL and value.lstrip("-").isdigit() and int(value) > 40:
                    value = "40"
                if draw(st.booleans()):
                    tokens[-1] = f"{opt}={value}"
                else:
                    tokens.append(value)
        elif choice == "other":
            tokens += [draw(st.sampled_from(["--K", "--n-rho", "--seed", "--kind", "--scheme"])), "3"]
        elif choice == "abbrev":
            tokens += [draw(st.sampled_from(["--outp", "--rec", "--ext", "--n-t", "--verb", "--over"])), "1"]
        elif choice == "stray":
            tokens.append(draw(TEXT))
        else:
            tokens.append("-v")
    return tokens


OUTPUTS = st.sampled_from(["good"] * 6 + ["wrong_ext", "adir", "afile", "under_file", "missing_parent", "input"])


def output_path(kind: str, workdir: Path, ext: str, input_path: Path) -> str:
    return {
        "good": str(workdir / f"out{ext}"),
        "wrong_ext": str(workdir / "out.xyz") if ext else str(workdir / "afile"),
        "adir": str(workdir / "adir"),
        "afile": str(workdir / "afile"),
        "under_file": str(workdir / "afile" / f"out{ext}"),
        "missing_parent": str(workdir / "no" / "such" / f"out{ext}"),
        "input": str(input_path),
    }[kind]


def new_workdir(tmp: str) -> Path:
    w = Path(tmp)
    (w / "adir").mkdir()
    (w / "afile").write_text("x\n")
    return w


@pytest.fixture(scope="module")
def tube_stl(tmp_path_factory):
    """STL bytes of the tube phantom (r 10 mm, 100 mm long along z, 4 mm triangles)."""
    from vcs.phantoms import make_phantom, write_stl

    d = tmp_path_factory.mktemp("props")
    write_stl(make_phantom("tube", resolution=4.0), d / "tube.stl")
    return (d / "tube.stl").read_bytes()


@pytest.fixture(scope="module")
def model_json(tmp_path_factory, tube_stl):
    """model.json of the fitted tube, for coords/cartesian/wall/grid."""
    d = tmp_path_factory.mktemp("props")
    (d / "tube.stl").write_bytes(tube_stl)
    r = vcs_in_process("fit", d / "tube.stl", "-o", d / "fit", "--units", "mm", "--K", "5", "--R", "5")
    assert r.returncode == 0, r.stderr
    return (d / "fit" / "model.json").read_bytes()


# ---------------------------------------------------------------------------------------------
# properties


@settings(max_examples=30, **SETTINGS)
@given(
    mesh=meshes(),
    ext=st.sampled_from([".stl", ".ply", ".obj"]),
    command=st.sampled_from(["fit", "fit", "ends"]),
    knots=st.sampled_from([[], ["--K", "5", "--R", "5"], ["--K", "3", "--R", "4"]]),
    units=st.sampled_from(["auto", "mm"]),
)
def test_fit_and_ends_on_random_meshes(mesh, ext, command, knots, units):
    """Random surfaces (tubes of any size, resolution and scale, some with a NaN vertex, flipped
    triangles or flat; triangle soups; random bytes; empty files), good arguments."""
    with tempfile.TemporaryDirectory() as tmp:
        w = new_workdir(tmp)
        path = w / f"mesh{ext}"
        write_mesh(mesh, path)
        out = str(w / ("out" if command == "fit" else "out.json"))
        # a coarse random tube has too few vertices for the default 19 x 15 wall knots: mostly fewer
        argv = [command, str(path), "-o", out, "--units", units, *(knots if command == "fit" else [])]
        before = state(w)
        check(vcs_in_process(*argv), w, before, [path])


@settings(max_examples=40, **SETTINGS)
@given(command=st.sampled_from(["fit", "fit", "ends"]), data=st.data())
def test_fit_and_ends_on_random_arguments(tube_stl, command, data):
    """A good tube, random options and output paths."""
    with tempfile.TemporaryDirectory() as tmp:
        w = new_workdir(tmp)
        path = w / "tube.stl"
        path.write_bytes(tube_stl)
        out = output_path(data.draw(OUTPUTS), w, "" if command == "fit" else ".json", path)
        argv = [command, str(path), "-o", out, *data.draw(option_tokens(command))]
        before = state(w)
        check(vcs_in_process(*argv), w, before, [path])


@settings(max_examples=40, **SETTINGS)
@given(table=point_tables(), command=st.sampled_from(["coords", "cartesian"]), data=st.data())
def test_coords_and_cartesian_on_random_points(model_json, table, command, data):
    with tempfile.TemporaryDirectory() as tmp:
        w = new_workdir(tmp)
        model = w / "model.json"
        model.write_bytes(model_json)
        suffix, body = table
        pts = w / f"points{suffix}"
        pts.write_bytes(body)
        out = output_path(data.draw(OUTPUTS), w, ".csv", pts)
        argv = [command, str(model), str(pts), "-o", out, *data.draw(option_tokens(command))]
        before = state(w)
        check(vcs_in_process(*argv), w, before, [model, pts])


@settings(max_examples=60, **SETTINGS)
@given(command=st.sampled_from(["wall", "grid", "phantom"]), data=st.data())
def test_wall_grid_phantom_on_random_arguments(model_json, command, data):
    with tempfile.TemporaryDirectory() as tmp:
        w = new_workdir(tmp)
        model = w / "model.json"
        model.write_bytes(model_json)
        ext = {"wall": ".stl", "grid": ".vtu", "phantom": ".stl"}[command]
        out = output_path(data.draw(OUTPUTS), w, ext, model)
        head = [command] if command == "phantom" else [command, str(model)]
        argv = [*head, "-o", out, *data.draw(option_tokens(command))]
        if command == "phantom" and "--kind" not in " ".join(argv) and not data.draw(st.booleans()):
            argv += ["--kind", "tube"]  # the aorta (default) takes a second: keep most examples quick
        before = state(w)
        check(vcs_in_process(*argv), w, before, [model])


@settings(max_examples=100, **SETTINGS)
@given(
    words=st.lists(
        st.one_of(
            TEXT,
            st.sampled_from(sorted(COMMANDS)),
            st.sampled_from(["-o", "-v", "--help"]),
            st.sampled_from(["--units", "--K", "--n-tau", "--inlet", "--seed", "-", "--", "-1", "=", "--o"]),
        ),
        max_size=6,
    )
)
def test_random_argument_strings(words):
    """Any words at all: argparse errors, help (exit 0), a command that fails on a missing input,
    or now and then one that succeeds (`phantom -o x`); never a traceback."""
    with tempfile.TemporaryDirectory() as tmp:
        w = new_workdir(tmp)
        # every other word is a path inside the temporary folder (nothing is written elsewhere)
        argv = [
            x if not x or x.startswith("-") or x in COMMANDS else str(w / x.replace("/", "_").replace(".", "_"))
            for x in words
        ]
        before = state(w)
        check(vcs_in_process(*argv), w, before, [])


def _quick(option: str, value: str) -> bool:
    """Leave out the in-range values that only make a run slow (a property test is not a load
    test): phantom edges below 0.5 mm (millions of triangles), extensions of 10-100 diameters."""
    try:
        v = float(value)
    except ValueError:
        return True
    if option == "--resolution":
        return not 0.1 <= v < 0.5
    if option.startswith("--extend"):
        return not 10 < v <= 100
    return True


NUMERIC = [
    ("phantom", "--seed"),
    ("phantom", "--resolution"),
    ("wall", "--n-tau"),
    ("wall", "--n-theta"),
    ("wall", "--extend-inlet"),
    ("wall", "--extend-outlet"),
    ("grid", "--n-tau"),
    ("grid", "--n-theta"),
    ("grid", "--n-rho"),
    ("fit", "--K"),
    ("fit", "--R"),
    ("fit", "--L"),
    ("fit", "--recentre"),
]


@settings(max_examples=80, **SETTINGS)
@given(pair=st.sampled_from(NUMERIC), value=NUMBERS, joined=st.booleans())
def test_any_value_of_a_numeric_option(model_json, tube_stl, pair, value, joined):
    """Every numeric option, any value (negative, zero, huge, NaN, infinite, not a number):
    exit 0 or 2 with one line; the phantom is the default aorta, where a negative seed reaches
    numpy."""
    command, option = pair
    assume(_quick(option, value))
    with tempfile.TemporaryDirectory() as tmp:
        w = new_workdir(tmp)
        (w / "model.json").write_bytes(model_json)
        (w / "tube.stl").write_bytes(tube_stl)
        head = {
            "phantom": ["phantom", "-o", str(w / "p.stl"), "--resolution", "4"],
            "wall": ["wall", str(w / "model.json"), "-o", str(w / "w.stl")],
            "grid": ["grid", str(w / "model.json"), "-o", str(w / "g.vtu")],
            "fit": ["fit", str(w / "tube.stl"), "-o", str(w / "f"), "--units", "mm", "--K", "5", "--R", "5"],
        }[command]
        argv = [*head, *([f"{option}={value}"] if joined else [option, value])]
        before = state(w)
        check(vcs_in_process(*argv), w, before, [w / "model.json", w / "tube.stl"])
