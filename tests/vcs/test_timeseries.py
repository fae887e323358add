"""The error bar of a time average (vcs.cfd.timeseries) against processes whose answers are known:
an Ornstein-Uhlenbeck process (exponential autocorrelation, integral time scale tau, variance of
the mean 2 tau sigma^2 / T), a sine (T_int = P / (2 pi)), a constant; and the SIMPLE early stop
of a stalled run (vcs.cfd.steady.PlateauWatch) on synthetic solver logs."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import lfilter

from vcs.cfd.timeseries import integral_time_scale, mean_error, time_weighted_mean, uniform_record


def _ou(rng: np.random.Generator, n: int, dt: float, tau: float, sigma: float = 1.0) -> np.ndarray:
    """An Ornstein-Uhlenbeck record: the exact AR(1) discretisation, started from its stationary law."""
    a = math.exp(-dt / tau)
    e = rng.standard_normal(n)
    x = lfilter([sigma * math.sqrt(1 - a * a)], [1, -a], e, zi=[a * sigma * rng.standard_normal()])[0]
    return x


def test_integral_time_scale_of_known_processes():
    rng = np.random.default_rng(0)
    dt, tau = 1e-3, 0.02
    ts = [integral_time_scale(_ou(rng, 20000, dt, tau), dt) for _ in range(20)]
    assert np.mean(ts) == pytest.approx(tau, rel=0.15)  # exp(-s/tau) integrates to tau
    period = 0.1
    t = np.arange(0, 5, dt)
    assert integral_time_scale(np.sin(2 * np.pi * t / period), dt) == pytest.approx(period / (2 * np.pi), rel=0.02)
    assert integral_time_scale(np.full(100, 3.0), dt) == 0.0


def test_confidence_interval_covers_the_true_mean():
    """95 % intervals of 300 independent OU records of 100 integral time scales cover the true mean
    in 90-99 % of them, and the standard error matches the spread of the means and the exact
    sqrt(2 tau / T) sigma within 15 %."""
    rng = np.random.default_rng(1)
    dt, tau, T, mu = 2e-3, 0.05, 5.0, 3.0
    n = int(T / dt)
    t = dt * np.arange(1, n + 1)
    res = [mean_error(t, mu + _ou(rng, n, dt, tau), 0.0) for _ in range(300)]
    means = np.array([r["mean"] for r in res])
    se = np.array([r["standard_error"] for r in res])
    cover = np.mean([abs(r["mean"] - mu) <= r["half_width"] for r in res])
    assert 0.90 <= cover <= 0.99, cover
    exact = math.sqrt(2 * tau / T)
    assert np.std(means) == pytest.approx(exact, rel=0.15)
    assert np.median(se) == pytest.approx(exact, rel=0.15)
    assert all(r["bound"] == "statistics" and r["n_batches"] >= 5 for r in res)


def test_short_records_get_error_bars_that_cover_the_true_mean():
    """OU records of 10 integral time scales (3 batches of 3 T_int fit): >= 90 % of 300 get an error
    bar from the statistics (not their range) and the 95 % intervals cover the true mean in 82-99 %
    of them (the integral time scale of a short record is underestimated: 90 % with this seed)."""
    rng = np.random.default_rng(3)
    dt, tau, mu = 2e-3, 0.05, 3.0
    n = int(10 * tau / dt)
    t = dt * np.arange(1, n + 1)
    res = [mean_error(t, mu + _ou(rng, n, dt, tau), 0.0) for _ in range(300)]
    assert np.mean([r["bound"] == "statistics" for r in res]) >= 0.9
    cover = np.mean([abs(r["mean"] - mu) <= r["half_width"] for r in res])
    assert 0.82 <= cover <= 0.99, cover


def test_short_record_is_not_known_and_range_bounds_a_settled_signal():
    rng = np.random.default_rng(2)
    dt, tau = 1e-3, 0.05
    t = dt * np.arange(1, 201)
    x = _ou(rng, 100, dt, tau)  # 2 integral time scales: fewer than 3 batches of 3 T_int
    r = mean_error(t[:100], x, 0.0)
    # the statistics cannot tell (infinite); the record's range is the only bound
    assert r["n_batches"] < 3 and r["standard_error"] == math.inf
    assert r["bound"] == "range" and r["half_width"] == pytest.approx(np.ptp(x))
    # a laminar flow settling: an exponential approach, range 1e-4 of the mean: known to 1e-4 at once
    x = 10.0 * (1 + 1e-4 * np.exp(-t / 0.1))
    r = mean_error(t, x, 0.0)
    assert r["bound"] == "range" and r["half_width"] == pytest.approx(np.ptp(x)) and r["half_width"] < 2e-3
    # a constant is known exactly
    assert mean_error(t, np.full(200, 2.0), 0.0)["half_width"] == 0.0


def test_time_weighting_and_uniform_record():
    t = np.array([0.1, 0.2, 0.5, 1.0])  # steps of 0.1, 0.1, 0.3, 0.5
    x = np.array([1.0, 2.0, 3.0, 4.0])
    assert float(time_weighted_mean(t, x, 0.0)) == pytest.approx((0.1 + 0.2 + 0.9 + 2.0) / 1.0)
    assert float(time_weighted_mean(t, x, 0.2)) == pytest.approx((0.9 + 2.0) / 0.8)
    xu, dt = uniform_record(t, x, 0.0)
    assert dt == pytest.approx(0.25) and xu[-1] == pytest.approx(4.0) and len(xu) == 4
    many = mean_error(t, np.column_stack([x, 2 * x]), 0.0)
    assert many["mean"] == pytest.approx([time_weighted_mean(t, x, 0.0), 2 * time_weighted_mean(t, x, 0.0)])


def _simple_log(path: Path, residuals: list[float]) -> None:
    rows = []
    for i, r in enumerate(residuals, start=51):
        rows.append(
            f"Time = {i}\n\n"
            f"smoothSolver:  Solving for Ux, Initial residual = {r:.6g}, Final residual = {0.1 * r:.6g}, "
            "No Iterations 2\n"
            f"smoothSolver:  Solving for Uy, Initial residual = {r:.6g}, Final residual = {0.1 * r:.6g}, "
            "No Iterations 2\n"
            f"smoothSolver:  Solving for Uz, Initial residual = {r:.6g}, Final residual = {0.1 * r:.6g}, "
            "No Iterations 2\n"
            f"GAMG:  Solving for p, Initial residual = {r:.6g}, Final residual = {0.01 * r:.6g}, No Iterations 3\n"
            f"time step continuity errors : sum local = 1e-06, global = 1e-08, cumulative = 1e-07\n"
            f"ExecutionTime = {i * 0.1:.3g} s  ClockTime = {i // 10} s\n\n"
        )
    path.write_text("".join(rows))


@pytest.mark.parametrize(
    ("name", "residuals", "stops", "stalled"),
    [
        # an unsteady flow: SIMPLE hovers at 1e-2 (AortaCFD patient1's coarctation jet)
        ("hovering high", [1e-2 * (1 + 0.3 * math.sin(i / 7)) for i in range(320)], True, True),
        # the same for only 250 iterations: fewer than three windows above max_residual, left alone
        ("high, too early", [1e-2 * (1 + 0.3 * math.sin(i / 7)) for i in range(250)], False, False),
        # a real-mesh plateau below max_residual: stopped for the plateau check after two windows
        ("plateau low", [2e-5 * (1 + 0.1 * math.sin(i / 5)) for i in range(210)], True, False),
        # still converging by a decade per 100 iterations: left alone
        ("converging", [1e-2 * 10 ** (-i / 100) for i in range(320)], False, False),
    ],
)
def test_simple_early_stop(tmp_path, name, residuals, stops, stalled):
    from vcs.cfd.steady import PlateauWatch

    (tmp_path / "system").mkdir()
    control = tmp_path / "system" / "controlDict"
    control.write_text("stopAt          endTime;\nendTime 1000;\n")
    log = tmp_path / "log.simpleFoam"
    _simple_log(log, residuals)
    watch = PlateauWatch(tmp_path, {"plateau": {"iterations": 100, "max_residual": 1e-3, "early_stop": True}})
    watch(log)
    # the whole log at once: stopped ahead of the solver when the log is short of decision + lead,
    # else where it is (writeNow)
    text = control.read_text()
    assert ("writeNow" in text or "endTime         " in text) is stops, name
    assert (watch.stopped_at is not None) is stops and watch.stalled is stalled
    if stops:
        rep = watch.report()
        assert rep["above_max_residual"] is stalled and rep["deterministic"] is ("writeNow" not in text)


def test_simple_early_stop_does_not_depend_on_when_the_log_is_read(tmp_path):
    """Issue 38: the plateau stop is decided from the residual series alone. The same solver log,
    read at different moments (every 7 or every 13 iterations, as a loaded or an idle machine would
    let the watch look), gives the same decision iteration and the same stop, set ahead of the
    solver (endTime and writeInterval), never writeNow."""
    from vcs.cfd.steady import STOP_LEAD, PlateauWatch

    # a decade less per iteration for 150 iterations, then constant
    residuals = [2e-5 * 10.0 ** max(150 - i, 0) for i in range(400)]
    results = []
    for every in (7, 13):
        case = tmp_path / f"every{every}"
        (case / "system").mkdir(parents=True)
        control = case / "system" / "controlDict"
        control.write_text("stopAt          endTime;\nendTime         1000;\nwriteInterval   1000;\n")
        watch = PlateauWatch(case, {"plateau": {"iterations": 100, "max_residual": 1e-3, "early_stop": True}})
        log = case / "log.simpleFoam"
        for n in range(every, len(residuals) + 1, every):
            _simple_log(log, residuals[:n])  # the log as the solver has written it so far
            watch(log)
            if watch.stopped_at is not None:
                break
        text = control.read_text()
        assert "writeNow" not in text and watch.report()["deterministic"] is True
        assert f"endTime         {watch.stopped_at};" in text and f"writeInterval   {watch.stopped_at};" in text
        results.append((watch.decided_at, watch.stopped_at))
    assert results[0] == results[1] and results[0][1] == results[0][0] + STOP_LEAD
    # hand check: the first window of 100 whose first tenth's mean log10 residual is within
    # log10(1.5) = 0.18 of its last tenth's holds only the ramp's last row (one decade up: +0.1;
    # two rows: +0.3), rows 149-248 (0-based); the log numbers its rows from iteration 51
    assert results[0][0] == 51 + 248


def test_mser_finds_the_end_of_a_start_up_transient():
    """MSER-5 on an OU record (tau 10 ms) plus a decaying start-up 10 exp(-t / 0.3 s), which falls to
    the noise level at 0.69 s: the truncation point lies at 0.4-1.0 s; on the stationary record
    alone, in its first 10 %; on records of 1 s (the start-up 70 % of it) the wash-out is not called
    over (truncation not in the first third) in 90 % of 200 records, on records of 3 s it is in 95 %."""
    from vcs.cfd.timeseries import mser_truncation

    rng = np.random.default_rng(0)
    dt, n = 1e-3, 4000
    t = dt * np.arange(n)
    d, stat, short, long = [], [], [], []
    for _ in range(200):
        noise = _ou(rng, n, dt, 0.01)
        x = noise + 10 * np.exp(-t / 0.3)
        d.append(mser_truncation(x) * n * dt)
        stat.append(mser_truncation(noise))
        short.append(mser_truncation(x[:1000]))
        long.append(mser_truncation(x[:3000]))
    assert 0.4 <= np.median(d) <= 1.0 and min(d) > 0.3
    assert max(stat) < 0.1
    assert np.mean(np.array(short) >= 1 / 3) >= 0.9
    assert np.mean(np.array(long) < 1 / 3) >= 0.95
    assert mser_truncation(np.ones(10)) == 1.0  # fewer than 4 batches: not known
