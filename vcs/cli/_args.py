"""Argument helpers shared by the command modules of :mod:`vcs.cli`.

argparse types for integer ranges, the output-path checks (an output directory, never an input
overwritten) and the JSON writer. Imports nothing from the rest of :mod:`vcs.cli`.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
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
