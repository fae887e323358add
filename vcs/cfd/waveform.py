"""An inflow waveform: one cardiac cycle of volumetric flow rate, read from a CSV or .flow file (pure numpy).

File format (one cycle, closed)::

    # any number of comment lines (source, licence, numbers), also blank lines
    time_s,flow_rate_l_min
    0.000,0.0
    0.005,0.62
    ...
    0.800,0.0

* the first time is 0 and the times increase strictly;
* the cycle is *closed*: the last row is the end of the cycle, its time is the period T and its
  flow repeats the first row's (within ``CLOSED_RTOL`` of the largest flow in the file), so the
  periodic curve is continuous;
* at least ``MIN_SAMPLES`` rows.

The header names the units: the time column ``time_s`` or ``time_ms``, the flow column
``flow_rate_l_min`` (L/min), ``flow_ml_s`` / ``flow_rate_ml_s`` (mL/s) or ``flow_m3_s`` /
``flow_rate_m3_s`` (m^3/s), or cells such as ``time [ms]``, ``flow [L/min]``, ``Q (mL/s)``
(:data:`TIME_HEADERS`, :data:`FLOW_HEADERS`, :data:`TIME_UNITS`, :data:`FLOW_UNITS`).
SimVascular's ``.flow`` files (two whitespace-separated columns, s and mL/s, inflow negative) are
read too (:func:`load_flow_file`: the sign is flipped).

Between the rows the flow is linear; beyond the cycle it repeats (``Q(t + T) = Q(t)``). Every
number the :class:`Waveform` reports (mean, stroke volume, Fourier coefficients) is computed
exactly for that periodic piecewise-linear curve. Flows are stored in m^3/s (1 L/min =
1/60000 m^3/s).

The default waveform, :func:`default_waveform_path`, is a synthetic ascending-aorta inflow; its
construction and sources are written in its comment lines.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vcs.errors import VCSInputError  # bad input: a ValueError with a one-line message

HEADER = ("time_s", "flow_rate_l_min")
"""The default header's two column names, in this order (:data:`TIME_HEADERS`, :data:`FLOW_HEADERS`:
the others accepted)."""

L_MIN = 1.0 / 60000.0
"""1 L/min in m^3/s."""

TIME_HEADERS = {"time_s": 1.0, "time_ms": 1e-3}
"""Accepted names of the time column -> seconds per unit."""

FLOW_HEADERS = {
    "flow_rate_l_min": (L_MIN, "L/min"),
    "flow_ml_s": (1e-6, "mL/s"),
    "flow_rate_ml_s": (1e-6, "mL/s"),
    "flow_m3_s": (1.0, "m^3/s"),
    "flow_rate_m3_s": (1.0, "m^3/s"),
}
"""Accepted names of the flow column -> (m^3/s per unit, the unit)."""

TIME_UNITS = {"s": 1.0, "ms": 1e-3}
"""Units of a ``time [unit]`` header cell -> seconds per unit."""

FLOW_UNITS = {
    "l/min": (L_MIN, "L/min"),
    "ml/s": (1e-6, "mL/s"),
    "cm3/s": (1e-6, "mL/s"),
    "cm^3/s": (1e-6, "mL/s"),
    "m3/s": (1.0, "m^3/s"),
    "m^3/s": (1.0, "m^3/s"),
}
"""Units of a ``flow [unit]`` / ``Q (unit)`` header cell -> (m^3/s per unit, the unit)."""

_UNIT_CELL = re.compile(r"([a-z_ ]+?)\s*[\[(]\s*([a-z0-9^/ ]+?)\s*[\])]")

MIN_SAMPLES = 20
"""Fewest rows of a cycle (a cardiac cycle needs ~20 points to show ejection and diastole)."""

CLOSED_RTOL = 1e-6
"""The last flow must equal the first within this fraction of the largest |flow| of the file."""

END_SYSTOLE_RISE = 0.02
"""Hysteresis of :meth:`Waveform.phases`: a minimum after the peak counts once the flow has risen
above it by this fraction of the cycle's range (max - min); smaller wiggles are noise."""


