"""Checking a Snakemake report (``snakemake --report report.html``) as a person would: open it in
headless Chromium (Debian's ``chromium``), look at the start page and at figures and tables
navigated to through the report's own app, and check that what is shown is there and not blank.

The report of Snakemake 9 is one self-contained page: a React app whose data are JavaScript
variables (``var results = {...}``: every item with its caption and its file as a data URI;
``var categories = {...}``) and whose view is set by ``app.setView(...)`` (there is no URL for a
view). A view is reached by a copy of the page that calls ``app.setView`` once loaded
(:func:`with_view`), exactly what a click in the menu does."""

from __future__ import annotations

import base64
import io
import json
import os
import re
import shutil
import signal
import subprocess
from pathlib import Path
from urllib.parse import unquote_to_bytes

import numpy as np
from PIL import Image

CHROMIUM = shutil.which("chromium")
WINDOW = (1600, 1200)
CATEGORIES = {"Atlas", "Shape", "Flow", "Patients"}


def report_data(report: Path) -> tuple[dict, dict]:
    """(results, categories) of a report: {path: item (name, labels, caption, mime_type,
    data_uri, ...)} and {category: {subcategory: [path, ...]}}."""
    text = Path(report).read_text()

    def var(name: str):
        m = re.search(rf'<script id="{name}">\s*var \w+ = (.*?);\n\s*</script>', text, re.S)
        assert m, f"no {name} in {report}"
        return json.loads(m.group(1))

    return var("results"), var("categories")


def decoded(uri: str) -> bytes:
    """The bytes of a data URI (base64 or percent-encoded)."""
    head, _, data = uri.partition(",")
    return base64.b64decode(data) if head.endswith(";base64") else unquote_to_bytes(data)


