"""The transient solve, for a flow SIMPLE cannot settle: pimpleFoam from the last SIMPLE state, a
wash-out, then an averaging window (fieldAverage) that ends as soon as its means are known to the
stated tolerance (:mod:`vcs.cfd.timeseries`: batch means with the integral time scale), or at its
longest; the verdict with an error bar on each time average, and ``transient.png``.

The time step is set by the cells the flow crosses (:func:`courant_plan`): cells cut thin by the
snapped inlet and outlet planes (slivers a tenth of a cell deep along the flow) would otherwise
set pimpleFoam's Courant-limited step for the whole lumen.
"""

from __future__ import annotations

import logging
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vcs.cfd.case import render_files
from vcs.cfd.foamfiles import function_series, parse_solver_log, patch_geometry, read_internal_field
from vcs.cfd.openfoam import FLAVOURS
from vcs.cfd.status import _log_summary, _wall_faces
from vcs.cfd.steady import STAGE_FILES, request_write_now
from vcs.cfd.timeseries import mean_error, mser_truncation, uniform_record
from vcs.cfd.utilities import Stop, _fmt_time, _Runner, _solver_failure, _time_dirs, progress, time_precision

log = logging.getLogger(__name__)

N_PROBES = 64
"""Cells whose velocity is recorded at every time step (drawn by volume: the root mean square over
them estimates the volume L2 norm, the U criterion of the window)."""

END_PLANE_CELLS = 1.5
"""Cells closer to an inlet or outlet plane than this many of their own sizes are end-plane cells
(:func:`courant_plan`)."""

CHECK_EVERY_S = 15.0
"""Wall-clock seconds between two looks of :class:`AverageWatch` at the window's records."""


@dataclass
class _Pimple:
    """What every pimpleFoam stage of one transient solve shares: the case, its description, the
    runner, the MPI ranks, the folder holding the time folders (the case or processor0), the
    stages' template settings and the ``status["transient"]`` dict being filled."""

    case_dir: Path
    state: dict[str, Any]
    run: _Runner
    ranks: int
    root: Path
    common: dict[str, Any]
    tr: dict[str, Any]


def _round_up(x: float, digits: int = 3) -> float:
    """``x`` > 0 rounded up to ``digits`` significant digits (short time-folder names)."""
    if x <= 0:
        return 0.0
    e = math.floor(math.log10(x)) - digits + 1
    return math.ceil(x / 10.0**e - 1e-9) * 10.0**e


def transient_plan(state: dict[str, Any], volume: float, start_time: float, peak_velocity: float) -> dict[str, Any]:
    """The wash-out and the averaging window of the transient solve, from the flow-through time.

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
        ``flow_through_time_s`` = volume / flow rate; ``washout_s``, ``min_window_s``,
        ``max_window_s`` (rounded up to 3 significant digits) and the same in flow-through times;
        solver times ``start_time``, ``averaging_start_time``, ``min_end_time``, ``max_end_time``;
        ``delta_t_initial_s`` (max_co x smallest cell / peak velocity; pimpleFoam lowers it
        when the Courant number asks), ``max_delta_t_s`` (a fiftieth of a flow-through time and
        a twentieth of the shortest window).
    """
    cfd = state["cfd"]
    tr = cfd["solver"]["transient"]
    t_ft = volume / float(state["flow_rate"])
    washout = _round_up(float(tr["washout_flow_throughs"]) * t_ft)
    washout_min = min(_round_up(float(tr["min_washout_flow_throughs"]) * t_ft), washout)
    w_min = _round_up(float(tr["min_flow_throughs"]) * t_ft)
    w_max = max(_round_up(float(tr["max_flow_throughs"]) * t_ft), w_min)
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
        "min_washout_s": washout_min,
        "max_washout_s": washout,
        "min_window_s": w_min,
        "min_window_flow_throughs": w_min / t_ft,
        "max_window_s": w_max,
        "max_window_flow_throughs": w_max / t_ft,
        "start_time": start_time,
        "averaging_start_time": t_w,
        "min_end_time": t_w + w_min,
        "max_end_time": t_w + w_max,
        "delta_t_initial_s": float(tr["max_co"]) * h_min / max(peak_velocity, 1e-12),
        "max_delta_t_s": min(0.02 * t_ft, 0.05 * w_min),
    }


