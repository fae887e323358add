"""`fit_vessel` runs its self-intersection test on a second thread only with a core to spare
(vcs.vessel.spare_core): a Snakemake job of one thread (OMP_NUM_THREADS=1) or a process pinned to
one core gets no thread. Either way the fit and its report are the same."""

from __future__ import annotations

import os
import signal
import threading

import pytest
from test_self_intersections import folded_tube

from vcs.io import Surface
from vcs.vessel import _Background, fit_vessel, spare_core


@pytest.mark.parametrize(
    "omp, cores, expected", [(None, {0, 1}, True), ("1", {0, 1}, False), (None, {0}, False), ("4", {0, 1}, True)]
)
def test_spare_core_follows_the_affinity_and_omp_num_threads(monkeypatch, omp, cores, expected):
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: cores)
    if omp is None:
        monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    else:
        monkeypatch.setenv("OMP_NUM_THREADS", omp)
    assert spare_core() is expected


def test_background_runs_on_a_thread_only_when_asked():
    names = []

    def who() -> str:
        names.append(threading.current_thread().name)
        return "done"

    assert _Background(who, threaded=True).result() == "done"
    assert _Background(who, threaded=False).result() == "done"
    assert names[0] == "who" and names[1] == threading.main_thread().name


def test_background_hands_the_exception_to_the_caller():
    def fail() -> None:
        raise ValueError("from the thread")

    for threaded in (True, False):
        with pytest.raises(ValueError, match="from the thread"):
            _Background(fail, threaded=threaded).result()


def test_the_fit_is_the_same_with_and_without_the_thread(monkeypatch):
    """On a tube whose wall folds through itself: the same crossings, report and model."""
    V, F, _ = folded_tube()
    results = []
    for omp in ("2", "1"):
        monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
        monkeypatch.setenv("OMP_NUM_THREADS", omp)
        model, report, _ = fit_vessel(Surface(V, F, {}, "mm", "given", "folded"))
        report.pop("timings_s")
        results.append((report, model.to_dict()))
    assert results[0][0]["self_intersecting_triangles"] > 0
    assert results[0] == results[1]


def test_the_thread_leaves_ctrl_c_to_the_main_thread():
    """The thread starts with SIGINT and SIGTERM blocked: the kernel hands them to the main thread,
    where signals_held() can hold them back (a Ctrl-C inside VTK's code is a crash)."""
    seen = []

    def mask() -> None:
        seen.append(signal.pthread_sigmask(signal.SIG_BLOCK, set()))

    _Background(mask, threaded=True).result()
    assert {signal.SIGINT, signal.SIGTERM} <= seen[0]
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())  # the main thread's is unchanged
