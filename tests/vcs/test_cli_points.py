"""Points on the `vcs` command line (issue 10): a value may start with a minus sign after a space,
carry blanks, or be split by the shell at its commas; real scanner coordinates are mostly negative."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import sweep


def run(*args):
    return subprocess.run([sys.executable, "-m", "vcs.cli", *map(str, args)], capture_output=True, text=True)


SHIFT = np.array([-212.5, -40.0, -1250.0])  # real scanner coordinates are mostly negative


@pytest.mark.parametrize(
    "given, expected",
    [
        (["--inlet", "-40,0,0"], "-40,0,0"),
        (["--inlet=-40,0,0"], "-40,0,0"),
        (["--inlet", "-40, 0, 0"], "-40, 0, 0"),
        (["--inlet", " -40,0,0"], " -40,0,0"),
        (["--inlet", "-.5,-1e-3,-2"], "-.5,-1e-3,-2"),
        (["--inlet", "end:0"], "end:0"),
        (["--inlet", "40,0,0"], "40,0,0"),
        (["--inlet", "-40,", "0,", "0"], "-40,0,0"),  # unquoted "-40, 0, 0": three shell words
        (["--inlet", "40,", "-1,", "-2"], "40,-1,-2"),
        (["--inlet=-40,", "0,", "-0.5"], "-40,0,-0.5"),
    ],
)
def test_point_options_accept_a_leading_minus_sign(given, expected):
    from vcs.cli.main import parse_args

    args = parse_args(["fit", "m.stl", "-o", "out", *given, "--outlet", "-1,-2,-3"])
    assert args.inlet == expected and args.outlet == "-1,-2,-3"


@pytest.fixture(scope="module")
def negative_tube_stl(tmp_path_factory):
    """The tube of ``tube_stl`` moved to negative coordinates (mm): ends at SHIFT and SHIFT + (~9, 0, 100)."""
    import trimesh

    c = lambda s: np.stack([10 * np.sin(2 * s), 0 * s, 100 * s], -1)  # noqa: E731
    ex = lambda s: np.tile([1.0, 0, 0], (len(s), 1))  # noqa: E731
    ey = lambda s: np.tile([0, 1.0, 0], (len(s), 1))  # noqa: E731
    V, F = sweep(c, ex, ey, 8.0, 80, 40)
    path = tmp_path_factory.mktemp("negative") / "tube.stl"
    trimesh.Trimesh(V + SHIFT, F, process=False).export(path)
    return path


def test_fit_with_negative_points_after_a_space(negative_tube_stl, tmp_path):
    """`vcs fit MESH --inlet -212.5,-40,-1250 --outlet "x, y, z"` works (argparse alone refuses it);
    the points choose the ends: here the outlet is the loop at z = -1250, so tau runs backwards."""
    top = SHIFT + [10 * np.sin(2.0), 0, 100]
    inlet = ",".join(f"{v:g}" for v in top)  # "-203.407,-40,-1150"
    outlet = ", ".join(f"{v:g}" for v in SHIFT)  # "-212.5, -40, -1250"
    r = run("fit", negative_tube_stl, "-o", tmp_path / "f", "--units", "mm", "--inlet", inlet, "--outlet", outlet)
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "f" / "fit_report.json").read_text())
    assert np.linalg.norm(np.array(rep["inlet"]["center_mm"]) - top) < 1.0
    assert np.linalg.norm(np.array(rep["outlet"]["center_mm"]) - SHIFT) < 1.0
