"""Running a rendered OpenFOAM case: blockMesh, snappyHexMesh, checkMesh, the inlet profile,
[decomposePar], simpleFoam (start-up, main stage, optional averaging fallback),
[reconstructPar], wallShearStress; convergence, flow rates, pressure difference and WSS
collected into ``status.json``."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vcs.cfd.case import CASE_JSON, inlet_profile, patch_role, render_files
from vcs.cfd.foamfiles import last_function_value, mean_function_value, parse_solver_log, patch_geometry
from vcs.cfd.openfoam import detect_openfoam, foam_env

# --------------------------------------------------------------------------- running


def _run_group(
    cmd: list[str], cwd: Path, env: dict[str, str], out: Any, timeout: float | None
) -> subprocess.CompletedProcess[bytes]:
    """Run ``cmd`` in its own process group and wait; on a timeout, Ctrl-C (KeyboardInterrupt) or
    any other exit of the caller, stop the WHOLE group (mpirun and every rank: SIGTERM, then
    SIGKILL after 5 s) before re-raising, so that no solver keeps running after its job ended."""
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        return subprocess.CompletedProcess(cmd, returncode=proc.wait(timeout=timeout))
    except BaseException:
        stop_group(proc)
        raise


def stop_group(proc: subprocess.Popen[bytes]) -> None:
    """SIGTERM to the process group of ``proc`` (started with ``start_new_session``), SIGKILL
    after 5 s if it is still there."""
    for sig, grace in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=grace)
            break
        except subprocess.TimeoutExpired:
            continue


class _Runner:
    """Runs OpenFOAM utilities in a case, each logged to ``logs/log.<name>`` and timed."""

    def __init__(self, case_dir: Path, timings: dict[str, float], timeout: float | None) -> None:
        self.case = case_dir
        self.logs = case_dir / "logs"
        self.logs.mkdir(exist_ok=True)
        self.timings = timings
        self.timeout = timeout
        self.env = foam_env()

    def __call__(self, args: list[str], log: str, ranks: int = 1) -> subprocess.CompletedProcess[bytes]:
        """Run ``args`` (under mpirun with -parallel when ranks > 1); a timeout gives returncode -9,
        an executable that cannot be started 127. Never raises, except when the caller is interrupted
        (Ctrl-C, or SIGTERM turned into KeyboardInterrupt by the workflow scripts): then the
        utility's whole process group is stopped first."""
        cmd = list(args)
        if ranks > 1:
            mpi = ["mpirun", "--oversubscribe", "-np", str(ranks)]
            if hasattr(os, "geteuid") and os.geteuid() == 0:
                mpi.insert(1, "--allow-run-as-root")
            for var in ("WM_PROJECT_DIR", "FOAM_SIGFPE"):
                if var in self.env:
                    mpi += ["-x", var]
            cmd = mpi + cmd + ["-parallel"]
        t0 = time.perf_counter()
        with open(self.logs / f"log.{log}", "w") as fh:
            fh.write(f"# {' '.join(cmd)}\n")
            fh.flush()
            try:
                r = _run_group(cmd, self.case, self.env, fh, self.timeout)
            except subprocess.TimeoutExpired:
                r = subprocess.CompletedProcess(cmd, returncode=-9)
                fh.write(f"\n# vcsflow: timeout after {self.timeout} s\n")
            except OSError as exc:  # e.g. the utility is not on PATH: a failed utility, not a crash
                r = subprocess.CompletedProcess(cmd, returncode=127)
                fh.write(f"\n--> FOAM FATAL ERROR: vcsflow could not start {cmd[0]}: {exc}\n")
        self.timings[log] = round(self.timings.get(log, 0.0) + time.perf_counter() - t0, 3)
        return r


def _latest_time(case_dir: Path) -> str | None:
    """Name of the case's largest numeric time folder, or None."""
    times = []
    for p in case_dir.iterdir():
        if p.is_dir():
            try:
                times.append((float(p.name), p.name))
            except ValueError:
                pass
    return max(times)[1] if times else None


