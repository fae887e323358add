"""Collecting a run's results into ``status.json``: the solver logs (residuals, iterations,
``residuals.csv/png``, PyFoam's cross-check), flow rates, mass imbalance, patch pressures and the
inlet-outlet pressure difference, WSS on the wall (time-averaged: TAWSS and OSI), and writing the
file at the end of a run."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vcs.cfd.case import patch_role
from vcs.cfd.foamfiles import (
    function_series,
    last_function_value,
    oscillatory_shear_index,
    parse_solver_log,
    patch_geometry,
    read_patch_field,
    window_mean,
)
from vcs.cfd.outlets import outlet_plan, outlet_summary, pressure_outlets
from vcs.cfd.utilities import _latest_time

N_WAVEFORM = 200
"""Phase points of an rcr outlet's last-cycle flow and pressure waveforms in status.json."""


def _json_safe(obj: Any) -> Any:
    """``obj`` with every non-finite float (an error bar not known yet: inf; NaN) as None, so that
    status.json is strict JSON (json.dumps would write the non-standard Infinity/NaN tokens)."""
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, (float, np.floating)) and not np.isfinite(obj):
        return None
    return obj


def finish(
    case_dir: Path, status: dict[str, Any], reason: str | None = None, failed_log: str | None = None
) -> dict[str, Any]:
    """Record the reason and the failed utility's log, write status.json, return the status.

    Parameters
    ----------
    case_dir : Path
        The case.
    status : dict
        The status of the run (``timings_s`` gets its ``total``).
    reason : str or None
        Why the run ended where it did (None: keep ``status["reason"]``).
    failed_log : str or None
        The utility that failed: ``failed_log`` is the absolute path of ``logs/log.<failed_log>``.

    Returns
    -------
    dict
        ``status``, as written.
    """
    if reason:
        status["reason"] = reason
    if failed_log:  # the log of the utility that failed (absolute path), for the user and the atlas
        status["failed_log"] = str(case_dir / "logs" / f"log.{failed_log}")
    timings = status["timings_s"]
    timings["total"] = round(sum(v for k, v in timings.items() if k != "total"), 3)
    (case_dir / "status.json").write_text(json.dumps(_json_safe(status), indent=2, default=float))
    return status


def collect(
    case_dir: Path,
    status: dict[str, Any],
    logs: list[Path],
    state: dict[str, Any],
    window: tuple[float, float] | None = None,
) -> None:
    """Add residuals, iterations, flow rates, mass imbalance, the inlet-outlet pressure difference
    and WSS (time-averaged: TAWSS and OSI too) to ``status``.

    Parameters
    ----------
    case_dir : Path
        The case.
    status : dict
        The status being built (``fields`` says which field files hold the result).
    logs : list of Path
        The SIMPLE stages' logs (residuals, iterations).
    state : dict
        Case description.
    window : (float, float) or None
        The averaging window (solver times, s) of a time-averaged result: flow rates and patch
        pressures are time-weighted means over it; None: the last value.
    """
    _collect_logs(case_dir, status, logs)
    _collect_patches(case_dir, status, state, window)
    _collect_outlets(case_dir, status, state, window)
    _collect_wall_shear(case_dir, status, state)


def _collect_logs(case_dir: Path, status: dict[str, Any], logs: list[Path]) -> None:
    """Iterations per stage, the last residuals and continuity errors, ``residuals.csv/png`` and
    PyFoam's reading of the last log (see :func:`collect`)."""
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
    last_log = [lg for lg in logs if lg.exists()][-1:]
    own_last = parse_solver_log(last_log[0])["rows"][-1:] if last_log else []
    status["pyfoam_log_analysis"] = _pyfoam_check(last_log[0], own_last[0] if own_last else None) if last_log else None