def default_waveform_path() -> Path:
    """The shipped ascending-aorta inflow waveform (package data ``vcs/data/waveforms``).

    Returns
    -------
    Path
        ``ascending_aorta.csv``: a synthetic adult resting inflow (75 bpm, 70 mL stroke volume,
        5.25 L/min, a 1.5 mL end-systolic backflow); construction and sources in its comment lines.
    """
    return Path(__file__).resolve().parents[1] / "data" / "waveforms" / "ascending_aorta.csv"


def _cycle_problem(t: NDArray[np.floating], q: NDArray[np.floating], unit: str) -> tuple[int, str] | None:
    """The first rule of the format that the samples break.

    Parameters
    ----------
    t, q : (n,) float
        Times (s) and flows (in ``unit``, for the messages).
    unit : str
        Unit of ``q``.

    Returns
    -------
    (int, str) or None
        Index of the offending sample and a message ending in the fix; None when the cycle is valid.
    """
    n = len(t)
    bad = np.flatnonzero(~(np.isfinite(t) & np.isfinite(q)))
    if len(bad):
        i = int(bad[0])
        return i, f"time {t[i]:g} s, flow {q[i]:g} {unit}: not finite; give finite numbers"
    if n and t[0] != 0.0:
        return 0, f"the cycle starts at time {t[0]:g} s, not 0; shift the times so that the first row is at 0"
    step = np.flatnonzero(np.diff(t) <= 0)
    if len(step):
        i = int(step[0]) + 1
        return i, (
            f"time {t[i]:g} s is not after the previous row's {t[i - 1]:g} s; "
            "list one cycle with strictly increasing times"
        )
    if n < MIN_SAMPLES:
        return max(n - 1, 0), (f"only {n} samples, at least {MIN_SAMPLES} are needed; sample the cycle more densely")
    scale = float(np.max(np.abs(q)))
    if abs(q[-1] - q[0]) > CLOSED_RTOL * scale:
        return n - 1, (
            f"the cycle is not closed: the last flow {q[-1]:g} {unit} differs from the first {q[0]:g} {unit}; "
            "end the file with a row at t = period that repeats the first row's flow"
        )
    if not t[-1] > 0:  # follows from the rules above; kept so that a Waveform never has T <= 0
        return n - 1, f"the period (last time) {t[-1]:g} s is not positive; end the cycle at t = period > 0"
    return None


