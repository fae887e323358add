"""The steady strategy: simpleFoam's start-up (first order) and main stage (residualControl),
and, when SIMPLE stops above the residual tolerance, the plateau check (more iterations; steady
when the solution no longer changes). Also the convergence criterion in words."""

from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vcs.cfd.case import render_files
from vcs.cfd.foamfiles import function_series, parse_solver_log, read_internal_field
from vcs.cfd.status import _log_summary, _wall_faces, _wall_values, collect
from vcs.cfd.utilities import Stop, _Runner, _solver_failure, _time_dirs, progress

# the files every solver stage renders again (end time, schemes, residual control, averaging)
STAGE_FILES = ["system/controlDict", "system/fvSchemes", "system/fvSolution"]


@dataclass
class SteadyResult:
    """What the steady stage leaves to the rest of :func:`vcs.cfd.run.run_case`.

    Attributes
    ----------
    converged : bool
        SIMPLE converged (residualControl, or the plateau check).
    main : dict
        The main SIMPLE stage's log (:func:`vcs.cfd.foamfiles.parse_solver_log`).
    logs : list of Path
        The SIMPLE stages' logs, in the order they ran (start-up, main, plateau check).
    """

    converged: bool
    main: dict[str, Any]
    logs: list[Path]


def steady_solve(
    case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner, ranks: int, prof: dict[str, Any]
) -> SteadyResult:
    """SIMPLE: start-up, main stage, and the plateau check when the residuals stopped above the
    tolerance; fills ``status`` (``solver_log``, ``converged``, ``criterion_used``, ``fields``,
    ``reason``, ``plateau``).

    Parameters
    ----------
    case_dir : Path
        A meshed case (decomposed when ``ranks`` > 1).
    state : dict
        Case description (``cfd.solver``).
    status : dict
        The status being built.
    run : _Runner
        Runs the solver in the case.
    ranks : int
        MPI ranks.
    prof : dict
        The inlet profile (:func:`vcs.cfd.case.inlet_profile`; ``peak_velocity``).

    Returns
    -------
    SteadyResult
        Converged or not (a divergence, handed to the transient fallback, is not), the main
        stage's log, the stages' logs.

    Raises
    ------
    Stop
        The start-up failed; the main stage failed other than by a divergence the transient
        fallback can take over; or no SIMPLE iteration could be read from its log.
    """
    logs: list[Path] = []
    main, diverged = _run_simple(case_dir, state, status, run, ranks, logs)
    converged = _residuals_converged(case_dir, state, status, logs, main, diverged)
    if not converged:
        if diverged is not None:  # the transient starts from the last state SIMPLE wrote (its start-up's)
            status["reason"] = diverged
        else:
            converged = _residual_plateau(case_dir, state, status, run, ranks, prof, main, logs)
    return SteadyResult(converged, main, logs)


def _run_simple(
    case_dir: Path, state: dict[str, Any], status: dict[str, Any], run: _Runner, ranks: int, logs: list[Path]
) -> tuple[dict[str, Any], str | None]:
    """simpleFoam start-up (``startup_iterations`` at ``startup_scheme``, no residualControl) and
    main stage (up to ``max_iterations``); their logs appended to ``logs``.

    Returns the main stage's parsed log and, when it diverged and the transient fallback will take
    over, the divergence in words (else None); raises :class:`Stop` for any other failure.
    """
    sol = state["cfd"]["solver"]
    n_start = int(sol["startup_iterations"])
    if n_start > 0:
        render_files(
            case_dir, state, STAGE_FILES, end_time=n_start, div_scheme=sol["startup_scheme"], residual_control=False
        )
        r = run(["simpleFoam"], "simpleFoam.startup", ranks)
        logs.append(case_dir / "logs" / "log.simpleFoam.startup")
        if r.returncode != 0:
            raise Stop(_solver_failure(logs[-1], "start-up"), "simpleFoam.startup")
    render_files(case_dir, state, STAGE_FILES, end_time=int(sol["max_iterations"]))
    watch = PlateauWatch(case_dir, sol, end_iteration=int(sol["max_iterations"]))
    r = run(["simpleFoam"], "simpleFoam", ranks, watch=watch if watch.enabled else None)
    logs.append(case_dir / "logs" / "log.simpleFoam")
    main = parse_solver_log(logs[-1])
    status["solver_log"] = _log_summary(main, logs[-1])
    if watch.stopped_at is not None:
        watch.ended([r for r in main["rows"] if "p" in r])
        status["plateau_early_stop"] = watch.report()
    if r.returncode == 0:
        return main, None
    failure = _solver_failure(logs[-1], "main")
    if sol.get("fallback") != "transient" or "diverged" not in failure:
        collect(case_dir, status, logs, state)
        raise Stop(failure, "simpleFoam")
    return main, failure  # steady SIMPLE blew up; an unsteady flow may still have a time average


