"""Pulsatile flow with the real OpenFOAM (ESI): Womersley flow in a straight rigid tube.

The truth is the analytic Womersley solution of the waveform's Fourier series
(:mod:`vcs.cfd.womersley`): the centreline velocity and the wall shear stress over the cycle
(amplitude and phase), TAWSS and OSI (flow reversal in the waveform), OSI = 0 for a steady flow
and 0.5 for a zero-mean oscillation; the markers accumulated by fieldAverage at every time step
against the every-step record of the area-mean |WSS|. CI-sized meshes; the convergence with the
mesh is bench/pulsatile_womersley.py's.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from vcs.cfd import detect_openfoam, render_case, run_case
from vcs.cfd.foamfiles import function_table
from vcs.cfd.verification import harmonic_errors
from vcs.cfd.waveform import load_waveform
from vcs.cfd.womersley import centreline_velocity, tawss_osi, wall_shear_stress
from vcs.phantoms.analytic import write_closed_tube_stl

HAVE_FOAM = shutil.which("pimpleFoam") is not None and detect_openfoam()[0] == "esi"
needs_foam = pytest.mark.skipif(not HAVE_FOAM, reason="Debian's ESI OpenFOAM (pimpleFoam) not installed")

R = 0.005  # tube radius [m]
LENGTH = 0.05  # [m]
AXIS = np.array([0.0, 0.0, 1.0])
NU = 3.37e-6
PERIOD = 0.4  # [s]: Womersley number R sqrt(2 pi / (T nu)) = 10.8
Q0 = 2.0e-6  # mean flow [m3/s] (mean velocity 2.5 cm/s)


def write_waveform(path: Path, mean: float, amplitude: float, n: int = 200) -> Path:
    """A CSV of one cycle of Q(t) = mean + amplitude sin(2 pi t / T) (closed: the last row repeats
    the first)."""
    t = np.linspace(0.0, PERIOD, n + 1)
    q = (mean + amplitude * np.sin(2 * np.pi * t / PERIOD)) * 6e4
    q[-1] = q[0]
    rows = "\n".join(f"{a:.8g},{b:.10g}" for a, b in zip(t, q))
    path.write_text(
        f"# test waveform: {mean} + {amplitude} sin(2 pi t / {PERIOD}) m3/s\ntime_s,flow_rate_l_min\n{rows}\n"
    )
    return path


def pulsatile_cfd(waveform: Path, cell: float, **pulsatile) -> dict:
    return {
        "mesh": {"cell_size": cell, "layers": 2},
        "physics": {"nu": NU},
        "inlet": {"type": "parabolic", "waveform": str(waveform), "scaling": "fixed"},
        "pulsatile": {
            "profile": "womersley",
            "cycles": 3,
            "discard_cycles": 1,
            "max_cycles": 4,
            "periodicity_tolerance": 0.02,
            "tawss_tolerance": 0.02,
            "samples_per_cycle": 80,
            "probes": [[0.0, 0.0, LENGTH / 2]],
            **pulsatile,
        },
    }


def run_tube(
    tmp: Path, name: str, mean: float, amplitude: float, cell: float = 7.5e-4, **pulsatile
) -> tuple[Path, dict]:
    stl = write_closed_tube_stl(tmp / f"{name}.stl", radius=R, length=LENGTH, n_theta=96, n_z=40, axis=AXIS)
    wf = write_waveform(tmp / f"{name}.csv", mean, amplitude)
    case = tmp / name
    render_case(case, stl, pulsatile_cfd(wf, cell, **pulsatile), flavour="esi")
    return case, run_case(case, ranks=1)


@pytest.fixture(scope="module")
def reversing(tmp_path_factory):
    """A waveform with flow reversal: Q = Q0 (1 + 1.5 sin wt)."""
    tmp = tmp_path_factory.mktemp("womersley")
    case, st = run_tube(tmp, "rev", Q0, 1.5 * Q0)
    return case, st, load_waveform(tmp / "rev.csv")


def _last_cycle(record: np.ndarray, st: dict) -> tuple[np.ndarray, np.ndarray]:
    """(time in the cycle, values) of the last kept cycle of an every-step record."""
    t1 = st["pulsatile"]["window"][1]
    t0 = t1 - PERIOD
    m = (record[:, 0] > t0 + 1e-9) & (record[:, 0] <= t1 + 1e-9)
    return record[m, 0] - t0, record[m, 1:]


@pytest.mark.openfoam
@needs_foam
def test_womersley_tube_against_the_analytic_solution(reversing):
    case, st, wf = reversing
    assert st["converged"], st["reason"]
    pu = st["pulsatile"]
    assert pu["periodic"] and pu["cycles_run"] <= 4
    assert st["inlet"]["type"] == "timeVaryingMappedFixedValue" and st["inlet"]["flux_error_rel"] < 1e-6
    coeffs = wf.fourier(10)
    # centreline velocity over the last cycle, at mid-length (probe), against Womersley
    t, u = _last_cycle(function_table(case, "probes", "U"), st)
    e = harmonic_errors(t, u @ AXIS, centreline_velocity(t, coeffs, PERIOD, R, NU), PERIOD)
    assert abs(e["mean_rel"]) < 0.05 and abs(e["amplitude_rel"]) < 0.05 and abs(e["phase_deg"]) < 5, e
    # the wall shear stress over the cycle: the area-mean WSS vector on the wall at every time step
    # (developed Womersley flow: uniform, axial, signed; OpenFOAM's wallShearStress is the stress on
    # the fluid, opposite the near-wall flow: minus it is the shear along the flow), and |WSS|
    t, w = _last_cycle(function_table(case, "wss_wall"), st)
    exact = wall_shear_stress(t, coeffs, PERIOD, R, NU)
    e = harmonic_errors(t, -(w[:, 1:4] @ AXIS), exact, PERIOD)
    assert abs(e["mean_rel"]) < 0.08 and abs(e["amplitude_rel"]) < 0.08 and abs(e["phase_deg"]) < 5, e
    assert e["max_rel"] < 0.1, e
    assert np.abs(w[:, 0] - np.abs(exact)).max() < 0.1 * np.abs(exact).max()
    # TAWSS and OSI over the kept cycles (accumulated every time step by fieldAverage)
    tawss_ex, osi_ex = tawss_osi(coeffs, PERIOD, R, NU)
    assert osi_ex > 0.2  # the waveform reverses: the wall shear reverses for part of the cycle
    assert st["tawss_Pa"]["mean"] == pytest.approx(tawss_ex * st["rho"], rel=0.08)
    assert st["osi"]["mean"] == pytest.approx(osi_ex, abs=0.03)


@pytest.mark.openfoam
@needs_foam
def test_accumulated_markers_match_the_every_step_records(reversing):
    """The fieldAverage accumulation behind TAWSS and OSI against the every-step records of the
    same quantities, integrated densely (trapezoid over every time step of the kept cycles): the
    area mean of a time mean is the time mean of the area mean, for |WSS| (TAWSS) and for the WSS
    vector (the numerator of OSI)."""
    from vcs.cfd.status import _wall_faces, _wall_values

    case, st, _ = reversing
    t0, t1 = st["pulsatile"]["window"]
    rec = function_table(case, "wss_wall")
    m = (rec[:, 0] >= t0 - 1e-9) & (rec[:, 0] <= t1 + 1e-9)
    dense = np.trapezoid(rec[m, 1:], rec[m, 0], axis=0) / (t1 - t0)
    assert st["tawss_Pa"]["mean"] / st["rho"] == pytest.approx(dense[0], rel=0.01)
    state = json.loads((case / "vcsflow_case.json").read_text())
    walls = _wall_faces(case, state)
    area = np.concatenate([a for _, a in walls])
    mean_vec = np.mean([_wall_values(case / t, "wallShearStressMean", walls) for t in st["pulsatile"]["mean_times"]], 0)
    accumulated = (mean_vec * area[:, None]).sum(0) / area.sum()
    assert np.linalg.norm(accumulated - dense[1:4]) < 0.01 * np.linalg.norm(dense[1:4])


@pytest.mark.openfoam
@needs_foam
def test_osi_is_zero_for_a_steady_flow_and_half_for_a_zero_mean_oscillation(tmp_path):
    """OSI from the accumulated wall shear: 0 when the shear never reverses, 1/2 when it spends
    as much of the cycle one way as the other. Neither needs a periodic state (a steady flow from
    rest is still developing after two cycles here: R^2/nu = 7 s), so a short run does."""
    fast = {"cycles": 2, "max_cycles": 2, "periodicity_tolerance": 1.0, "tawss_tolerance": 1.0}
    fast |= {"probes": [], "min_steps_per_cycle": 50}
    _, steady = run_tube(tmp_path, "steady", Q0, 0.0, cell=1.0e-3, **fast)
    assert steady["pulsatile"]["evaluated"], steady["reason"]
    assert steady["osi"]["max"] < 1e-3
    _, osc = run_tube(tmp_path, "osc", 0.0, 2 * Q0, cell=1.0e-3, **fast)
    assert osc["pulsatile"]["evaluated"], osc["reason"]
    assert osc["osi"]["mean"] == pytest.approx(0.5, abs=0.03)


@pytest.mark.openfoam
@needs_foam
def test_pulsatile_fields_on_the_vcs_grid(reversing, tmp_path):
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "vcs"))
    from test_resample import straight_model

    from vcs.cfd import sample_pulsatile

    case, st, wf = reversing
    model = straight_model(radius_mm=R * 1e3, length_mm=LENGTH * 1e3, axis=AXIS)
    f = sample_pulsatile(case, model, st["pulsatile"], n_tau=12, n_theta=8, n_rho=5, rho_density=st["rho"])
    assert str(f["field_source"]) == "pulsatile"
    for key in ("TAWSS", "OSI", "RRT", "ECAP"):
        assert f[key].shape == (12, 8)
    tawss_ex, osi_ex = tawss_osi(wf.fourier(10), PERIOD, R, NU)
    mid = slice(3, 9)  # away from the ends
    assert np.median(f["TAWSS"][mid]) == pytest.approx(tawss_ex * st["rho"], rel=0.15)
    assert np.median(f["OSI"][mid]) == pytest.approx(osi_ex, abs=0.04)
    osi, tawss = f["OSI"][mid], f["TAWSS"][mid]
    np.testing.assert_allclose(f["ECAP"][mid], osi / tawss, rtol=1e-12)
    np.testing.assert_allclose(f["RRT"][mid], 1 / ((1 - 2 * osi) * tawss), rtol=1e-12)
    assert list(f["phase_names"]) == ["peak_systole", "end_systole", "mid_diastole"]
    peak = f["phase/peak_systole/U"]
    assert peak.shape == f["U"].shape
    # at peak systole the axial velocity on the axis is near its analytic value
    t_peak = st["pulsatile"]["phases"]["peak_systole"]["phase_s"]
    u_ex = float(centreline_velocity(np.array([t_peak]), wf.fourier(10), PERIOD, R, NU)[0])
    assert float(np.median(peak[mid, :, 0] @ AXIS)) == pytest.approx(u_ex, rel=0.12)
    json.dumps(st)  # status.json is plain JSON
    assert math.isfinite(st["pulsatile"]["cycles"][-1]["cpu_s"])
