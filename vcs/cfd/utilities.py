"""Running OpenFOAM utilities: each in its own process group (stopped whole on a timeout, Ctrl-C or
SIGTERM), logged to ``logs/log.<name>`` and timed; the case's time folders; and a failed
utility's or solver's log turned into a one-line reason (FOAM FATAL ERROR, divergence, timeout,
death by a signal)."""

from __future__ import annotations

import logging
import os
import re
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vcs._signals import signals_deferred
from vcs.cfd.openfoam import foam_env

# the progress of a case (the workflow's openfoam_solve log): one logger for every stage of
# vcs.cfd.run.run_case, named after it
progress = logging.getLogger("vcs.cfd.run")


class Stop(Exception):
    """A stage of :func:`vcs.cfd.run.run_case` cannot go on: the run ends with ``reason``.

    Parameters
    ----------
    reason : str or None
        Why, in one line (status.json ``reason``; None keeps the reason already recorded).
    failed_log : str or None
        Name of the failed utility's log (``logs/log.<failed_log>``; status.json ``failed_log``).
    """

    def __init__(self, reason: str | None, failed_log: str | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.failed_log = failed_log


def _run_group(
    cmd: list[str],
    cwd: Path,
    env: dict[str, str],
    out: Any,
    timeout: float | None,
    watch: Callable[[], object] | None = None,
    poll_s: float = 2.0,
) -> subprocess.CompletedProcess[bytes]:
    """Run ``cmd`` in its own process group and wait; on a timeout, Ctrl-C (KeyboardInterrupt) or
    any other exit of the caller, stop the WHOLE group (mpirun and every rank: SIGTERM, then
    SIGKILL after 5 s) before re-raising, so that no solver keeps running after its job ended.
    ``watch``, when given, is called every ``poll_s`` seconds while the command runs (e.g. to
    read its log and ask the solver to stop)."""
    proc = None
    try:
        # a Ctrl-C inside Popen itself would leave the new group running with no `proc` to stop it:
        # deferred to the end of the call, where it raises inside this try
        with signals_deferred():
            proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
        if watch is None:
            return subprocess.CompletedProcess(cmd, returncode=proc.wait(timeout=timeout))
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            wait = poll_s if end is None else min(poll_s, max(end - time.monotonic(), 0.0))
            try:
                return subprocess.CompletedProcess(cmd, returncode=proc.wait(timeout=wait))
            except subprocess.TimeoutExpired:
                if end is not None and time.monotonic() >= end:
                    raise
                watch()
    except BaseException:
        if proc is not None:
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

    def __call__(
        self, args: list[str], log: str, ranks: int = 1, watch: Callable[[Path], object] | None = None
    ) -> subprocess.CompletedProcess[bytes]:
        """Run ``args`` (under mpirun with -parallel when ranks > 1); a timeout gives returncode -9,
        an executable that cannot be started 127. Never raises, except when the caller is interrupted
        (Ctrl-C, or SIGTERM turned into KeyboardInterrupt by the workflow scripts): then the
        utility's whole process group is stopped first. ``watch(log file)`` is called every
        ``watch.poll_s`` seconds (2 s when it has none) while it runs."""
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
        progress.info("running %s (logs/log.%s)", " ".join(args), log)
        with open(self.logs / f"log.{log}", "w") as fh:
            fh.write(f"# {' '.join(cmd)}\n")
            fh.flush()
            try:
                log_file = self.logs / f"log.{log}"
                r = _run_group(
                    cmd,
                    self.case,
                    self.env,
                    fh,
                    self.timeout,
                    None if watch is None else lambda: watch(log_file),
                    poll_s=float(getattr(watch, "poll_s", 2.0)),
                )
            except subprocess.TimeoutExpired:
                r = subprocess.CompletedProcess(cmd, returncode=-9)
                fh.write(f"\n# vcsflow: timeout after {self.timeout} s\n")
            except OSError as exc:  # e.g. the utility is not on PATH: a failed utility, not a crash
                r = subprocess.CompletedProcess(cmd, returncode=127)
                fh.write(f"\n--> FOAM FATAL ERROR: vcsflow could not start {cmd[0]}: {exc}\n")
            else:
                if r.returncode < 0:  # killed from outside (OOM killer, kill, a scheduler): say by what
                    try:
                        name = signal.Signals(-r.returncode).name
                    except ValueError:
                        name = "unknown signal"
                    fh.write(f"\n# vcsflow: killed by signal {-r.returncode} ({name})\n")
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


def _time_dirs(root: Path) -> list[tuple[float, str]]:
    """(value, name) of the numeric time folders in ``root``, sorted by value."""
    out = []
    if root.is_dir():
        for p in root.iterdir():
            if p.is_dir():
                try:
                    out.append((float(p.name), p.name))
                except ValueError:
                    pass
    return sorted(out)


TIME_PRECISION = 10
"""The controlDict's ``timePrecision`` (significant digits of a time folder's name), unless a
folder already written needs more (:func:`time_precision`)."""


def time_precision(root: Path) -> int:
    """The ``timePrecision`` a solver restarted from ``root``'s latest time needs to find its folder.

    OpenFOAM names a time folder with ``timePrecision`` significant digits and raises that precision
    on its own when two names would round alike or the name would misstate the time (ESI v1912
    ``Time::operator++``: "Increased the timePrecision from 10 to 13 ..."). A run started with
    ``startFrom latestTime`` names the time it reads with its controlDict's precision, so a folder
    written at 13 digits (``366.0959205891``) is looked for as ``366.0959206`` and not found (AortaCFD
    patient1's averaging stage after a wash-out stopped by writeNow). So: the most significant digits of
    any time folder name under ``root``, at least :data:`TIME_PRECISION`.

    >>> import tempfile
    >>> d = Path(tempfile.mkdtemp())
    >>> for name in ("0", "366", "366.0959205891", "1e-05"):
    ...     (d / name).mkdir()
    >>> time_precision(d)
    13
    """
    digits = [TIME_PRECISION]
    for _, name in _time_dirs(root):
        mantissa = name.lstrip("+-").split("e")[0].split("E")[0].replace(".", "").lstrip("0")
        digits.append(len(mantissa))
    return max(digits)


def _fmt_time(t: float) -> str:
    """A solver time for a dictionary (12 significant digits)."""
    return f"{t:.12g}"


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
    else:
        sig = _signal_reason(txt, log)
        if sig:
            return f"{utility} {sig}"
    return f"{utility} failed{detail} (see logs/log.{utility})"


# signals that come from outside a process (the OOM killer and kill send KILL; schedulers TERM,
# XCPU; a closed terminal HUP): any other signal is the utility's own crash
_OUTSIDE_SIGNALS = ("SIGKILL", "SIGTERM", "SIGINT", "SIGHUP", "SIGXCPU")


def _signal_reason(txt: str, log: Path) -> str | None:
    """``was killed by signal N (NAME) ...`` / ``crashed with signal ...`` when the runner
    recorded a death by signal in the log (see :class:`_Runner`), else None."""
    k = re.search(r"# vcsflow: killed by signal (\d+) \(([\w ]+)\)", txt)
    if not k:
        return None
    if k.group(2) in _OUTSIDE_SIGNALS:
        return (
            f"was killed by signal {k.group(1)} ({k.group(2)}) from outside the run "
            f"(out of memory, a scheduler's limit, or kill; see logs/{log.name})"
        )
    return f"crashed with signal {k.group(1)} ({k.group(2)}) (see logs/{log.name})"


def _solver_failure(log: Path, stage: str, solver: str = "simpleFoam") -> str:
    """One-line reason for a failed solver stage from the end of its log."""
    txt = log.read_text(errors="replace")[-4000:] if log.exists() else ""
    m = re.search(r"(FOAM FATAL[^\n]*\n(?:[^\n]*\n){0,6})", txt)
    # a divergence: OpenFOAM's sigFpe handler's stack trace, the shell's "Floating point exception"
    # at the start of a line, or death by SIGFPE; NOT the banner's "trapFpe: Floating point
    # exception trapping enabled" (or the older "sigFpe : Enabling ..."), which every log has
    if (
        "sigFpe::sigHandler" in txt
        or re.search(r"^Floating point exception", txt, re.M)
        or "# vcsflow: killed by signal 8 (SIGFPE)" in txt
    ):
        return f"{solver} ({stage}) diverged: floating point exception (see logs/{log.name})"
    if "# vcsflow: timeout" in txt:
        return f"{solver} ({stage}) stopped: timeout (cfd.solver.timeout_s; see logs/{log.name})"
    k = _signal_reason(txt, log)
    if k:
        return f"{solver} ({stage}) {k}"
    if m:
        return f"{solver} ({stage}) failed: " + " ".join(m.group(1).split())[:400]
    return f"{solver} ({stage}) exited with an error (see logs/{log.name})"
