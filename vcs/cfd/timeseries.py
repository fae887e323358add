"""Statistics of a time average from one finite, autocorrelated record (pure numpy/scipy).

The transient solve averages a turbulent-like or periodic flow over a window; how well that
window's mean is known depends on how long the window is against the time over which the signal
forgets itself, its integral time scale. Two standard estimates of the standard error of the mean
are combined (the larger is kept, so that neither a short record nor a slowly decaying
autocorrelation makes the error look smaller than it is):

* the integral-time-scale estimate: var(mean) = 2 T_int sigma^2 / T (e.g. Bendat & Piersol,
  *Random Data*, 4th ed., Eq. 8.17; Tennekes & Lumley 1972, Sec. 6.4), T_int the integral of the
  autocorrelation up to its first zero crossing;
* batch means: the record cut into ``n_b`` consecutive batches, each at least
  :data:`BATCH_INTEGRAL_SCALES` integral time scales long (nearly independent), var(mean) =
  var(batch means) / n_b (Fishman 1978; Law & Kelton, *Simulation Modeling and Analysis*, Sec. 9.5.3),

and the confidence interval is Student's t with ``n_b - 1`` degrees of freedom. With fewer than
:data:`MIN_BATCHES` batches the statistical error is not known yet (infinite). Whatever the
statistics, a window's mean lies within the range of the values averaged, and so does the mean
of a longer record of a signal that stays within it: the record's range (max - min) bounds the
error too, and the smaller of the two bounds is reported (a laminar
flow settling to a steady state has a long, slowly decaying autocorrelation but a range far inside
any tolerance; ``bound`` says which one was used).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special

BATCH_INTEGRAL_SCALES = 3.0
"""Batch length in integral time scales (batch means of an exponentially correlated signal 3 T_int
long correlate by ~0.15; the integral-time-scale estimate, kept when larger, covers the rest)."""

MIN_BATCHES = 3
"""Fewest batches for an error bar (below it the mean's error is unknown: infinite). Student's t
with 2 degrees of freedom (4.30 at 95 %) widens the interval of so few batches honestly: on
Ornstein-Uhlenbeck records of 6-15 integral time scales, 95 % intervals with at least 3 batches
cover the true mean as often as with at least 5 (83-92 % against 85-92 %; the integral time
scale of a short record is underestimated either way) and give 86-99 % of the records an error
bar from the statistics (median 1.5-1.9 standard errors) where 5 gave 46-82 % (the rest bounded
by their range, median 5 standard errors at 6 T_int): ``tests/vcs/test_timeseries.py``. AortaCFD patient1's probe
cells in the jet's wake (integral scales 40-85 ms) then have an error bar after 2 flow-through
times instead of their range, which held its window to 10 flow-throughs (docs/benchmarks/real-cohort.md)."""

MSER_BATCH = 5
"""Observations per batch of the MSER truncation rule (MSER-5)."""


def uniform_record(t: ArrayLike, x: ArrayLike, start: float | None = None) -> tuple[NDArray[np.floating], float]:
    """A solver's record on a uniform time grid, for its autocorrelation.

    Parameters
    ----------
    t : (n,) float
        Increasing times (an adjustable time step: not uniform). Row i stands for the step ending
        at ``t[i]`` (as OpenFOAM's function objects write it).
    x : (n,) or (n, m) float
        Values (``m`` signals side by side).
    start : float, optional
        Start of the window (default: the first time); rows at or before it are dropped.

    Returns
    -------
    (N, ...) float, float
        ``x`` linearly interpolated on N = number of rows equally spaced times from the window's
        start to its last time, and that spacing (0 for fewer than 2 rows).
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if start is not None:
        keep = t > start
        t, x = t[keep], x[keep]
        t0 = float(start)
    else:
        t0 = float(t[0]) if len(t) else 0.0
    n = len(t)
    if n < 2:
        return x, 0.0
    tu = np.linspace(t0, float(t[-1]), n + 1)[1:]
    dt = float(tu[1] - tu[0])
    if x.ndim == 1:
        return np.interp(tu, t, x), dt
    return np.column_stack([np.interp(tu, t, x[:, j]) for j in range(x.shape[1])]), dt


def time_weighted_mean(t: ArrayLike, x: ArrayLike, start: float) -> NDArray[np.floating]:
    """Mean over the window (start, t[-1]], each row weighted by its time step (fieldAverage's
    ``base time`` mean). ``x`` (n,) or (n, m): returns a scalar array or (m,)."""
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    keep = t > start
    t, x = t[keep], x[keep]
    w = np.diff(np.concatenate([[start], t]))
    return np.tensordot(w, x, axes=(0, 0)) / w.sum()


def integral_time_scale(x: ArrayLike, dt: float) -> float:
    """Integral time scale of a uniformly sampled signal: the integral of its autocorrelation
    rho(s) = <x'(t) x'(t + s)> / <x'^2> from 0 to the first zero crossing (trapezoid rule).

    Parameters
    ----------
    x : (n,) float
        The signal on a uniform grid of spacing ``dt``.
    dt : float
        The spacing.

    Returns
    -------
    float
        T_int (s); 0 for a constant signal; the record length when rho never crosses zero (the
        record is shorter than the signal's memory).
    """
    x = np.asarray(x, dtype=float)
    n = len(x)
    xp = x - x.mean()
    var = float(xp @ xp)
    if n < 2 or var <= 1e-300 * n or not np.isfinite(var):
        return 0.0
    m = 1 << int(2 * n - 1).bit_length()
    f = np.fft.rfft(xp, m)
    acf = np.fft.irfft(f * np.conj(f), m)[:n] / var  # biased estimate: rho(0) = 1, |rho| <= 1
    neg = np.flatnonzero(acf <= 0.0)
    if not len(neg):
        return n * dt
    k = int(neg[0])
    # up to the zero crossing, interpolated between the last positive lag and the first non-positive
    area = float(np.trapezoid(acf[:k], dx=dt)) if k > 1 else 0.0
    a, b = float(acf[k - 1]), float(acf[k])
    return area + 0.5 * a * (a / (a - b)) * dt


def mean_error(
    t: ArrayLike, x: ArrayLike, start: float, confidence: float = 0.95, t_int: float | None = None
) -> dict[str, Any]:
    """Time average of a record over (start, t[-1]] and the half-width of its confidence interval.

    Parameters
    ----------
    t : (n,) float
        Times (any spacing; row i stands for the step ending at ``t[i]``).
    x : (n,) or (n, m) float
        One signal, or ``m`` signals (each gets its own scale and error).
    start : float
        Start of the averaging window.
    confidence : float
        Confidence level of the interval (0.95).
    t_int : float, optional
        The integral time scale to use (default: each signal's own, :func:`integral_time_scale`).

    Returns
    -------
    dict
        ``mean``, ``std`` (of the signal), ``integral_time_s``, ``n_batches``,
        ``standard_error`` (the larger of the integral-time-scale and batch-means estimates),
        ``half_width`` (the smaller of t quantile x standard error (inf with fewer than
        :data:`MIN_BATCHES` batches) and the record's range; inf with fewer than 2 samples),
        ``bound`` (``statistics`` or
        ``range``), ``window_s``: floats (``bound`` a str), or (m,) arrays for ``m`` signals.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    one = x.ndim == 1
    xs = x[:, None] if one else x
    keep = t > start
    out: dict[str, list[Any]] = {k: [] for k in ("mean", "std", "integral_time_s", "n_batches", "standard_error")}
    out["half_width"] = []
    out["bound"] = []
    window = float(t[keep][-1] - start) if keep.any() else 0.0
    for j in range(xs.shape[1]):
        r: dict[str, Any] = _one_mean_error(t[keep], xs[keep, j], start, window, confidence, t_int)
        rng = float(np.ptp(xs[keep, j])) if keep.sum() >= 2 else math.inf
        if rng < r["half_width"]:
            r["half_width"], r["bound"] = rng, "range"
        else:
            r["bound"] = "statistics"
        for k, v in r.items():
            out[k].append(v)
    res: dict[str, Any] = {k: (v[0] if one else np.array(v)) for k, v in out.items()}
    res["window_s"] = window
    return res


def _one_mean_error(
    t: NDArray[np.floating],
    x: NDArray[np.floating],
    start: float,
    window: float,
    confidence: float,
    t_int: float | None,
) -> dict[str, float]:
    """:func:`mean_error` of one signal already cut to its window."""
    if len(t) < 2 or window <= 0:
        nan = float("nan")
        return {"mean": nan, "std": nan, "integral_time_s": nan, "n_batches": 0, "standard_error": math.inf,
                "half_width": math.inf}  # fmt: skip
    mean = float(time_weighted_mean(t, x, start))
    xu, dt = uniform_record(t, x, start)
    std = float(np.std(xu))
    ti = integral_time_scale(xu, dt) if t_int is None else float(t_int)
    if std <= 1e-12 * max(abs(mean), 1e-300):  # a constant signal: known exactly
        return {"mean": mean, "std": std, "integral_time_s": ti, "n_batches": len(xu), "standard_error": 0.0,
                "half_width": 0.0}  # fmt: skip
    batch = max(BATCH_INTEGRAL_SCALES * ti, dt)
    nb = int(window // batch)
    if nb < MIN_BATCHES:
        return {"mean": mean, "std": std, "integral_time_s": ti, "n_batches": nb, "standard_error": math.inf,
                "half_width": math.inf}  # fmt: skip
    per = len(xu) // nb
    means = xu[len(xu) - nb * per :].reshape(nb, per).mean(axis=1)  # the last nb * per samples
    se_batch = float(np.std(means, ddof=1) / math.sqrt(nb))
    se_acf = std * math.sqrt(2.0 * ti / window)
    se = max(se_batch, se_acf)
    q = float(special.stdtrit(nb - 1, 0.5 + 0.5 * confidence))  # Student's t quantile (scipy.stats.t.ppf's own)
    return {"mean": mean, "std": std, "integral_time_s": ti, "n_batches": nb, "standard_error": se,
            "half_width": q * se}  # fmt: skip


def mser_truncation(x: ArrayLike, batch: int = MSER_BATCH) -> float:
    """Where a record's start-up transient ends: the MSER-5 truncation point (White 1997, "An
    effective truncation heuristic for bias reduction in simulation output", Simulation 69;
    White, Cobb & Spratt 2000).

    The record (uniformly sampled) is cut into batches of ``batch`` observations with means y_j,
    j = 0..n-1; d* minimises MSER(d) = sum_{j >= d} (y_j - mean_{j >= d} y)^2 / (n - d)^2 (the
    squared standard error of the mean of what is kept) over d = 0..n/2 (the first half only: at
    the record's end a few batches can have a spuriously small spread). A d* at the end of that
    range says the start-up is not over yet (the rule's own test: a longer record is needed).

    Parameters
    ----------
    x : (N,) float
        The record on a uniform time grid.
    batch : int
        Observations per batch (5).

    Returns
    -------
    float
        d* / n in [0, 0.5]: the fraction of the record that is start-up transient (0.5 or more:
        not over, or not known with fewer than 4 batches: 1.0).
    """
    x = np.asarray(x, dtype=float)
    n = len(x) // batch
    if n < 4:
        return 1.0
    y = x[len(x) - n * batch :].reshape(n, batch).mean(axis=1)  # the record's last n * batch samples
    s1 = np.cumsum(y[::-1])[::-1]  # sum over j >= d
    s2 = np.cumsum((y * y)[::-1])[::-1]
    m = n - np.arange(n)
    stat = (s2 - s1 * s1 / m) / (m * m)
    return float(np.argmin(stat[: n // 2 + 1]) / n)
