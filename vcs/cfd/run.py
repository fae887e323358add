"""Running a rendered OpenFOAM case: :func:`run_case`, the stages in order, each a named function.

1. start: OpenFOAM installed and of the case's flavour, the case cleaned of an earlier run;
2. mesh: blockMesh, snappyHexMesh, checkMesh and the patch check (:mod:`vcs.cfd.meshing`);
3. the inlet profile on the mesh faces, [decomposePar];
4. steady solve: simpleFoam start-up and main stage, the plateau check (:mod:`vcs.cfd.steady`);
5. the transient solve when SIMPLE did not converge: pimpleFoam wash-out and an averaging window
   that ends when its means are known to the tolerance, with their error bars (:mod:`vcs.cfd.transient`);
   A case with an inflow waveform (``cfd.inlet.waveform``) goes from the mesh to the pulsatile
   solve instead (:func:`_pulsatile`: the inlet's boundary data, whole cycles until periodic,
   the kept cycles' markers: :mod:`vcs.cfd.pulsatile`);
6. [reconstructPar], then convergence, flow rates, the inlet-outlet pressure difference, WSS
   (TAWSS, OSI) and the mesh's prism-layer coverage collected into ``status.json``
   (:mod:`vcs.cfd.status`).

A stage that cannot go on raises :class:`vcs.cfd.utilities.Stop` (the reason and the failed log);
:mod:`vcs.cfd.utilities` runs the OpenFOAM utilities (process groups, signals, timeouts).
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from vcs.cfd.case import CASE_JSON, inlet_profile, render_files
from vcs.cfd.meshing import mesh_case, patch_check
from vcs.cfd.openfoam import detect_openfoam
from vcs.cfd.pulsatile import kept_wall_markers, pulsatile_plan, pulsatile_solve, write_cycle_table, write_inlet_data
from vcs.cfd.status import _pyfoam_check, collect, finish
from vcs.cfd.steady import STAGE_FILES, _criterion_text, plateau_pressure_change, steady_solve, volume_l2_ratio
from vcs.cfd.transient import transient_fallback, transient_plan, window_statistics
from vcs.cfd.utilities import Stop, _Runner, _solver_failure, _utility_failure, stop_group

# run_case, and the names other code imported from vcs.cfd.run before it was split into modules
__all__ = [
    "STAGE_FILES",
    "_Runner",
    "_pyfoam_check",
    "_solver_failure",
    "_utility_failure",
    "inlet_profile",
    "patch_check",
    "plateau_pressure_change",
    "run_case",
    "stop_group",
    "transient_plan",
    "volume_l2_ratio",
    "window_statistics",
]


def run_case(case_dir: Path | str, *, ranks: int | None = None) -> dict[str, Any]:
    """Mesh and solve a rendered case; writes ``status.json``, ``residuals.csv/png``, ``logs/log.*``.

    Steps: blockMesh, snappyHexMesh -overwrite (jet refinement cylinder, wall prism layers),
    checkMesh, the patch check (:func:`vcs.cfd.meshing.patch_check`: an STL solid lost or
    under-resolved in meshing, or a leak into the background box, stops before the solver with
    the reason in words; so does a failed checkMesh), inlet profile, [decomposePar], simpleFoam
    start-up (first order) then main stage (residualControl); residuals levelled off below
    ``solver.plateau.max_residual``: :func:`vcs.cfd.steady._plateau_check` (more iterations,
    steady when nothing changes). If SIMPLE does not converge (or diverges: floating point
    exception) and ``solver.fallback`` is ``transient``: pimpleFoam from the last SIMPLE state
    written (after a divergence, the start-up's) (adjustable time step at Courant number <=
    ``max_co`` on the cells the flow crosses), a wash-out of ``washout_flow_throughs`` then an
    averaging window (fieldAverage of U, p, wallShearStress and |wallShearStress|) of
    ``min_flow_throughs`` to ``max_flow_throughs`` flow-through times (lumen volume / flow rate),
    ended as soon as its means are known to the tolerance; ``converged`` is true only then
    (:func:`vcs.cfd.transient.window_statistics`). [reconstructPar]; wallShearStress.
    Failures do not raise: they are reported in the status (``reason``, ``failed_log``); nothing
    raises for a failed, unreadable or not converged run, with or without the fallback. Solver
    logs of both families are read (openfoam.org 10 prints ``Time = 12s``, ESI ``Time = 12``).

    Parameters
    ----------
    case_dir : Path or str
        A case written by :func:`vcs.cfd.case.render_case`.
    ranks : int or None
        MPI ranks (1: serial); None: ``cfd.ranks`` of the case.

    Returns
    -------
    dict
        The status (also ``status.json``): ``converged``, ``criterion``, ``criterion_used``
        (``residualControl``, ``residual_plateau``, ``time_average_stationary`` or ``none``),
        ``plateau`` (the plateau check, when it ran), ``reason``,
        ``iterations`` (SIMPLE), ``final_residuals``, ``cells``, ``lumen_volume_m3``, ``mesh``
        (``sizing``: the cell size and why, the background box, the levels; ``patches``: faces per
        STL solid; ``background_faces``; prism-layer coverage, jet refinement), ``mesh_ok`` and
        ``stage`` (``mesh`` when meshing stopped the patient), ``inflow`` (the flow rate applied
        and why: :func:`vcs.cfd.sizing.choose_inflow`), ``mass_imbalance`` (relative), ``flow_rates``
        (m^3/s), ``patch_pressure`` (kinematic, m^2/s^2), ``inlet_minus_outlet_pressure``
        (m^2/s^2 and Pa; negative = pressure recovery), ``wall_shear_stress_Pa`` (and, for a
        time average, ``tawss_Pa`` and ``osi``), ``fields`` (which field files hold the
        result), ``transient`` (the window, its means' error bars; only when the fallback ran),
        ``time_average_errors`` (the relative half-widths),
        ``timings_s`` (s), the inlet profile summary, ``solver_log`` (the main SIMPLE stage's
        log: time unit, convergence message and its count, ``End`` reached, execution/clock
        time in s, the banner's family/version/build), ``pyfoam_log_analysis`` (PyFoam's
        reading of the last SIMPLE log and whether it agrees with the own parser) and more.
    """
    case_dir = Path(case_dir).resolve()
    state = _read_state(case_dir, ranks)
    ranks = int(state["cfd"]["ranks"])
    installed, version = detect_openfoam()
    status = _new_status(case_dir, state, version)
    try:
        run = _start(case_dir, state, status, installed)
        mesh_case(case_dir, state, status, run)
        if state.get("waveform"):
            _pulsatile(case_dir, state, status, run, ranks)
            return finish(case_dir, status)
        prof = _inlet(case_dir, state, status)
        _decompose(case_dir, state, run)
        steady = steady_solve(case_dir, state, status, run, ranks, prof)
        transient = None
        if not steady.converged and state["cfd"]["solver"].get("fallback") == "transient":
            transient = transient_fallback(case_dir, state, status, run, ranks, prof)
        _reconstruct(state, status, run, transient)
        collect(case_dir, status, steady.logs, state, window=_averaging_window(transient))
        if steady.converged and not steady.main["rows"] and steady.main["converged_iterations"]:
            status["iterations"] = int(steady.main["converged_iterations"])  # the message's count, no row read
    except Stop as stop:
        return finish(case_dir, status, stop.reason, stop.failed_log)
    return finish(case_dir, status)


def _read_state(case_dir: Path, ranks: int | None) -> dict[str, Any]:
    """The case description (``case.json``) with the MPI ranks (``cfd.ranks``, at least 1) and
    their decomposition (``decomposition_n``: split along the longest STL extent)."""
    state: dict[str, Any] = json.loads((case_dir / CASE_JSON).read_text())
    cfd = state["cfd"]
    ranks = max(int(ranks if ranks is not None else cfd.get("ranks", 1)), 1)
    n = [1, 1, 1]  # hierarchical/simple: split along the longest STL extent
    lo, hi = (np.array(b) for b in state["stl_bounds"])
    n[int(np.argmax(hi - lo))] = ranks
    state["decomposition_n"] = n
    state["cfd"]["ranks"] = ranks
    return state


def _new_status(case_dir: Path, state: dict[str, Any], version: str | None) -> dict[str, Any]:
    """The status before anything ran: not converged, the case's set-up and criterion."""
    cfd = state["cfd"]
    return {
        "case": str(case_dir),
        "flavour": state["flavour"],
        "openfoam_version": version,
        "ranks": cfd["ranks"],
        # MPI changes the order of sums: results agree to round-off, not bit for bit, across rank counts
        "decomposition": {"method": cfd["decomposition"]["method"], "n": state.get("decomposition_n")},
        "converged": False,
        "criterion": _criterion_text(cfd["solver"]),
        "iterations": 0,
        "final_residuals": {},
        "mass_imbalance": None,
        "cells": None,
        "timings_s": {},
        "reason": None,
        "inlet": {"type": cfd["inlet"]["type"]},
        "units": {"p": "m2/s2 (kinematic); *_Pa = x rho", "wallShearStress": "m2/s2 (kinematic); *_Pa = x rho"},
        "rho": cfd["physics"]["rho"],
        "nu": cfd["physics"]["nu"],
        "mesh": {"sizing": state.get("mesh_sizing")},  # the cell size and why (render_case)
        "inflow": state.get("inflow"),  # the flow rate applied and why (render_case)
        "geometry": _geometry(state),
    }


def _geometry(state: dict[str, Any]) -> dict[str, Any]:
    """The lumen the case was meshed from (``cfd.geometry``) and its ends: name, role (inlet, outlet
    = the section's tau = 1 end, branch), area-centroid ``center_m``, ``area_m2``, equivalent radius."""
    ends = []
    for s in state["solids"]:
        if s["role"] not in ("inlet", "outlet"):
            continue
        role = "branch" if s["name"].lower().startswith("branch") else s["role"]
        ends.append(
            {
                "name": s["name"],
                "role": role,
                "center_m": s.get("center_m"),
                "area_m2": s["area_m2"],
                "equivalent_radius_m": float(np.sqrt(s["area_m2"] / np.pi)),
            }
        )
    return {"type": state["cfd"].get("geometry", "model"), "stl": state.get("stl_source"), "ends": ends}


def _start(case_dir: Path, state: dict[str, Any], status: dict[str, Any], installed: str | None) -> _Runner:
    """Stage 1: the installed OpenFOAM is the case's flavour; the case cleaned of an earlier run
    (:func:`_clean`). Returns the runner of its utilities (timed in ``status["timings_s"]``)."""
    if installed is None:
        raise Stop("no OpenFOAM installation found (simpleFoam not on PATH)")
    if installed != state["flavour"]:
        raise Stop(f"case rendered for flavour {state['flavour']!r} but the installed OpenFOAM is {installed!r}")
    run = _Runner(case_dir, status["timings_s"], state["cfd"]["solver"].get("timeout_s"))
    _clean(case_dir, state)
    return run


def _clean(case_dir: Path, state: dict[str, Any]) -> None:
    """Restart from a clean case (re-run safety): no processor folders, time folders > 0,
    postProcessing, mesh, logs or earlier outputs; a placeholder inlet until the mesh exists."""
    for d in case_dir.glob("processor*"):
        shutil.rmtree(d)
    for d in case_dir.iterdir():  # restart from a clean 0/ (re-run safety)
        if d.is_dir() and d.name not in ("0", "constant", "system", "logs"):
            try:
                if float(d.name) > 0:
                    shutil.rmtree(d)
            except ValueError:
                if d.name == "postProcessing":
                    shutil.rmtree(d)
    shutil.rmtree(case_dir / "constant" / "polyMesh", ignore_errors=True)
    for f in (case_dir / "logs").glob("log.*"):
        f.unlink()
    shutil.rmtree(case_dir / "constant" / "boundaryData", ignore_errors=True)
    for old in ("residuals.csv", "residuals.png", "transient.png", "pulsatile.png", "cycles.json"):
        (case_dir / old).unlink(missing_ok=True)
    render_files(case_dir, state, ["0/U", "0/p"])  # placeholder inlet until the mesh exists


def _inlet(case_dir: Path, state: dict[str, Any], status: dict[str, Any]) -> dict[str, Any]:
    """Stage 3: the inlet profile on the real mesh faces, flux exact, written to ``0/U``; its
    summary in ``status["inlet"]``. Returns the profile (:func:`vcs.cfd.case.inlet_profile`)."""
    t0 = time.perf_counter()
    try:
        prof = inlet_profile(case_dir, state)
    except Exception as exc:  # noqa: BLE001
        raise Stop(f"inlet profile: {exc}") from exc
    render_files(case_dir, state, ["0/U"], inlet_values=prof["values"].tolist())
    status["timings_s"]["inletProfile"] = round(time.perf_counter() - t0, 3)
    status["inlet"].update({k: v for k, v in prof.items() if k != "values"})
    return prof


def _pulsatile(case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner, ranks: int) -> None:
    """Stages 3-6 of a pulsatile case (an inflow waveform): the inlet boundary data, [decomposePar],
    whole cycles until periodic (:func:`vcs.cfd.pulsatile.pulsatile_solve`), [reconstructPar of the
    kept folders], the flow rates and pressures over the kept cycles and their wall markers."""
    t0 = time.perf_counter()
    plan = pulsatile_plan(state)
    try:
        status["inlet"].update(write_inlet_data(case_dir, state, plan))
    except Stop:
        raise
    except Exception as exc:  # noqa: BLE001
        raise Stop(f"inlet boundary data: {exc}") from exc
    render_files(case_dir, state, ["0/U"])
    status["timings_s"]["inletProfile"] = round(time.perf_counter() - t0, 3)
    _decompose(case_dir, state, run)
    pu = pulsatile_solve(case_dir, state, status, run, ranks)
    if ranks > 1:
        times = ",".join([*pu["mean_times"], *(ph["time_name"] for ph in pu["phases"].values())])
        if run(["reconstructPar", "-time", times], "reconstructPar").returncode != 0:
            raise Stop("reconstructPar failed", "reconstructPar")
    collect(case_dir, status, [], state, window=tuple(pu["window"]))
    status.update(kept_wall_markers(case_dir, state, pu))
    status["fields"] = {"source": "pulsatile", "mean_times": pu["mean_times"]}
    write_cycle_table(case_dir, pu)


def _decompose(case_dir: Path, state: dict[str, Any], run: _Runner) -> None:
    """Stage 3, with more than one rank: decomposePar."""
    if state["cfd"]["ranks"] > 1:
        render_files(case_dir, state, ["system/decomposeParDict"])
        if run(["decomposePar", "-force"], "decomposePar").returncode != 0:
            raise Stop(_utility_failure(case_dir, "decomposePar"), "decomposePar")


def _reconstruct(state: dict[str, Any], status: dict[str, Any], run: _Runner, transient: dict[str, Any] | None) -> None:
    """Stage 6, with more than one rank: reconstructPar of the latest time (a transient fallback
    that was evaluated reconstructed its own window)."""
    if state["cfd"]["ranks"] > 1 and not (transient and transient.get("evaluated")):
        if run(["reconstructPar", "-latestTime"], "reconstructPar").returncode != 0:
            raise Stop(
                (status["reason"] + "; " if status["reason"] else "") + "reconstructPar failed", "reconstructPar"
            )


def _averaging_window(transient: dict[str, Any] | None) -> tuple[float, float] | None:
    """The averaging window (solver times) of an evaluated transient fallback, else None (the
    result is the last state)."""
    if transient is not None and transient.get("averaging_start_time") is not None and transient.get("evaluated"):
        return (transient["averaging_start_time"], transient["end_time"])
    return None