@dataclass(frozen=True, eq=False)
class Waveform:
    """One periodic cycle of volumetric flow rate, linear between samples.

    Build it with :func:`load_waveform` (or directly from samples that follow the same rules).

    Attributes
    ----------
    time_s : (n,) float
        Sample times, s: ``0 = t_0 < ... < t_{n-1} = period_s``.
    flow_m3_s : (n,) float
        Flow rate at the samples, m^3/s (positive along the inflow direction);
        ``flow_m3_s[-1] == flow_m3_s[0]`` within :data:`CLOSED_RTOL`.
    period_s : float
        Cycle period T, s (the last time).
    source : str
        Where the samples came from (the CSV path).
    """

    time_s: NDArray[np.floating]
    flow_m3_s: NDArray[np.floating]
    period_s: float
    source: str = ""

    def __post_init__(self) -> None:
        t = np.array(self.time_s, dtype=float)
        q = np.array(self.flow_m3_s, dtype=float)
        if t.ndim != 1 or t.shape != q.shape:
            raise VCSInputError(
                f"waveform {self.source}: time {t.shape} and flow {q.shape} must be 1-D of the same length"
            )
        problem = _cycle_problem(t, q, "m^3/s")
        if problem is not None:
            raise VCSInputError(f"waveform {self.source}: sample {problem[0] + 1}: {problem[1]}")
        if not math.isclose(float(self.period_s), float(t[-1]), rel_tol=1e-12):
            raise VCSInputError(
                f"waveform {self.source}: period {self.period_s!r} s is not the last time {t[-1]:g} s; "
                "give period_s = time_s[-1]"
            )
        t.flags.writeable = False
        q.flags.writeable = False
        object.__setattr__(self, "time_s", t)
        object.__setattr__(self, "flow_m3_s", q)
        object.__setattr__(self, "period_s", float(t[-1]))

    # ------------------------------------------------------------------ values
    @property
    def n_samples(self) -> int:
        """Number of rows (the closing row included)."""
        return int(len(self.time_s))

    @property
    def omega(self) -> float:
        """Angular frequency of the cycle, 2 pi / T (rad/s)."""
        return 2.0 * math.pi / self.period_s

    @property
    def mean_m3_s(self) -> float:
        """Time average over the cycle, m^3/s (trapezoidal rule: exact for the piecewise-linear curve)."""
        return float(np.trapezoid(self.flow_m3_s, self.time_s) / self.period_s)

    @property
    def peak_m3_s(self) -> float:
        """Largest flow of the cycle, m^3/s."""
        return float(self.flow_m3_s.max())

    @property
    def min_m3_s(self) -> float:
        """Smallest flow of the cycle, m^3/s (negative when the flow reverses)."""
        return float(self.flow_m3_s.min())

    @property
    def reversal(self) -> bool:
        """Whether the flow reverses (any sample below zero) during the cycle."""
        return bool(self.min_m3_s < 0.0)

    def forward_volume_m3(self) -> float:
        """Volume carried forward over one cycle: the integral of max(Q, 0), m^3.

        Exact for the piecewise-linear curve: a segment that changes sign contributes the triangle
        on the positive side of its zero crossing.
        """
        t, q = self.time_s, self.flow_m3_s
        h, a, b = np.diff(t), q[:-1], q[1:]
        both = h * (np.maximum(a, 0.0) + np.maximum(b, 0.0)) / 2.0
        cross = (a * b) < 0
        with np.errstate(divide="ignore", invalid="ignore"):
            pos = np.maximum(a, b)
            tri = h * pos**2 / (2.0 * (np.abs(a) + np.abs(b)))
        return float(np.where(cross, tri, both).sum())

    def __call__(self, t: ArrayLike) -> NDArray[np.floating]:
        """Flow rate at any times (periodic linear interpolation), m^3/s.

        Parameters
        ----------
        t : float or array
            Times, s, any real (before 0 or after T: the cycle repeats).

        Returns
        -------
        ndarray
            Shaped like ``t``.
        """
        tau = np.mod(np.asarray(t, dtype=float), self.period_s)
        return np.asarray(np.interp(tau, self.time_s, self.flow_m3_s))

    def scaled(self, factor: float) -> Waveform:
        """The same cycle with every flow multiplied by ``factor`` (e.g. to a patient's mean flow).

        Parameters
        ----------
        factor : float
            Finite multiplier (``q_patient / w.mean_m3_s`` gives a waveform of mean ``q_patient``).

        Returns
        -------
        Waveform
            New waveform; same times, period and source.
        """
        if not math.isfinite(factor):
            raise VCSInputError(f"waveform scale factor {factor!r} is not finite; give a finite number")
        return Waveform(self.time_s, self.flow_m3_s * factor, self.period_s, self.source)

    def fourier(self, n_harmonics: int) -> NDArray[np.complexfloating]:
        """Fourier coefficients of the periodic piecewise-linear curve, exactly.

        ``Q(t) = Re(sum_{n=0}^{N} Q_n exp(i n omega t))`` with ``omega = 2 pi / T`` and
        ``Q_0 = mean``, ``Q_n = (2 / T) int_0^T Q(t) exp(-i n omega t) dt`` for ``n >= 1`` (the
        real-signal form: twice the two-sided coefficient). On each segment ``[t_k, t_{k+1}]`` of
        slope ``s_k`` the integral is done in closed form (by parts)::

            int Q e^{-i k t} dt = i (Q_{k+1} e^{-i k t_{k+1}} - Q_k e^{-i k t_k}) / k
                                  + s_k (e^{-i k t_{k+1}} - e^{-i k t_k}) / k^2

        (``k = n omega``; the first terms telescope to zero over a closed cycle). The coefficients
        decay like ``1/n^2`` (the curve has corners); the truncated series converges uniformly.

        Parameters
        ----------
        n_harmonics : int
            Highest harmonic N (>= 0).

        Returns
        -------
        (N + 1,) complex
            ``Q_0 .. Q_N``, m^3/s (``Q_0`` real).
        """
        if n_harmonics < 0:
            raise VCSInputError(f"n_harmonics {n_harmonics} is negative; give 0 or more")
        t, q = self.time_s, self.flow_m3_s
        slope = np.diff(q) / np.diff(t)
        k = self.omega * np.arange(1, n_harmonics + 1)[:, None]  # (N, 1)
        e = np.exp(-1j * k * t[None, :])  # (N, n)
        ends = 1j * (q[-1] * e[:, -1] - q[0] * e[:, 0]) / k[:, 0]
        inner = (slope[None, :] * np.diff(e, axis=1)).sum(axis=1) / k[:, 0] ** 2
        coeffs = np.empty(n_harmonics + 1, dtype=complex)
        coeffs[0] = self.mean_m3_s
        coeffs[1:] = 2.0 * (ends + inner) / self.period_s
        return coeffs

    def phases(self) -> dict[str, float]:
        """Named instants of the cycle, s (within ``[0, T)``).

        * ``peak_systole``: the time of the largest flow (the first, if several samples share it);
        * ``end_systole``: the first minimum of the flow after the peak, i.e. the end of the systolic
          deceleration: the trough of the end-systolic backflow when the flow reverses (aortic valve
          closure, the incisura; Nichols, O'Rourke & Vlachopoulos, *McDonald's Blood Flow in
          Arteries*, 6th ed., 2011), else the instant the decelerating flow first stops falling.
          Walking forward (periodically) from the peak, the running minimum is kept until the flow
          rises above it by :data:`END_SYSTOLE_RISE` of the cycle's range, so that small wiggles of
          a measured curve are not taken for the minimum;
        * ``mid_diastole``: midway between ``end_systole`` and the end of the cycle (``T``).

        Returns
        -------
        dict
            ``peak_systole``, ``end_systole``, ``mid_diastole`` (s).
        """
        t, q = self.time_s[:-1], self.flow_m3_s[:-1]  # one period, the closing row left out
        n = len(q)
        ip = int(np.argmax(q))
        rise = END_SYSTOLE_RISE * (q.max() - q.min())
        i_min = ip
        for k in range(1, n):
            i = (ip + k) % n
            if q[i] < q[i_min]:
                i_min = i
            elif q[i] > q[i_min] + rise:
                break
        end = float(t[i_min])
        return {
            "peak_systole": float(t[ip]),
            "end_systole": end,
            "mid_diastole": 0.5 * (end + self.period_s),
        }

    def summary(self) -> dict[str, Any]:
        """The cycle's numbers, JSON-ready.

        Returns
        -------
        dict
            ``period_s``, ``heart_rate_bpm`` (60 / T), ``mean_l_min``, ``peak_l_min``, ``min_l_min``,
            ``stroke_volume_ml`` (forward volume, the integral of the positive flow, mL),
            ``reversal`` (bool), ``n_samples``, ``source``.
        """
        return {
            "period_s": self.period_s,
            "heart_rate_bpm": 60.0 / self.period_s,
            "mean_l_min": self.mean_m3_s / L_MIN,
            "peak_l_min": self.peak_m3_s / L_MIN,
            "min_l_min": self.min_m3_s / L_MIN,
            "stroke_volume_ml": self.forward_volume_m3() * 1e6,
            "reversal": self.reversal,
            "n_samples": self.n_samples,
            "source": self.source,
        }


