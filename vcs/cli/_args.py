"""Argument helpers shared by the command modules of :mod:`vcs.cli`.

argparse types for integer and float ranges, options whose value is a point (``--inlet -40,0,0``:
a value that starts with a minus sign), the output-path checks (a file or a directory whose parent
exists and is writable, never an input overwritten), atomic writes (:func:`atomic_file`,
:class:`OutputFolder`: a temporary file in the same directory, then :func:`os.replace`; a failed
or interrupted rerun into an output folder keeps the earlier outputs whole, a failed one leaves a
failure record beside them) and the JSON
writer. Imports nothing from the rest of :mod:`vcs.cli`.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import secrets
import shutil
import tempfile
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType
from typing import Any

from vcs._signals import signals_held
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


def float_at_least(minimum: float, *, strict: bool = False, maximum: float | None = None) -> Callable[[str], float]:
    """An argparse ``type``: the argument as a finite float >= ``minimum`` (> when ``strict``), <= ``maximum``.

    Parameters
    ----------
    minimum : float
        Smallest accepted value.
    strict : bool
        Refuse ``minimum`` itself (for sizes that must be positive).
    maximum : float, optional
        Largest accepted value.

    Returns
    -------
    parse : callable
        ``parse(text) -> float``; raises :class:`argparse.ArgumentTypeError` (exit code 2) for a
        non-number, NaN, an infinity, or a value out of range (``--extend-inlet -1`` is an error,
        not 0).
    """

    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"'{text}' is not a finite number")
        if v < minimum or (strict and v == minimum):
            raise argparse.ArgumentTypeError(f"{v:g} must be {'>' if strict else '>='} {minimum:g}")
        if maximum is not None and v > maximum:
            raise argparse.ArgumentTypeError(f"{v:g} must be <= {maximum:g}")
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


def _writable_parent(p: Path) -> None:
    """Check that the directory that will hold ``p`` exists, is a directory and can be written.

    Raises
    ------
    VCSInputError
        ``p``'s parent is missing, lies under a regular file, or refuses a new file (permissions,
        read-only file system); one line naming the path and the fix.
    """
    parent = p.parent
    if not parent.is_dir():
        up = parent
        while not up.exists() and up != up.parent:
            up = up.parent
        if up.exists() and not up.is_dir():
            raise VCSInputError(f"output '{p}' lies under '{up}', which is a file, not a directory; choose another -o")
        raise VCSInputError(f"directory '{parent}' does not exist; create it first or choose another -o")
    try:  # the real test: root ignores permission bits, a read-only file system does not
        with tempfile.NamedTemporaryFile(dir=parent, prefix=".vcs-write-test-"):
            pass
    except OSError as exc:
        raise VCSInputError(
            f"cannot write to directory '{parent}' ({exc.strerror or exc}); choose another -o"
        ) from None


def _as_output_path(path: PathLike) -> Path:
    """``Path(path)``, refusing an empty or NUL-holding name (one line, exit code 2)."""
    text = str(path)
    if not text.strip() or "\x00" in text:
        raise VCSInputError(f"output {text!r} is not a file name; choose another -o")
    return Path(text)


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
    out = _as_output_path(output)
    for i in inputs:
        if i is not None and str(i) and "\x00" not in str(i) and out.resolve() == Path(i).resolve():
            raise VCSInputError(f"output '{out}' is also an input; choose another -o (inputs are never overwritten)")
    return out


def output_file(
    path: PathLike,
    *inputs: PathLike | None,
    suffixes: Sequence[str] = (),
    overwrite: bool = True,
    option: str = "-o",
) -> Path:
    """Check an output file before any work is done: all that can be known about ``path`` up front.

    Parameters
    ----------
    path : str or Path
        The output file the user named.
    *inputs : str, Path or None
        The command's inputs (``path`` must be none of them).
    suffixes : sequence of str
        Accepted extensions, lower case with the dot (``(".vtu",)``); empty: any.
    overwrite : bool
        False: an existing ``path`` is refused (`vcs phantom` without ``--overwrite``).
    option : str
        The option that named ``path``, for the message.

    Returns
    -------
    Path
        ``Path(path)``.

    Raises
    ------
    VCSInputError
        ``path`` is a directory, has another extension, is an input, exists (``overwrite``
        False), or its parent is missing, lies under a regular file or cannot be written.
    """
    text = str(path)
    p = not_an_input(path, *inputs)
    if p.is_dir() or text.endswith(("/", os.sep)):
        example = p / f"out{suffixes[0] if suffixes else ''}"
        raise VCSInputError(f"{option} '{text}' is a directory; give a file name, e.g. {example}")
    if suffixes and p.suffix.lower() not in suffixes:
        raise VCSInputError(f"{option} '{p}' must end in {' or '.join(suffixes)}")
    if p.exists() and not overwrite:
        raise VCSInputError(f"{option} '{p}' exists; choose another file or give --overwrite to replace it")
    _writable_parent(p)
    return p


def output_dir(path: PathLike, *inputs: PathLike | None, names: Sequence[str] = ()) -> Path:
    """Check an output directory before any work is done (it is created later, by :class:`OutputFolder`).

    Parameters
    ----------
    path : str or Path
        The ``-o`` argument: an existing directory or a new one whose parent exists.
    *inputs : str, Path or None
        The command's inputs: none may be one of the files ``names`` in the directory.
    names : sequence of str
        The files the command writes (or removes when a run no longer writes them) in the directory.

    Returns
    -------
    Path
        ``Path(path)``.

    Raises
    ------
    VCSInputError
        ``path`` exists and is not a directory, its parent is missing or lies under a regular
        file, it cannot be written, or one of the outputs is an input.
    """
    p = _as_output_path(path)
    if p.exists() and not p.is_dir():
        raise VCSInputError(f"output '{p}' exists and is not a directory; choose another -o")
    for name in names:
        not_an_input(p / name, *inputs)
    _writable_parent(p / ".vcs" if p.is_dir() else p)
    return p


def _temporary_name(path: Path) -> Path:
    """A fresh hidden name beside ``path`` with the same extension (writers choose formats by it)."""
    return path.with_name(f".{path.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}")


def remove_leftovers(path: Path) -> list[Path]:
    """Remove the temporary files of ``path`` left by a run that died while writing (a crash, SIGKILL).

    Only names made by :func:`_temporary_name` whose process no longer exists are removed (a
    run writing the same output right now keeps its file).

    Parameters
    ----------
    path : Path
        An output file.

    Returns
    -------
    list of Path
        The files removed.
    """
    pattern = re.compile(re.escape(f".{path.name}.") + r"(\d+)-[0-9a-f]{8}\.tmp" + re.escape(path.suffix) + "$")
    removed = []
    with os.scandir(path.parent) as entries:
        for e in entries:
            m = pattern.match(e.name)
            if m is not None and not _process_exists(int(m.group(1))):
                Path(e.path).unlink(missing_ok=True)
                removed.append(Path(e.path))
    return removed


def _process_exists(pid: int) -> bool:
    """Whether process ``pid`` is running (ours counts)."""
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


@contextmanager
def atomic_file(path: Path) -> Iterator[Path]:
    """Write ``path`` atomically: yield a temporary name in the same directory, then rename it.

    On success the temporary file replaces ``path`` (:func:`os.replace`: a reader sees the old
    file or the whole new one, never a part); on any exception (and Ctrl-C) it is removed and
    ``path`` is left as it was. Temporary files of ``path`` left by a run that died are removed
    first (:func:`remove_leftovers`).

    Parameters
    ----------
    path : Path
        The output file.

    Yields
    ------
    Path
        Where to write (same directory and extension as ``path``).

    Raises
    ------
    VCSInputError
        The system refused the write (a full disk, a file size limit): one line naming ``path``.
    """
    remove_leftovers(path)
    tmp = _temporary_name(path)
    try:
        yield tmp
        if not tmp.exists():
            raise RuntimeError(f"nothing was written to {tmp}")
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise VCSInputError(f"cannot write '{path}' ({exc.strerror or exc}); nothing was written") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


class OutputFolder:
    """The outputs of a command that writes several files into one directory (`vcs fit`, `vcs sensitivity`).

    Used as a context manager around the whole computation. The files are built in a hidden
    temporary folder inside the directory (:meth:`file`) and moved into place together when the
    block succeeds, in the order of ``names`` (put the file whose presence means "complete"
    last, e.g. ``model.json``), with Ctrl-C and SIGTERM held back for those few renames; outputs
    of an earlier run that this run did not write (e.g. ``residual_map.png`` without
    ``--residual-png``) and an earlier failure record are then removed. Nothing the user had is
    touched before that: when the block fails (an error, Ctrl-C, SIGTERM, out of memory) or the
    process is killed, the temporary folder goes (a killed run's is removed by the next run) and
    the outputs of an earlier run stay whole and usable. After an error (not an interruption),
    ``<command>_failed.json`` (the command line's error and the earlier outputs kept) says that
    the last run failed and what is still there; a directory this run created is removed again.

    Parameters
    ----------
    path : Path
        The directory, checked by :func:`output_dir`; created (not its parents) when missing.
    names : sequence of str
        Every file the command can write there.
    command : str
        The subcommand (``"fit"``): names the failure record ``fit_failed.json``.
    """

    def __init__(self, path: Path, names: Sequence[str], command: str) -> None:
        self.path = path
        self.names = list(names)
        self.record = path / f"{command}_failed.json"
        self.command = command
        self._staged: dict[str, Path] = {}
        self._created = False
        self._stage: Path | None = None

    def __enter__(self) -> OutputFolder:
        try:
            if not self.path.is_dir():
                self._created = True
                self.path.mkdir()
            for name in self.names:
                remove_leftovers(self.path / name)
            _remove_dead_stages(self.path, self.command)
            self._stage = self.path / f".{self.command}.{os.getpid()}-{secrets.token_hex(4)}.tmp"
            self._stage.mkdir()
        except BaseException:  # Ctrl-C right after mkdir: __exit__ would not run
            self._discard()
            if self._created and self.path.is_dir() and not any(self.path.iterdir()):
                self.path.rmdir()
            raise
        return self

    def file(self, name: str) -> Path:
        """The temporary path to write output ``name`` to (moved into place on success).

        Parameters
        ----------
        name : str
            One of ``names``.

        Returns
        -------
        Path
            ``name`` in the hidden temporary folder.
        """
        if name not in self.names:
            raise ValueError(f"{name} is not an output of vcs {self.command}")
        assert self._stage is not None
        self._staged[name] = self._stage / name
        return self._staged[name]

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc is None:
            missing = [n for n, t in self._staged.items() if not t.exists()]
            if missing:
                self._discard()
                raise RuntimeError(f"vcs {self.command} did not write {', '.join(missing)}")
            try:
                with signals_held():
                    for name in self.names:
                        if name in self._staged:
                            os.replace(self._staged[name], self.path / name)
                        else:
                            (self.path / name).unlink(missing_ok=True)  # an earlier run's, not this one's
                    self.record.unlink(missing_ok=True)
            except KeyboardInterrupt as interrupt:  # held back during the renames: the new outputs are whole
                interrupt.after_outputs_complete = True  # type: ignore[attr-defined]
                raise
            finally:
                self._discard()
            return
        self._discard()
        kept = sorted(n for n in self.names if (self.path / n).is_file())
        if isinstance(exc, KeyboardInterrupt):  # Ctrl-C or SIGTERM: the user knows; nothing to record
            pass
        elif kept or not self._created:
            record = {
                "command": f"vcs {self.command}",
                "error": str(exc) or type(exc).__name__,
                "kept_earlier_outputs": kept,
                "note": f"the last vcs {self.command} into this folder failed; "
                + (
                    "the outputs listed are an earlier run's, kept as they were (they do not reflect the "
                    "failed command line)"
                    if kept
                    else "it wrote nothing"
                ),
            }
            with atomic_file(self.record) as tmp:
                write_json(tmp, record)
        if self._created and self.path.is_dir() and not any(self.path.iterdir()):
            self.path.rmdir()

    def _discard(self) -> None:
        if self._stage is not None:
            shutil.rmtree(self._stage, ignore_errors=True)
            self._stage = None


def _remove_dead_stages(path: Path, command: str) -> None:
    """Remove the temporary folders of :class:`OutputFolder` runs that died (killed, out of memory)."""
    pattern = re.compile(re.escape(f".{command}.") + r"(\d+)-[0-9a-f]{8}\.tmp$")
    with os.scandir(path) as entries:
        for e in entries:
            m = pattern.match(e.name)
            if m is not None and e.is_dir(follow_symlinks=False) and not _process_exists(int(m.group(1))):
                shutil.rmtree(e.path, ignore_errors=True)


def seconds_since_process_start() -> float | None:
    """Wall-clock seconds since this process started (interpreter start-up and imports included),
    from /proc (Linux, 10 ms resolution); None elsewhere.

    Returns
    -------
    float or None
    """
    try:
        with open("/proc/self/stat") as fh:
            start_ticks = int(fh.read().rsplit(")", 1)[1].split()[19])  # field 22: starttime
        with open("/proc/uptime") as fh:
            uptime = float(fh.read().split()[0])
        return max(0.0, uptime - start_ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return None


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write ``data`` as JSON: indent 1, sorted keys, trailing newline (stable bytes for diffs).

    Parameters
    ----------
    path : Path
        Output file (overwritten; pass the temporary name of :func:`atomic_file` or
        :meth:`OutputFolder.file`).
    data : dict
        JSON-serialisable content.
    """
    path.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
