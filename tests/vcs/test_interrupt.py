"""A solve that is interrupted (timeout, Ctrl-C, SIGTERM from scancel or Snakemake) stops its whole
OpenFOAM process group: no rank keeps running after the job ended."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from vcs.cfd.run import _Runner

ROOT = Path(__file__).resolve().parents[2]


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _alive(pid: int) -> bool:
    """True while ``pid`` runs (a zombie waiting for its reaper counts as gone)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


def _gone(pid: int, within: float = 10.0) -> bool:
    end = time.monotonic() + within
    while time.monotonic() < end:
        if not _alive(pid):
            return True
        time.sleep(0.1)
    return False


def _wait_for(path: Path, within: float = 20.0) -> int:
    end = time.monotonic() + within
    while time.monotonic() < end:
        if path.is_file() and path.read_text().strip():
            return int(path.read_text())
        time.sleep(0.05)
    raise AssertionError(f"{path} never written")


# a "solver" whose rank runs in the background, as mpirun's ranks do (ignoring SIGHUP)
RANK = "nohup sleep 300 >/dev/null 2>&1 & echo $! > rank.pid; wait"


def test_timeout_stops_the_whole_process_group(tmp_path):
    timings: dict[str, float] = {}
    r = _Runner(tmp_path, timings, timeout=1.0)(["sh", "-c", RANK], "fake")
    assert r.returncode == -9
    assert "timeout after 1.0 s" in (tmp_path / "logs" / "log.fake").read_text()
    assert _gone(int((tmp_path / "rank.pid").read_text())), "the background rank survived the timeout"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_to_a_workflow_job_stops_its_solver(tmp_path, sig):
    """A workflow script (workflow/scripts/_common.py) that gets SIGTERM (scancel) or SIGINT exits
    130 with one line in its log, and its running utility's process group is gone."""
    log = tmp_path / "job.log"
    script = textwrap.dedent(
        f"""
        import sys, types
        sys.path.insert(0, {str(ROOT / "workflow" / "scripts")!r})
        import _common
        from pathlib import Path
        from vcs.cfd.run import _Runner
        smk = types.SimpleNamespace(log=[{str(log)!r}])
        log = _common.setup(smk, "test")
        def main(smk):
            _Runner(Path({str(tmp_path)!r}), {{}}, timeout=None)(["sh", "-c", {RANK!r}], "solver")
        _common.run(main, smk, log)
        """
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    # SIGINT at its default in the child even when this test runs in a background job (where the
    # shell set it to ignored, and Python would then install no KeyboardInterrupt handler)
    proc = subprocess.Popen([sys.executable, "-c", script], env=env, preexec_fn=_default_sigint)
    rank = _wait_for(tmp_path / "rank.pid")
    # the rank writes its pid while the job's Popen may still be returning: a signal inside Popen
    # itself (before the job holds the process to stop its group) is not what this tests
    time.sleep(0.5)
    proc.send_signal(sig)
    assert proc.wait(timeout=30) == 130
    assert _gone(rank), "the solver's rank kept running after its job was interrupted"
    text = log.read_text()
    assert "interrupted" in text and "Traceback" not in text, text


def test_ctrl_c_inside_popen_still_stops_the_group(tmp_path, monkeypatch):
    """A Ctrl-C that lands while ``subprocess.Popen`` is still starting the utility (before the
    job holds the process) is deferred to the end of that call: the job raises KeyboardInterrupt
    and the new process group is stopped all the same (without the deferral it kept running)."""
    real_popen = subprocess.Popen

    def popen_then_ctrl_c(*args, **kwargs):
        proc = real_popen(*args, **kwargs)
        _wait_for(tmp_path / "rank.pid")  # the rank is running
        os.kill(os.getpid(), signal.SIGINT)  # ...and Ctrl-C comes before Popen has returned
        time.sleep(0.2)
        return proc

    monkeypatch.setattr(subprocess, "Popen", popen_then_ctrl_c)
    # Python's own Ctrl-C handler, also when the suite runs as a background job (SIGINT ignored)
    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            _Runner(tmp_path, {}, timeout=None)(["sh", "-c", RANK], "fake")
    finally:
        signal.signal(signal.SIGINT, old)
    assert _gone(int((tmp_path / "rank.pid").read_text())), "the rank outlived a Ctrl-C inside Popen"


def test_deferred_signals_are_all_delivered_and_the_handlers_restored():
    """Inside signals_deferred a SIGINT that is ignored stays ignored and a SIGTERM that comes after
    it is not lost: it reaches the job's own handler when the block ends; both handlers are the
    job's again afterwards."""
    from vcs._signals import signals_deferred

    got = []

    def on_term(signum, frame):
        got.append(signum)

    old_int = signal.signal(signal.SIGINT, signal.SIG_IGN)
    old_term = signal.signal(signal.SIGTERM, on_term)
    try:
        with signals_deferred():
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(0.05)
            assert got == []  # deferred
        time.sleep(0.05)
        assert got == [signal.SIGTERM]
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGTERM) is on_term
    finally:
        signal.signal(signal.SIGINT, old_int)
        signal.signal(signal.SIGTERM, old_term)