class PlateauWatch:
    """Stops the main SIMPLE stage as soon as its residuals have levelled off (read from its log
    while it runs), instead of after ``max_iterations``: the plateau check then decides.

    Levelled off at iteration n: at least twice ``plateau.iterations`` (the window W) iterations ran
    and neither initial residual (p, U) fell by more than a factor :data:`EARLY_STOP_DECLINE` over
    iterations n - W + 1 .. n (geometric means of the window's first and last tenth). Below
    ``plateau.max_residual`` the plateau check then decides; above it (``stalled``: an unsteady
    flow, e.g. the jet of a coarctation, whose SIMPLE residuals hover at 1e-2) the main stage needs
    three windows of iterations before it is stopped, and the transient solve takes over at once
    instead of after ``max_iterations`` (AortaCFD patient1 at 0.59 mm: ~1 CPU s per iteration).
    A run still converging (residuals falling by a decade per few hundred iterations) is left
    alone, to meet residualControl. (With ``fallback: none`` a stalled run is stopped too: it
    would end not converged at ``max_iterations`` all the same.)

    Reproducible: the decision is a function of the residual series alone. Every iteration n the
    log holds is judged on the rows up to n (:meth:`levelled`), whenever the log happens to be
    read, so the first n* at which the residuals levelled off does not depend on when the watch
    looked; the stop is then set ahead of the solver, at iteration n* + :data:`STOP_LEAD`
    (``endTime`` and ``writeInterval`` in system/controlDict, read by the solver at its next
    iteration: ``runTimeModifiable``), so the same inputs stop at the same iteration on a loaded or
    an idle machine. Only when the solver is already past that iteration when the watch reads the
    log (more than :data:`STOP_LEAD` iterations between two looks) it is stopped where it is
    (``stopAt writeNow``) and the report says ``deterministic: false``.
    """

    def __init__(self, case_dir: Path, sol: dict[str, Any], *, end_iteration: int | None = None) -> None:
        pl = sol.get("plateau") or {}
        self.end_iteration = end_iteration  # the stage's own endTime: a stop is never set past it
        self.control = case_dir / "system" / "controlDict"
        self.window = int(pl.get("iterations", 0))
        self.max_residual = float(pl.get("max_residual", 0.0))
        self.enabled = bool(pl.get("early_stop", False)) and self.window > 0
        self.stopped_at: int | None = None
        self.decided_at: int | None = None
        self.deterministic = True
        self.stalled = False
        self.decline: dict[str, float] = {}
        self._judged = 0  # rows judged so far (each judged once, on the rows up to it)
        self.poll_s = WATCH_POLL_S  # read by vcs.cfd.utilities._Runner

    def levelled(self, rows: list[dict[str, float]]) -> tuple[dict[str, float], bool] | None:
        """Whether the residuals up to the last of ``rows`` levelled off: (the decline over the
        window (log10 of the fall of p and U), above ``max_residual``), else None."""
        if len(rows) < 2 * self.window:
            return None
        win = rows[-self.window :]
        above = not max(max(r["p"], r["U"]) for r in win) < self.max_residual
        if above and len(rows) < 3 * self.window:
            return None
        k = max(self.window // 10, 1)
        decline = {
            f: float(np.mean(np.log10([r[f] for r in win[:k]])) - np.mean(np.log10([r[f] for r in win[-k:]])))
            for f in ("p", "U")
        }
        return (decline, above) if max(decline.values()) < np.log10(EARLY_STOP_DECLINE) else None

    def __call__(self, log: Path) -> None:
        """Read the log; judge every iteration not judged yet; at the first that levelled off,
        set the solver's stop :data:`STOP_LEAD` iterations on (once)."""
        if self.decided_at is not None or not log.exists():
            return
        rows = [r for r in parse_solver_log(log)["rows"] if "p" in r and "U" in r]
        for n in range(max(self._judged + 1, 2 * self.window), len(rows) + 1):
            found = self.levelled(rows[:n])
            if found is None:
                continue
            self.decline, self.stalled = found
            self.decided_at = int(rows[n - 1]["time"])
            target = self.decided_at + STOP_LEAD
            now = int(rows[-1]["time"])
            if self.end_iteration is not None and target >= self.end_iteration:
                self.stopped_at = self.end_iteration  # it ends there anyway: nothing to change
            elif now < target - 1:  # the solver reads controlDict at its next iteration
                request_end_at(self.control, target)
                self.stopped_at = target
            else:
                request_write_now(self.control)
                self.stopped_at, self.deterministic = now + 1, False
            progress.info(
                "SIMPLE residuals levelled off at iteration %d (p %.3g, U %.3g; fell by x%.2f, x%.2f over %d)%s; "
                "stopping it at iteration %d%s",
                self.decided_at,
                rows[n - 1]["p"],
                rows[n - 1]["U"],
                10 ** self.decline["p"],
                10 ** self.decline["U"],
                self.window,
                f" above {self.max_residual:g}: not a steady solution" if self.stalled else " (the plateau check next)",
                self.stopped_at,
                "" if self.deterministic else " (the solver was past the set stop: where it is, not reproducible)",
            )
            return
        self._judged = max(self._judged, len(rows))

    def ended(self, rows: list[dict[str, float]]) -> None:
        """After the run: the iteration it really ended at (the log's last), when that is not the
        set stop (residualControl met, or the solver ended, before it)."""
        if rows and self.stopped_at is not None and int(rows[-1]["time"]) != self.stopped_at:
            self.stopped_at = int(rows[-1]["time"])

    def report(self) -> dict[str, Any]:
        """status.json ``plateau_early_stop``: where it was decided and stopped, the decline over
        the window, and whether the stop is reproducible (set ahead of the solver)."""
        return {
            "iteration": self.stopped_at,
            "decided_at": self.decided_at,
            "lead": STOP_LEAD,
            "deterministic": self.deterministic,
            "window": self.window,
            "decline_factor": {f: float(10**v) for f, v in self.decline.items()},
            "max_decline_factor": EARLY_STOP_DECLINE,
            "above_max_residual": self.stalled,
        }


STOP_LEAD = 50
"""Iterations between the one at which :class:`PlateauWatch` finds the residuals levelled off and
the one the solver is stopped at (set ahead of it, so that the stop does not depend on when the log
was read: the watch reads it every :data:`WATCH_POLL_S` s, a few iterations of a real aorta, ~25
of a CI-sized case)."""

WATCH_POLL_S = 0.25
"""How often (s) :class:`PlateauWatch` reads the solver's log."""


def request_end_at(control: Path, iteration: int) -> None:
    """Ask a running steady solver to end at ``iteration`` and write its state there: ``endTime``
    and ``writeInterval`` (``writeControl timeStep``) of its system/controlDict set to it, read
    again at its next step (``runTimeModifiable``; the time stamp moved past OpenFOAM's
    ``fileModificationSkew``, as :func:`request_write_now`)."""
    before = control.stat().st_mtime
    text = control.read_text()
    text = re.sub(r"^endTime\s+\S+;", f"endTime         {iteration};", text, count=1, flags=re.M)
    text = re.sub(r"^writeInterval\s+\S+;", f"writeInterval   {iteration};", text, count=1, flags=re.M)
    tmp = control.with_name(f".{control.name}.endAt")  # written whole, then renamed: never read half
    tmp.write_text(text)
    os.utime(tmp, (time.time(), max(time.time(), before + 60.0)))
    os.replace(tmp, control)


def request_write_now(control: Path) -> None:
    """Ask a running solver to write its state and end: ``stopAt writeNow`` in its
    system/controlDict (read again at its next step: ``runTimeModifiable``), the file's time stamp
    moved a minute on, past OpenFOAM's ``fileModificationSkew`` (10 s), so that the change is seen
    at once."""
    before = control.stat().st_mtime
    text = control.read_text()
    tmp = control.with_name(f".{control.name}.writeNow")  # written whole, then renamed: never read half
    tmp.write_text(text.replace("stopAt          endTime;", "stopAt          writeNow;", 1))
    os.utime(tmp, (time.time(), max(time.time(), before + 60.0)))
    os.replace(tmp, control)


EARLY_STOP_DECLINE = 1.5
"""Largest fall (factor) of the p and U residuals over the plateau window at which the main SIMPLE
stage is stopped early (:class:`PlateauWatch`)."""


def _residuals_converged(
    case_dir: Path,
    state: dict[str, Any],
    status: dict[str, Any],
    logs: list[Path],
    main: dict[str, Any],
    diverged: str | None,
) -> bool:
    """Did the main stage meet residualControl (its message, or the last residuals below the
    tolerance)? Fills ``converged``, ``criterion_used`` and ``fields`` of ``status``; raises
    :class:`Stop` when the log holds no iteration to judge (and nothing to start a transient from)."""
    last = main["rows"][-1] if main["rows"] else {}
    tol = float(state["cfd"]["solver"]["tolerance"])
    if diverged is None and not last and not main["converged_message"]:
        # nothing to judge convergence on, and nothing to start a transient run from: say so
        collect(case_dir, status, logs, state)
        raise Stop(
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
    return converged


def _residual_plateau(
    case_dir: Path,
    state: dict[str, Any],
    status: dict[str, Any],
    run: _Runner,
    ranks: int,
    prof: dict[str, Any],
    main: dict[str, Any],
    logs: list[Path],
) -> bool:
    """SIMPLE stopped above the tolerance: the reason, then :func:`_plateau_check` (its log
    appended to ``logs``). True when the extra iterations converged or showed a plateau (then
    ``status`` says so and has no reason)."""
    last = main["rows"][-1] if main["rows"] else {}
    tol = float(state["cfd"]["solver"]["tolerance"])
    status["reason"] = (
        f"SIMPLE did not reach initial residuals < {tol:g} in {int(last.get('time', 0))} "
        f"iterations (last p {last.get('p', float('nan')):.3g}, U {last.get('U', float('nan')):.3g})"
    )
    plateau = _plateau_check(case_dir, state, status, run, ranks, prof, last)
    if plateau.get("log"):
        logs.append(plateau.pop("log"))
    if plateau.get("converged_by") is not None:
        status["converged"] = True
        status["criterion_used"] = plateau["converged_by"]
        status["reason"] = None
        return True
    if plateau.get("ran"):
        status["reason"] += f"; plateau check ({status['plateau']['iterations']} more iterations): "
        status["reason"] += status["plateau"]["why"]
    return False


def _plateau_check(
    case_dir: Path,
    state: dict[str, Any],
    status: dict[str, Any],
    run: _Runner,
    ranks: int,
    prof: dict[str, Any],
    last: dict[str, Any],
) -> dict[str, Any]:
    """SIMPLE stopped above the residual tolerance: is it a plateau of a steady solution?

    On real meshes the initial residuals of SIMPLE often level off above 1e-5 (a few distorted
    cells near snapped edges) while the solution no longer changes. When the last residuals are
    below ``cfd.solver.plateau.max_residual``, SIMPLE runs ``plateau.iterations`` more iterations
    from its last state; the solution is steady (``converged_by`` ``residual_plateau``) when the
    residuals stay below ``max_residual`` over those iterations, the inlet-outlet pressure
    difference departs from its first value by less than ``plateau.tolerance`` at every one of
    them (relative to max(|dp|, 10 % of the inlet dynamic pressure), as in :func:`vcs.cfd.transient.window_statistics`;
    every iteration, so a limit cycle whose period divides the window cannot pass), and the
    area-mean |WSS| and U (volume-weighted L2 of the change / of U) differ between the two states
    by less than ``plateau.tolerance``. A flow that keeps changing (a jet, vortex shedding) fails
    the test and goes to the fallback.
    Fills ``status["plateau"]``; never raises (a failure is recorded as ``why``).

    Returns
    -------
    dict
        ``converged_by``: ``residualControl`` (the extra iterations met the tolerance),
        ``residual_plateau`` or None; ``ran``: the extra iterations ran; ``log``: their log.
    """
    sol = state["cfd"]["solver"]
    pl = sol.get("plateau") or {}
    n_it = int(pl.get("iterations", 0))
    out: dict[str, Any] = {"converged_by": None}
    if n_it <= 0:
        return out
    info: dict[str, Any] = {
        "iterations": n_it,
        "max_residual": float(pl["max_residual"]),
        "tolerance": float(pl["tolerance"]),
        "stationary": False,
    }
    status["plateau"] = info
    res = {k: float(last[k]) for k in ("p", "U") if k in last}
    if len(res) < 2 or not max(res.values()) < info["max_residual"]:
        info["why"] = f"residuals {res} not below {info['max_residual']:g}: no plateau check"
        return out
    try:
        _plateau_iterations(case_dir, state, run, ranks, prof, info, out)
    except Exception as exc:  # noqa: BLE001 - the check never raises: its failure is a reason
        info["why"] = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
    return out


def _plateau_iterations(
    case_dir: Path,
    state: dict[str, Any],
    run: _Runner,
    ranks: int,
    prof: dict[str, Any],
    info: dict[str, Any],
    out: dict[str, Any],
) -> None:
    """The plateau check's extra SIMPLE iterations and the comparison of the states before and
    after them (:func:`_plateau_check`); fills ``info`` (``status["plateau"]``) and ``out``."""
    sol = state["cfd"]["solver"]
    n_it = int(info["iterations"])
    root = case_dir / "processor0" if ranks > 1 else case_dir
    times = _time_dirs(root)
    if not times:
        info["why"] = "SIMPLE wrote no time folder"
        return
    t0, t0_name = times[-1]
    end = int(round(t0)) + n_it
    render_files(case_dir, state, STAGE_FILES, end_time=end, cell_volumes=True)
    out["ran"] = True
    r = run(["simpleFoam"], "simpleFoam.plateau", ranks)
    out["log"] = case_dir / "logs" / "log.simpleFoam.plateau"
    parsed = parse_solver_log(out["log"])
    if r.returncode != 0:
        info["why"] = _solver_failure(out["log"], "plateau check")
        return
    if parsed["converged_message"] or (
        parsed["rows"]
        and parsed["rows"][-1].get("p", 1) < float(sol["tolerance"])
        and parsed["rows"][-1].get("U", 1) < float(sol["tolerance"])
    ):
        info["why"] = "the extra iterations met the residual tolerance"
        out["converged_by"] = "residualControl"
        return
    t1, t1_name = _time_dirs(root)[-1]
    if t1 <= t0:
        info["why"] = "the plateau check wrote no new time folder"
        return
    worst = max((max(row.get("p", 1.0), row.get("U", 1.0)) for row in parsed["rows"]), default=float("nan"))
    info["max_residual_in_window"] = worst
    if not worst < info["max_residual"]:
        info["why"] = f"a residual rose to {worst:.3g} (>= {info['max_residual']:g}) during the extra iterations"
        return
    if ranks > 1 and run(["reconstructPar", "-time", f"{t0_name},{t1_name}"], "reconstructPar").returncode != 0:
        info["why"] = "reconstructPar failed"
        return
    diffs = _state_change(case_dir, state, t0, t0_name, t1, t1_name, float(prof["peak_velocity"]))
    info.update({"from_iteration": t0_name, "to_iteration": t1_name, "changes": diffs})
    bad = [k for k, v in diffs.items() if not v < info["tolerance"]]  # NaN is not stationary
    info["stationary"] = not bad
    if bad:
        info["why"] = "still changing: " + ", ".join(f"{k} {100 * diffs[k]:.3g} %" for k in bad)
    else:
        out["converged_by"] = "residual_plateau"


def volume_l2_ratio(vol: NDArray[np.floating], diff: NDArray[np.floating], ref: NDArray[np.floating]) -> float:
    """Volume-weighted L2 norm of a change of a vector field relative to that of the field:
    sqrt(sum V |diff|^2 / sum V |ref|^2) (the U criterion of the plateau check)."""
    return float(np.sqrt((vol * (diff**2).sum(1)).sum() / max((vol * (ref**2).sum(1)).sum(), 1e-300)))


def plateau_pressure_change(dp: NDArray[np.floating], scale: float) -> float:
    """Largest relative departure of the inlet-outlet pressure difference from its first value
    over the plateau check's iterations: max_i |dp_i - dp_0| / scale (``scale`` > 0)."""
    dp = np.asarray(dp, dtype=float)
    return float(np.max(np.abs(dp - dp[0])) / scale) if len(dp) else float("nan")


def _state_change(
    case_dir: Path, state: dict[str, Any], t0: float, d0: str, t1: float, d1: str, peak_velocity: float
) -> dict[str, float]:
    """Relative change of the inlet-outlet pressure difference, the area-mean |WSS| and U (volume
    L2) between two written SIMPLE states (time folders ``d0`` and ``d1``, solver times t0, t1)."""
    from vcs.cfd.outlets import pressure_outlets

    inlets = [p["name"] for p in state["patches"] if p["role"] == "inlet"]
    outlets = pressure_outlets(state["patches"])  # the main outlets when there are branches

    def series(name: str) -> dict[int, float]:
        ser = function_series(case_dir, f"pressure_{name}")
        return {int(round(t)): float(v) for t, v in ser if t0 - 0.5 < t < t1 + 0.5}

    s_in = series(inlets[0])
    s_out = [series(n) for n in outlets]
    its = [i for i in range(int(round(t0)), int(round(t1)) + 1) if i in s_in and all(i in o for o in s_out)]
    if len(its) != int(round(t1)) - int(round(t0)) + 1:
        raise ValueError(f"patch pressures missing at some iterations from {t0:g} to {t1:g}")
    dps = np.array([s_in[i] - float(np.mean([o[i] for o in s_out])) for i in its])
    dp_scale = max(abs(dps[-1]), 0.1 * 0.5 * peak_velocity**2)
    walls = _wall_faces(case_dir, state)
    area = np.concatenate([a for _, a in walls])

    def wss(d: str) -> float:
        v = _wall_values(case_dir / d, "wallShearStress", walls)
        return float((np.linalg.norm(v, axis=1) * area).sum() / area.sum())

    w0, w1 = wss(d0), wss(d1)
    vol = read_internal_field(case_dir / d1 / "V")
    u0 = read_internal_field(case_dir / d0 / "U", len(vol))
    u1 = read_internal_field(case_dir / d1 / "U", len(vol))
    if u0.shape != u1.shape or len(u1) != len(vol):
        raise ValueError(f"U ({u0.shape}, {u1.shape}) and V ({vol.shape}) do not match")
    l2 = volume_l2_ratio(vol, u1 - u0, u1)
    return {
        # every iteration of the window, not only its ends: a limit cycle whose period divides the
        # window would have equal ends
        "inlet_minus_outlet_pressure": plateau_pressure_change(dps, dp_scale),
        "wss_mean": abs(w1 - w0) / max(abs(w1), 1e-300),
        "U_L2": l2,
    }


def _criterion_text(sol: dict[str, Any]) -> str:
    """The convergence criterion of a solver set-up, in words (status.json ``criterion``)."""
    txt = f"initial residuals of p and U < {sol['tolerance']:g}"
    pl = sol.get("plateau") or {}
    if int(pl.get("iterations", 0)) > 0:
        txt += (
            f"; or a residual plateau: residuals < {pl['max_residual']:g} throughout {int(pl['iterations'])} more "
            f"SIMPLE iterations, the inlet-outlet pressure difference within {100 * pl['tolerance']:g} % of its "
            f"first value at every one of them, and mean |WSS| and U (volume L2) changed by < "
            f"{100 * pl['tolerance']:g} %"
        )
        if pl.get("early_stop"):
            txt += (
                f" (the main stage stopped early once the residuals, below {pl['max_residual']:g}, fell by less "
                f"than x{EARLY_STOP_DECLINE:g} over {int(pl['iterations'])} iterations)"
            )
    if sol.get("fallback") == "transient":
        tr = sol["transient"]
        txt += (
            f"; else (fallback transient) the time average after a {tr['washout_flow_throughs']:g} flow-through "
            f"wash-out, over {tr['min_flow_throughs']:g} to {tr['max_flow_throughs']:g} flow-through times, ended as "
            f"soon as the {100 * tr['confidence']:g} % confidence intervals of its means are within "
            f"{100 * tr['error_tolerance']:g} % (inlet-outlet pressure difference, mean TAWSS) and "
            f"{100 * tr['error_tolerance_U']:g} % (U, L2 over probe cells); stationary only then"
        )
    return txt
