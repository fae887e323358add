"""Argument helpers shared by the command modules of :mod:`vcs.cli`.

argparse types for integer ranges, options whose value is a point (``--inlet -40,0,0``: a value
that starts with a minus sign), the output-path checks (an output directory, never an input
overwritten) and the JSON writer. Imports nothing from the rest of :mod:`vcs.cli`.
"""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from vcs.errors import VCSInputError

PathLike = str | Path


def int_at_least(minimum: int) -> Callable[[str], int]:
    """An argparse ``type``: the argument as an integer that must be >= ``minimum``.

    Parameters
    ----------
    minimum : int
        Smallest accepted value (inclusive).

    Returns
    -------
    parse : callable
        ``parse(text) -> int``; raises :class:`argparse.ArgumentTypeError` (reported by argparse
        as ``argument --X: ...``, exit code 2) for a non-integer or a value below ``minimum``.
    """

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None
        if v < minimum:
            raise argparse.ArgumentTypeError(f"{v} must be >= {minimum}")
        return v

    return parse


positive_int: Callable[[str], int] = int_at_least(1)
"""argparse ``type``: an integer >= 1 (knot numbers, grid sizes)."""

non_negative_int: Callable[[str], int] = int_at_least(0)
"""argparse ``type``: an integer >= 0 (iteration counts)."""

POINT_OPTIONS: set[str] = set()
"""Option strings registered by :func:`add_point_argument` (their values may start with a minus sign)."""

# a value that starts like a negative number: "-40,0,0", "-.5, 1, 2", "-1e-3,0,0"
_NEGATIVE_VALUE = re.compile(r"-\s*\.?[0-9]")
_NUMBER = re.compile(r"[-+]?\s*\.?[0-9]")


def add_point_argument(parser: argparse.ArgumentParser, *flags: str, **kwargs: Any) -> argparse.Action:
    """Add an option that takes a point ``x,y,z`` (or another value that may start with a minus sign).

    argparse reads a value such as ``-40,0,0`` after a space as an unknown option ("expected one
    argument"); the flags registered here are rewritten to ``--flag=value`` by
    :func:`join_point_values` before parsing, so ``--inlet -40,0,0`` and ``--inlet=-40,0,0`` both work.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The (sub)parser of the command.
    *flags : str
        Option strings, e.g. ``"--inlet"``.
    **kwargs
        Passed to :meth:`argparse.ArgumentParser.add_argument`.

    Returns
    -------
    argparse.Action
        The added action.
    """
    POINT_OPTIONS.update(f for f in flags if f.startswith("--"))
    return parser.add_argument(*flags, **kwargs)


def join_point_values(argv: Sequence[str]) -> list[str]:
    """``argv`` with the value of each point option joined to it: ``--flag=VALUE``.

    For flags registered by :func:`add_point_argument`: ``--flag VALUE`` becomes ``--flag=VALUE``
    when VALUE starts like a negative number (``-40,0,0``, ``-.5,1,2``; leading blanks allowed),
    which argparse would take for an option; and a point split by the shell at its commas
    (``--inlet -40, 0, 0`` unquoted: ``-40,`` ``0,`` ``0``) is put back together (a value ending in
    a comma takes the next argument, at most twice). Everything after ``--`` is left alone.

    Parameters
    ----------
    argv : sequence of str
        Command-line arguments without the program name.

    Returns
    -------
    list of str
        The arguments for :meth:`argparse.ArgumentParser.parse_args`.
    """
    out: list[str] = []
    i = 0
    while i < len(argv):
        arg = argv[i]
        if arg == "--":
            out.extend(argv[i:])
            break
        flag, eq, value = arg.partition("=")
        if flag in POINT_OPTIONS and (eq or i + 1 < len(argv)):
            if not eq:
                value = argv[i + 1]
                if not _NEGATIVE_VALUE.match(value.lstrip()) and not value.rstrip().endswith(","):
                    out.append(arg)  # an ordinary value: argparse reads it as it is
                    i += 1
                    continue
                i += 1
            for _ in range(2):  # "-40," "0," "0": the shell split the point at its blanks
                if not (value.rstrip().endswith(",") and i + 1 < len(argv) and _NUMBER.match(argv[i + 1].lstrip())):
                    break
                value += argv[i + 1]
                i += 1
            out.append(f"{flag}={value}")
            i += 1
            continue
        out.append(arg)
        i += 1
    return out


def output_dir(path: PathLike) -> Path:
    """The output directory ``path``, created (with parents) when missing.

    Parameters
    ----------
    path : str or Path
        The ``-o`` argument.

    Returns
    -------
    Path
        The directory, which exists on return.

    Raises
    ------
    VCSInputError
        ``path`` exists and is not a directory.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise VCSInputError(f"output '{p}' exists and is not a directory; choose another -o")
    p.mkdir(parents=True, exist_ok=True)
    return p


def not_an_input(output: PathLike, *inputs: PathLike | None) -> Path:
    """``output`` as a Path, refusing a file the user gave as input (inputs are never overwritten).

    Parameters
    ----------
    output : str or Path
        A file the command is about to write.
    *inputs : str, Path or None
        The command's input files; ``None`` (an optional input not given) is skipped.

    Returns
    -------
    Path
        ``Path(output)``.

    Raises
    ------
    VCSInputError
        ``output`` resolves to the same path as one of ``inputs``.
    """
    out = Path(output)
    for i in inputs:
        if i is not None and out.resolve() == Path(i).resolve():
            raise VCSInputError(f"output '{out}' is also an input; choose another -o (inputs are never overwritten)")
    return out


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as JSON: indent 1, sorted keys, trailing newline (stable bytes for diffs).

    Parameters
    ----------
    path : Path
        Output file (overwritten).
    data : dict
        JSON-serialisable content.
    """
    path.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
