"""A bench script's table in the documentation's format: docs/data/bench/<name>.json, shown on a
page by the ``vcs-bench-table`` directive (docs/_ext/vcsdocs.py). Standard library only.

    write_table(path, command=command_line(), measured="best of 3", columns=[...], rows=[[...], ...])

The file names the command that wrote it (``"source": "written by <command>"``) and where and when
it was measured (date, platform, CPU model and count, load averages at writing), so the page can
say how to re-measure every number it shows.

A bench script prints its table and, given ``--json PATH``, writes it with :func:`emit` (each row
printed as it is made), or with :func:`save` when what it prints is another table::

    emit(COLUMNS, (cells(pid) for pid in ids), a.json, "one run", json_columns=..., json_row=...)
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
from collections.abc import Callable, Iterable, Sequence
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


def sig(x: float, digits: int = 2) -> str:
    """``x`` to ``digits`` significant digits, an exponent as people write it: ``1e-9``, ``1.2e-4``
    (``f"{x:.2g}"`` gives ``1e-09``, ``0.00012``)."""
    s = f"{x:.{digits}g}"
    if "e" not in s and x != 0 and abs(x) < 1e-3:
        s = f"{x:.{digits - 1}e}"
    if "e" in s:
        mantissa, exponent = s.split("e")
        if "." in mantissa:
            mantissa = mantissa.rstrip("0").rstrip(".")
        s = f"{mantissa}e{int(exponent)}"
    return s


def markdown_row(cells: Sequence[str]) -> str:
    """One row of a markdown table: ``| a | b |``."""
    return "| " + " | ".join(cells) + " |"


def save(
    json_path: str | os.PathLike | None,
    *,
    columns: list[str],
    rows: list[list[str]],
    measured: str,
    command: str | None = None,
    notes: list[str] | None = None,
) -> Path | None:
    """:func:`write_table` to ``json_path`` when it is given (a script's ``--json PATH``; None:
    nothing is written), the command by default this process's (:func:`command_line`)."""
    if not json_path:
        return None
    cmd = command if command is not None else command_line()
    return write_table(json_path, command=cmd, measured=measured, columns=columns, rows=rows, notes=notes)


def emit(
    columns: list[str],
    rows: Iterable[Sequence[str]],
    json_path: str | os.PathLike | None = None,
    measured: str = "",
    command: str | None = None,
    *,
    notes: list[str] | None = None,
    json_columns: list[str] | None = None,
    json_row: Callable[[list[str]], list[str]] | None = None,
) -> list[list[str]]:
    """Print a markdown table, each row as soon as ``rows`` yields it, then :func:`save` it.

    Parameters
    ----------
    columns : list of str
        The printed header.
    rows : iterable of lists of str
        The printed rows (a generator: each is printed before the next is made).
    json_path, measured, command, notes
        As :func:`save` (nothing is written without ``json_path``).
    json_columns : list of str, optional
        The docs table's columns, when they are not the printed ones.
    json_row : callable, optional
        A printed row as a row of the docs table (default: the row itself).

    Returns
    -------
    list of list of str
        The printed rows.
    """
    print(markdown_row(columns))
    print("|---" * len(columns) + "|", flush=True)
    printed = []
    for r in rows:
        printed.append(list(r))
        print(markdown_row(printed[-1]), flush=True)
    save(
        json_path,
        columns=list(json_columns if json_columns is not None else columns),
        rows=[json_row(r) for r in printed] if json_row else printed,
        measured=measured,
        command=command,
        notes=notes,
    )
    return printed
