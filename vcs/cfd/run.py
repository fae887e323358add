"""Running a rendered OpenFOAM case: blockMesh, snappyHexMesh, checkMesh, the inlet profile,
[decomposePar], simpleFoam (start-up, main stage), the transient fallback (pimpleFoam wash-out
and averaging window, stationarity test of the time average), [reconstructPar]; convergence,
flow rates, the inlet-outlet pressure difference, WSS (TAWSS, OSI) and the mesh's prism-layer
coverage collected into ``status.json``."""

from __future__ import annotations

import json
import math
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from vcs.cfd.case import CASE_JSON, inlet_profile, render_files
from vcs.cfd.foamfiles import (
    function_series,
    parse_check_mesh_volume,
    parse_solver_log,
    read_internal_field,
    window_mean,
)
from vcs.cfd.meshing import _check_mesh, _mesh_report, patch_check
from vcs.cfd.openfoam import detect_openfoam
from vcs.cfd.status import _log_summary, _pyfoam_check, _wall_faces, _wall_values, collect
from vcs.cfd.steady import STAGE_FILES, _criterion_text, _plateau_check, plateau_pressure_change, volume_l2_ratio
from vcs.cfd.utilities import (
    _fmt_time,
    _Runner,
    _solver_failure,
    _time_dirs,
    _utility_failure,
    progress,
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
            transient = _transient_fallback(case_dir, state, status, run, ranks, prof)
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


# --------------------------------------------------------------------------- transient fallback


def _round_up(x: float, digits: int = 3) -> float:
    """``x`` > 0 rounded up to ``digits`` significant digits (short time-folder names)."""
    if x <= 0:
        return 0.0
    e = math.floor(math.log10(x)) - digits + 1
    return math.ceil(x / 10.0**e - 1e-9) * 10.0**e


def transient_plan(state: dict[str, Any], volume: float, start_time: float, peak_velocity: float) -> dict[str, Any]:
    """The wash-out and averaging window of the transient fallback, from the flow-through time.

    Parameters
    ----------
    state : dict
        Case description (``cfd.solver.transient``, ``flow_rate`` m^3/s, ``mesh_sizing``
        (smallest cell); without it ``cfd.mesh`` and ``jet_region``).
    volume : float
        Lumen (mesh) volume [m^3].
    start_time : float
        Solver time the transient run starts from (the last SIMPLE iteration, a label in s).
    peak_velocity : float
        Largest inlet velocity [m/s], for the first time step.

    Returns
    -------
    dict
        ``flow_through_time_s`` = volume / flow rate, ``washout_s``, ``window_s`` (rounded up to 3
        significant digits), ``washout_flow_throughs``, ``window_flow_throughs`` (the rounded
        values in flow-through times), ``start_time``, ``averaging_start_time``, ``mid_time``,
        ``end_time`` (solver times, s), ``delta_t_initial_s`` (max_co x smallest cell /
        peak velocity; pimpleFoam lowers it further when the Courant number asks),
        ``max_delta_t_s`` (a twentieth of the half window).
    """
    cfd = state["cfd"]
    tr = cfd["solver"]["transient"]
    t_ft = volume / float(state["flow_rate"])
    washout = _round_up(float(tr["washout_flow_throughs"]) * t_ft)
    window = _round_up(float(tr["flow_throughs"]) * t_ft)
    if state.get("mesh_sizing"):
        h_min = float(state["mesh_sizing"]["smallest_cell_m"])
    else:  # a state without sizing: a numeric cell size and the configured levels
        m = cfd["mesh"]
        levels = [*m["surface_level"], *m["wall_level"], *m["inlet_level"], *m["outlet_level"]]
        if state.get("jet_region"):
            levels.append(state["jet_region"]["level"])
        h_min = float(m["cell_size"]) / 2 ** max(int(x) for x in levels)
    t_w = start_time + washout
    return {
        "flow_through_time_s": t_ft,
        "washout_s": washout,
        "washout_flow_throughs": washout / t_ft,
        "window_s": window,
        "window_flow_throughs": window / t_ft,
        "start_time": start_time,
        "averaging_start_time": t_w,
        "mid_time": t_w + 0.5 * window,
        "end_time": t_w + window,
        "delta_t_initial_s": float(tr["max_co"]) * h_min / max(peak_velocity, 1e-12),
        "max_delta_t_s": 0.05 * window,
    }


def _transient_fallback(
    case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner, ranks: int, prof: dict[str, Any]
) -> dict[str, Any]:
    """Run the transient fallback and judge its stationarity; fills ``status``; never raises.

    Wash-out, averaging window, stationarity test of its halves; a window that is not stationary
    is doubled (pimpleFoam continued, fieldAverage continuing its sums) and re-tested, at most
    ``transient.max_doublings`` times (``status["transient"]["extensions"]``).

    Returns the ``status["transient"]`` dict (``evaluated`` true when the half-window test ran).
    """
    simple_reason = status["reason"]
    tr: dict[str, Any] = {"solver": "pimpleFoam", "evaluated": False, "steady_not_converged": simple_reason}
    status["transient"] = tr
    status["criterion_used"] = "none"

    def fail(why: str, log: str | None = None) -> dict[str, Any]:
        status["reason"] = f"{simple_reason}; transient fallback: {why}"
        if log:
            status["failed_log"] = str(case_dir / "logs" / f"log.{log}")
        return tr

    try:
        volume = status.get("lumen_volume_m3")
        if not volume:
            return fail("lumen volume unknown (checkMesh printed no 'Total volume'), no flow-through time")
        root = case_dir / "processor0" if ranks > 1 else case_dir
        times = _time_dirs(root)
        if not times or times[-1][0] <= 0:
            return fail("the SIMPLE stage wrote no time folder to start from")
        plan = transient_plan(state, float(volume), times[-1][0], float(prof["peak_velocity"]))
        tr.update(plan)
        tr["started_from"] = f"SIMPLE iteration {times[-1][1]}"
        progress.info(
            "steady SIMPLE not converged (%s): transient fallback from iteration %s, flow-through time "
            "%.3g s, wash-out %.3g s, window %.3g s (%.3g flow-through times), solver time %s to %s",
            simple_reason,
            times[-1][1],
            plan["flow_through_time_s"],
            plan["washout_s"],
            plan["window_s"],
            plan["window_flow_throughs"],
            _fmt_time(plan["start_time"]),
            _fmt_time(plan["end_time"]),
        )
        steps: dict[str, int] = {}
        tr["time_steps"] = steps
        common = {
            "transient": True,
            "residual_control": False,
            "delta_t": _fmt_time(plan["delta_t_initial_s"]),
            "max_delta_t": _fmt_time(plan["max_delta_t_s"]),
        }
        # the restart would take the time step of the SIMPLE stage (1) from <time>/uniform/time:
        # without that file the controlDict's deltaT applies, lowered to max_co by pimpleFoam
        for t_dir in [case_dir / times[-1][1]] + [d / times[-1][1] for d in case_dir.glob("processor*")]:
            (t_dir / "uniform" / "time").unlink(missing_ok=True)
        stages = []
        if plan["washout_s"] > 0:
            stages.append(("washout", plan["averaging_start_time"], plan["washout_s"], False))
        stages.append(("average", plan["end_time"], 0.5 * plan["window_s"], True))
        parsed: dict[str, Any] = {}
        for name, end, interval, average in stages:
            render_files(
                case_dir,
                state,
                STAGE_FILES,
                end_time=_fmt_time(end),
                write_interval=_fmt_time(interval),
                average=average,
                **common,
            )
            log = f"pimpleFoam.{name}"
            r = run(["pimpleFoam"], log, ranks)
            parsed = parse_solver_log(case_dir / "logs" / f"log.{log}")
            steps[name] = len(parsed["rows"])
            if r.returncode != 0:
                return fail(_solver_failure(case_dir / "logs" / f"log.{log}", name, "pimpleFoam"), log)
        tr["courant_max"] = parsed["courant_max"]
        tr["delta_t_s"] = {"min": parsed["delta_t_min"], "max": parsed["delta_t_max"]}
        tr["solver_log"] = _log_summary(parsed, case_dir / "logs" / "log.pimpleFoam.average")
        if parsed["rows"]:
            tr["final_residuals"] = {k: parsed["rows"][-1][k] for k in ("p", "U") if k in parsed["rows"][-1]}
        written = [t for t in _time_dirs(root) if t[0] > plan["averaging_start_time"] + 1e-9]
        if not written:
            return fail("the averaging stage wrote no time folder", "pimpleFoam.average")
        mid = min(written, key=lambda t: abs(t[0] - plan["mid_time"]))
        end = written[-1]
        slack = 1e-3 * plan["window_s"]  # write times are hit exactly (adjustableRunTime), names rounded
        if abs(end[0] - plan["end_time"]) > slack or abs(mid[0] - plan["mid_time"]) > slack:
            return fail(
                f"the averaging stage ended at {end[1]} (planned {_fmt_time(plan['end_time'])}), middle write at "
                f"{mid[1]} (planned {_fmt_time(plan['mid_time'])})",
                "pimpleFoam.average",
            )
        if ranks > 1:
            if run(["reconstructPar", "-time", f"{mid[1]},{end[1]}"], "reconstructPar").returncode != 0:
                return fail("reconstructPar failed", "reconstructPar")
        tr["mid_time_folder"], tr["end_time_folder"] = mid[1], end[1]
        verdict = stationarity(case_dir, state, plan, mid[1], end[1], float(prof["peak_velocity"]))
        _log_verdict(plan, verdict)
        # not stationary: double the window, continuing the average, at most max_doublings times
        doublings = int(state["cfd"]["solver"]["transient"].get("max_doublings") or 0)
        extensions: list[dict[str, Any]] = []
        tr["extensions"] = extensions
        while not verdict["stationary"] and len(extensions) < doublings:
            extensions.append(
                {"window_flow_throughs": plan["window_flow_throughs"], **verdict["half_window_differences"]}
            )
            w = plan["window_s"]
            plan = {
                **plan,
                "window_s": 2 * w,
                "window_flow_throughs": 2 * plan["window_flow_throughs"],
                "mid_time": plan["end_time"],
                "end_time": plan["end_time"] + w,
            }
            tr.update(plan)
            progress.info(
                "doubling the window to %.3g flow-through times (%d of at most %d): pimpleFoam continues to %s",
                plan["window_flow_throughs"],
                len(extensions),
                doublings,
                _fmt_time(plan["end_time"]),
            )
            render_files(
                case_dir,
                state,
                STAGE_FILES,
                end_time=_fmt_time(plan["end_time"]),
                write_interval=_fmt_time(w),
                average=True,
                average_continue=True,
                **common,
            )
            log = f"pimpleFoam.extend{len(extensions)}"
            r = run(["pimpleFoam"], log, ranks)
            parsed = parse_solver_log(case_dir / "logs" / f"log.{log}")
            steps[f"extend{len(extensions)}"] = len(parsed["rows"])
            if r.returncode != 0:
                return fail(_solver_failure(case_dir / "logs" / f"log.{log}", log, "pimpleFoam"), log)
            last = _time_dirs(root)[-1]
            if abs(last[0] - plan["end_time"]) > slack:
                return fail(f"the window extension ended at {last[1]} (planned {_fmt_time(plan['end_time'])})", log)
            if ranks > 1 and run(["reconstructPar", "-time", last[1]], "reconstructPar").returncode != 0:
                return fail("reconstructPar failed", "reconstructPar")
            mid, end = end, last
            tr["courant_max"] = max(tr["courant_max"] or 0.0, parsed["courant_max"] or 0.0)
            lo = [x for x in (tr["delta_t_s"]["min"], parsed["delta_t_min"]) if x is not None]
            hi = [x for x in (tr["delta_t_s"]["max"], parsed["delta_t_max"]) if x is not None]
            tr["delta_t_s"] = {"min": min(lo) if lo else None, "max": max(hi) if hi else None}
            tr["solver_log"] = _log_summary(parsed, case_dir / "logs" / f"log.{log}")
            if parsed["rows"]:
                tr["final_residuals"] = {k: parsed["rows"][-1][k] for k in ("p", "U") if k in parsed["rows"][-1]}
            tr["mid_time_folder"], tr["end_time_folder"] = mid[1], end[1]
            verdict = stationarity(case_dir, state, plan, mid[1], end[1], float(prof["peak_velocity"]))
            _log_verdict(plan, verdict)
        tr.update(verdict)
        tr["evaluated"] = True
        status["criterion_used"] = "time_average_stationary"
        status["fields"] = {
            "U": "UMean",
            "p": "pMean",
            "WSS": "wallShearStressMean",
            "TAWSS": "magWallShearStressMean",
            "time_averaged": True,
        }
        _plot_transient(case_dir, state, plan, verdict["halves"])
        if verdict["stationary"]:
            status["converged"] = True
            status["reason"] = None
        else:
            status["reason"] = f"{simple_reason}; {verdict['why']}"
        return tr
    except Exception as exc:  # noqa: BLE001 - the fallback never raises: its failure is a reason
        return fail(f"{type(exc).__name__}: {' '.join(str(exc).split())}")


_HALF_WORDS = {  # the half-window differences of :func:`stationarity`, in words
    "inlet_minus_outlet_pressure": "inlet-outlet pressure difference",
    "tawss_mean": "mean TAWSS",
    "U_L2": "U (L2)",
}


def _log_verdict(plan: dict[str, Any], verdict: dict[str, Any]) -> None:
    """One log line: the stationarity test of a window (:func:`stationarity`)."""
    d, tol = verdict["half_window_differences"], verdict["tolerances"]
    progress.info(
        "window of %.3g flow-through times: half-window differences %s: %s",
        plan["window_flow_throughs"],
        ", ".join(f"{_HALF_WORDS[k]} {100 * d[k]:.2g} % (tolerance {100 * tol[k]:g} %)" for k in d),
        "stationary" if verdict["stationary"] else "not stationary",
    )


def stationarity(
    case_dir: Path, state: dict[str, Any], plan: dict[str, Any], mid: str, end: str, peak_velocity: float
) -> dict[str, Any]:
    """Compare the two halves of the averaging window (the stationarity test of the time average).

    fieldAverage wrote the running means at the middle (= mean of the first half, M1) and at the
    end (= mean of the whole window, M) of the window; the halves are equally long, so the mean
    of the second half is M2 = 2 M - M1, exactly. Compared (relative differences):

    * inlet-outlet pressure difference (time-weighted means of the patch-averaged p over each
      half), relative to |dp| of the whole window but at least 10 % of the inlet dynamic pressure
      U_peak^2 / 2 (dp may cross zero);
    * area-weighted mean TAWSS (time average of |WSS|) on the wall, relative to the window's;
    * U: volume-weighted L2 norm of UMean2 - UMean1 relative to that of the window's UMean.

    Parameters
    ----------
    case_dir : Path
        The (reconstructed) case.
    state : dict
        Case description (patches, ``cfd.solver.transient`` tolerances, ``cfd.physics.rho``).
    plan : dict
        :func:`transient_plan` (the solver times of the window).
    mid, end : str
        Names of the time folders at the middle and at the end of the window.
    peak_velocity : float
        Largest inlet velocity [m/s].

    Returns
    -------
    dict
        ``halves``: {``first``, ``second``, ``window``: {``inlet_minus_outlet_pressure_Pa``,
        ``tawss_mean_Pa``}}, ``half_window_differences``: {``inlet_minus_outlet_pressure``,
        ``tawss_mean``, ``U_L2``} (relative), ``tolerances`` (the same keys), ``stationary``
        (bool), ``why`` (one line, when not stationary).
    """
    tr = state["cfd"]["solver"]["transient"]
    rho = float(state["cfd"]["physics"]["rho"])
    t_w, t_m, t_e = plan["averaging_start_time"], plan["mid_time"], plan["end_time"]
    # dp of each half from the per-step patch averages (time-weighted, as fieldAverage does)
    inlets = [p["name"] for p in state["patches"] if p["role"] == "inlet"]
    outlets = [p["name"] for p in state["patches"] if p["role"] == "outlet"]

    def dp(a: float, b: float) -> float:
        pin = [window_mean(case_dir, f"pressure_{n}", a, b) for n in inlets]
        pout = [window_mean(case_dir, f"pressure_{n}", a, b) for n in outlets]
        vin = [v for v in pin if v is not None]
        vout = [v for v in pout if v is not None]
        if len(vin) != len(pin) or len(vout) != len(pout) or not vin or not vout:
            raise ValueError(f"no patch pressure written between solver times {a:g} and {b:g}")
        return vin[0] - float(np.mean(vout))

    dp1, dp2, dpw = dp(t_w, t_m), dp(t_m, t_e), dp(t_w, t_e)
    dp_scale = max(abs(dpw), 0.1 * 0.5 * peak_velocity**2)
    # TAWSS: area-mean of magWallShearStressMean (linear in the mean, so second half = 2 M - M1)
    walls = _wall_faces(case_dir, state)
    area = np.concatenate([a for _, a in walls])
    tm1 = float((_wall_values(case_dir / mid, "magWallShearStressMean", walls) * area).sum() / area.sum())
    tmw = float((_wall_values(case_dir / end, "magWallShearStressMean", walls) * area).sum() / area.sum())
    tm2 = 2.0 * tmw - tm1
    # U: volume-weighted L2
    vol = read_internal_field(case_dir / end / "V")
    u1 = read_internal_field(case_dir / mid / "UMean", len(vol))
    uw = read_internal_field(case_dir / end / "UMean", len(vol))
    if u1.shape != uw.shape or len(uw) != len(vol):
        raise ValueError(f"UMean ({u1.shape}, {uw.shape}) and V ({vol.shape}) do not match")
    u2 = 2.0 * uw - u1
    l2 = volume_l2_ratio(vol, u2 - u1, uw)
    diffs = {
        "inlet_minus_outlet_pressure": abs(dp2 - dp1) / dp_scale,
        "tawss_mean": abs(tm2 - tm1) / max(abs(tmw), 1e-300),
        "U_L2": l2,
    }
    tols = {
        "inlet_minus_outlet_pressure": float(tr["stationarity_tolerance"]),
        "tawss_mean": float(tr["stationarity_tolerance"]),
        "U_L2": float(tr["stationarity_tolerance_U"]),
    }
    bad = [k for k in diffs if not diffs[k] <= tols[k]]  # NaN counts as not stationary
    out: dict[str, Any] = {
        "halves": {
            "first": {"inlet_minus_outlet_pressure_Pa": dp1 * rho, "tawss_mean_Pa": tm1 * rho},
            "second": {"inlet_minus_outlet_pressure_Pa": dp2 * rho, "tawss_mean_Pa": tm2 * rho},
            "window": {"inlet_minus_outlet_pressure_Pa": dpw * rho, "tawss_mean_Pa": tmw * rho},
        },
        "half_window_differences": diffs,
        "tolerances": tols,
        "pressure_difference_scale_Pa": dp_scale * rho,
        "stationary": not bad,
    }
    if bad:
        out["why"] = (
            f"time average not stationary: the two halves of the {plan['window_s']:.4g} s averaging window "
            f"({plan['window_flow_throughs']:.3g} flow-through times of {plan['flow_through_time_s']:.3g} s, after a "
            f"{plan['washout_s']:.3g} s wash-out) differ by "
            + ", ".join(f"{100 * diffs[k]:.3g} % in {_HALF_WORDS[k]} (tolerance {100 * tols[k]:g} %)" for k in bad)
            + "; lengthen cfd.solver.transient.flow_throughs or max_doublings (or washout_flow_throughs)"
        )
    return out


def _plot_transient(case_dir: Path, state: dict[str, Any], plan: dict[str, Any], halves: dict[str, Any]) -> None:
    """``transient.png``: the inlet-outlet pressure difference over the transient run, the window
    and its two half means (best effort, never fails)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        rho = float(state["cfd"]["physics"]["rho"])
        ins = [p["name"] for p in state["patches"] if p["role"] == "inlet"]
        outs = [p["name"] for p in state["patches"] if p["role"] == "outlet"]
        a = function_series(case_dir, f"pressure_{ins[0]}")
        outs_s = [function_series(case_dir, f"pressure_{n}") for n in outs]
        sel = a[:, 0] > plan["start_time"]
        t = a[sel, 0] - plan["start_time"]
        po = np.mean([np.interp(a[sel, 0], o[:, 0], o[:, 1]) for o in outs_s], axis=0)
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(t, (a[sel, 1] - po) * rho, lw=0.6, label="instantaneous")
        t_w, t_m, t_e = (plan[k] - plan["start_time"] for k in ("averaging_start_time", "mid_time", "end_time"))
        ax.axvspan(t_w, t_e, alpha=0.1, label="averaging window")
        for (a0, b0), half in ((t_w, t_m), halves["first"]), ((t_m, t_e), halves["second"]):
            ax.hlines(half["inlet_minus_outlet_pressure_Pa"], a0, b0, colors="k")
        ax.set_xlabel(f"time since the end of SIMPLE [s] (flow-through time {plan['flow_through_time_s']:.3g} s)")
        ax.set_ylabel("p(inlet) - p(outlet) [Pa]")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
        fig.tight_layout()
        fig.savefig(case_dir / "transient.png", dpi=100)
        plt.close(fig)
    except Exception:  # noqa: BLE001 - plotting must never fail a run
        pass
