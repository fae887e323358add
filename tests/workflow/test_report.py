"""The report's cohort table (workflow/scripts/_cohort_table.py) and the checks that open a report
in headless Chromium (report_check.py, used on a real cohort's report by test_demo.py): a blank
figure fails them. Seconds; the Chromium part skips without Debian's ``chromium``."""

from __future__ import annotations

import base64
import io
import sys
from pathlib import Path

import numpy as np
import pytest
import report_check as rc
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "workflow" / "scripts"))
import _cohort_table  # noqa: E402

ATLAS = {
    "patients_included": ["steady", "averaged"],
    "patients_excluded": [{"id": "broken", "stage": "mesh", "reason": "not converged: blockMesh failed <log>"}],
    "field_sources": {"steady": "instantaneous", "averaged": "time_average"},
}
STATUSES = {
    "steady": {"converged": True, "criterion_used": "residualControl", "iterations": 106, "cells": 19810},
    "averaged": {
        "converged": True,
        "criterion_used": "time_average_stationary",
        "iterations": 2000,
        "cells": 15000,
        "mass_imbalance": 2e-7,
        "transient": {"stationary": True, "relative_errors": {"dp": 0.004, "wss": 0.012, "u": None}},
    },
    "broken": {"converged": False, "stage": "mesh", "mesh_ok": False, "reason": "blockMesh failed"},
}


def test_cohort_table_has_every_patient_with_method_verdict_and_exclusion(tmp_path):
    rows = _cohort_table.cohort_rows(["broken", "steady", "averaged"], ATLAS, STATUSES, {"steady": {"quality": "ok"}})
    assert [r["id"] for r in rows] == ["broken", "steady", "averaged"]  # the sheet's order
    broken, steady, averaged = rows
    assert (broken["verdict"], broken["stage"], broken["method"], broken["converged"]) == (
        "excluded",
        "mesh",
        "-",
        "no",
    )
    assert broken["reason"] == "not converged: blockMesh failed <log>"
    assert (steady["verdict"], steady["method"], steady["judgement"], steady["cells"]) == (
        "in atlas",
        "steady",
        "converged",
        19810,
    )
    assert steady["fit_quality"] == "ok" and steady["mass_imbalance"] == "-"
    assert averaged["method"] == "transient" and averaged["flow_source"] == "time_average"
    assert averaged["judgement"] == "stationary (largest error 1.2%)"
    pulsatile = {"pulsatile": {"periodic": False, "cycles_run": 6}, "converged": False}
    assert _cohort_table.solve_method(pulsatile) == "pulsatile"
    assert _cohort_table.judgement(pulsatile) == "not periodic after 6 cycles"

    _cohort_table.write_html(rows, tmp_path / "patients.html")
    page = (tmp_path / "patients.html").read_text()
    assert "<script" not in page  # self-contained, static
    assert '<p id="summary">2 of 3 patients in the atlas, 1 excluded.</p>' in page
    assert '<tr class="excluded" id="patient-broken">' in page and "blockMesh failed &lt;log&gt;" in page
    _cohort_table.write_tsv(rows, tmp_path / "patients.tsv")
    lines = (tmp_path / "patients.tsv").read_text().splitlines()
    assert lines[0].split("\t") == [k for k, _ in _cohort_table.COLUMNS] and len(lines) == 4
    assert lines[1].split("\t")[:3] == ["broken", "excluded", "mesh"]


def _png(rgb: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(rgb.astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _figure() -> np.ndarray:
    """A white figure with a coloured gradient panel (as a field on a wall)."""
    rgb = np.full((300, 400, 3), 255, np.uint8)
    ramp = np.linspace(0, 255, 200)
    rgb[50:250, 100:300, 0] = ramp[None, :]
    rgb[50:250, 100:300, 1] = 80
    rgb[50:250, 100:300, 2] = 255 - ramp[None, :]
    return rgb


def test_blank_reason_tells_a_blank_figure_from_a_drawn_one():
    assert rc.blank_reason(_figure()) is None
    white = np.full((300, 400, 3), 255, np.uint8)
    assert "of the pixels differ from the background" in rc.blank_reason(white)
    rim = white.copy()
    rim[150, 100:300] = (200, 0, 0)  # a one-pixel line: nothing to read
    assert rc.blank_reason(rim) is not None
    assert rc.coloured_fraction(_figure()) > 0.25 and rc.coloured_fraction(white) == 0
    assert rc.pixels(_png(_figure())).shape == (300, 400, 3)


@pytest.mark.skipif(rc.CHROMIUM is None, reason="chromium not installed (Debian's chromium: scripts/install.sh)")
def test_chromium_screenshot_shows_an_embedded_figure_and_a_blank_one_fails(tmp_path):
    shots = {}
    for name, rgb in (("drawn", _figure()), ("blank", np.full((300, 400, 3), 255, np.uint8))):
        uri = "data:image/png;base64," + base64.b64encode(_png(rgb)).decode()
        page = tmp_path / f"{name}.html"
        page.write_text(
            '<!doctype html><html><body style="margin:0"><div id="app"></div><script>'
            "window.addEventListener('load', function () { var i = document.createElement('img');"
            f" i.src = {uri!r}; i.style.marginLeft = '700px'; document.getElementById('app').appendChild(i); }});"
            "</script></body></html>"
        )
        dom = rc.chromium(page)
        assert '<img src="data:image/png;base64,' in dom  # the script ran before the DOM was taken
        shots[name] = tmp_path / f"{name}.png"
        rc.chromium(page, screenshot=shots[name], window=(1200, 600))
    drawn = rc.content(rc.pixels(shots["drawn"]))
    assert rc.blank_reason(drawn) is None and rc.coloured_fraction(drawn) > 0.01
    assert rc.blank_reason(rc.content(rc.pixels(shots["blank"]))) is not None
