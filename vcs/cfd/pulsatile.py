"""Pulsatile flow: pimpleFoam over whole cardiac cycles, judged periodic cycle to cycle.

The stages of :func:`pulsatile_solve` (called by :func:`vcs.cfd.run.run_case` when the case has an
inflow waveform, ``cfd.inlet.waveform``):

1. the inlet: the waveform's flow rate on the inlet faces at ``samples_per_cycle`` instants per
   cycle (Womersley, parabolic or plug profile mapped to the section's shape, the discrete flux
   exact at every instant: :func:`vcs.cfd.womersley.inlet_velocities`), written as
   ``constant/boundaryData/<inlet>`` for ``timeVaryingMappedFixedValue`` (both flavours; linear in
   time between the instants, no compiled code) by :func:`write_inlet_data`;
2. cycles from rest: each cycle one pimpleFoam run from its start to its end, cut at the named
   phase instants (peak systole, end systole, mid diastole: :meth:`vcs.cfd.waveform.Waveform.phases`)
   where the instantaneous fields are written; ``fieldAverage`` accumulates U, p, the wall shear
   stress vector and its magnitude at **every time step** over the cycle (restarted at the cycle's
   start, continued across its cuts), so the cycle's TAWSS and mean WSS vector are exact time
   integrals of the discrete solution, not snapshot averages;
3. periodicity, after every cycle from the second on: the cycle-to-cycle change of the inlet-outlet
   pressure difference waveform, of the outlet flow rate waveform (both on a common phase grid,
   relative to their cycle's largest magnitude) and of the TAWSS map (area-weighted L2, relative):
   :func:`cycle_change`. Periodic when the waveforms' changes are below ``periodicity_tolerance``
   and the map's below ``tawss_tolerance`` once at least ``cycles`` have run (the diastolic vortices
   of a real aorta decay over R^2/nu, about a minute: its TAWSS map changed 4-6 % per cycle at
   cycles 2-4 on demo aortas while the waveforms were periodic to 0.1 %);
   one more cycle otherwise, up to ``max_cycles``; not periodic then:
   ``converged`` false with the changes as the reason;
4. the result: the last ``cycles - discard_cycles`` cycles are kept (the first ``discard_cycles``
   are the wash-in from rest); their cycle-mean fields (each cycle's end folder) and the last
   cycle's phase folders are kept, the rest deleted as the run goes (disk). status.json
   ``pulsatile`` names them; :func:`vcs.cfd.resample.sample_pulsatile` averages and resamples them.

Outlets: the free outflow of the steady case (p = 0; U ``inletOutlet``: zero gradient where the
flow leaves, U = 0 on faces where it enters). The flux through a reversing outlet face is still
set by the pressure equation (it must be: the shipped waveform has a net end-systolic backflow,
which the outlet has to supply), but the fluid it lets in carries no momentum into the domain:
no inflow jet builds up through a zero-gradient velocity, and the run stays bounded through the
deceleration and the backflow.

Time step: adjustable at Courant number ``max_co``, at most ``period / min_steps_per_cycle`` (the
waveform's instants resolved). From the first phase cut of the first cycle on (peak systole by
default: the largest flow), the limit is set by the cells the flow crosses, as in the transient
solve (:func:`vcs.cfd.transient.courant_plan`): the slivers snapping cuts at the end planes (5x the
interior's Courant number on a demo aorta at peak systole) run up to ``max_co_end_cells`` with
``outer_correctors``. Recorded per cycle in status.json with its CPU time.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vcs.cfd.foamfiles import (
    function_series,
    oscillatory_shear_index,
    patch_geometry,
    read_boundary,
    read_faces,
    read_patch_field,
    read_points,
)
from vcs.cfd.transient import _Pimple, _run_stage, courant_plan
from vcs.cfd.utilities import Stop, _fmt_time, _Runner, _time_dirs, progress
from vcs.cfd.waveform import Waveform

#: the phase instants written by default (see :meth:`vcs.cfd.waveform.Waveform.phases`)
DEFAULT_PHASES = ("peak_systole", "end_systole", "mid_diastole")
#: the per-cycle mean fields written by fieldAverage at each cycle's end
MEAN_FIELDS = ("UMean", "pMean", "wallShearStressMean", "magWallShearStressMean")
#: phase points on which the waveforms of two cycles are compared
N_PHASE = 200


# --------------------------------------------------------------------------- the waveform of a case


def case_waveform(state: dict[str, Any]) -> Waveform:
    """The applied (scaled) inflow waveform of a rendered case (``state["waveform"]``)."""
    w = state["waveform"]
    return Waveform(
        time_s=np.asarray(w["time_s"], float),
        flow_m3_s=np.asarray(w["flow_m3_s"], float),
        period_s=float(w["period_s"]),
        source=str(w.get("source", "")),
    )


def pulsatile_plan(state: dict[str, Any]) -> dict[str, Any]:
    """The cycles, the phase instants and the time-step bounds of a pulsatile case.

    Returns
    -------
    dict
        ``period_s``, ``cycles``, ``discard_cycles``, ``keep_cycles`` (= cycles - discard),
        ``max_cycles``, ``tolerance``, ``phases`` ({name: offset in the cycle, s}),
        ``max_delta_t_s`` (period / min_steps_per_cycle), ``delta_t_initial_s``, ``max_co``,
        ``outer_correctors``.
    """
    pu = state["cfd"]["pulsatile"]
    wf = case_waveform(state)
    period = wf.period_s
    named = wf.phases()
    phases = {}
    for name in pu["phases"]:
        if name not in named:
            raise Stop(f"unknown phase {name!r} in cfd.pulsatile.phases; known: {', '.join(named)}")
        phases[name] = float(named[name])
    cycles = int(pu["cycles"])
    discard = int(pu["discard_cycles"])
    max_dt = period / float(pu["min_steps_per_cycle"])
    return {
        "period_s": period,
        "cycles": cycles,
        "discard_cycles": discard,
        "keep_cycles": cycles - discard,
        "max_cycles": int(pu["max_cycles"]),
        "tolerance": float(pu["periodicity_tolerance"]),
        "tawss_tolerance": float(pu["tawss_tolerance"]),
        "phases": dict(sorted(phases.items(), key=lambda kv: kv[1])),
        "max_delta_t_s": max_dt,
        "delta_t_initial_s": max_dt / 20.0,
        "max_co": float(pu["max_co"]),
        "outer_correctors": int(pu["outer_correctors"]),
    }


# --------------------------------------------------------------------------- inlet boundary data


def _patch_boundary_edges(case_dir: Path, patch: str) -> NDArray[np.floating]:
    """(E, 2, 3) end points of the edges on the rim of a patch (edges used by one of its faces)."""
    poly = case_dir / "constant" / "polyMesh"
    b = read_boundary(poly)[patch]
    faces = read_faces(poly, int(b["startFace"]), int(b["nFaces"]))
    count: dict[tuple[int, int], int] = {}
    for f in faces:
        n = len(f)
        for i in range(n):
            a, c = int(f[i]), int(f[(i + 1) % n])
            key = (a, c) if a < c else (c, a)
            count[key] = count.get(key, 0) + 1
    rim = np.array([k for k, v in count.items() if v == 1], dtype=np.int64)
    pts = read_points(poly)
    return pts[rim]


def _vector_list(a: NDArray[np.floating]) -> str:
    """An OpenFOAM list of vectors (the headerless boundaryData format both flavours read)."""
    body = "\n".join(f"({x:.10g} {y:.10g} {z:.10g})" for x, y, z in a)
    return f"{len(a)}\n(\n{body}\n)\n"


def boundary_instants(wf: Waveform, samples_per_cycle: int, cycles: int) -> NDArray[np.floating]:
    """The instants of the inlet boundary data over ``cycles`` cycles (and one sample more): a
    uniform grid of ``samples_per_cycle`` per cycle (the Womersley profile's shape changes in time)
    joined with the waveform's own knots, so that OpenFOAM's linear interpolation in time between
    them gives the waveform's flow rate exactly at every time (its mean too), whatever the grid.
    Instants closer than 1e-6 of the period are merged (five significant digits of a time folder
    name would not tell them apart otherwise)."""
    period = wf.period_s
    one = np.union1d(np.arange(samples_per_cycle) * (period / samples_per_cycle), wf.time_s[:-1])
    keep = np.concatenate([[True], np.diff(one) > 1e-6 * period])
    one = one[keep]
    times = (one[None, :] + period * np.arange(cycles)[:, None]).ravel()
    return np.concatenate([times, [cycles * period, cycles * period + period / samples_per_cycle]])


def write_inlet_data(case_dir: Path, state: dict[str, Any], plan: dict[str, Any]) -> dict[str, Any]:
    """Write ``constant/boundaryData/<inlet>`` (points, and U at the instants of
    :func:`boundary_instants` for ``max_cycles`` cycles) for the ``timeVaryingMappedFixedValue`` inlet.

    The profile (``cfd.pulsatile.profile``) is :func:`vcs.cfd.womersley.inlet_velocities` on the
    normalised radius of :func:`vcs.cfd.womersley.section_radius` (about the rim's centroid),
    along the inward normal of the inlet patch, its
    discrete flux the waveform's flow rate at every instant. ``mapMethod nearest`` on the face
    centres themselves: the values are the faces' own. Each face's velocity is along its own inward
    normal (as OpenFOAM's flowRateInletVelocity does), so the flux sum_f u_f |S_f| is the
    waveform's Q(t) exactly on a snapped, not quite flat inlet too.

    Returns
    -------
    dict
        The inlet summary for status.json (``patch``, ``profile``, ``n_faces``, ``patch_area``,
        ``direction``, ``centre``, ``samples_per_cycle``, ``instants``, ``flux_error_rel`` (the
        largest over the instants), ``peak_velocity`` (m/s), ``womersley_number``).
    """
    from vcs.cfd.womersley import inlet_velocities, section_radius, womersley_number

    pu = state["cfd"]["pulsatile"]
    name = next(p["name"] for p in state["patches"] if p["role"] == "inlet")
    centres, sf = patch_geometry(case_dir, name)
    area = np.linalg.norm(sf, axis=1)
    n_in = -sf.sum(0) / np.linalg.norm(sf.sum(0))  # the section's inward normal
    n_face = -sf / area[:, None]  # each face's own inward normal: the flux u_f |S_f| (weights > 0)
    rim = _patch_boundary_edges(case_dir, name)
    mid, length = rim.mean(1), np.linalg.norm(rim[:, 1] - rim[:, 0], axis=1)
    centre = (mid * length[:, None]).sum(0) / length.sum()  # centroid of the rim
    s = section_radius(centres, centre, n_in, rim)
    wf = case_waveform(state)
    period = plan["period_s"]
    n_per = int(pu["samples_per_cycle"])
    times = boundary_instants(wf, n_per, plan["max_cycles"])
    r_eq = math.sqrt(float(area.sum()) / math.pi)
    nu = float(state["cfd"]["physics"]["nu"])
    speed = inlet_velocities(s, area, times, wf, str(pu["profile"]), r_eq, nu, n_harmonics=int(pu["harmonics"]))
    flux = speed @ area
    target = wf(times)
    scale = max(float(np.abs(target).max()), 1e-300)
    bd = case_dir / "constant" / "boundaryData" / name
    shutil.rmtree(bd, ignore_errors=True)
    bd.mkdir(parents=True)
    (bd / "points").write_text(_vector_list(centres))
    for t, u in zip(times, speed):
        d = bd / _fmt_time(float(t))
        d.mkdir()
        (d / "U").write_text(_vector_list(u[:, None] * n_face))
    omega = 2 * math.pi / period
    return {
        "patch": name,
        "type": "timeVaryingMappedFixedValue",
        "profile": pu["profile"],
        "n_faces": int(len(area)),
        "patch_area": float(area.sum()),
        "direction": [float(x) for x in n_in],
        "centre": [float(x) for x in centre],
        "samples_per_cycle": n_per,
        "instants": int(len(times)),
        "flux_error_rel": float(np.abs(flux - target).max() / scale),
        "peak_velocity": float(np.abs(speed).max()),
        "womersley_number": womersley_number(r_eq, omega, nu),
        "equivalent_radius_m": r_eq,
    }


# --------------------------------------------------------------------------- per-cycle records


def cycle_records(case_dir: Path, state: dict[str, Any], start: float, end: float) -> dict[str, NDArray[np.floating]]:
    """The inlet-outlet pressure difference (kinematic; the main outlet's pressure when there are
    branches: :func:`vcs.cfd.outlets.pressure_outlets`), the inlet flow rate, each outlet's flow rate
    (``q_outlets``, (n_outlets, N_PHASE)) and their sum, and each outlet's area-mean kinematic
    pressure (``p_outlets``) of one cycle, linearly interpolated on ``N_PHASE`` phase points
    (fraction of the cycle)."""
    phase = (np.arange(N_PHASE) + 0.5) / N_PHASE
    tq = start + phase * (end - start)

    def series(name: str) -> NDArray[np.floating]:
        s = function_series(case_dir, name)
        if s.size == 0:
            raise Stop(f"no record of function object {name} in postProcessing")
        m = (s[:, 0] >= start - 1e-12) & (s[:, 0] <= end + 1e-12)
        if m.sum() < 2:
            raise Stop(f"function object {name} recorded fewer than 2 values in the cycle {start:g}-{end:g} s")
        return np.interp(tq, s[m, 0], s[m, 1])

    from vcs.cfd.outlets import pressure_outlets

    inl = [p["name"] for p in state["patches"] if p["role"] == "inlet"]
    outl = [p["name"] for p in state["patches"] if p["role"] == "outlet"]
    p_in = np.mean([series(f"pressure_{n}") for n in inl], axis=0)
    p_out = np.mean([series(f"pressure_{n}") for n in pressure_outlets(state["patches"])], axis=0)
    q_outlets = np.array([series(f"flowRate_{n}") for n in outl])
    return {
        "phase": phase,
        "dp": p_in - p_out,
        "q_in": -np.sum([series(f"flowRate_{n}") for n in inl], axis=0),
        "q_out": q_outlets.sum(axis=0),
        "q_outlets": q_outlets,
        "p_outlets": np.array([series(f"pressure_{n}") for n in outl]),
    }


def cycle_change(prev: dict[str, Any], cur: dict[str, Any], area: NDArray[np.floating]) -> dict[str, float]:
    """Cycle-to-cycle change of a pulsatile run (SimVascular's and VaMPy's periodicity check, made
    quantitative on three quantities):

        dp:       max_phi |dp_k(phi) - dp_{k-1}(phi)| / max_phi |dp_k(phi)|
        flow:     max_o max_phi |Q_o,k(phi) - Q_o,k-1(phi)| / max_phi |Q_in,k(phi)|  (o: each outlet)
        pressure: max_o max_phi |P_o,k(phi) - P_o,k-1(phi)| / max_o max_phi |P_o,k(phi)|
        tawss:    sqrt(sum_f A_f (TAWSS_k - TAWSS_{k-1})^2 / sum_f A_f TAWSS_k^2)

    with phi the phase in the cycle and f the wall faces (TAWSS of each cycle alone). The flow
    check is on each outlet: with one outlet, incompressibility makes its flow the prescribed
    inflow at every instant (the check is then met to the solver's tolerance); with several it
    is the split between them that has to settle. The pressure check is on each outlet's own
    pressure, not a difference: Windkessel outlets (``rcr``) charge their capacitors over several
    cycles (time constant R_d C) while the pressure difference across the lumen is already
    periodic; on p = 0 outlets it is 0.

    Parameters
    ----------
    prev, cur : dict
        ``records`` (:func:`cycle_records`) and ``tawss`` ((F,) float) of two consecutive cycles.
    area : (F,) float
        Wall face areas.
    """
    a, b = prev["records"], cur["records"]
    dp = float(np.abs(b["dp"] - a["dp"]).max() / max(np.abs(b["dp"]).max(), 1e-300))
    flow = float(np.abs(b["q_outlets"] - a["q_outlets"]).max() / max(np.abs(b["q_in"]).max(), 1e-300))
    scale = float(np.abs(b["p_outlets"]).max())
    pressure = float(np.abs(b["p_outlets"] - a["p_outlets"]).max() / scale) if scale > 0 else 0.0
    t0, t1 = prev["tawss"], cur["tawss"]
    tawss = float(np.sqrt((area * (t1 - t0) ** 2).sum() / max((area * t1**2).sum(), 1e-300)))
    return {"dp": dp, "flow": flow, "pressure": pressure, "tawss": tawss}


def _wall_field(case_dir: Path, state: dict[str, Any], ranks: int, time_name: str, field: str) -> NDArray[np.floating]:
    """A field's values on every wall face of a time folder (the processors' concatenated, in a
    fixed order, when ``ranks`` > 1)."""
    roots = [case_dir] if ranks <= 1 else sorted(case_dir.glob("processor*"), key=lambda p: int(p.name[9:]))
    vals = []
    for root in roots:
        for p in state["patches"]:
            if p["role"] != "wall":
                continue
            v = read_patch_field(root / time_name / field, p["name"])
            if v is None:
                raise Stop(f"{time_name}/{field} has no values on the wall patch {p['name']!r}")
            vals.append(v)
    return np.concatenate(vals)


def _wall_areas(case_dir: Path, state: dict[str, Any], ranks: int) -> NDArray[np.floating]:
    """Wall face areas in the order of :func:`_wall_field`."""
    roots = [case_dir] if ranks <= 1 else sorted(case_dir.glob("processor*"), key=lambda p: int(p.name[9:]))
    out = []
    for root in roots:
        for p in state["patches"]:
            if p["role"] == "wall":
                _, sf = patch_geometry(root, p["name"])
                out.append(np.linalg.norm(sf, axis=1))
    return np.concatenate(out)


# --------------------------------------------------------------------------- the cycles


def pulsatile_solve(
    case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner, ranks: int
) -> dict[str, Any]:
    """Run whole cycles until periodic (or ``max_cycles``); fills ``status``; raises :class:`Stop`
    when a stage fails.

    Parameters
    ----------
    case_dir : Path
        The meshed case with its inlet boundary data (decomposed when ``ranks`` > 1).
    state : dict
        Case description (``cfd.pulsatile``, ``waveform``).
    status : dict
        The status being built.
    run : _Runner
        Runs the utilities in the case.
    ranks : int
        MPI ranks.

    Returns
    -------
    dict
        ``status["pulsatile"]``: ``period_s``, ``cycles_run``, ``periodic``, ``changes`` (per
        cycle from the second), ``kept_cycles`` (1-based), ``window`` (start, end s),
        ``mean_times`` (the kept cycles' end folders: their cycle means), ``phases`` ({name:
        ``time_s``, ``time_name``, ``phase_s``, ``flow_rate_m3_s``}), ``cycles`` (per cycle: time
        steps, time step range, largest Courant number, CPU s), the plan.
    """
    plan = pulsatile_plan(state)
    pu: dict[str, Any] = {"solver": "pimpleFoam", "evaluated": False, **plan}
    status["pulsatile"] = pu
    status["criterion"] = (
        "periodic: cycle-to-cycle change of the pressure difference, outlet flow and outlet pressure waveforms "
        f"< {plan['tolerance']:g}"
        f" and of the TAWSS map < {plan['tawss_tolerance']:g} (relative), after at least {plan['cycles']} cycles, "
        f"at most {plan['max_cycles']}"
    )
    status["criterion_used"] = "none"
    solve = _Pimple(case_dir, state, run, ranks, case_dir / "processor0" if ranks > 1 else case_dir, {}, pu)
    solve.common.update(
        transient=True,
        residual_control=False,
        delta_t=_fmt_time(plan["delta_t_initial_s"]),
        max_delta_t=_fmt_time(plan["max_delta_t_s"]),
        max_co=plan["max_co"],
        outer_correctors=plan["outer_correctors"] if plan["max_co"] > 1.0 else 1,  # PISO-like at Co <= 1
        probe_points=state["cfd"]["pulsatile"].get("probes") or None,
    )
    cycles, changes, periodic = _run_until_periodic(solve, plan)
    kept = cycles[-plan["keep_cycles"] :]
    pu.update(
        {
            "evaluated": True,
            "cycles_run": len(cycles),
            "periodic": periodic,
            "changes": changes,
            "cycles": [{k2: v for k2, v in c.items() if k2 not in ("records", "tawss")} for c in cycles],
            "kept_cycles": [c["index"] for c in kept],
            "window": [kept[0]["start"], kept[-1]["end"]],
            "mean_times": [c["end_name"] for c in kept],
            "phases": _phase_record(state, plan, cycles[-1]),
        }
    )
    _plot(case_dir, cycles, plan)
    _verdict(status, plan, len(cycles), changes, periodic)
    return pu


def _run_until_periodic(
    solve: _Pimple, plan: dict[str, Any]
) -> tuple[list[dict[str, Any]], list[dict[str, Any]], bool]:
    """Cycles until periodic (at least ``cycles``, at most ``max_cycles``): (the cycles' records,
    the cycle-to-cycle changes, periodic)."""
    case_dir, state, ranks = solve.case_dir, solve.state, solve.ranks
    area = _wall_areas(case_dir, state, ranks)
    period = plan["period_s"]
    cycles: list[dict[str, Any]] = []
    changes: list[dict[str, Any]] = []
    periodic = False
    for k in range(1, plan["max_cycles"] + 1):
        cycle = _run_cycle(solve, plan, k)
        cycle["records"] = cycle_records(case_dir, state, (k - 1) * period, k * period)
        cycle["tawss"] = _wall_field(case_dir, state, ranks, cycle["end_name"], "magWallShearStressMean")
        cycles.append(cycle)
        if k >= 2:
            ch = cycle_change(cycles[-2], cycle, area)
            changes.append({"cycle": k, **ch})
            progress.info(
                "cycle %d: change from cycle %d: pressure difference %.2f%%, outlet flow %.2f%%, outlet pressure "
                "%.2f%% (tolerance %.2g%%), TAWSS %.2f%% (tolerance %.2g%%)",
                k,
                k - 1,
                100 * ch["dp"],
                100 * ch["flow"],
                100 * ch["pressure"],
                100 * plan["tolerance"],
                100 * ch["tawss"],
                100 * plan["tawss_tolerance"],
            )
            periodic = k >= plan["cycles"] and _periodic(ch, plan)
        _prune(case_dir, ranks, cycles, plan)
        if periodic:
            break
    return cycles, changes, periodic


def _periodic(change: dict[str, float], plan: dict[str, Any]) -> bool:
    """The waveforms within ``periodicity_tolerance`` and the TAWSS map within ``tawss_tolerance``."""
    waveforms = max(change["dp"], change["flow"], change.get("pressure", 0.0))
    return waveforms <= plan["tolerance"] and change["tawss"] <= plan["tawss_tolerance"]


def _verdict(
    status: dict[str, Any], plan: dict[str, Any], n_cycles: int, changes: list[dict[str, Any]], periodic: bool
) -> None:
    """``converged``, ``criterion_used`` and the reason of a pulsatile run."""
    if periodic:
        status.update(converged=True, criterion_used="periodic_cycles", reason=None)
        return
    last = changes[-1] if changes else {"dp": math.inf, "flow": math.inf, "pressure": math.inf, "tawss": math.inf}
    status["converged"] = False
    status["reason"] = (
        f"not periodic after {n_cycles} cycles (cfd.pulsatile.max_cycles): the last cycle-to-cycle change "
        f"is pressure difference {100 * last['dp']:.2f}%, outlet flow {100 * last['flow']:.2f}%, outlet pressure "
        f"{100 * last.get('pressure', 0.0):.2f}% (tolerance "
        f"{100 * plan['tolerance']:.2g}%), TAWSS {100 * last['tawss']:.2f}% (tolerance "
        f"{100 * plan['tawss_tolerance']:.2g}%); raise max_cycles"
    )


def _run_cycle(solve: _Pimple, plan: dict[str, Any], k: int) -> dict[str, Any]:
    """Cycle ``k`` (1-based): pimpleFoam from its start to its end, cut at the phase instants
    (each cut writes the instantaneous fields there); fieldAverage restarted at the cycle's start
    and continued across the cuts. Returns the cycle's record (times, steps, CPU)."""
    period = plan["period_s"]
    start, end = (k - 1) * period, k * period
    cuts = sorted({start + off for off in plan["phases"].values() if 0 < off < period}) + [end]
    t0 = time.process_time()
    wall0 = time.perf_counter()
    steps = 0
    dts: list[float] = []
    co: list[float] = []
    cpu = 0.0
    for i, cut in enumerate(cuts):
        parsed = _run_stage(solve, f"cycle{k}.{i}", cut, None, average=True, continue_average=i > 0)
        if k == 1 and i == 0 and len(cuts) > 1:
            _end_plane_limit(solve, plan)
        steps += len(parsed["rows"])
        dts += [x for x in (parsed["delta_t_min"], parsed["delta_t_max"]) if x]
        if parsed["courant_max"] is not None:
            co.append(parsed["courant_max"])
        cpu += float(parsed.get("execution_time_s") or 0.0) * solve.ranks  # ExecutionTime: CPU s of one rank
        if not any(abs(t - cut) < 1e-9 * max(1.0, cut) for t, _ in _time_dirs(solve.root)):
            raise Stop(f"pimpleFoam did not reach {cut:g} s in cycle {k}", f"pimpleFoam.cycle{k}.{i}")
    names = {round(t, 9): n for t, n in _time_dirs(solve.root)}
    return {
        "index": k,
        "start": start,
        "end": end,
        "end_name": names[round(end, 9)],
        "cut_names": [names[round(c, 9)] for c in cuts[:-1]],
        "time_steps": steps,
        "delta_t_s": {"min": min(dts, default=None), "max": max(dts, default=None)},
        "courant_max": max(co, default=None),
        "cpu_s": round(cpu, 2) if cpu else round(time.process_time() - t0, 2),
        "wall_s": round(time.perf_counter() - wall0, 2),
    }


def _end_plane_limit(solve: _Pimple, plan: dict[str, Any]) -> None:
    """After the first cut of the first cycle (peak systole by default: the largest flow), the
    Courant number limit set by the cells the flow crosses (:func:`vcs.cfd.transient.courant_plan`:
    the slivers snapping cuts at the end planes run up to ``max_co_end_cells``, with
    ``outer_correctors``), for the rest of the run; recorded in ``status["pulsatile"]["courant"]``."""
    pu = solve.state["cfd"]["pulsatile"]
    limits = {k: pu[k] for k in ("max_co", "max_co_end_cells", "outer_correctors")}
    try:
        cour = courant_plan(solve.case_dir, solve.state, solve.run, solve.ranks, solve.root, plan, limits=limits)
    except (Stop, OSError, ValueError) as exc:  # a cheaper time step is not worth a failed run
        reason = exc.reason if isinstance(exc, Stop) else f"{type(exc).__name__}: {exc}"
        progress.warning("end-plane Courant limit not set (%s): every cell stays at Co %g", reason, pu["max_co"])
        solve.tr["courant"] = {"error": reason, "pimple_max_co": solve.common["max_co"]}
        return
    solve.tr["courant"] = {k: v for k, v in cour.items() if k != "probe_points"}
    solve.common.update(max_co=cour["pimple_max_co"], outer_correctors=cour["outer_correctors"])


def _prune(case_dir: Path, ranks: int, cycles: list[dict[str, Any]], plan: dict[str, Any]) -> None:
    """Delete the time folders no longer needed: keep the end folders of the last ``keep_cycles``
    cycles (their means) and the last cycle's phase folders (in the case and in the processors)."""
    keep = {c["end_name"] for c in cycles[-plan["keep_cycles"] :]} | set(cycles[-1]["cut_names"])
    drop = {c["end_name"] for c in cycles} | {n for c in cycles for n in c["cut_names"]}
    roots = [case_dir] + ([p for p in case_dir.glob("processor*")] if ranks > 1 else [])
    for root in roots:
        for name in drop - keep:
            shutil.rmtree(root / name, ignore_errors=True)


def _phase_record(state: dict[str, Any], plan: dict[str, Any], last: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The phase instants of the last cycle: solver time and folder, offset in the cycle, flow rate.
    A phase at the cycle's start (offset 0, e.g. the peak of a waveform that starts at its maximum)
    is the cycle's end (the same phase of a periodic flow), whose folder is written anyway."""
    wf = case_waveform(state)
    out = {}
    cut_offsets = sorted({off for off in plan["phases"].values() if 0 < off < plan["period_s"]})
    folder = dict(zip(cut_offsets, last["cut_names"]))
    for name, off in plan["phases"].items():
        inside = 0 < off < plan["period_s"]
        out[name] = {
            "time_s": last["start"] + off if inside else last["end"],
            "time_name": folder[off] if inside else last["end_name"],
            "phase_s": off if inside else 0.0,
            "flow_rate_m3_s": float(wf(off)),
        }
    return out


def kept_wall_markers(case_dir: Path, state: dict[str, Any], pu: dict[str, Any]) -> dict[str, Any]:
    """TAWSS and OSI over the kept cycles on the wall faces (area-weighted mean, min, max, in Pa):
    the cycle means averaged (cycles of equal length: the kept window's time averages)."""
    rho = float(state["cfd"]["physics"]["rho"])
    area = _wall_areas(case_dir, state, 1)
    mean_vec = np.mean([_wall_field(case_dir, state, 1, n, "wallShearStressMean") for n in pu["mean_times"]], axis=0)
    tawss = np.mean([_wall_field(case_dir, state, 1, n, "magWallShearStressMean") for n in pu["mean_times"]], axis=0)
    osi = oscillatory_shear_index(mean_vec, tawss)

    def stats(x: NDArray[np.floating], scale: float) -> dict[str, float]:
        return {
            "mean": float((x * area).sum() / area.sum() * scale),
            "max": float(x.max() * scale),
            "min": float(x.min() * scale),
        }

    return {
        "wall_shear_stress_Pa": stats(np.linalg.norm(mean_vec, axis=1), rho)
        | {"field": "wallShearStressMean (kept cycles)"},
        "tawss_Pa": stats(tawss, rho) | {"field": "magWallShearStressMean (kept cycles)"},
        "osi": {"mean": float((osi * area).sum() / area.sum()), "max": float(osi.max()), "min": float(osi.min())},
    }


def _plot(case_dir: Path, cycles: list[dict[str, Any]], plan: dict[str, Any]) -> None:
    """``pulsatile.png``: the pressure difference and flow waveforms of every cycle over the
    phase, the kept ones solid, and the cycle-to-cycle changes."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        return
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    n_keep = plan["keep_cycles"]
    for i, c in enumerate(cycles):
        r = c["records"]
        kept = i >= len(cycles) - n_keep
        style = {"lw": 1.6 if kept else 0.8, "ls": "-" if kept else ":"}
        t = r["phase"] * plan["period_s"]
        ax[0].plot(t, r["dp"], label=f"cycle {c['index']}", **style)
        ax[1].plot(t, r["q_out"] * 6e4, **style)
    ax[0].set(xlabel="time in cycle [s]", ylabel="inlet - outlet p [m2/s2]", title="pressure difference")
    ax[1].set(xlabel="time in cycle [s]", ylabel="outlet flow [L/min]", title="outlet flow rate")
    ax[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(case_dir / "pulsatile.png", dpi=110)
    plt.close(fig)


def write_cycle_table(case_dir: Path, pu: dict[str, Any]) -> None:
    """``cycles.json``: per cycle its steps, CPU and change from the previous one (a bench reads it)."""
    changes = {c["cycle"]: c for c in pu.get("changes", [])}
    rows = [c | {"change": changes.get(c["index"])} for c in pu.get("cycles", [])]
    (case_dir / "cycles.json").write_text(json.dumps(rows, indent=1))
