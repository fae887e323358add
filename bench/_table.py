"""A bench script's table in the documentation's format: docs/data/bench/<name>.json, shown on a
page by the ``vcs-bench-table`` directive (docs/_ext/vcsdocs.py). Standard library only.

    write_table(path, command=command_line(), measured="best of 3", columns=[...], rows=[[...], ...])

The file names the command that wrote it (``"source": "written by <command>"``) and where and when
it was measured (date, platform, CPU model and count, load averages at writing), so the page can
say how to re-measure every number it shows.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
from datetime import datetime
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            return next(ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def machine() -> str:
    """Platform, CPU model and count, e.g. ``Linux x86_64, AMD EPYC 7B13, 2 cores``."""
    return f"{platform.system()} {platform.machine()}, {_cpu_model()}, {os.cpu_count()} cores"


def load() -> str:
    """The 1, 5 and 15 minute load averages, e.g. ``load 1.9 / 2.0 / 1.7 (1 / 5 / 15 min)``."""
    one, five, fifteen = os.getloadavg()
    return f"load {one:.1f} / {five:.1f} / {fifteen:.1f} (1 / 5 / 15 min)"


def _rel(arg: str) -> str:
    """A path inside the repository relative to it (as the docs name commands), others unchanged."""
    p = Path(arg)
    if p.is_absolute():
        try:
            return str(p.relative_to(REPO))
        except ValueError:
            return arg
    return arg


def command_line(env: tuple[str, ...] = ("OPENBLAS_NUM_THREADS",)) -> str:
    """This process's command line as run from the repository, e.g.
    ``OPENBLAS_NUM_THREADS=1 .venv/bin/python bench/fit_table.py --json docs/data/bench/fit_table.json``
    (the variables of ``env`` that are set come first)."""
    prefix = [f"{k}={os.environ[k]}" for k in env if k in os.environ]
    python = _rel(sys.executable)
    script = _rel(str(Path(sys.argv[0]).resolve()))
    return shlex.join([*prefix, python, script, *sys.argv[1:]])


def write_table(
    path: str | os.PathLike,
    *,
    command: str,
    measured: str,
    columns: list[str],
    rows: list[list[str]],
    notes: list[str] | None = None,
) -> Path:
    """Write a table as docs/data/bench JSON.

    Parameters
    ----------
    path : path-like
        The JSON file (its folder is created).
    command : str
        The command that produced the table, as a user types it (see :func:`command_line`).
    measured : str
        How it was measured (``"best of 3, wall / CPU seconds"``); the date, :func:`machine` and
        :func:`load` (at writing) are put before it.
    columns : list of str
        Column headers (single backticks mark code).
    rows : list of list of str
        One list per row, as many cells as ``columns``.
    notes : list of str, optional
        Paragraphs shown under the table.

    Returns
    -------
    Path
        The file written.
    """
    if any(len(r) != len(columns) for r in rows):
        raise ValueError(f"every row needs {len(columns)} cells (the columns {columns})")
    stamp = datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    data = {
        "command": command,
        "measured": f"{stamp} on {machine()}, {load()} at the end; {measured}",
        "source": f"written by {command}",
        "columns": list(columns),
        "rows": [[str(c) for c in r] for r in rows],
    }
    if notes:
        data["notes"] = list(notes)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")
    return path