def pixels(png: bytes | Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a PNG (bytes or file); transparency composited on white."""
    img = Image.open(io.BytesIO(png) if isinstance(png, bytes) else png)
    if img.mode in ("RGBA", "LA", "P"):
        img = img.convert("RGBA")
        white = Image.new("RGBA", img.size, (255, 255, 255, 255))
        img = Image.alpha_composite(white, img)
    return np.asarray(img.convert("RGB"))


def blank_reason(rgb: np.ndarray, *, min_fraction: float = 0.02, min_colours: int = 16) -> str | None:
    """Why ``rgb`` looks blank (None: it does not): fewer than ``min_fraction`` of its pixels
    differ from its commonest colour (the background) by more than 24 levels in a channel, or it
    has fewer than ``min_colours`` distinct colours."""
    flat = rgb.reshape(-1, 3).astype(int)
    colours, counts = np.unique(flat, axis=0, return_counts=True)
    background = colours[np.argmax(counts)]
    drawn = float((np.abs(flat - background).max(axis=1) > 24).mean())
    if drawn < min_fraction:
        return f"{drawn:.2%} of the pixels differ from the background {tuple(background)}"
    if len(colours) < min_colours:
        return f"only {len(colours)} colours"
    return None


def coloured_fraction(rgb: np.ndarray) -> float:
    """Fraction of pixels that are coloured (channel spread > 60: not white, grey or black)."""
    c = rgb.reshape(-1, 3).astype(int)
    return float(((c.max(axis=1) - c.min(axis=1)) > 60).mean())


def count_colour(rgb: np.ndarray, colour: tuple[int, int, int], tol: int = 3) -> int:
    """Pixels of ``rgb`` within ``tol`` levels of ``colour`` in every channel."""
    return int((np.abs(rgb.reshape(-1, 3).astype(int) - np.array(colour)).max(axis=1) <= tol).sum())


def chromium(page: Path, *, screenshot: Path | None = None, window: tuple[int, int] = WINDOW) -> str:
    """Open ``page`` in headless Chromium with its scripts run (10 s of virtual time): write a
    screenshot of the window to ``screenshot``, or return the DOM as the scripts left it. A
    Chromium that hangs (it seldom does, on a loaded machine) is killed and tried again, 3 times."""
    assert CHROMIUM, "chromium is not installed (scripts/install.sh)"
    profile = Path(page).parent / f".chromium-{Path(page).stem}"
    cmd = [
        CHROMIUM,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        f"--user-data-dir={profile}",
        f"--window-size={window[0]},{window[1]}",
        "--virtual-time-budget=10000",
        f"--screenshot={screenshot}" if screenshot else "--dump-dom",
        Path(page).resolve().as_uri(),
    ]
    for _attempt in range(3):
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
        try:
            out, err = proc.communicate(timeout=90)
            break
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)  # its own session: the browser and its helpers
            proc.communicate()
    else:
        raise AssertionError(f"{' '.join(cmd)} hung 3 times (90 s each)")
    shutil.rmtree(profile, ignore_errors=True)
    assert proc.returncode == 0, f"{' '.join(cmd)} failed ({proc.returncode}): {err[-2000:]}"
    if screenshot:
        assert Path(screenshot).is_file(), err[-2000:]
    return out


def with_view(report: Path, view: dict, out: Path) -> Path:
    """A copy of ``report`` that opens on ``view`` (the argument of the app's ``setView``, as a
    click in its menu gives it) once loaded."""
    text = Path(report).read_text()
    at = text.rindex("</body>")  # the last one: the bundled libraries' sources contain the string too
    script = (
        "<script>window.addEventListener('load', function () {"
        f" setTimeout(function () {{ app.setView({json.dumps(view)}); }}, 100); }});</script>\n"
    )
    Path(out).write_text(text[:at] + script + text[at:])
    return Path(out)


def show(results: dict, categories: dict, path: str) -> dict:
    """The view of the report's result ``path`` opened from its subcategory's menu."""
    ((cat, sub),) = [(c, s) for c, subs in categories.items() for s, paths in subs.items() if path in paths]
    kind = "html" if results[path]["mime_type"] == "text/html" else "img"
    return {
        "navbarMode": "subcategory",
        "category": cat,
        "subcategory": sub,
        "content": kind,
        "contentPath": results[path]["data_uri"],
        "resultPath": path,
    }


def content(rgb: np.ndarray) -> np.ndarray:
    """The part of a report screenshot right of the menu (the menu is at most 30 % wide)."""
    return rgb[:, int(0.3 * rgb.shape[1]) :]


def check_report(report: Path, results_dir: Path, *, excluded: dict[str, str]) -> None:
    """Assert that ``report`` holds the cohort of ``results_dir`` (a finished run): the four
    categories; every atlas figure, per-patient plot and QC sheet on disk in it, with a caption,
    decodable and not blank; the cohort table with every patient (``excluded``: {id: stage} of
    those not in the atlas, their rows marked excluded, with the stage)."""
    results, categories = report_data(report)
    res = Path(results_dir)
    rel = {str(p.relative_to(res.parent)) for p in res.rglob("*") if p.is_file()}

    assert set(categories) == CATEGORIES, sorted(categories)
    placed = {p: (c, s) for c, subs in categories.items() for s, paths in subs.items() for p in paths}
    figures = sorted(p for p in rel if p.startswith("results/atlas/figures/") and p.endswith(".png"))
    assert figures, "no atlas figures on disk"
    for p in figures:
        name = Path(p).name
        want = "Shape" if name.startswith("shape_") else "Flow" if name.startswith("flow_") else "Atlas"
        assert p in placed and placed[p][0] == want, (p, placed.get(p))
    patients = sorted(d.name for d in (res / "patients").iterdir() if d.is_dir())
    assert set(categories["Patients"]) == {"Cohort", *patients}, sorted(categories["Patients"])
    for pid in patients:
        on_disk = {f"results/patients/{pid}/status.json"} | {
            f"results/patients/{pid}/{f}"
            for f in ("qc.png", "case/residuals.png", "case/transient.png", "case/pulsatile.png")
            if f"results/patients/{pid}/{f}" in rel
        }
        assert on_disk <= set(categories["Patients"][pid]), (pid, sorted(on_disk), categories["Patients"][pid])

    for path, item in results.items():
        text = re.sub(r"<[^>]+>", " ", item["caption"])
        assert len(text.split()) >= 15, f"{path}: caption {text!r}"
        assert "ERROR" not in item["caption"] and "system-message" not in item["caption"], (path, item["caption"])
        if item["mime_type"] == "image/png":
            reason = blank_reason(pixels(decoded(item["data_uri"])))
            assert reason is None, f"{path} looks blank: {reason}"

    table = decoded(results["results/atlas/patients.html"]["data_uri"]).decode()
    rows = {pid: cls for cls, pid in re.findall(r'<tr class="(\w+)" id="patient-([^"]+)">', table)}
    assert sorted(rows) == patients, table
    for pid in patients:
        assert rows[pid] == ("excluded" if pid in excluded else "included"), (pid, rows[pid])
    for pid, stage in excluded.items():
        row = re.search(rf'id="patient-{pid}">(.*?)</tr>', table, re.S).group(1)
        assert f'<td class="stage">{stage}</td>' in row, row


def check_in_chromium(report: Path, shots: Path, *, excluded: dict[str, str]) -> list[Path]:
    """Open ``report`` in headless Chromium as a person would and assert what it shows: the start
    page (the workflow description, the four categories in the menu), a Shape figure, a Flow
    figure and a QC sheet (the first excluded patient's when there is one) as a click in the
    menu shows them, each a screenshot whose figure area is drawn and coloured, with its
    subcategory's entries listed; the cohort table with green verdicts and, when ``excluded`` is
    not empty, red rows. Returns the screenshots (in ``shots``)."""
    results, categories = report_data(report)
    placed = {p: (c, s) for c, subs in categories.items() for s, paths in subs.items() for p in paths}
    patients = [s for s in categories["Patients"] if s != "Cohort"]
    shots.mkdir(parents=True, exist_ok=True)

    # in the browser: the start page
    dom = chromium(report)
    assert "VCS atlas of a cohort" in dom and "How to browse it" in dom, dom[-3000:]
    for cat in CATEGORIES:
        assert f">{cat}<" in menu_of(dom), cat
    start = shots / "start.png"
    chromium(report, screenshot=start)
    assert blank_reason(content(pixels(start))) is None

    # figures, as a click in the menu shows them
    shown = [
        p
        for p in ("results/atlas/figures/shape_mean_3d.png", "results/atlas/figures/flow_WSS_mean_3d.png")
        if p in results
    ]
    qc = [p for p in results if p.endswith("/qc.png")] or [p for p in results if p.endswith("/residuals.png")]
    qc.sort(key=lambda p: Path(p).parts[2] not in excluded)  # an excluded patient's first
    shown += qc[:1]
    assert len(shown) == 3, shown
    out = [start]
    for path in shown:
        page = with_view(report, show(results, categories, path), shots / f"{Path(path).stem}.html")
        dom = chromium(page)
        assert f'<img src="{results[path]["data_uri"][:200]}' in dom, f"{path} not shown"
        labels = [results[p]["labels"] for p in categories[placed[path][0]][placed[path][1]]]
        for lab in labels:  # the subcategory's menu lists its entries
            assert lab and all(str(v) in menu_of(dom) for v in lab.values()), (path, lab)
        shot = shots / f"{Path(path).stem}.png"
        chromium(page, screenshot=shot)
        area = content(pixels(shot))
        assert blank_reason(area) is None, f"{path} blank in the browser: {blank_reason(area)}"
        assert coloured_fraction(area) > 0.005, f"{path}: no colour in the browser ({coloured_fraction(area):.2%})"
        out.append(shot)

    # the cohort table: green verdicts, the rows of excluded patients red
    page = with_view(report, show(results, categories, "results/atlas/patients.html"), shots / "patients.html")
    shot = shots / "patients.png"
    chromium(page, screenshot=shot)
    area = content(pixels(shot))
    assert count_colour(area, (0xD8, 0xF0, 0xD8)) > 100 * (len(patients) - len(excluded)), "no green verdicts"
    assert (count_colour(area, (0xF8, 0xDC, 0xDC)) > 1000) == bool(excluded), "red rows of excluded patients"
    out.append(shot)
    return out


def menu_of(dom: str) -> str:
    """The DOM without its scripts (what the menu and the content show)."""
    return re.sub(r"<script.*?</script>", "", dom, flags=re.S)