def _header_units(fields: list[str]) -> tuple[float, float, str] | None:
    """(seconds per time unit, m^3/s per flow unit, the flow unit) of a header, or None.

    A header cell is a name of :data:`TIME_HEADERS` / :data:`FLOW_HEADERS` (case-insensitive), or a
    name with its unit in brackets or parentheses: ``time [ms]``, ``t (s)``, ``flow [L/min]``,
    ``Q (mL/s)`` (units of :data:`TIME_UNITS` / :data:`FLOW_UNITS`).
    """
    if len(fields) != 2:
        return None
    t_cell, q_cell = (f.strip().lower() for f in fields)
    t = TIME_HEADERS.get(t_cell)
    q = FLOW_HEADERS.get(q_cell)
    m = _UNIT_CELL.fullmatch(t_cell)
    if t is None and m and m.group(1) in ("time", "t"):
        t = TIME_UNITS.get(m.group(2).replace(" ", ""))
    m = _UNIT_CELL.fullmatch(q_cell)
    if q is None and m and m.group(1) in ("flow", "flow rate", "flow_rate", "q"):
        q = FLOW_UNITS.get(m.group(2).replace(" ", ""))
    if t is None or q is None:
        return None
    return t, q[0], q[1]


def _accepted_headers() -> str:
    """The accepted headers, for messages."""
    return (
        f"time column {' or '.join(TIME_HEADERS)}, flow column {', '.join(FLOW_HEADERS)} "
        "(or 'time [s]'/'time [ms]' and 'flow [L/min]'/'flow [mL/s]'/'flow [m3/s]')"
    )


