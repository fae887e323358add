"""Running a rendered OpenFOAM case: blockMesh, snappyHexMesh, checkMesh, the inlet profile,
[decomposePar], simpleFoam (start-up, main stage), the transient fallback (pimpleFoam wash-out
and averaging window, stationarity test of the time average), [reconstructPar]; convergence,
flow rates, the inlet-outlet pressure difference, WSS (TAWSS, OSI) and the mesh's prism-layer
coverage collected into ``status.json``."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from vcs.cfd.case import CASE_JSON, inlet_profile, render_files
from vcs.cfd.foamfiles import (
    parse_check_mesh_volume,
    parse_solver_log,
)
from vcs.cfd.meshing import _check_mesh, _mesh_report, patch_check
from vcs.cfd.openfoam import detect_openfoam
from vcs.cfd.status import _log_summary, _pyfoam_check, collect
from vcs.cfd.steady import STAGE_FILES, _criterion_text, _plateau_check, plateau_pressure_change, volume_l2_ratio
from vcs.cfd.transient import stationarity, transient_fallback, transient_plan
from vcs.cfd.utilities import (
    _Runner,
    _solver_failure,
    _utility_failure,
    stop_group,
)

# the names other code imports from vcs.cfd.run (tests, bench), kept importable while it is split
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
    "stationarity",
    "stop_group",
    "transient_plan",
    "volume_l2_ratio",
]


def run_case(case_dir: Path | str, *, ranks: int | None = None) -> dict[str, Any]:
    """Mesh and solve a rendered case; writes ``status.json``, ``residuals.csv/png``, ``logs/log.*``.

    Steps: blockMesh, snappyHexMesh -overwrite (jet refinement cylinder, wall prism layers),
    checkMesh, the patch check (:func:`patch_check`: an STL solid lost or under-resolved in
    meshing, or a leak into the background box, stops before the solver with the reason in
    words; so does a failed checkMesh), inlet profile, [decomposePar], simpleFoam start-up
    (first order) then main stage (residualControl); residuals levelled off below
    ``solver.plateau.max_residual``: :func:`_plateau_check` (more iterations, steady when
    nothing changes). If SIMPLE does not converge (or diverges: floating point exception) and
    ``solver.fallback`` is ``transient``: pimpleFoam from the last SIMPLE state written (after a
    divergence, the start-up's) (adjustable time step at Courant number <= ``max_co``), a
    wash-out of ``washout_flow_throughs`` then an averaging window of ``flow_throughs``
    flow-through times (lumen volume / flow rate) with fieldAverage of U, p, wallShearStress and
    |wallShearStress|; ``converged`` is true only when the two halves of the window agree
    (:func:`stationarity`). [reconstructPar]; wallShearStress. Failures do not raise: they are
    reported in the status (``reason``, ``failed_log``); nothing raises for a failed, unreadable
    or not converged run, with or without the fallback. Solver logs of both families are read
    (openfoam.org 10 prints ``Time = 12s``, ESI ``Time = 12``).

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
        result), ``transient`` (the window, its stationarity test; only when the fallback ran),
        ``timings_s`` (s), the inlet profile summary, ``solver_log`` (the main SIMPLE stage's
        log: time unit, convergence message and its count, ``End`` reached, execution/clock
        time in s, the banner's family/version/build), ``pyfoam_log_analysis`` (PyFoam's
        reading of the last SIMPLE log and whether it agrees with the own parser) and more.
    """
    case_dir = Path(case_dir).resolve()
    state = json.loads((case_dir / CASE_JSON).read_text())
    cfd = state["cfd"]
    sol = cfd["solver"]
    ranks = max(int(ranks if ranks is not None else cfd.get("ranks", 1)), 1)
    n = [1, 1, 1]  # hierarchical/simple: split along the longest STL extent
    lo, hi = (np.array(b) for b in state["stl_bounds"])
    n[int(np.argmax(hi - lo))] = ranks
    state["decomposition_n"] = n
    state["cfd"]["ranks"] = ranks
    timings: dict[str, float] = {}
    installed, version = detect_openfoam()
    status: dict[str, Any] = {
        "case": str(case_dir),
        "flavour": state["flavour"],
        "openfoam_version": version,
        "ranks": ranks,
        "converged": False,
        "criterion": _criterion_text(sol),
        "iterations": 0,
        "final_residuals": {},
        "mass_imbalance": None,
        "cells": None,
        "timings_s": timings,
        "reason": None,
        "inlet": {"type": cfd["inlet"]["type"]},
        "units": {"p": "m2/s2 (kinematic); *_Pa = x rho", "wallShearStress": "m2/s2 (kinematic); *_Pa = x rho"},
        "rho": cfd["physics"]["rho"],
        "nu": cfd["physics"]["nu"],
        "mesh": {"sizing": state.get("mesh_sizing")},  # the cell size and why (render_case)
        "inflow": state.get("inflow"),  # the flow rate applied and why (render_case)
    }

    def finish(reason: str | None = None, failed_log: str | None = None) -> dict[str, Any]:
        """Record the reason and the failed utility's log, write status.json, return the status."""
        if reason:
            status["reason"] = reason
        if failed_log:  # the log of the utility that failed (absolute path), for the user and the atlas
            status["failed_log"] = str(case_dir / "logs" / f"log.{failed_log}")
        status["timings_s"]["total"] = round(sum(v for k, v in timings.items() if k != "total"), 3)
        (case_dir / "status.json").write_text(json.dumps(status, indent=2, default=float))
        return status

    if installed is None:
        return finish("no OpenFOAM installation found (simpleFoam not on PATH)")
    if installed != state["flavour"]:
        return finish(f"case rendered for flavour {state['flavour']!r} but the installed OpenFOAM is {installed!r}")

    run = _Runner(case_dir, timings, sol.get("timeout_s"))
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
    for old in ("residuals.csv", "residuals.png", "transient.png"):
        (case_dir / old).unlink(missing_ok=True)
    render_files(case_dir, state, ["0/U", "0/p"])  # placeholder inlet until the mesh exists

    if run(["blockMesh"], "blockMesh").returncode != 0:
        return finish(_utility_failure(case_dir, "blockMesh"), "blockMesh")
    if run(["snappyHexMesh", "-overwrite"], "snappyHexMesh").returncode != 0:
        return finish(_utility_failure(case_dir, "snappyHexMesh"), "snappyHexMesh")
    status["mesh"].update(_mesh_report(case_dir, state))
    patches = patch_check(case_dir, state)
    status["mesh"]["patches"] = patches["patches"]
    status["mesh"]["background_faces"] = patches["background_faces"]
    run(["checkMesh"], "checkMesh")
    ok, cells, why = _check_mesh(case_dir / "logs" / "log.checkMesh")
    status["cells"] = cells
    check_log = (case_dir / "logs" / "log.checkMesh").read_text(errors="replace")
    status["lumen_volume_m3"] = parse_check_mesh_volume(check_log)
    if not patches["ok"]:  # a lost end or a leak: say so before anything else (checkMesh says OK)
        status["mesh_ok"] = False
        status["stage"] = "mesh"
        return finish(patches["reason"], "snappyHexMesh")
    if not ok:
        status["mesh_ok"] = False
        return finish(why, "checkMesh")
    status["mesh_ok"] = True

    # inlet profile on the real mesh faces, flux exact
    t0 = time.perf_counter()
    try:
        prof = inlet_profile(case_dir, state)
    except Exception as exc:  # noqa: BLE001
        return finish(f"inlet profile: {exc}")
    render_files(case_dir, state, ["0/U"], inlet_values=prof["values"].tolist())
    timings["inletProfile"] = round(time.perf_counter() - t0, 3)
    status["inlet"].update({k: v for k, v in prof.items() if k != "values"})

    if ranks > 1:
        render_files(case_dir, state, ["system/decomposeParDict"])
        if run(["decomposePar", "-force"], "decomposePar").returncode != 0:
            return finish(_utility_failure(case_dir, "decomposePar"), "decomposePar")

    logs = []
    n_start = int(sol["startup_iterations"])
    if n_start > 0:
        render_files(
            case_dir, state, STAGE_FILES, end_time=n_start, div_scheme=sol["startup_scheme"], residual_control=False
        )
        r = run(["simpleFoam"], "simpleFoam.startup", ranks)
        logs.append(case_dir / "logs" / "log.simpleFoam.startup")
        if r.returncode != 0:
            return finish(_solver_failure(logs[-1], "start-up"), "simpleFoam.startup")
    render_files(case_dir, state, STAGE_FILES, end_time=int(sol["max_iterations"]))
    r = run(["simpleFoam"], "simpleFoam", ranks)
    logs.append(case_dir / "logs" / "log.simpleFoam")
    main = parse_solver_log(logs[-1])
    status["solver_log"] = _log_summary(main, logs[-1])
    diverged = None  # SIMPLE's divergence, when the transient fallback takes over from it
    if r.returncode != 0:
        failure = _solver_failure(logs[-1], "main")
        if sol.get("fallback") != "transient" or "diverged" not in failure:
            collect(case_dir, status, logs, state)
            return finish(failure, "simpleFoam")
        diverged = failure  # steady SIMPLE blew up; an unsteady flow may still have a time average
    last = main["rows"][-1] if main["rows"] else {}
    tol = float(sol["tolerance"])
    if diverged is None and not last and not main["converged_message"]:
        # nothing to judge convergence on, and nothing to start a transient run from: say so
        collect(case_dir, status, logs, state)
        return finish(
            f"no SIMPLE iteration could be read from logs/log.simpleFoam ({main['time_lines']} time lines, "
            "none with residuals): unrecognised solver output, convergence unknown; fallback not run",
            "simpleFoam",
        )
    converged = diverged is None and bool(
        main["converged_message"] or (last.get("p", 1) < tol and last.get("U", 1) < tol)
    )
    status["converged"] = converged
    status["criterion_used"] = "residualControl" if converged else "none"
    status["fields"] = {"U": "U", "p": "p", "WSS": "wallShearStress", "time_averaged": False}
    transient: dict[str, Any] | None = None
    if not converged:
        if diverged is not None:  # the transient starts from the last state SIMPLE wrote (its start-up's)
            status["reason"] = diverged
        else:
            status["reason"] = (
                f"SIMPLE did not reach initial residuals < {tol:g} in {int(last.get('time', 0))} "
                f"iterations (last p {last.get('p', float('nan')):.3g}, U {last.get('U', float('nan')):.3g})"
            )
            plateau = _plateau_check(case_dir, state, status, run, ranks, prof, last)
            if plateau.get("log"):
                logs.append(plateau.pop("log"))
            if plateau.get("converged_by") is not None:
                converged = True
                status["converged"] = True
                status["criterion_used"] = plateau["converged_by"]
                status["reason"] = None
            elif plateau.get("ran"):
                status["reason"] += f"; plateau check ({status['plateau']['iterations']} more iterations): "
                status["reason"] += status["plateau"]["why"]
        if not converged and sol.get("fallback") == "transient":
            transient = transient_fallback(case_dir, state, status, run, ranks, prof)
    if ranks > 1 and not (transient and transient.get("evaluated")):  # the transient reconstructed its own
        if run(["reconstructPar", "-latestTime"], "reconstructPar").returncode != 0:
            return finish(
                (status["reason"] + "; " if status["reason"] else "") + "reconstructPar failed", "reconstructPar"
            )
    window = None
    if transient is not None and transient.get("averaging_start_time") is not None and transient.get("evaluated"):
        window = (transient["averaging_start_time"], transient["end_time"])
    collect(case_dir, status, logs, state, window=window)
    if converged and not main["rows"] and main["converged_iterations"]:
        status["iterations"] = int(main["converged_iterations"])  # the message's count, no row read
    return finish()