def _collect_patches(
    case_dir: Path, status: dict[str, Any], state: dict[str, Any], window: tuple[float, float] | None
) -> None:
    """Flow rates, mass imbalance, patch pressures and the inlet-outlet pressure difference from
    the function objects (see :func:`collect`)."""
    rho = float(state["cfd"]["physics"]["rho"])

    def fo_value(name: str) -> float | None:
        """Value of function object ``name``: mean over the averaging window, else the last one."""
        if window is not None:
            return window_mean(case_dir, name, *window)
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
    main = pressure_outlets(state["patches"])
    po = [v for k, v in pin.items() if k in main and v is not None]
    if pi and po:
        dp = pi[0] - float(np.mean(po))
        status["inlet_minus_outlet_pressure"] = {
            "kinematic_m2s2": dp,
            "Pa": dp * rho,
            "definition": "area-mean p on the inlet minus the mean of the main outlets' area-mean p"
            + (f" ({', '.join(main)}; the branches left out)" if len(main) < len(pin) - len(pi) else "")
            + (" (time-weighted over the averaging window)" if window is not None else ""),
            "pressure_recovery": bool(dp < 0),  # p rises downstream (e.g. after the jet): not a drop
        }


MMHG_PA = 133.322387415
"""1 mmHg in Pa."""


def cycle_pressures_mmhg(pressure_pa: list[float]) -> dict[str, float]:
    """Systolic (largest), diastolic (smallest) and mean (the average over the cycle's equally
    spaced phase points: its time mean) of one cycle's pressure waveform, in mmHg."""
    p = np.asarray(pressure_pa, dtype=float) / MMHG_PA
    return {"systolic": float(p.max()), "diastolic": float(p.min()), "mean": float(p.mean())}


def write_outlet_waveforms(case_dir: Path, outlets: list[dict[str, Any]]) -> None:
    """``outlets_last_cycle.csv`` (phase, then each outlet's flow in mL/s and pressure in mmHg over
    the last cycle) and ``outlets_last_cycle.png`` (both against the phase, one line per outlet) in
    the case folder, from status.json's ``outlets[*].last_cycle``."""
    have = [o for o in outlets if o.get("last_cycle")]
    if not have:
        return
    phase = np.asarray(have[0]["last_cycle"]["phase"])
    cols = [phase]
    header = ["phase"]
    for o in have:
        cols += [
            np.asarray(o["last_cycle"]["flow_rate_m3_s"]) * 1e6,
            np.asarray(o["last_cycle"]["pressure_pa"]) / MMHG_PA,
        ]
        header += [f"{o['name']}_flow_ml_s", f"{o['name']}_pressure_mmhg"]
    np.savetxt(
        case_dir / "outlets_last_cycle.csv",
        np.column_stack(cols),
        delimiter=",",
        header=",".join(header),
        comments="",
        fmt="%.8g",
    )
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6), layout="constrained")
    for o in have:
        lc = o["last_cycle"]
        pm = o.get("pressure_mmhg") or {}
        label = f"{o['name']} ({100 * (o.get('fraction') or 0):.0f} %)"
        ax[0].plot(lc["phase"], np.asarray(lc["flow_rate_m3_s"]) * 1e6, label=label)
        ax[1].plot(
            lc["phase"],
            np.asarray(lc["pressure_pa"]) / MMHG_PA,
            label=f"{o['name']} ({pm.get('systolic', 0):.0f}/{pm.get('diastolic', 0):.0f}, "
            f"mean {pm.get('mean', 0):.0f})",
        )
    ax[0].set(xlabel="phase of the last cycle", ylabel="outlet flow [mL/s]", title="flow (mean split)")
    ax[1].set(xlabel="phase of the last cycle", ylabel="outlet pressure [mmHg]", title="pressure (sys/dia, mean)")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.savefig(case_dir / "outlets_last_cycle.png", dpi=110)
    plt.close(fig)