def load_waveform(path: str | Path) -> Waveform:
    """Read one closed cardiac cycle from a CSV file or a SimVascular ``.flow`` file.

    Parameters
    ----------
    path : str or Path
        CSV file (format: the module docstring): optional ``#`` comment lines and blank lines, a
        header of two columns, the time (``time_s`` or ``time_ms``) then the flow
        (``flow_rate_l_min``, ``flow_ml_s``/``flow_rate_ml_s`` or ``flow_m3_s``/``flow_rate_m3_s``;
        also ``time [ms]``, ``Q (mL/s)``-style cells), then one ``time,flow`` row per sample; the
        first time is 0, the last row closes the cycle (its time is the period, its flow the first
        row's). A ``.flow`` file is read by :func:`load_flow_file`.

    Returns
    -------
    Waveform
        Times in s, flows converted to m^3/s; ``source`` is the path.

    Raises
    ------
    VCSInputError
        One line naming the file, the line (1-based, as an editor shows it) and the fix: no header
        or one with no accepted column names (the message lists them), a row without two
        numbers, a value that is not a finite number, times not strictly increasing, a first time
        other than 0, fewer than :data:`MIN_SAMPLES` rows, or a cycle that is not closed.
    """
    path = Path(path)
    if path.suffix.lower() == ".flow":
        return load_flow_file(path)
    text = _read(path)
    where = f"waveform {path}"
    header_line = None
    units: tuple[float, float, str] = (1.0, L_MIN, "L/min")
    names: tuple[str, str] = HEADER
    lines: list[int] = []
    values: list[tuple[float, float]] = []
    for number, line in _content_lines(text):
        fields = [f.strip() for f in line.split(",")]
        if header_line is None:
            found = _header_units(fields)
            if found is None:
                raise VCSInputError(
                    f"{where}: line {number}: header {line[:60]!r} is not a known one; the first line that is not "
                    f"a # comment must name the two columns: {_accepted_headers()}, e.g. {','.join(HEADER)}"
                )
            units, names, header_line = found, (fields[0], fields[1]), number
            continue
        if len(fields) != 2:
            raise VCSInputError(
                f"{where}: line {number}: {len(fields)} values, expected 2 ({names[0]}, {names[1]}); "
                "write one 'time,flow' pair per line"
            )
        row = [_value(f, name, where, number) for name, f in zip(names, fields)]
        lines.append(number)
        values.append((row[0], row[1]))
    if header_line is None:
        raise VCSInputError(
            f"{where}: line 1: no header line; start the table with the line {','.join(HEADER)} "
            f"(after any # comment lines; accepted: {_accepted_headers()})"
        )
    if not values:
        raise VCSInputError(
            f"{where}: line {header_line}: no rows after the header; give one cycle, "
            f"at least {MIN_SAMPLES} rows of {names[0]},{names[1]}"
        )
    return _cycle(path, lines, np.array(values, dtype=float), units)