def transient_fallback(
    case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner, ranks: int, prof: dict[str, Any]
) -> dict[str, Any]:
    """Run the transient solve and judge its time average; fills ``status``; never raises.

    Wash-out, then the averaging window: it ends once ``min_flow_throughs`` have passed and the
    means of the inlet-outlet pressure difference, of the area-mean |WSS| and of U are known to
    ``error_tolerance`` / ``error_tolerance_U`` (:func:`window_statistics`), else at
    ``max_flow_throughs``, not stationary.

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
        The ``status["transient"]`` dict (``evaluated`` true when the window was judged).
    """
    simple_reason = status["reason"]
    tr: dict[str, Any] = {"solver": "pimpleFoam", "evaluated": False, "steady_not_converged": simple_reason}
    status["transient"] = tr
    status["criterion_used"] = "none"
    try:
        plan, root = _start_from_simple(case_dir, state, status, tr, ranks, prof)
        sol = state["cfd"]["solver"]  # a case rendered before the transient key: the solver's, as then
        n_non_orth = sol["transient"].get("non_orthogonal_correctors", sol["n_non_orthogonal_correctors"])
        common = _pimple_settings(plan) | {"pimple_non_orthogonal_correctors": int(n_non_orth)}
        # the controlDict the Courant numbers are computed with (deltaT: the initial time step)
        render_files(
            case_dir, state, STAGE_FILES, end_time=_fmt_time(plan["max_end_time"]), write_interval="1", **common
        )
        cour = courant_plan(case_dir, state, run, ranks, root, plan)
        tr["courant"] = {k: v for k, v in cour.items() if k != "probe_points"}
        common.update(max_co=cour["pimple_max_co"], outer_correctors=cour["outer_correctors"])
        if cour["delta_t_expected_s"]:  # the first step at the Courant limit of the SIMPLE state, not the
            # inlet's (a coarctation jet is 5x faster than the inflow: Co 9 in the first step otherwise)
            common["delta_t"] = _fmt_time(min(cour["delta_t_expected_s"], plan["max_delta_t_s"]))
        peak = float(prof["peak_velocity"])
        common["probe_points"] = cour["probe_points"]
        solve = _Pimple(case_dir, state, run, ranks, root, common, tr)
        plan = _run_washout(solve, plan)
        end = _run_window(solve, plan, peak)
        verdict = window_statistics(case_dir, state, plan["averaging_start_time"], end[0], peak)
        _log_verdict(verdict)
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
        "steady SIMPLE not converged (%s): transient solve from iteration %s, flow-through time %.3g s, "
        "wash-out %.3g s, averaging window %.3g-%.3g s (%.3g-%.3g flow-through times; it ends when its means "
        "are known to the tolerance)",
        tr["steady_not_converged"],
        times[-1][1],
        plan["flow_through_time_s"],
        plan["washout_s"],
        plan["min_window_s"],
        plan["max_window_s"],
        plan["min_window_flow_throughs"],
        plan["max_window_flow_throughs"],
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


def _cell_fields(case_dir: Path, ranks: int, time_name: str, names: tuple[str, ...]) -> list[NDArray[np.floating]]:
    """Internal fields of a time folder, the processors' concatenated when ``ranks`` > 1 (the
    order does not matter to the callers: per-cell values side by side)."""
    roots = [case_dir] if ranks <= 1 else sorted(case_dir.glob("processor*"), key=lambda p: int(p.name[9:]))
    out: list[list[NDArray[np.floating]]] = [[] for _ in names]
    for r in roots:
        n = None
        for i, name in enumerate(names):
            v = read_internal_field(r / time_name / name, n)
            n = len(v)
            out[i].append(v)
    return [np.concatenate(v) for v in out]


def end_plane_cells(
    centres: NDArray[np.floating],
    volumes: NDArray[np.floating],
    planes: list[tuple[NDArray[np.floating], NDArray[np.floating], float]],
) -> NDArray[np.bool_]:
    """Cells at an end patch: within :data:`END_PLANE_CELLS` of their own size (cube root of the
    volume) from its plane (centroid, unit normal) and, in the plane, within the patch's radius
    (the largest distance of its faces from the centroid) plus two own sizes: the cells snapping
    cuts into slivers. (The plane alone would also take the lumen it crosses elsewhere: an aortic
    root's inlet plane cuts the descending aorta.)"""
    h = np.cbrt(volumes)
    near = np.zeros(len(centres), dtype=bool)
    for c, n, radius in planes:
        d = centres - c
        normal = d @ n
        in_plane = np.linalg.norm(d - normal[:, None] * n, axis=1)
        near |= (np.abs(normal) < END_PLANE_CELLS * h) & (in_plane < radius + 2.0 * h)
    return near