def _collect_outlets(
    case_dir: Path,
    status: dict[str, Any],
    state: dict[str, Any],
    window: tuple[float, float] | None,
) -> None:
    """status.json ``outlets`` (per outlet: flow, fraction of the inflow and its target, mean
    pressure; rcr: R_p, C, R_d and, pulsatile, the last cycle's flow and pressure waveforms) and
    ``outlet_mass_balance`` (:func:`vcs.cfd.outlets.outlet_summary`), from the flow rates and
    pressures :func:`_collect_patches` put in ``status`` (means over the window)."""
    plan = state.get("outlets")
    if plan is None:  # a state rendered before the outlet plan: free outlets
        areas = {s["name"]: s["area_m2"] for s in state.get("solids", [])}
        names = [p["name"] for p in state["patches"] if p["role"] == "outlet"]
        plan = outlet_plan(names, [areas.get(n, 1.0) for n in names], {"type": "free"}, flow_rate=1.0, rho=1.0)
    flows = status.get("flow_rates") or {}
    q_in = -sum(v for k, v in flows.items() if v is not None and patch_role(k) == "inlet")
    rho = float(state["cfd"]["physics"]["rho"])
    outlets, balance = outlet_summary(plan, flows, status.get("patch_pressure") or {}, q_in or None, rho)
    wf = state.get("waveform")
    if wf and window is not None:
        t1 = float(window[1])
        phase = (np.arange(N_WAVEFORM) + 0.5) / N_WAVEFORM
        tq = t1 - float(wf["period_s"]) * (1.0 - phase)
        for o in outlets:
            q = function_series(case_dir, f"flowRate_{o['name']}")
            p = function_series(case_dir, f"pressure_{o['name']}")
            if len(q) and len(p):
                o["last_cycle"] = {
                    "phase": [float(x) for x in phase],
                    "flow_rate_m3_s": [float(x) for x in np.interp(tq, q[:, 0], q[:, 1])],
                    "pressure_pa": [float(x) * rho for x in np.interp(tq, p[:, 0], p[:, 1])],
                }
                o["pressure_mmhg"] = cycle_pressures_mmhg(o["last_cycle"]["pressure_pa"])
        write_outlet_waveforms(case_dir, outlets)
    status["outlets"] = outlets
    status["outlet_mass_balance"] = balance


def _collect_wall_shear(case_dir: Path, status: dict[str, Any], state: dict[str, Any]) -> None:
    """WSS on the wall at the latest time (time-averaged: TAWSS and OSI too; see :func:`collect`)."""
    rho = float(state["cfd"]["physics"]["rho"])
    latest = _latest_time(case_dir)
    fields = status.get("fields") or {}
    if latest and float(latest) > 0:
        try:
            walls = _wall_faces(case_dir, state)
            if not walls:
                return
            a = np.concatenate([w[1] for w in walls])
            tdir = case_dir / latest
            wss_name = fields.get("WSS", "wallShearStress")
            if not (tdir / wss_name).exists():
                return
            mean_vec = _wall_values(tdir, wss_name, walls)
            mag = np.linalg.norm(mean_vec, axis=1)

            def stats(x: NDArray[np.floating], scale: float) -> dict[str, float]:
                return {
                    "mean": float((x * a).sum() / a.sum() * scale),
                    "max": float(x.max() * scale),
                    "min": float(x.min() * scale),
                }

            status["wall_shear_stress_Pa"] = stats(mag, rho) | {"field": wss_name}
            tawss_name = fields.get("TAWSS")
            if tawss_name and (tdir / tawss_name).exists():
                tawss = _wall_values(tdir, tawss_name, walls)
                status["tawss_Pa"] = stats(tawss, rho) | {"field": tawss_name}
                osi = oscillatory_shear_index(mean_vec, tawss)
                status["osi"] = {"mean": float((osi * a).sum() / a.sum()), "max": float(osi.max())}
        except Exception as exc:  # noqa: BLE001
            status["wall_shear_stress_Pa"] = {"error": str(exc)}


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


def _wall_faces(case_dir: Path, state: dict[str, Any]) -> list[tuple[str, NDArray[np.floating]]]:
    """(name, face areas m^2) of the wall patches."""
    out = []
    for p in state["patches"]:
        if p["role"] == "wall":
            _, sf = patch_geometry(case_dir, p["name"])
            out.append((p["name"], np.linalg.norm(sf, axis=1)))
    return out


def _wall_values(time_dir: Path, field: str, walls: list[tuple[str, NDArray[np.floating]]]) -> NDArray[np.floating]:
    """A field's values on all wall faces (concatenated in ``walls`` order)."""
    vals = []
    for name, a in walls:
        v = read_patch_field(time_dir / field, name, len(a))
        if v is None or len(v) != len(a):
            raise ValueError(f"{time_dir.name}/{field} has no values for patch {name!r}")
        vals.append(v)
    return np.concatenate(vals)