def load_flow_file(path: str | Path) -> Waveform:
    """Read SimVascular's ``.flow`` file (e.g. ``inflow.flow``): one cardiac cycle of inflow.

    Two whitespace-separated columns per line, the time (s) and the flow rate (mL/s = cm^3/s),
    negative into the model by SimVascular's convention (the flow along the outward normal of the
    inlet face): the sign is flipped, so that the waveform is positive along the inflow
    direction as every waveform of this package. Blank and ``#`` lines are skipped. The cycle rules
    are those of the CSV (first time 0, strictly increasing, closed, at least :data:`MIN_SAMPLES`
    rows).

    Parameters
    ----------
    path : str or Path
        The ``.flow`` file.

    Returns
    -------
    Waveform
        Flows in m^3/s (1 mL/s = 1e-6 m^3/s), positive into the vessel.

    Raises
    ------
    VCSInputError
        One line naming the file and line: a line without two numbers, a cycle rule broken, or a
        file whose mean flow is positive (flow out of the model in SimVascular's convention: negate
        its flows).
    """
    path = Path(path)
    text = _read(path)
    where = f"waveform {path}"
    lines: list[int] = []
    values: list[tuple[float, float]] = []
    for number, line in _content_lines(text):
        fields = line.replace(",", " ").split()
        if len(fields) != 2:
            raise VCSInputError(
                f"{where}: line {number}: {len(fields)} values, expected 2 (time in s, flow in mL/s); "
                "write one 'time flow' pair per line"
            )
        t, q = (_value(f, name, where, number) for name, f in zip(("time", "flow"), fields))
        lines.append(number)
        values.append((t, -q))  # SimVascular: inflow negative
    if not values:
        raise VCSInputError(f"{where}: no 'time flow' lines; give one cycle, at least {MIN_SAMPLES} lines")
    arr = np.array(values, dtype=float)
    w = _cycle(path, lines, arr, (1.0, 1e-6, "mL/s (sign flipped)"))
    if not w.mean_m3_s > 0.0:
        raise VCSInputError(
            f"{where}: the mean flow is {-w.mean_m3_s * 1e6:.4g} mL/s, out of the model by SimVascular's convention "
            "(inflow is negative in a .flow file); negate the flows of the file"
        )
    return w


def _content_lines(text: str) -> Iterator[tuple[int, str]]:
    """(1-based line number, stripped line) of every line that is neither blank nor a ``#`` comment."""
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if line and not line.startswith("#"):
            yield number, line


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except OSError as e:
        raise VCSInputError(f"cannot read waveform {path}: {e.strerror or e}; check the path") from None


def _value(text: str, name: str, where: str, number: int) -> float:
    """A finite number of a waveform file, or a one-line error naming the line."""
    try:
        x = float(text)
    except ValueError:
        raise VCSInputError(
            f"{where}: line {number}: {name} {text[:30]!r} is not a number; write decimal numbers"
        ) from None
    if not math.isfinite(x):
        raise VCSInputError(f"{where}: line {number}: {name} is {text!r}; give finite numbers")
    return x


def _cycle(path: Path, lines: list[int], arr: NDArray[np.floating], units: tuple[float, float, str]) -> Waveform:
    """The waveform of the samples ``arr`` (time, flow in the file's units), checked as a cycle."""
    t, q = arr[:, 0] * units[0], arr[:, 1] * units[1]
    problem = _cycle_problem(t, arr[:, 1], units[2])
    if problem is not None:
        raise VCSInputError(f"waveform {path}: line {lines[problem[0]]}: {problem[1]}")
    return Waveform(t, q, float(t[-1]), str(path))
