"""Shared fixtures for the vcs tests: analytic tubes with exactly known coordinates."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "vessels"


def sweep(center, frame1, frame2, radius, n_s, n_phi):
    """Tube vertices c(s) + r (cos phi f1 + sin phi f2) on a regular (s, phi) grid, open ends."""
    s = np.linspace(0.0, 1.0, n_s)
    phi = np.linspace(0, 2 * np.pi, n_phi, endpoint=False)
    c, f1, f2 = center(s), frame1(s), frame2(s)
    V = c[:, None] + radius * (np.cos(phi)[None, :, None] * f1[:, None] + np.sin(phi)[None, :, None] * f2[:, None])
    idx = np.arange(n_s * n_phi).reshape(n_s, n_phi)
    a, b = idx[:-1], idx[1:]
    a2, b2 = np.roll(a, -1, 1), np.roll(b, -1, 1)
    F = np.concatenate([np.stack([a, b, b2], -1).reshape(-1, 3), np.stack([a, b2, a2], -1).reshape(-1, 3)])
    return V.reshape(-1, 3), F


class Helix:
    """c(t) = (a cos t, a sin t, b t), t in [0, T]; exact arc length, Frenet frame and torsion."""

    def __init__(self, a=20.0, pitch=50.0, turns=1.5, r=5.0):
        self.a, self.b, self.T, self.r = a, pitch / (2 * np.pi), 2 * np.pi * turns, r
        self.speed = np.hypot(self.a, self.b)
        self.length = self.speed * self.T
        self.torsion = self.b / self.speed**2

    def c(self, s):
        t = np.asarray(s) * self.T
        return np.stack([self.a * np.cos(t), self.a * np.sin(t), self.b * t], -1)

    def tangent(self, s):
        t = np.asarray(s) * self.T
        return np.stack([-self.a * np.sin(t), self.a * np.cos(t), np.full_like(t, self.b)], -1) / self.speed

    def normal(self, s):
        t = np.asarray(s) * self.T
        return np.stack([-np.cos(t), -np.sin(t), np.zeros_like(t)], -1)

    def binormal(self, s):
        return np.cross(self.tangent(s), self.normal(s))

    def rmf(self, s, phi0):
        """Exact rotation-minimising v1: cos(phi) N + sin(phi) B with phi = phi0 - torsion * arc."""
        phi = phi0 - self.torsion * np.asarray(s) * self.length
        return np.cos(phi)[..., None] * self.normal(s) + np.sin(phi)[..., None] * self.binormal(s)


@pytest.fixture(scope="session")
def helix():
    return Helix()


@pytest.fixture(scope="session")
def shared_data():
    if not DATA.is_dir():
        pytest.skip(f"real vessel meshes not available ({DATA} is absent)")
    return DATA


def vcs_in_process(*args):
    """`vcs ARGS` run in this process (no interpreter start-up: ~50x faster than a subprocess for
    argument and path errors): a CompletedProcess with the exit code, stdout and stderr; argparse's
    SystemExit is caught like a process exit. An exception escaping main() is a failure of the test."""
    import contextlib
    import io
    import subprocess

    from vcs.cli import main

    out, err = io.StringIO(), io.StringIO()
    argv = [str(a) for a in args]
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    return subprocess.CompletedProcess(argv, code, out.getvalue(), err.getvalue())