def _check_mesh(log: Path) -> tuple[bool, int | None, str]:
    """(mesh OK, number of cells, why not) from a checkMesh log."""
    txt = log.read_text(errors="replace")
    m = re.search(r"^\s*cells:\s+(\d+)", txt, re.M)
    cells = int(m.group(1)) if m else None
    if "Mesh OK." in txt:
        return True, cells, ""
    fails = re.findall(r"\*\*\*.*", txt)
    m = re.search(r"Failed (\d+) mesh checks", txt)
    why = (f"checkMesh failed {m.group(1)} check(s): " if m else "checkMesh did not report 'Mesh OK.': ") + "; ".join(
        f.strip() for f in fails[:5]
    )
    return False, cells, why


def _read_patch_vectors(field_file: Path, patch: str) -> NDArray[np.floating] | None:
    """A patch's vector values in an ASCII field file ((n, 3), or (1, 3) when uniform), or None."""
    txt = field_file.read_text(errors="replace")
    bf = txt.find("boundaryField")
    m = re.search(rf"\b{re.escape(patch)}\s*\{{[^{{}}]*?value\s+nonuniform\s+List<vector>\s*(\d+)\s*\(", txt[bf:], re.S)
    if not m:
        m2 = re.search(rf"\b{re.escape(patch)}\s*\{{[^{{}}]*?value\s+uniform\s*\(([^)]*)\)", txt[bf:], re.S)
        return None if not m2 else np.array([[float(x) for x in m2.group(1).split()]])
    n = int(m.group(1))
    start = bf + m.end()
    vals = re.findall(r"\(([^()]*)\)", txt[start : start + n * 80 + 1000])[:n]
    return np.array([[float(x) for x in v.split()] for v in vals])


