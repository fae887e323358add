"""The transient fallback, for a flow SIMPLE cannot settle: pimpleFoam from the last SIMPLE state,
a wash-out then an averaging window of flow-through times (fieldAverage), the stationarity test
of the time average (the window's two halves agree), the window doubled while it is not
stationary, and ``transient.png``."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from vcs.cfd.case import render_files
from vcs.cfd.foamfiles import function_series, parse_solver_log, read_internal_field, window_mean
from vcs.cfd.status import _log_summary, _wall_faces, _wall_values
from vcs.cfd.steady import STAGE_FILES, volume_l2_ratio
from vcs.cfd.utilities import Stop, _fmt_time, _Runner, _solver_failure, _time_dirs, progress

# a time folder: (solver time, folder name)
TimeDir = tuple[float, str]


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


def transient_fallback(
    case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner, ranks: int, prof: dict[str, Any]
) -> dict[str, Any]:
    """Run the transient fallback and judge its stationarity; fills ``status``; never raises.

    Wash-out, averaging window, stationarity test of its halves; a window that is not stationary
    is doubled (pimpleFoam continued, fieldAverage continuing its sums) and re-tested, at most
    ``transient.max_doublings`` times (``status["transient"]["extensions"]``).

    Parameters
    ----------
    case_dir : Path
        The case, after SIMPLE (decomposed when ``ranks`` > 1).
    state : dict
        Case description (``cfd.solver.transient``).
    status : dict
        The status being built; its ``reason`` says why SIMPLE did not do.
    run : _Runner
        Runs the utilities in the case.
    ranks : int
        MPI ranks.
    prof : dict
        The inlet profile (``peak_velocity``).

    Returns
    -------
    dict
        The ``status["transient"]`` dict (``evaluated`` true when the half-window test ran).
    """
    simple_reason = status["reason"]
    tr: dict[str, Any] = {"solver": "pimpleFoam", "evaluated": False, "steady_not_converged": simple_reason}
    status["transient"] = tr
    status["criterion_used"] = "none"
    try:
        plan, root = _start_from_simple(case_dir, state, status, tr, ranks, prof)
        common = _pimple_settings(plan)
        _run_washout_and_window(case_dir, state, run, ranks, plan, common, tr)
        mid, end = _window_folders(case_dir, run, ranks, plan, tr, root)
        verdict = stationarity(case_dir, state, plan, mid[1], end[1], float(prof["peak_velocity"]))
        _log_verdict(plan, verdict)
        plan, verdict = _double_until_stationary(
            case_dir, state, run, ranks, prof, plan, common, tr, root, end, verdict
        )
        _record_verdict(case_dir, state, status, tr, plan, verdict, simple_reason)
        return tr
    except Stop as stop:
        return _fail(case_dir, status, tr, simple_reason, stop.reason, stop.failed_log)
    except Exception as exc:  # noqa: BLE001 - the fallback never raises: its failure is a reason
        return _fail(case_dir, status, tr, simple_reason, f"{type(exc).__name__}: {' '.join(str(exc).split())}")


def _fail(
    case_dir: Path,
    status: dict[str, Any],
    tr: dict[str, Any],
    simple_reason: str | None,
    why: str | None,
    log: str | None = None,
) -> dict[str, Any]:
    """The fallback failed: the reason (SIMPLE's, then why the fallback failed) and the failed log."""
    status["reason"] = f"{simple_reason}; transient fallback: {why}"
    if log:
        status["failed_log"] = str(case_dir / "logs" / f"log.{log}")
    return tr


def _start_from_simple(
    case_dir: Path, state: dict[str, Any], status: dict[str, Any], tr: dict[str, Any], ranks: int, prof: dict[str, Any]
) -> tuple[dict[str, Any], Path]:
    """The plan of the fallback (:func:`transient_plan`) from the last SIMPLE time folder, logged
    and recorded in ``tr``; that folder made ready for the restart. Returns (plan, the folder
    holding the time folders: the case, or processor0)."""
    volume = status.get("lumen_volume_m3")
    if not volume:
        raise Stop("lumen volume unknown (checkMesh printed no 'Total volume'), no flow-through time")
    root = case_dir / "processor0" if ranks > 1 else case_dir
    times = _time_dirs(root)
    if not times or times[-1][0] <= 0:
        raise Stop("the SIMPLE stage wrote no time folder to start from")
    plan = transient_plan(state, float(volume), times[-1][0], float(prof["peak_velocity"]))
    tr.update(plan)
    tr["started_from"] = f"SIMPLE iteration {times[-1][1]}"
    progress.info(
        "steady SIMPLE not converged (%s): transient fallback from iteration %s, flow-through time "
        "%.3g s, wash-out %.3g s, window %.3g s (%.3g flow-through times), solver time %s to %s",
        tr["steady_not_converged"],
        times[-1][1],
        plan["flow_through_time_s"],
        plan["washout_s"],
        plan["window_s"],
        plan["window_flow_throughs"],
        _fmt_time(plan["start_time"]),
        _fmt_time(plan["end_time"]),
    )
    # the restart would take the time step of the SIMPLE stage (1) from <time>/uniform/time:
    # without that file the controlDict's deltaT applies, lowered to max_co by pimpleFoam
    for t_dir in [case_dir / times[-1][1]] + [d / times[-1][1] for d in case_dir.glob("processor*")]:
        (t_dir / "uniform" / "time").unlink(missing_ok=True)
    return plan, root


def _pimple_settings(plan: dict[str, Any]) -> dict[str, Any]:
    """The controlDict/fvSolution settings of every pimpleFoam stage (:func:`render_files` keywords)."""
    return {
        "transient": True,
        "residual_control": False,
        "delta_t": _fmt_time(plan["delta_t_initial_s"]),
        "max_delta_t": _fmt_time(plan["max_delta_t_s"]),
    }


def _run_washout_and_window(
    case_dir: Path,
    state: dict[str, Any],
    run: _Runner,
    ranks: int,
    plan: dict[str, Any],
    common: dict[str, Any],
    tr: dict[str, Any],
) -> None:
    """pimpleFoam: the wash-out (when there is one), then the averaging window (fieldAverage,
    written at its middle and end); time steps, Courant number, time steps and the last log in
    ``tr``. Raises :class:`Stop` when a stage fails."""
    steps: dict[str, int] = {}
    tr["time_steps"] = steps
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
            raise Stop(_solver_failure(case_dir / "logs" / f"log.{log}", name, "pimpleFoam"), log)
    tr["courant_max"] = parsed["courant_max"]
    tr["delta_t_s"] = {"min": parsed["delta_t_min"], "max": parsed["delta_t_max"]}
    tr["solver_log"] = _log_summary(parsed, case_dir / "logs" / "log.pimpleFoam.average")
    if parsed["rows"]:
        tr["final_residuals"] = {k: parsed["rows"][-1][k] for k in ("p", "U") if k in parsed["rows"][-1]}


def _window_folders(
    case_dir: Path, run: _Runner, ranks: int, plan: dict[str, Any], tr: dict[str, Any], root: Path
) -> tuple[TimeDir, TimeDir]:
    """The time folders at the middle and at the end of the averaging window (as planned,
    reconstructed when ``ranks`` > 1); their names in ``tr``. Raises :class:`Stop` when they are
    missing or off the plan."""
    written = [t for t in _time_dirs(root) if t[0] > plan["averaging_start_time"] + 1e-9]
    if not written:
        raise Stop("the averaging stage wrote no time folder", "pimpleFoam.average")
    mid = min(written, key=lambda t: abs(t[0] - plan["mid_time"]))
    end = written[-1]
    slack = 1e-3 * plan["window_s"]  # write times are hit exactly (adjustableRunTime), names rounded
    if abs(end[0] - plan["end_time"]) > slack or abs(mid[0] - plan["mid_time"]) > slack:
        raise Stop(
            f"the averaging stage ended at {end[1]} (planned {_fmt_time(plan['end_time'])}), middle write at "
            f"{mid[1]} (planned {_fmt_time(plan['mid_time'])})",
            "pimpleFoam.average",
        )
    if ranks > 1:
        if run(["reconstructPar", "-time", f"{mid[1]},{end[1]}"], "reconstructPar").returncode != 0:
            raise Stop("reconstructPar failed", "reconstructPar")
    tr["mid_time_folder"], tr["end_time_folder"] = mid[1], end[1]
    return mid, end


def _double_until_stationary(
    case_dir: Path,
    state: dict[str, Any],
    run: _Runner,
    ranks: int,
    prof: dict[str, Any],
    plan: dict[str, Any],
    common: dict[str, Any],
    tr: dict[str, Any],
    root: Path,
    end: TimeDir,
    verdict: dict[str, Any],
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Not stationary: double the window, continuing the average, at most ``max_doublings`` times
    (each in ``tr["extensions"]``, each judged by :func:`stationarity`). Returns the last plan and
    verdict; raises :class:`Stop` when an extension fails."""
    doublings = int(state["cfd"]["solver"]["transient"].get("max_doublings") or 0)
    slack = 1e-3 * plan["window_s"]  # of the first window, as for its folders
    extensions: list[dict[str, Any]] = []
    tr["extensions"] = extensions
    while not verdict["stationary"] and len(extensions) < doublings:
        extensions.append({"window_flow_throughs": plan["window_flow_throughs"], **verdict["half_window_differences"]})
        plan, last = _extend_window(case_dir, state, run, ranks, plan, common, tr, root, slack, doublings)
        mid, end = end, last
        tr["mid_time_folder"], tr["end_time_folder"] = mid[1], end[1]
        verdict = stationarity(case_dir, state, plan, mid[1], end[1], float(prof["peak_velocity"]))
        _log_verdict(plan, verdict)
    return plan, verdict


def _extend_window(
    case_dir: Path,
    state: dict[str, Any],
    run: _Runner,
    ranks: int,
    plan: dict[str, Any],
    common: dict[str, Any],
    tr: dict[str, Any],
    root: Path,
    slack: float,
    doublings: int,
) -> tuple[dict[str, Any], TimeDir]:
    """One doubling of the window (the ``len(tr["extensions"])``-th): pimpleFoam continued for
    the window's length, fieldAverage continuing its sums; the doubled plan and the solver's
    numbers in ``tr``. Returns (the doubled plan, the new end's time folder)."""
    n = len(tr["extensions"])
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
        n,
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
    log = f"pimpleFoam.extend{n}"
    r = run(["pimpleFoam"], log, ranks)
    parsed = parse_solver_log(case_dir / "logs" / f"log.{log}")
    tr["time_steps"][f"extend{n}"] = len(parsed["rows"])
    if r.returncode != 0:
        raise Stop(_solver_failure(case_dir / "logs" / f"log.{log}", log, "pimpleFoam"), log)
    last = _time_dirs(root)[-1]
    if abs(last[0] - plan["end_time"]) > slack:
        raise Stop(f"the window extension ended at {last[1]} (planned {_fmt_time(plan['end_time'])})", log)
    if ranks > 1 and run(["reconstructPar", "-time", last[1]], "reconstructPar").returncode != 0:
        raise Stop("reconstructPar failed", "reconstructPar")
    tr["courant_max"] = max(tr["courant_max"] or 0.0, parsed["courant_max"] or 0.0)
    lo = [x for x in (tr["delta_t_s"]["min"], parsed["delta_t_min"]) if x is not None]
    hi = [x for x in (tr["delta_t_s"]["max"], parsed["delta_t_max"]) if x is not None]
    tr["delta_t_s"] = {"min": min(lo) if lo else None, "max": max(hi) if hi else None}
    tr["solver_log"] = _log_summary(parsed, case_dir / "logs" / f"log.{log}")
    if parsed["rows"]:
        tr["final_residuals"] = {k: parsed["rows"][-1][k] for k in ("p", "U") if k in parsed["rows"][-1]}
    return plan, last


def _record_verdict(
    case_dir: Path,
    state: dict[str, Any],
    status: dict[str, Any],
    tr: dict[str, Any],
    plan: dict[str, Any],
    verdict: dict[str, Any],
    simple_reason: str | None,
) -> None:
    """The last window's verdict in ``tr`` and ``status`` (the time-averaged fields are the
    result; converged when stationary), and ``transient.png``."""
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
    dp1, dp2, dpw = _half_window_pressures(case_dir, state, plan)
    dp_scale = max(abs(dpw), 0.1 * 0.5 * peak_velocity**2)
    tm1, tm2, tmw = _half_window_tawss(case_dir, state, mid, end)
    l2 = _half_window_velocity(case_dir, mid, end)
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
        out["why"] = _not_stationary_why(plan, diffs, tols, bad)
    return out


def _half_window_pressures(case_dir: Path, state: dict[str, Any], plan: dict[str, Any]) -> tuple[float, float, float]:
    """The inlet-outlet pressure difference (kinematic) over the first half, the second half and
    the whole averaging window (see :func:`stationarity`)."""
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

    return dp(t_w, t_m), dp(t_m, t_e), dp(t_w, t_e)


def _half_window_tawss(case_dir: Path, state: dict[str, Any], mid: str, end: str) -> tuple[float, float, float]:
    """The area-mean TAWSS (kinematic) of the first half, the second half and the whole window
    (see :func:`stationarity`)."""
    # TAWSS: area-mean of magWallShearStressMean (linear in the mean, so second half = 2 M - M1)
    walls = _wall_faces(case_dir, state)
    area = np.concatenate([a for _, a in walls])
    tm1 = float((_wall_values(case_dir / mid, "magWallShearStressMean", walls) * area).sum() / area.sum())
    tmw = float((_wall_values(case_dir / end, "magWallShearStressMean", walls) * area).sum() / area.sum())
    tm2 = 2.0 * tmw - tm1
    return tm1, tm2, tmw


def _half_window_velocity(case_dir: Path, mid: str, end: str) -> float:
    """Volume-weighted L2 norm of the second half's mean U minus the first half's, relative to
    that of the window's (see :func:`stationarity`)."""
    # U: volume-weighted L2
    vol = read_internal_field(case_dir / end / "V")
    u1 = read_internal_field(case_dir / mid / "UMean", len(vol))
    uw = read_internal_field(case_dir / end / "UMean", len(vol))
    if u1.shape != uw.shape or len(uw) != len(vol):
        raise ValueError(f"UMean ({u1.shape}, {uw.shape}) and V ({vol.shape}) do not match")
    u2 = 2.0 * uw - u1
    return volume_l2_ratio(vol, u2 - u1, uw)


def _not_stationary_why(plan: dict[str, Any], diffs: dict[str, float], tols: dict[str, float], bad: list[str]) -> str:
    """The reason of a window that is not stationary, in one line (see :func:`stationarity`)."""
    return (
        f"time average not stationary: the two halves of the {plan['window_s']:.4g} s averaging window "
        f"({plan['window_flow_throughs']:.3g} flow-through times of {plan['flow_through_time_s']:.3g} s, after a "
        f"{plan['washout_s']:.3g} s wash-out) differ by "
        + ", ".join(f"{100 * diffs[k]:.3g} % in {_HALF_WORDS[k]} (tolerance {100 * tols[k]:g} %)" for k in bad)
        + "; lengthen cfd.solver.transient.flow_throughs or max_doublings (or washout_flow_throughs)"
    )


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
