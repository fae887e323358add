"""vcs.cfd.waveform: one cardiac cycle read from a CSV file. Bad files give one line naming the file,
the line and the fix; the numbers of a cycle (mean, stroke volume, Fourier coefficients) are exact
for the periodic piecewise-linear curve, checked against hand-computed curves and a dense FFT; the
shipped ascending-aorta waveform is physiological and is the closed form its comments state."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from vcs.cfd.waveform import L_MIN, MIN_SAMPLES, Waveform, default_waveform_path, load_waveform
from vcs.errors import VCSInputError

HEADER = "time_s,flow_rate_l_min"


def _rows(n: int = 40, period: float = 1.0) -> list[str]:
    """A valid closed cycle of ``n`` rows: 3 + 2 sin(2 pi t / T) L/min."""
    t = np.linspace(0.0, period, n)
    q = 3.0 + 2.0 * np.sin(2 * np.pi * t / period)
    q[-1] = q[0]
    return [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, q)]


def _write(tmp_path: Path, lines: list[str], name: str = "flow.csv") -> Path:
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_valid_file_with_comments_loads_in_si_units(tmp_path):
    path = _write(tmp_path, ["# source: a test", "", "# second comment", HEADER, *_rows(40)])
    w = load_waveform(path)
    assert w.n_samples == 40 and w.period_s == 1.0 and w.source == str(path)
    assert w.flow_m3_s[0] == pytest.approx(3.0 / 60000)
    assert w.mean_m3_s == pytest.approx(3.0 * L_MIN, rel=1e-12)  # the sine's trapezoids cancel
    assert not w.reversal
    with pytest.raises(ValueError):
        w.flow_m3_s[0] = 1.0  # read-only arrays: a frozen value object


# (file lines, the line number the message must name, a phrase of the message)
BAD = {
    "empty": ([], 1, "no header"),
    "only_comments": (["# nothing"], 1, "no header"),
    "no_header": (_rows(40), 1, "header"),
    "wrong_header": (["# c", "t,Q", *_rows(40)], 2, "header"),
    "header_only": ([HEADER], 1, "no rows"),
    "three_columns": ([HEADER, *_rows(40)[:5], "0.2,1.0,3.0", *_rows(40)[5:]], 7, "expected 2"),
    "not_a_number": ([HEADER, *_rows(40)[:9], "0.3,abc", *_rows(40)[10:]], 11, "not a number"),
    "nan": ([HEADER, *_rows(40)[:3], "0.1,nan", *_rows(40)[4:]], 5, "finite"),
    "inf_time": ([HEADER, *_rows(40)[:3], "inf,1.0", *_rows(40)[4:]], 5, "finite"),
    "not_increasing": (["#", "#", HEADER, *_rows(40)[:6], _rows(40)[4], *_rows(40)[7:]], 10, "strictly increasing"),
    "first_time_not_0": ([HEADER, "0.01,3.0", *_rows(40)[1:]], 2, "not 0"),
    "too_few": ([HEADER, *_rows(MIN_SAMPLES - 1)], MIN_SAMPLES, f"at least {MIN_SAMPLES}"),
    "not_closed": ([HEADER, *_rows(40)[:-1], "1.0,4.0"], 41, "not closed"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_files_give_one_line_naming_the_file_and_the_line(tmp_path, case):
    lines, line, phrase = BAD[case]
    path = _write(tmp_path, lines, name=f"bad_{case}.csv")
    with pytest.raises(VCSInputError) as e:
        load_waveform(path)
    msg = str(e.value)
    assert "\n" not in msg
    assert f"bad_{case}.csv" in msg and f"line {line}:" in msg and phrase in msg, msg
    assert ";" in msg  # the fix follows the problem


def test_missing_file_is_one_line(tmp_path):
    with pytest.raises(VCSInputError, match="cannot read waveform .*nowhere.csv"):
        load_waveform(tmp_path / "nowhere.csv")


def test_closed_within_tolerance_is_accepted(tmp_path):
    rows = _rows(40)
    t_end, q_end = rows[-1].split(",")
    w = load_waveform(_write(tmp_path, [HEADER, *rows[:-1], f"{t_end},{float(q_end) * (1 + 1e-7)!r}"]))
    assert w.n_samples == 40


def _triangle() -> Waveform:
    """0 -> 6 L/min at 0.2 s -> -2 at 0.4 s -> 0 at 0.5 s, 0 until T = 1 s (21 samples)."""
    knots_t, knots_q = [0.0, 0.2, 0.4, 0.5, 1.0], [0.0, 6.0, -2.0, 0.0, 0.0]
    t = np.linspace(0.0, 1.0, 21)
    return Waveform(t, np.interp(t, knots_t, knots_q) * L_MIN, 1.0, "triangle")


def test_numbers_of_a_hand_computed_cycle():
    w = _triangle()
    # areas (L/min * s): 0.6 up, 0.2 * (6 - 2) / 2 = 0.4 over [0.2, 0.4] of which +0.45 -0.05
    # (zero at 0.35 s), -0.1 over [0.4, 0.5]
    assert w.mean_m3_s == pytest.approx((0.6 + 0.4 - 0.1) * L_MIN)
    assert w.forward_volume_m3() == pytest.approx((0.6 + 0.45) * L_MIN)
    assert w.peak_m3_s == pytest.approx(6 * L_MIN) and w.min_m3_s == pytest.approx(-2 * L_MIN)
    assert w.reversal
    s = w.summary()
    assert json.loads(json.dumps(s, allow_nan=False)) == s
    assert s["stroke_volume_ml"] == pytest.approx(1.05 / 60 * 1000)
    assert s["mean_l_min"] == pytest.approx(0.9) and s["heart_rate_bpm"] == 60.0
    assert w.phases() == {"peak_systole": 0.2, "end_systole": 0.4, "mid_diastole": 0.7}


def test_call_is_periodic_linear_interpolation():
    w = _triangle()
    assert float(w(0.1)) == pytest.approx(3 * L_MIN)
    t = np.array([[0.1, 0.3], [0.45, 0.9]])
    for shift in (-2.0, 1.0, 3.0):
        np.testing.assert_allclose(w(t + shift), w(t), rtol=1e-12, atol=1e-20)
    assert w(t).shape == (2, 2)
    assert float(w(-0.55)) == pytest.approx(float(w(0.45)))


def test_scaled_keeps_the_shape():
    w = _triangle()
    v = w.scaled(2.5)
    assert v.mean_m3_s == pytest.approx(2.5 * w.mean_m3_s) and v.source == w.source
    np.testing.assert_array_equal(v.time_s, w.time_s)
    assert v.phases() == w.phases()
    with pytest.raises(VCSInputError):
        w.scaled(math.nan)


def test_fourier_is_exact_for_the_piecewise_linear_curve():
    """Against an independent dense FFT of the interpolant (error O(1/M^2) for M samples)."""
    w = load_waveform(default_waveform_path())
    n = 30
    c = w.fourier(n)
    m = 2**16
    t = np.arange(m) * w.period_s / m
    f = np.fft.rfft(w(t)) / m
    ref = np.concatenate([[f[0].real], 2 * f[1 : n + 1]])
    np.testing.assert_allclose(c, ref, rtol=0, atol=1e-6 * w.peak_m3_s)
    assert c[0] == pytest.approx(w.mean_m3_s) and c[0].imag == 0


def test_fourier_series_reproduces_the_samples():
    w = load_waveform(default_waveform_path())
    c = w.fourier(40)
    n = np.arange(len(c))
    series = np.real(np.exp(1j * w.omega * np.outer(w.time_s, n)) @ c)
    err = np.max(np.abs(series - w.flow_m3_s))
    assert err < 0.01 * w.peak_m3_s, err / w.peak_m3_s
    # fewer harmonics: worse, still the right mean
    c5 = w.fourier(5)
    assert c5[0] == c[0] and np.allclose(c5, c[:6])


def test_shipped_waveform_is_physiological():
    path = default_waveform_path()
    assert path.is_file() and path.parent.name == "waveforms"
    w = load_waveform(path)
    s = w.summary()
    assert 4.0 <= s["mean_l_min"] <= 6.0
    assert 50.0 <= s["heart_rate_bpm"] <= 90.0
    assert 55.0 <= s["stroke_volume_ml"] <= 100.0
    assert s["reversal"] and s["n_samples"] >= 50
    ph = w.phases()
    assert 0 < ph["peak_systole"] < ph["end_systole"] < ph["mid_diastole"] < w.period_s
    assert ph["end_systole"] == pytest.approx(0.315)  # the trough of the backflow lobe
    text = path.read_text()
    assert "Weissler" in text and "stroke volume" in text and "75 bpm" in text


def test_shipped_waveform_is_the_closed_form_of_its_comments():
    """The comment lines state the curve; the rows must be it (to the 6 decimals written)."""
    T, tp, te, tb, beta = 0.8, 0.09, 0.285, 0.06, 0.1
    qmax = 70.0 / ((te - beta * tb) / 2)  # mL/s
    w = load_waveform(default_waveform_path())
    t = w.time_s
    q = np.select(
        [t <= tp, t <= te, t <= te + tb],
        [
            qmax / 2 * (1 - np.cos(np.pi * t / tp)),
            qmax / 2 * (1 + np.cos(np.pi * (t - tp) / (te - tp))),
            -beta * qmax / 2 * (1 - np.cos(2 * np.pi * (t - te) / tb)),
        ],
        0.0,
    )
    np.testing.assert_allclose(w.flow_m3_s / L_MIN, q * 0.06, rtol=0, atol=6e-7)
    assert w.period_s == T and np.allclose(np.diff(t), 0.005)
    assert f"Qmax = {qmax:.2f} mL/s" in default_waveform_path().read_text()


def test_end_systole_ignores_small_wiggles():
    """A measured curve's deceleration may wiggle; the first minimum that the flow then rises from
    by more than 2 % of the range counts (here the backflow trough at 0.4 s, not the wiggle)."""
    t = np.linspace(0.0, 1.0, 101)
    q = np.interp(t, [0.0, 0.1, 0.25, 0.26, 0.27, 0.4, 0.45, 1.0], [0, 10, 4, 4.1, 3.9, -1, 0, 0])
    w = Waveform(t, q * L_MIN, 1.0, "wiggle")
    assert w.phases()["end_systole"] == pytest.approx(0.4)


def test_direct_construction_is_checked():
    t = np.linspace(0, 1, 30)
    with pytest.raises(VCSInputError, match="not closed"):
        Waveform(t, t, 1.0, "ramp")
    with pytest.raises(VCSInputError, match="period"):
        Waveform(t, np.sin(2 * np.pi * t) ** 2, 2.0, "sine")