def _write_residuals(case_dir: Path, rows: list[dict[str, Any]]) -> None:
    """Write ``residuals.csv`` and (best effort) ``residuals.png`` of the parsed log rows."""
    import csv

    keys = ["iteration", "p", "U", "cont_local", "cont_global", "cont_cumulative"]
    with open(case_dir / "residuals.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(keys)
        for r in rows:
            w.writerow([r.get("time") if k == "iteration" else r.get(k, "") for k in keys])
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        it = [r["time"] for r in rows]
        for k in ("p", "U"):
            ax.semilogy(it, [r.get(k, np.nan) for r in rows], label=k)
        ax.set_xlabel("SIMPLE iteration")
        ax.set_ylabel("initial residual")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(case_dir / "residuals.png", dpi=100)
        plt.close(fig)
    except Exception:  # plotting must never fail a run
        pass


def _use_means(time_dir: Path) -> list[str]:
    """Fallback: replace U and p by their fieldAverage means (instantaneous kept as *.instantaneous).

    Parameters
    ----------
    time_dir : Path
        The time folder written by the averaging stage.

    Returns
    -------
    list of str
        The fields replaced (``"U"``, ``"p"``); a field without its ``<f>Mean`` file is left as
        it is.
    """
    done = []
    for f in ("U", "p"):
        mean = time_dir / f"{f}Mean"
        if mean.exists() and (time_dir / f).exists():
            shutil.move(time_dir / f, time_dir / f"{f}.instantaneous")
            txt = mean.read_text()
            txt = re.sub(rf"(object\s+){f}Mean;", rf"\1{f};", txt, count=1)
            (time_dir / f).write_text(txt)
            done.append(f)
    return done


def _log_summary(parsed: dict[str, Any], log: Path) -> dict[str, Any]:
    """What status.json keeps of a parsed solver log (see :func:`parse_solver_log`)."""
    return {
        "log": log.name,
        "time_lines": parsed["time_lines"],
        "time_unit": parsed["time_unit"],
        "iterations_read": len(parsed["rows"]),
        "converged_message": parsed["converged_message"],
        "converged_iterations": parsed["converged_iterations"],
        "ended": parsed["ended"],
        "execution_time_s": parsed["execution_time_s"],
        "clock_time_s": parsed["clock_time_s"],
        "banner": parsed["banner"],
    }


def run_case(case_dir: Path | str, *, ranks: int | None = None) -> dict[str, Any]:
    """Mesh and solve a rendered case; writes ``status.json``, ``residuals.csv/png``, ``logs/log.*``.

    Steps: blockMesh, snappyHexMesh -overwrite, checkMesh (failure stops), inlet profile,
    [decomposePar], simpleFoam start-up (first order) then main stage (residualControl);
    if not converged and solver.fallback == 'average': averaging stage with fieldAverage whose
    means replace U and p; [reconstructPar]; wallShearStress. Failures do not raise: they are
    reported in the status (``reason``, ``failed_log``); nothing raises for a failed,
    unreadable or not converged run, with or without the fallback. Solver logs of both families
    are read (openfoam.org 10 prints ``Time = 12s``, ESI ``Time = 12``).

    Parameters
    ----------
    case_dir : Path or str
        A case written by :func:`vcs.cfd.case.render_case`.
    ranks : int or None
        MPI ranks (1: serial); None: ``cfd.ranks`` of the case.

    Returns
    -------
    dict
        The status (also ``status.json``): ``converged``, ``reason``, ``iterations``,
        ``final_residuals``, ``cells``, ``mass_imbalance`` (relative), ``flow_rates`` (m^3/s),
        ``patch_pressure`` (kinematic, m^2/s^2), ``pressure_drop`` (m^2/s^2 and Pa),
        ``wall_shear_stress_Pa``, ``timings_s`` (s), the inlet profile summary, ``solver_log``
        (the main stage's log: time unit, convergence message and its count, ``End`` reached,
        execution/clock time in s, the banner's family/version/build), ``pyfoam_log_analysis``
        (PyFoam's reading of the last log and whether it agrees with the own parser) and more.
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
        "criterion": f"initial residuals of p and U < {sol['tolerance']:g}",
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
    render_files(case_dir, state, ["0/U", "0/p"])  # placeholder inlet until the mesh exists

    if run(["blockMesh"], "blockMesh").returncode != 0:
        return finish(_utility_failure(case_dir, "blockMesh"), "blockMesh")
    if run(["snappyHexMesh", "-overwrite"], "snappyHexMesh").returncode != 0:
        return finish(_utility_failure(case_dir, "snappyHexMesh"), "snappyHexMesh")
    run(["checkMesh"], "checkMesh")
    ok, cells, why = _check_mesh(case_dir / "logs" / "log.checkMesh")
    status["cells"] = cells
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

    stage_files = ["system/controlDict", "system/fvSchemes", "system/fvSolution"]
    logs = []
    n_start = int(sol["startup_iterations"])
    if n_start > 0:
        render_files(
            case_dir, state, stage_files, end_time=n_start, div_scheme=sol["startup_scheme"], residual_control=False
        )
        r = run(["simpleFoam"], "simpleFoam.startup", ranks)
        logs.append(case_dir / "logs" / "log.simpleFoam.startup")
        if r.returncode != 0:
            return finish(_solver_failure(logs[-1], "start-up"), "simpleFoam.startup")
    render_files(case_dir, state, stage_files, end_time=int(sol["max_iterations"]))
    r = run(["simpleFoam"], "simpleFoam", ranks)
    logs.append(case_dir / "logs" / "log.simpleFoam")
    main = parse_solver_log(logs[-1])
    status["solver_log"] = _log_summary(main, logs[-1])
    if r.returncode != 0:
        _collect(case_dir, status, logs, state)
        return finish(_solver_failure(logs[-1], "main"), "simpleFoam")
    last = main["rows"][-1] if main["rows"] else {}
    tol = float(sol["tolerance"])
    if not last and not main["converged_message"]:
        # nothing to judge convergence on, and nothing to start an average from: say so
        _collect(case_dir, status, logs, state)
        return finish(
            f"no SIMPLE iteration could be read from logs/log.simpleFoam ({main['time_lines']} time lines, "
            "none with residuals): unrecognised solver output, convergence unknown; fallback not run",
            "simpleFoam",
        )
    converged = bool(main["converged_message"] or (last.get("p", 1) < tol and last.get("U", 1) < tol))
    status["converged"] = converged
    averaged = False
    if not converged:
        status["reason"] = (
            f"SIMPLE did not reach initial residuals < {tol:g} in {int(last.get('time', 0))} "
            f"iterations (last p {last.get('p', float('nan')):.3g}, U {last.get('U', float('nan')):.3g})"
        )
        if sol.get("fallback") == "average" and int(sol["average_iterations"]) > 0:
            status["averaging_from"] = int(last.get("time", sol["max_iterations"]))
            end = status["averaging_from"] + int(sol["average_iterations"])
            render_files(case_dir, state, stage_files, end_time=end, residual_control=False, average=True)
            r = run(["simpleFoam"], "simpleFoam.average", ranks)
            logs.append(case_dir / "logs" / "log.simpleFoam.average")
            if r.returncode != 0:
                _collect(case_dir, status, logs, state)
                return finish(status["reason"] + "; " + _solver_failure(logs[-1], "averaging"), "simpleFoam.average")
            averaged = True
    if ranks > 1:
        if run(["reconstructPar", "-latestTime"], "reconstructPar").returncode != 0:
            return finish(
                (status["reason"] + "; " if status["reason"] else "") + "reconstructPar failed", "reconstructPar"
            )
    fallback_note = ""
    if averaged:
        latest = _latest_time(case_dir)  # the averaging stage wrote a time folder
        try:
            means = _use_means(case_dir / latest) if latest and float(latest) > status["averaging_from"] else []
        except OSError as exc:  # a field file that cannot be moved or written: reported below
            means, latest = [], f"{latest} ({type(exc).__name__}: {exc})"
        if means == ["U", "p"]:
            run(["simpleFoam", "-postProcess", "-func", "wallShearStress", "-latestTime"], "wallShearStress")
            status["criterion_used"] = "pseudo_steady_time_average"
        else:  # no means to report: the fields stay the instantaneous ones, and the status says so
            averaged = False
            status["criterion_used"] = "none"
            fallback_note = (
                f"; fallback: the averaging stage wrote no UMean/pMean (latest time {latest}), "
                "U and p are the instantaneous fields of the last iteration"
            )
        status["average_iterations"] = int(sol["average_iterations"])
    else:
        status["criterion_used"] = "residualControl" if converged else "none"
    _collect(case_dir, status, logs, state)
    if converged and not main["rows"] and main["converged_iterations"]:
        status["iterations"] = int(main["converged_iterations"])  # the message's count, no row read
    if averaged:
        rel = status.get("averaging", {}).get("max_initial_residual")
        status["converged_relaxed"] = bool(rel is not None and rel < float(sol["relaxed_tolerance"]))
        rel_txt = f"{rel:.3g}" if rel is not None else "unknown (no iteration read from logs/log.simpleFoam.average)"
        fallback_note = (
            f"; fallback: U and p are the time averages over the last {sol['average_iterations']} "
            f"iterations (pseudo-steady), max residual during averaging {rel_txt} "
            f"(relaxed criterion {sol['relaxed_tolerance']:g}: "
            f"{'met' if status['converged_relaxed'] else 'not met'})"
        )
    if fallback_note:
        status["reason"] = (status["reason"] or "") + fallback_note
    return finish()


def _utility_failure(case_dir: Path, utility: str) -> str:
    """'<utility> failed: <FOAM FATAL ERROR message> (see logs/log.<utility>)'."""
    log = case_dir / "logs" / f"log.{utility}"
    txt = log.read_text(errors="replace")[-4000:] if log.exists() else ""
    m = re.search(r"FOAM FATAL (?:IO )?ERROR[^\n]*\n((?:[^\n]*\n){0,8})", txt)
    detail = ""
    if m:  # the message lines, without the "From ..."/"in file ..." trailer
        lines = [ln.strip() for ln in m.group(1).splitlines() if ln.strip()]
        lines = [ln for ln in lines if not ln.startswith(("From ", "in file ", "at line ", "FOAM exiting"))]
        detail = ": " + " ".join(" ".join(lines).split())[:300] if lines else ""
    elif "# vcsflow: timeout" in txt:
        detail = ": timeout"
    return f"{utility} failed{detail} (see logs/log.{utility})"


def _solver_failure(log: Path, stage: str) -> str:
    """One-line reason for a failed simpleFoam stage from the end of its log."""
    txt = log.read_text(errors="replace")[-4000:] if log.exists() else ""
    m = re.search(r"(FOAM FATAL[^\n]*\n(?:[^\n]*\n){0,6})", txt)
    if "Floating point exception" in txt or "sigFpe" in txt:
        return f"simpleFoam ({stage}) diverged: floating point exception (see logs/{log.name})"
    if m:
        return f"simpleFoam ({stage}) failed: " + " ".join(m.group(1).split())[:400]
    return f"simpleFoam ({stage}) exited with an error (see logs/{log.name})"


def _pyfoam_check(log: Path, own: dict[str, Any] | None = None) -> dict[str, Any]:
    """Cross-check of the own log parser with PyFoam's BoundingLogAnalyzer (last iteration).

    Parameters
    ----------
    log : Path
        A solver log.
    own : dict or None
        The own parser's last row of that log (``time`` and initial residuals), to compare with.

    Returns
    -------
    dict
        ``log``, ``last_iteration`` (float or None), ``initial_residuals`` (PyFoam's names:
        ``Ux``, ``p``, ...), ``continuity``; ``agrees_with_parser`` (bool, when ``own`` is given:
        same last iteration and p residual within 1e-6 relative); ``note`` when PyFoam read no
        time line (e.g. a time unit its regular expression does not accept); ``error`` (and
        nothing else) when PyFoam failed.
    """
    try:
        from PyFoam.LogAnalysis.BoundingLogAnalyzer import BoundingLogAnalyzer

        a = BoundingLogAnalyzer(doFiles=False, doTimelines=True)
        with open(log) as fh:
            a.analyze(fh)
        lin = a.getAnalyzer("Linear").getCurrentData()
        cont = a.getAnalyzer("Continuity").getCurrentData()
        try:  # PyFoam gives the time as a string, "" when it read no time line
            t: float | None = float(a.getTime())
        except (TypeError, ValueError):
            t = None
        out: dict[str, Any] = {
            "log": log.name,
            "last_iteration": t,
            "initial_residuals": {k: v for k, v in lin.items() if "_" not in k},
            "continuity": cont,
        }
    except Exception as exc:  # noqa: BLE001 - optional cross-check only
        return {"log": log.name, "error": f"{type(exc).__name__}: {exc}"}
    if out["last_iteration"] is None:
        unit = parse_solver_log(log)["time_unit"]
        out["note"] = (
            f"PyFoam's analyzer read no time line of {log.name} (time unit {unit!r}); "
            "its residuals cannot be tied to an iteration"
        )
    if own:
        p_own, p_pf = own.get("p"), out["initial_residuals"].get("p")
        out["agrees_with_parser"] = bool(
            out["last_iteration"] == own.get("time")
            and p_own is not None
            and p_pf is not None
            and abs(float(p_pf) - float(p_own)) <= 1e-6 * max(abs(float(p_own)), 1e-300)
        )
    return out


def _collect(case_dir: Path, status: dict[str, Any], logs: list[Path], state: dict[str, Any]) -> None:
    """Add residuals, iterations, flow rates, mass imbalance, pressure drop and WSS to ``status``."""
    rows: list[dict[str, Any]] = []
    stage_iters = {}
    for lg in logs:
        if lg.exists():
            parsed = parse_solver_log(lg)
            rows += parsed["rows"]
            stage_iters[lg.name.replace("log.", "")] = len(parsed["rows"])
    status["stage_iterations"] = stage_iters
    if rows:
        _write_residuals(case_dir, rows)
        last = rows[-1]
        status["iterations"] = int(last["time"])
        status["final_residuals"] = {k: last[k] for k in ("p", "U") if k in last}
        status["continuity_errors"] = {
            k.replace("cont_", ""): last[k] for k in ("cont_local", "cont_global", "cont_cumulative") if k in last
        }
        if logs and logs[-1].name.endswith(".average"):
            avg_rows = parse_solver_log(logs[-1])["rows"]
            status["averaging"] = {
                "max_initial_residual": float(max(max(r.get("p", 0), r.get("U", 0)) for r in avg_rows))
                if avg_rows
                else None
            }
    last_log = [lg for lg in logs if lg.exists()][-1:]
    own_last = parse_solver_log(last_log[0])["rows"][-1:] if last_log else []
    status["pyfoam_log_analysis"] = _pyfoam_check(last_log[0], own_last[0] if own_last else None) if last_log else None
    rho = float(state["cfd"]["physics"]["rho"])
    avg_from = status.get("averaging_from")

    def fo_value(name: str) -> float | None:
        """Value of function object ``name`` (window mean in the fallback, else last)."""
        # fallback: mean over the averaging window (consistent with UMean/pMean); else last iteration
        if avg_from is not None:
            return mean_function_value(case_dir, name, avg_from)
        return last_function_value(case_dir, name)

    flows = {}
    for p in state["patches"]:
        if p["role"] in ("inlet", "outlet"):
            flows[p["name"]] = fo_value(f"flowRate_{p['name']}")
    status["flow_rates"] = flows
    q_in = sum(v for k, v in flows.items() if v is not None and patch_role(k) == "inlet")
    q_out = sum(v for k, v in flows.items() if v is not None and patch_role(k) == "outlet")
    if q_in:
        status["mass_imbalance"] = abs(q_in + q_out) / abs(q_in)
    pin = {p["name"]: fo_value(f"pressure_{p['name']}") for p in state["patches"] if p["role"] in ("inlet", "outlet")}
    status["patch_pressure"] = pin
    pi = [v for k, v in pin.items() if patch_role(k) == "inlet" and v is not None]
    po = [v for k, v in pin.items() if patch_role(k) == "outlet" and v is not None]
    if pi and po:
        dp = pi[0] - float(np.mean(po))
        status["pressure_drop"] = {"kinematic_m2s2": dp, "Pa": dp * rho}
    latest = _latest_time(case_dir)
    if latest and float(latest) > 0:
        wss_file = case_dir / latest / "wallShearStress"
        walls = [p["name"] for p in state["patches"] if p["role"] == "wall"]
        if wss_file.exists() and walls:
            try:
                vals, areas = [], []
                for w in walls:
                    v = _read_patch_vectors(wss_file, w)
                    _, sf = patch_geometry(case_dir, w)
                    a = np.linalg.norm(sf, axis=1)
                    if v is not None and len(v) == 1:
                        v = np.repeat(v, len(a), 0)
                    if v is not None and len(v) == len(a):
                        vals.append(np.linalg.norm(v, axis=1))
                        areas.append(a)
                if vals:
                    mag, a = np.concatenate(vals), np.concatenate(areas)
                    status["wall_shear_stress_Pa"] = {
                        "mean": float((mag * a).sum() / a.sum() * rho),
                        "max": float(mag.max() * rho),
                        "min": float(mag.min() * rho),
                    }
            except Exception as exc:  # noqa: BLE001
                status["wall_shear_stress_Pa"] = {"error": str(exc)}
