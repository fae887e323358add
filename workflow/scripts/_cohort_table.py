"""The cohort table of the Snakemake report (category Patients): one row per patient of the sheet,
in the atlas or not, from atlas.json (``patients_included``, ``patients_excluded`` with stage and
reason, ``field_sources``), each patient's ``status.json`` (how the flow was solved and judged) and
``fit_report.json`` (the fit's quality). Written as ``patients.tsv`` (for a spreadsheet) and as a
self-contained ``patients.html`` (the report shows it in a frame)."""

from __future__ import annotations

import csv
import html
from collections.abc import Mapping
from pathlib import Path
from typing import Any

COLUMNS = (
    ("id", "patient"),
    ("verdict", "verdict"),
    ("stage", "excluded at"),
    ("reason", "reason"),
    ("method", "method"),
    ("converged", "converged"),
    ("criterion_used", "criterion"),
    ("judgement", "judgement"),
    ("cells", "cells"),
    ("iterations", "iterations"),
    ("mass_imbalance", "mass imbalance"),
    ("flow_source", "flow in atlas"),
    ("fit_quality", "fit quality"),
    ("fit_residual_p95_mm", "fit residual p95 (mm)"),
)
"""(key, heading) of every column, in order."""


def solve_method(status: Mapping[str, Any]) -> str:
    """``pulsatile`` (cycles), ``transient`` (the time-averaged fallback of a steady run that did
    not converge), ``steady`` (SIMPLE), or ``-`` when no solver ran (a failure before the solve)."""
    if status.get("pulsatile"):
        return "pulsatile"
    if status.get("transient"):
        return "transient"
    if status.get("iterations") or status.get("criterion_used"):
        return "steady"
    return "-"


def judgement(status: Mapping[str, Any]) -> str:
    """The verdict on the run's result in a few words: a pulsatile run's periodicity, a transient
    run's stationarity (its largest relative error bar), a steady run's criterion."""
    pul = status.get("pulsatile") or {}
    if pul:
        return f"{'periodic' if pul.get('periodic') else 'not periodic'} after {pul.get('cycles_run', '?')} cycles"
    tr = status.get("transient") or {}
    if tr:
        errors = [abs(v) for v in (tr.get("relative_errors") or {}).values() if isinstance(v, (int, float))]
        worst = f" (largest error {max(errors):.1%})" if errors else ""
        return ("stationary" if tr.get("stationary") else "not stationary") + worst
    if status.get("criterion_used"):
        return "converged" if status.get("converged") else "not converged"
    return "-"


def cohort_rows(
    ids: list[str],
    atlas: Mapping[str, Any],
    statuses: Mapping[str, Mapping[str, Any]],
    reports: Mapping[str, Mapping[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """One row per patient of ``ids`` (the sheet's order): {key of :data:`COLUMNS`: value}.

    ``atlas`` is atlas.json's content, ``statuses`` {id: status.json}, ``reports``
    {id: fit_report.json} (a failure record of the fit has no quality). Missing values are ``-``.
    """
    excluded = {e["id"]: e for e in atlas.get("patients_excluded", [])}
    included = set(atlas.get("patients_included", []))
    sources = atlas.get("field_sources") or {}
    rows = []
    for pid in ids:
        st = statuses.get(pid) or {}
        rep = (reports or {}).get(pid) or {}
        ex = excluded.get(pid)
        mass = st.get("mass_imbalance")
        p95 = rep.get("residual_p95_mm")
        row = {
            "id": pid,
            "verdict": "in atlas" if pid in included else "excluded",
            "stage": ex["stage"] if ex else "-",
            "reason": ex["reason"] if ex else "-",
            "method": solve_method(st),
            "converged": {True: "yes", False: "no"}.get(st.get("converged"), "-"),
            "criterion_used": st.get("criterion_used") or "-",
            "judgement": judgement(st),
            "cells": st.get("cells") if st.get("cells") is not None else "-",
            "iterations": st.get("iterations") if st.get("iterations") is not None else "-",
            "mass_imbalance": f"{mass:.1e}" if isinstance(mass, (int, float)) else "-",
            "flow_source": sources.get(pid, "-"),
            "fit_quality": rep.get("quality") or "-",
            "fit_residual_p95_mm": f"{p95:.3f}" if isinstance(p95, (int, float)) else "-",
        }
        rows.append(row)
    return rows


def write_tsv(rows: list[dict[str, Any]], path: str | Path) -> None:
    """``rows`` as a tab-separated table with the column keys as header."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, delimiter="\t", lineterminator="\n")
        w.writerow([k for k, _ in COLUMNS])
        for r in rows:
            w.writerow([str(r[k]).replace("\t", " ").replace("\n", " ") for k, _ in COLUMNS])


_STYLE = """
body { font-family: sans-serif; font-size: 13px; margin: 12px; }
table { border-collapse: collapse; }
th, td { border: 1px solid #bbb; padding: 3px 6px; text-align: left; vertical-align: top; }
th { background: #eee; }
tr.included td.verdict { background: #d8f0d8; }
tr.excluded td { background: #f8dcdc; }
td.reason { max-width: 32em; overflow-wrap: anywhere; }
"""


def write_html(rows: list[dict[str, Any]], path: str | Path, *, title: str = "Patients of the cohort") -> None:
    """``rows`` as one self-contained HTML page (inline style, no script): a line saying how many
    patients are in the atlas, then the table, an excluded patient's row in red."""
    n_in = sum(r["verdict"] == "in atlas" for r in rows)
    head = "".join(f"<th>{html.escape(h)}</th>" for _, h in COLUMNS)
    body = []
    for r in rows:
        cls = "included" if r["verdict"] == "in atlas" else "excluded"
        cells = "".join(f'<td class="{k}">{html.escape(str(r[k]))}</td>' for k, _ in COLUMNS)
        body.append(f'<tr class="{cls}" id="patient-{html.escape(r["id"])}">{cells}</tr>')
    page = (
        '<!doctype html>\n<html lang="en"><head><meta charset="utf-8">'
        f"<title>{html.escape(title)}</title><style>{_STYLE}</style></head><body>\n"
        f"<h1>{html.escape(title)}</h1>\n"
        f'<p id="summary">{n_in} of {len(rows)} patients in the atlas, {len(rows) - n_in} excluded.</p>\n'
        f"<table><thead><tr>{head}</tr></thead><tbody>\n" + "\n".join(body) + "\n</tbody></table>\n</body></html>\n"
    )
    Path(path).write_text(page)