def courant_plan(
    case_dir: Path,
    state: dict[str, Any],
    run: _Runner,
    ranks: int,
    root: Path,
    plan: dict[str, Any],
    *,
    limits: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The Courant number limit of pimpleFoam, set by the cells the flow crosses, and the probe cells.

    The Courant number of each cell, Co = 0.5 sum_f |phi_f| dt / V (OpenFOAM's ``CourantNo``),
    is computed on the SIMPLE state. Where the snapped inlet or outlet plane cuts a background
    cell, snappyHexMesh leaves a sliver a fraction of a cell deep along the flow, whose Courant
    number is several times that of any cell the flow crosses (AortaCFD patient1: 4 outlet-plane
    cells at 2.2x the largest elsewhere held its time step at 8.6e-5 s). pimpleFoam limits the
    largest Co over all cells, so the limit it is given is ``max_co`` x (largest Co / largest Co
    away from the end planes, :func:`end_plane_cells`), at most ``max_co_end_cells``: the cells
    the flow crosses run at ``max_co``, the end-plane slivers above it, and then with
    ``outer_correctors`` PIMPLE outer correctors (a few cells above Co 1 in the flow extensions,
    outside the measured section).

    ``limits``: ``max_co``, ``max_co_end_cells`` and ``outer_correctors`` (default
    ``cfd.solver.transient``; a pulsatile run passes ``cfd.pulsatile``'s and calls this on its
    state at peak systole). The time step of the Courant numbers is the one stored with the state
    (``<time>/uniform/time``), else the controlDict's (``plan["delta_t_initial_s"]``).

    Returns
    -------
    dict
        ``courant_per_s_max`` (largest Co / dt over all cells, 1/s), ``courant_per_s_interior``
        (away from the end planes), ``end_plane_factor`` (their ratio, >= 1),
        ``end_plane_cells`` (how many end-plane cells exceed the interior's largest Co),
        ``pimple_max_co``, ``outer_correctors``, ``delta_t_expected_s`` (pimpleFoam's time step on
        the SIMPLE state), ``probe_points`` ((N, 3) m: :data:`N_PROBES` cells away from the end
        planes, drawn with probability proportional to their volume, seed 0).
    """
    tr = limits if limits is not None else state["cfd"]["solver"]["transient"]
    t_name = _time_dirs(root)[-1][1]
    stored = root / t_name / "uniform" / "time"
    m = re.search(
        r"^\s*deltaT\s+([-+0-9.eE]+)\s*;", stored.read_text(errors="replace") if stored.exists() else "", re.M
    )
    dt_used = float(m.group(1)) if m else float(plan["delta_t_initial_s"])
    funcs = "(CourantNo writeCellCentres writeCellVolumes)"
    if run(["postProcess", "-funcs", funcs, "-time", t_name], "postProcess.courant", ranks).returncode != 0:
        raise Stop(
            "postProcess (CourantNo, cell centres and volumes on the SIMPLE state) failed", "postProcess.courant"
        )
    co, centres, vols = _cell_fields(case_dir, ranks, t_name, ("Co", "C", "V"))
    per_s = co / dt_used  # Co per second of time step
    planes = []
    for p in state["patches"]:
        if p["role"] in ("inlet", "outlet"):
            c, sf = patch_geometry(case_dir, p["name"])
            a = np.linalg.norm(sf, axis=1)
            n = sf.sum(axis=0)
            centre = (c * a[:, None]).sum(axis=0) / a.sum()
            planes.append((centre, n / np.linalg.norm(n), float(np.linalg.norm(c - centre, axis=1).max())))
    near = end_plane_cells(centres, vols, planes)
    c_max = float(per_s.max())
    c_in = float(per_s[~near].max()) if (~near).any() else c_max
    factor = max(c_max / c_in, 1.0) if c_in > 0 else 1.0
    max_co = float(tr["max_co"])
    pimple_co = min(max_co * factor, max(float(tr["max_co_end_cells"]), max_co))
    outer = 1 if pimple_co <= 1.0 + 1e-9 else int(tr["outer_correctors"])
    rng = np.random.default_rng(0)
    pool = np.flatnonzero(~near)
    k = min(N_PROBES, len(pool))
    pick = rng.choice(pool, size=k, replace=False, p=vols[pool] / vols[pool].sum()) if k else pool
    out = {
        "courant_per_s_max": c_max,
        "courant_per_s_interior": c_in,
        "end_plane_factor": factor,
        "end_plane_cells": int((per_s[near] > c_in).sum()),
        "pimple_max_co": pimple_co,
        "outer_correctors": outer,
        "delta_t_expected_s": pimple_co / c_max if c_max > 0 else None,
        "probe_points": centres[np.sort(pick)].tolist(),
    }
    progress.info(
        "Courant number on the state at %s s: largest %.3g/s (%d end-plane cells above the %.3g/s of the cells the "
        "flow crosses, x%.2f): pimpleFoam maxCo %.3g, %d outer corrector(s), time step ~%.3g s",
        t_name,
        c_max,
        out["end_plane_cells"],
        c_in,
        factor,
        pimple_co,
        outer,
        out["delta_t_expected_s"] or float("nan"),
    )
    return out


def write_origin(root: Path, flavour: str) -> float:
    """The time from which the next pimpleFoam run counts its ``adjustableRunTime`` writes (so that
    ``writeInterval = end - origin`` writes exactly at the stage's end): the latest time (ESI), or
    the ``beginTime`` kept in its ``uniform/time`` (openfoam.org v10; absent: the latest time)."""
    start, name = _time_dirs(root)[-1]
    if FLAVOURS[flavour].get("write_origin") != "begin_time":
        return start
    tdict = root / name / "uniform" / "time"
    m = (
        re.search(r"^\s*beginTime\s+([-+0-9.eE]+)\s*;", tdict.read_text(errors="replace"), re.M)
        if tdict.exists()
        else None
    )
    return float(m.group(1)) if m else start


def _run_stage(solve: _Pimple, name: str, end: float, watch: Any, *, average: bool, **extra: Any) -> dict[str, Any]:
    """One pimpleFoam stage (``washout``, ``average``; a pulsatile cycle's parts) from the latest
    time to ``end`` (or until ``watch`` stops it), writing only at its end (``extra``: more template
    settings); its time steps, time step range and Courant number merged into ``tr``. Returns the
    parsed log; raises :class:`Stop` when it fails."""
    case_dir, tr = solve.case_dir, solve.tr
    render_files(
        case_dir,
        solve.state,
        STAGE_FILES,
        end_time=_fmt_time(end),
        write_interval=_fmt_time(end - write_origin(solve.root, solve.state["flavour"])),
        average=average,
        monitors=True,
        time_precision=time_precision(solve.root),  # the latest folder may carry more digits than 10
        **(solve.common | extra),
    )
    log = f"pimpleFoam.{name}"
    r = solve.run(["pimpleFoam"], log, solve.ranks, watch=watch)
    parsed = parse_solver_log(case_dir / "logs" / f"log.{log}")
    tr.setdefault("time_steps", {})[name] = len(parsed["rows"])
    dt = tr.get("delta_t_s") or {}
    lo = [x for x in (dt.get("min"), parsed["delta_t_min"]) if x]
    hi = [x for x in (dt.get("max"), parsed["delta_t_max"]) if x]
    tr["delta_t_s"] = {"min": min(lo, default=None), "max": max(hi, default=None)}
    co = [c for c in (tr.get("courant_max"), parsed["courant_max"]) if c is not None]
    tr["courant_max"] = max(co, default=None)
    if r.returncode != 0:
        raise Stop(_solver_failure(case_dir / "logs" / f"log.{log}", name, "pimpleFoam"), log)
    return parsed


def _run_washout(solve: _Pimple, plan: dict[str, Any]) -> dict[str, Any]:
    """The wash-out: pimpleFoam from the SIMPLE state, ended by :class:`WashoutWatch` once the
    start-up transient is over (at least ``min_washout_flow_throughs``, at most
    ``washout_flow_throughs``). Returns the plan with the window moved to start where the
    wash-out ended (``washout_s``, ``averaging_start_time``, ``min_end_time``, ``max_end_time``)."""
    if plan["washout_s"] <= 0:
        return plan
    watch = WashoutWatch(solve.case_dir, solve.state, plan)
    _run_stage(solve, "washout", plan["averaging_start_time"], watch, average=False)
    end = _time_dirs(solve.root)[-1]
    if end[0] <= plan["start_time"]:
        raise Stop("the wash-out wrote no time folder", "pimpleFoam.washout")
    washout = end[0] - plan["start_time"]
    moved = {
        **plan,
        "washout_s": washout,
        "washout_flow_throughs": washout / plan["flow_through_time_s"],
        "averaging_start_time": end[0],
        "min_end_time": end[0] + plan["min_window_s"],
        "max_end_time": end[0] + plan["max_window_s"],
    }
    solve.tr.update(moved)
    solve.tr["washout"] = watch.report()
    return moved


def _run_window(solve: _Pimple, plan: dict[str, Any], peak_velocity: float) -> tuple[float, str]:
    """The averaging window (fieldAverage; the records judged while it runs by
    :class:`AverageWatch`, the means written at its end). Returns the end's time folder (solver
    time, name); raises :class:`Stop` when the stage fails or ends off the plan."""
    case_dir, tr = solve.case_dir, solve.tr
    watch = AverageWatch(case_dir, solve.state, plan, peak_velocity)
    parsed = _run_stage(solve, "average", plan["max_end_time"], watch, average=True)
    tr["solver_log"] = _log_summary(parsed, case_dir / "logs" / "log.pimpleFoam.average")
    if parsed["rows"]:
        tr["final_residuals"] = {k: parsed["rows"][-1][k] for k in ("p", "U") if k in parsed["rows"][-1]}
    if watch.stopped_at is not None:
        tr["ended_early_at"] = watch.stopped_at
    written = [t for t in _time_dirs(solve.root) if t[0] > plan["averaging_start_time"] + 1e-9]
    if not written:
        raise Stop("the averaging stage wrote no time folder", "pimpleFoam.average")
    end_dir = written[-1]
    if end_dir[0] < plan["min_end_time"] - 1e-3 * plan["min_window_s"]:
        raise Stop(
            f"the averaging stage ended at {end_dir[1]}, before the shortest window's end "
            f"{_fmt_time(plan['min_end_time'])}",
            "pimpleFoam.average",
        )
    if solve.ranks > 1 and solve.run(["reconstructPar", "-time", end_dir[1]], "reconstructPar").returncode != 0:
        raise Stop("reconstructPar failed", "reconstructPar")
    tr["end_time"] = end_dir[0]
    tr["end_time_folder"] = end_dir[1]
    return end_dir


MSER_OVER = 1.0 / 3.0
"""The wash-out is over when every record's MSER-5 truncation point lies in its first third
(:func:`vcs.cfd.timeseries.mser_truncation`): what follows the start-up is at least twice as
long as the start-up (on a decaying transient plus noise this ends the wash-out at 2-3 times the
transient's length: ``tests/vcs/test_timeseries.py``)."""


class WashoutWatch:
    """Ends the wash-out once the start-up transient is over: every :data:`CHECK_EVERY_S` s of wall
    clock, after ``min_washout_flow_throughs``, it reads the records since the SIMPLE state
    (inlet-outlet pressure difference, area-mean |WSS|, mean speed at the probe cells) and finds
    each one's MSER-5 truncation point; when all lie in the first :data:`MSER_OVER` of the
    record it asks pimpleFoam to write and stop (``stopAt writeNow``). The averaging window starts
    there."""

    def __init__(self, case_dir: Path, state: dict[str, Any], plan: dict[str, Any]) -> None:
        self.case_dir, self.state, self.plan = case_dir, state, plan
        self.next_look = time.monotonic() + CHECK_EVERY_S
        self.stopped_at: float | None = None
        self.fractions: dict[str, float] = {}

    def __call__(self, log: Path) -> None:
        """Look at the records (at most every :data:`CHECK_EVERY_S` s); stop the solver once (see class)."""
        if self.stopped_at is not None or time.monotonic() < self.next_look:
            return
        self.next_look = time.monotonic() + CHECK_EVERY_S
        t0 = self.plan["start_time"]
        try:
            rec = _records(self.case_dir, self.state, t0, math.inf)
        except Exception:  # noqa: BLE001 - nothing yet, a record caught mid-write: look again later
            return
        now = float(rec["t"][-1])
        if now - t0 < self.plan["min_washout_s"]:
            return
        self.fractions = washout_fractions(rec, t0)
        if max(self.fractions.values()) < MSER_OVER:
            request_write_now(self.case_dir / "system" / "controlDict")
            self.stopped_at = now
            progress.info(
                "wash-out: start-up transient over after %.3g flow-through times (MSER-5 truncation at %s of the "
                "record); stopping pimpleFoam, the averaging window starts there",
                (now - t0) / self.plan["flow_through_time_s"],
                ", ".join(f"{k} {100 * v:.0f} %" for k, v in self.fractions.items()),
            )

    def report(self) -> dict[str, Any]:
        """status.json ``transient.washout``: where it ended and why."""
        return {
            "ended_early_at": self.stopped_at,
            "mser_truncation_fractions": self.fractions,
            "over_below_fraction": MSER_OVER,
        }


def washout_fractions(rec: dict[str, Any], start: float) -> dict[str, float]:
    """The MSER-5 truncation point (fraction of the record) of each record since ``start``
    (:func:`_records`; U as the mean speed over the probe cells)."""
    series = {"inlet_minus_outlet_pressure": rec["dp"], "tawss_mean": rec["tawss"]}
    if rec["U"] is not None:
        u = rec["U"].reshape(len(rec["t"]), -1, 3)
        series["U"] = np.linalg.norm(u, axis=2).mean(axis=1)
    out = {}
    for k, x in series.items():
        xu, _ = uniform_record(rec["t"], x, start)
        out[k] = mser_truncation(xu)
    return out


class AverageWatch:
    """Ends the averaging window as soon as its means are known to the tolerance: every
    :data:`CHECK_EVERY_S` s of wall clock it reads the window's records (patch pressures, area-mean
    |WSS|, probe velocities); once ``min_flow_throughs`` have passed and
    :func:`window_statistics` finds every half-width within its tolerance, it asks pimpleFoam to
    write and stop (``stopAt writeNow``): fieldAverage writes the means at that time."""

    def __init__(self, case_dir: Path, state: dict[str, Any], plan: dict[str, Any], peak_velocity: float) -> None:
        self.case_dir, self.state, self.plan = case_dir, state, plan
        self.peak = float(peak_velocity)
        self.next_look = time.monotonic() + CHECK_EVERY_S
        self.stopped_at: float | None = None

    def __call__(self, log: Path) -> None:
        """Look at the records (at most every :data:`CHECK_EVERY_S` s); stop the solver once (see class)."""
        if self.stopped_at is not None or time.monotonic() < self.next_look:
            return
        self.next_look = time.monotonic() + CHECK_EVERY_S
        t0 = self.plan["averaging_start_time"]
        try:
            now = float(function_series(self.case_dir, _dp_names(self.state)[0][0])[-1, 0])
        except Exception:  # noqa: BLE001 - a watch never stops the solver by failing
            return
        if now < self.plan["min_end_time"]:
            return
        try:
            stats = window_statistics(self.case_dir, self.state, t0, now, self.peak)
        except Exception:  # noqa: BLE001 - a record caught mid-write: look again later
            return
        if stats["stationary"]:
            request_write_now(self.case_dir / "system" / "controlDict")
            self.stopped_at = now
            progress.info(
                "averaging window: means known to the tolerance after %.3g flow-through times: %s; stopping pimpleFoam",
                (now - t0) / self.plan["flow_through_time_s"],
                _errors_text(stats),
            )


def _dp_names(state: dict[str, Any]) -> tuple[list[str], list[str]]:
    """The function-object names of the inlet and of the outlet patch pressures (the main outlets
    when there are branches: :func:`vcs.cfd.outlets.pressure_outlets`)."""
    from vcs.cfd.outlets import pressure_outlets

    inlets = [f"pressure_{p['name']}" for p in state["patches"] if p["role"] == "inlet"]
    outlets = [f"pressure_{n}" for n in pressure_outlets(state["patches"])]
    return inlets, outlets


def _records(case_dir: Path, state: dict[str, Any], start: float, end: float) -> dict[str, Any]:
    """The window's records (start, end]: times, inlet-outlet pressure difference, area-mean |WSS|
    (kinematic), probe velocities (n, 3 N)."""
    inlets, outlets = _dp_names(state)
    p_in = function_series(case_dir, inlets[0])
    t = p_in[:, 0]
    sel = (t > start + 1e-12) & (t <= end + 1e-12)
    t = t[sel]
    if len(t) < 2:
        raise ValueError(f"fewer than 2 time steps recorded between solver times {start:g} and {end:g}")
    p_out = np.mean([np.interp(t, s[:, 0], s[:, 1]) for s in (function_series(case_dir, n) for n in outlets)], axis=0)
    dp = p_in[sel, 1] - p_out
    walls = _wall_faces(case_dir, state)
    areas = np.array([a.sum() for _, a in walls])
    wss = [function_series(case_dir, f"wss_{name}") for name, _ in walls]
    if any(len(w) == 0 for w in wss):
        raise ValueError("no area-mean |WSS| recorded on the wall")
    tawss = sum(ar * np.interp(t, w[:, 0], w[:, 1]) for ar, w in zip(areas, wss, strict=True)) / areas.sum()
    probes = _probe_series(case_dir)
    u = None
    if probes is not None and len(probes):
        pt, pv = probes[:, 0], probes[:, 1:]
        u = np.column_stack([np.interp(t, pt, pv[:, j]) for j in range(pv.shape[1])])
    return {"t": t, "dp": dp, "tawss": tawss, "U": u}


def _probe_series(case_dir: Path) -> NDArray[np.floating] | None:
    """The probes' U record (time, then 3 components per probe) of the latest start folder; None
    when there is none. A last line still being written is left out (rows must have 1 + 3 N
    numbers for the N probes of the file's header); probes outside the mesh (OpenFOAM writes a
    huge value) are dropped."""
    files = sorted((case_dir / "postProcessing" / "probes").glob("*/U"), key=lambda p: float(p.parent.name))
    if not files:
        return None
    text = files[-1].read_text(errors="replace")
    n_probes = len(re.findall(r"^#\s*Probe\s+\d+\s*\(", text, re.M))
    width = 1 + 3 * n_probes
    rows = []
    for line in text.splitlines(keepends=True):
        if line.startswith("#") or not line.endswith("\n"):
            continue
        vals = line.replace("(", " ").replace(")", " ").split()
        if n_probes and len(vals) == width:
            try:
                rows.append([float(v) for v in vals])
            except ValueError:
                continue
    if not rows:
        return None
    arr = np.array(rows)
    u = arr[:, 1:].reshape(len(arr), -1, 3)
    ok = np.all(np.abs(u) < 1e10, axis=(0, 2))
    return np.column_stack([arr[:, :1], u[:, ok, :].reshape(len(arr), -1)])


def window_statistics(
    case_dir: Path, state: dict[str, Any], start: float, end: float, peak_velocity: float
) -> dict[str, Any]:
    """The time averages of the window (start, end] and their error bars: known to the tolerance?

    For each record (inlet-outlet pressure difference, area-mean |WSS| on the wall, and the
    velocity at the probe cells), the mean and the half-width of its confidence interval
    (:func:`vcs.cfd.timeseries.mean_error`: batch means over at least 3 batches of 3 integral time
    scales, and the integral-time-scale estimate 2 T_int sigma^2 / T, the larger; or the record's
    range when smaller). Relative half-widths:

    * dp: half-width / max(|mean dp|, 10 % of the inlet dynamic pressure U_peak^2 / 2) (dp may
      cross zero);
    * TAWSS (area mean): half-width / mean;
    * U: sqrt(sum_i |half-width_i|^2 / sum_i |mean U_i|^2) over the probe cells (drawn by
      volume: an estimate of the volume L2 norm of the error field relative to that of the mean).

    The means are known when each is within ``error_tolerance`` (dp, TAWSS) or
    ``error_tolerance_U`` (U).

    Returns
    -------
    dict
        ``window_s``, ``confidence``, ``statistics`` {``inlet_minus_outlet_pressure``,
        ``tawss_mean``: {``mean_Pa``, ``half_width_Pa``, ``relative``, ``integral_time_s``,
        ``n_batches``}, ``U``: {``relative``, ``n_probes``, ``integral_time_s`` (median),
        ``n_batches`` (least)}}, ``relative_errors``, ``tolerances``, ``stationary`` (bool: all
        known), ``why`` (one line, when not).
    """
    tr = state["cfd"]["solver"]["transient"]
    rho = float(state["cfd"]["physics"]["rho"])
    conf = float(tr["confidence"])
    rec = _records(case_dir, state, start, end)
    t = rec["t"]
    e_dp = mean_error(t, rec["dp"], start, conf)
    e_w = mean_error(t, rec["tawss"], start, conf)
    dp_scale = max(abs(e_dp["mean"]), 0.1 * 0.5 * peak_velocity**2)
    rel = {
        "inlet_minus_outlet_pressure": e_dp["half_width"] / dp_scale,
        "tawss_mean": e_w["half_width"] / max(abs(e_w["mean"]), 1e-300),
    }
    st: dict[str, Any] = {
        "inlet_minus_outlet_pressure": _scalar_stats(e_dp, rho, rel["inlet_minus_outlet_pressure"]),
        "tawss_mean": _scalar_stats(e_w, rho, rel["tawss_mean"]),
    }
    if rec["U"] is not None:
        e_u = mean_error(t, rec["U"], start, conf)
        hw, mean = np.asarray(e_u["half_width"]), np.asarray(e_u["mean"])
        rel["U"] = float(np.sqrt((hw**2).sum() / max((mean**2).sum(), 1e-300)))
        st["U"] = {
            "relative": rel["U"],
            "n_probes": len(mean) // 3,
            "integral_time_s": float(np.median(e_u["integral_time_s"])),
            "n_batches": int(np.min(e_u["n_batches"])),
            "bound_range_probes": int(np.any(np.asarray(e_u["bound"]).reshape(-1, 3) == "range", axis=1).sum()),
        }
    if rec["U"] is None and (case_dir / "postProcessing" / "probes").is_dir():
        rel["U"] = math.inf  # probes asked for, no complete record (yet): U not known
        st["U"] = {"relative": math.inf, "n_probes": 0}
    tols = {
        "inlet_minus_outlet_pressure": float(tr["error_tolerance"]),
        "tawss_mean": float(tr["error_tolerance"]),
        "U": float(tr["error_tolerance_U"]),
    }
    tols = {k: v for k, v in tols.items() if k in rel}
    bad = [k for k in rel if not rel[k] <= tols[k]]  # NaN and inf: not known
    out: dict[str, Any] = {
        "window_s": float(end - start),
        "confidence": conf,
        "statistics": st,
        "relative_errors": rel,
        "tolerances": tols,
        "stationary": not bad,
    }
    if bad:
        out["why"] = "; ".join(f"{_WORDS[k]} known to +-{_pct(rel[k])} (tolerance {100 * tols[k]:g} %)" for k in bad)
    return out


def _scalar_stats(e: dict[str, Any], rho: float, relative: float) -> dict[str, Any]:
    """status.json's statistics of one scalar record (kinematic -> Pa)."""
    return {
        "mean_Pa": float(e["mean"]) * rho,
        "half_width_Pa": float(e["half_width"]) * rho,
        "relative": float(relative),
        "integral_time_s": float(e["integral_time_s"]),
        "n_batches": int(e["n_batches"]),
        "bound": str(e["bound"]),
    }


_WORDS = {
    "inlet_minus_outlet_pressure": "inlet-outlet pressure difference",
    "tawss_mean": "mean TAWSS",
    "U": "U (L2 over the probe cells)",
}


def _pct(x: float) -> str:
    """A relative error in per cent (``unknown`` when infinite: too few batches yet)."""
    return f"{100 * x:.2g} %" if np.isfinite(x) else "unknown (too few integral time scales)"


def _errors_text(stats: dict[str, Any]) -> str:
    """The relative half-widths of :func:`window_statistics`, in words."""
    rel, tol = stats["relative_errors"], stats["tolerances"]
    return ", ".join(f"{_WORDS[k]} +-{_pct(rel[k])} (tolerance {100 * tol[k]:g} %)" for k in rel)


def _log_verdict(verdict: dict[str, Any]) -> None:
    """One log line: the verdict of the window (:func:`window_statistics`)."""
    progress.info(
        "averaging window of %.4g s: %s: %s",
        verdict["window_s"],
        _errors_text(verdict),
        "stationary" if verdict["stationary"] else "not known to the tolerance",
    )


def _record_verdict(
    case_dir: Path,
    state: dict[str, Any],
    status: dict[str, Any],
    tr: dict[str, Any],
    plan: dict[str, Any],
    verdict: dict[str, Any],
    simple_reason: str | None,
) -> None:
    """The window's verdict in ``tr`` and ``status`` (the time-averaged fields are the result;
    converged when every mean is known to its tolerance), and ``transient.png``."""
    tr.update(verdict)
    tr["window_flow_throughs"] = verdict["window_s"] / plan["flow_through_time_s"]
    tr["evaluated"] = True
    status["criterion_used"] = "time_average_stationary"
    status["time_average_errors"] = {
        "confidence": verdict["confidence"],
        "relative": verdict["relative_errors"],
        "tolerances": verdict["tolerances"],
        "window_flow_throughs": tr["window_flow_throughs"],
    }
    status["fields"] = {
        "U": "UMean",
        "p": "pMean",
        "WSS": "wallShearStressMean",
        "TAWSS": "magWallShearStressMean",
        "time_averaged": True,
    }
    _plot_transient(case_dir, state, plan, verdict)
    if verdict["stationary"]:
        status["converged"] = True
        status["reason"] = None
    else:
        bad = [k for k, v in verdict["relative_errors"].items() if not v <= verdict["tolerances"][k]]
        keys = " or ".join(dict.fromkeys("error_tolerance_U" if k == "U" else "error_tolerance" for k in bad))
        which = "the window ended early but" if tr.get("ended_early_at") is not None else "after the longest window"
        status["reason"] = (
            f"{simple_reason}; time average not known to the tolerance ({which} "
            f"{tr['window_flow_throughs']:.3g} flow-through times of {plan['flow_through_time_s']:.3g} s, after a "
            f"{plan['washout_s']:.3g} s wash-out): {verdict['why']}; raise cfd.solver.transient.max_flow_throughs "
            f"(or {keys or 'error_tolerance'})"
        )


def _plot_transient(case_dir: Path, state: dict[str, Any], plan: dict[str, Any], verdict: dict[str, Any]) -> None:
    """``transient.png``: each quantity the verdict judged (inlet-outlet pressure difference, the
    wall's area-mean |WSS|, the probe cells' mean |U|) over the transient run, its running mean
    over the averaging window, the final mean with its error bar, and in each title its relative
    error against the tolerance; the verdict in the figure's title (best effort, never fails)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        rho = float(state["cfd"]["physics"]["rho"])
        rec = _records(case_dir, state, plan["start_time"], plan["start_time"] + 1e9)
        t = rec["t"] - plan["start_time"]
        t_w = plan["averaging_start_time"] - plan["start_time"]
        sel = t > t_w
        rel, tols, stats = verdict["relative_errors"], verdict["tolerances"], verdict["statistics"]
        rows = [("inlet_minus_outlet_pressure", rec["dp"] * rho, "p(inlet) - p(outlet) [Pa]")]
        rows.append(("tawss_mean", rec["tawss"] * rho, "area-mean |WSS| [Pa]"))
        if rec["U"] is not None:
            u = np.asarray(rec["U"], float)
            speed = np.linalg.norm(u.reshape(len(u), -1, 3), axis=2).mean(axis=1)
            rows.append(("U", speed, "probe cells' mean |U| [m/s]"))
        fig, axes = plt.subplots(len(rows), 1, figsize=(7, 2.3 * len(rows) + 0.8), sharex=True, squeeze=False)
        for ax, (key, y, label) in zip(axes[:, 0], rows, strict=True):
            ax.plot(t, y, lw=0.5, label="instantaneous")
            if sel.sum() > 1:
                w = np.diff(np.concatenate([[t_w], t[sel]]))
                ax.plot(t[sel], np.cumsum(w * y[sel]) / np.cumsum(w), "k", lw=1.2, label="running mean")
            s = stats.get(key) or {}
            if np.isfinite(s.get("half_width_Pa", np.nan)):
                m, hw = s["mean_Pa"], s["half_width_Pa"]
                ax.axhspan(
                    m - hw, m + hw, color="k", alpha=0.15, label=f"mean +- {100 * verdict['confidence']:g} % interval"
                )
            ax.axvspan(t_w, t[-1], alpha=0.08, label="averaging window")
            known = rel.get(key, np.inf) <= tols.get(key, 0.0)
            ax.set_title(
                f"{_WORDS[key]}: +-{_pct(rel.get(key, np.inf))} (tolerance {100 * tols.get(key, np.nan):g} %)"
                + ("" if known else " - not known"),
                fontsize=9,
                color="black" if known else "#b2182b",
            )
            ax.set_ylabel(label, fontsize=8)
            ax.grid(True, alpha=0.3)
        axes[0, 0].legend(loc="best", fontsize=7)
        axes[-1, 0].set_xlabel(
            f"time since the end of SIMPLE [s] (flow-through time {plan['flow_through_time_s']:.3g} s)"
        )
        head = "every mean known to its tolerance: stationary" if verdict["stationary"] else "NOT stationary"
        fig.suptitle(f"transient window of {verdict['window_s']:.3g} s: {head}", fontsize=10)
        fig.tight_layout()
        fig.savefig(case_dir / "transient.png", dpi=100)
        plt.close(fig)
    except Exception:  # noqa: BLE001 - plotting must never fail a run
        log.warning("transient.png not drawn", exc_info=True)
