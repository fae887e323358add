"""Command line: `vcs fit|ends|coords|cartesian|wall|grid|lumen|phantom|sensitivity`.

Bad input ends with one line on stderr naming the problem and the fix, and exit code 2; running
out of memory is exit code 3 (not the input's fault: a coarser mesh or grid, or more memory).
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import warnings
from collections.abc import Sequence
from typing import NoReturn

from vcs._signals import signals_held
from vcs.cli._args import join_point_values
from vcs.cli.ends import add_commands as add_ends_commands
from vcs.cli.fit import add_commands as add_fit_commands
from vcs.cli.lumen import add_commands as add_lumen_commands
from vcs.cli.phantom import add_commands as add_phantom_commands
from vcs.cli.points import add_commands as add_points_commands
from vcs.cli.sensitivity import add_commands as add_sensitivity_commands
from vcs.cli.wall import add_commands as add_wall_commands
from vcs.errors import VCSInputError

# the order of the subcommands in `vcs --help`
_COMMAND_GROUPS = (
    add_fit_commands,
    add_ends_commands,
    add_points_commands,
    add_phantom_commands,
    add_wall_commands,
    add_lumen_commands,
    add_sensitivity_commands,
)

EXIT_OK, EXIT_INTERNAL, EXIT_INPUT, EXIT_MEMORY, EXIT_INTERRUPTED, EXIT_TERMINATED = 0, 1, 2, 3, 130, 143
"""Exit codes of `vcs`: success, a bug (report it), bad input (fix it), out of memory, Ctrl-C, SIGTERM."""

# characters str.splitlines() breaks at: escaped so that an error is always one line
_LINE_BREAKS = str.maketrans({c: repr(c)[1:-1] for c in "\n\r\v\f\x1c\x1d\x1e\x85\u2028\u2029"})


def one_line(text: str) -> str:
    """``text`` with line breaks escaped (``\\n``): a path or value holding one cannot split a message.

    Parameters
    ----------
    text : str
        A message.

    Returns
    -------
    str
        The message on one line.
    """
    return text.translate(_LINE_BREAKS)


class _Parser(argparse.ArgumentParser):
    """The `vcs` parsers: no abbreviated options (``--outp`` is not ``--output``), and a usage
    error is one line, ``vcs CMD: error: ... (see vcs CMD --help)``, exit code 2."""

    def __init__(self, **kwargs: object) -> None:
        kwargs["allow_abbrev"] = False
        super().__init__(**kwargs)  # type: ignore[arg-type]

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_INPUT, one_line(f"{self.prog}: error: {message} (see {self.prog} --help)") + "\n")


def build_parser() -> argparse.ArgumentParser:
    """The `vcs` argument parser with every subcommand.

    Every parser refuses abbreviated options (``allow_abbrev=False``), and ``-v`` is accepted
    before or after the subcommand (it is added to each subparser with a suppressed default, so
    that it never resets a ``-v`` given before the subcommand).

    Returns
    -------
    argparse.ArgumentParser
        ``prog="vcs"``; each subcommand sets ``func`` (its ``cmd_*`` function) and ``command``.
    """
    p = _Parser(
        prog="vcs",
        description=__doc__.splitlines()[0],
        epilog="exit codes: 0 done, 2 bad input or a refused output (one line says what to fix), "
        "3 out of memory, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM), 1 internal error (a bug; -v shows "
        "the traceback)",
    )
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr; tracebacks of internal errors")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add_commands in _COMMAND_GROUPS:
        add_commands(sub)
    for sp in sub.choices.values():
        sp.add_argument(
            "-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="as vcs -v (anywhere on the line)"
        )
    return p


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """Parse `vcs` arguments; a point option's value may start with a minus sign after a space.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    argparse.Namespace
        As :meth:`argparse.ArgumentParser.parse_args` of :func:`build_parser`, after
        :func:`vcs.cli._args.join_point_values` (``--inlet -40,0,0`` -> ``--inlet=-40,0,0``).
        An unknown argument is reported by the subcommand's parser (``vcs fit: error:
        unrecognized arguments: --rec 2``), exit code 2.
    """
    parser = build_parser()
    args, extra = parser.parse_known_args(join_point_values(sys.argv[1:] if argv is None else list(argv)))
    if extra:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        sub.choices[args.command].error(f"unrecognized arguments: {' '.join(extra)}")
    return args


class Terminated(KeyboardInterrupt):
    """SIGTERM (scancel, Snakemake, kill) raised as an interruption, so that every ``finally`` and
    context manager cleans up as for Ctrl-C (the earlier outputs kept, temporary files removed)."""


def _terminate_as_interrupt() -> None:
    """Make SIGTERM raise :class:`Terminated` in the main thread (the default would end the process
    at once, leaving temporary files)."""

    def handler(signum: int, frame: object) -> None:
        raise Terminated()

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, handler)


#: C-extension modules every command may use, imported before it runs (:func:`_import_heavy_modules`).
HEAVY_MODULES = (
    "vtkmodules.util.numpy_support",
    "vtkmodules.vtkCommonCore",
    "vtkmodules.vtkCommonDataModel",
    "vtkmodules.vtkFiltersCore",
    "vtkmodules.vtkFiltersGeneral",
    "vtkmodules.vtkIOGeometry",
    "vtkmodules.vtkIOLegacy",
    "vtkmodules.vtkIOPLY",
    "vtkmodules.vtkIOXML",
    "scipy.interpolate",
    "scipy.ndimage",
    "scipy.sparse.csgraph",
    "scipy.spatial",
    "vcs.vessel",
)


def _import_heavy_modules(extra: Sequence[str] = ()) -> None:
    """Import the C-extension modules the commands use (VTK's readers, writers and filters, scipy's:
    :data:`HEAVY_MODULES`) and those only one command needs (``extra``: a command's
    ``heavy_modules`` default: trimesh for `vcs wall`, pyvista for `vcs grid`), so that none is
    imported while a command runs. trimesh (with networkx and PIL, ~0.3 s) and pyvista (~0.2 s,
    ~35 MB) are only imported by the commands that use them."""
    import importlib

    for name in (*HEAVY_MODULES, *extra):
        importlib.import_module(name)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the `vcs` command line.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit code (:data:`EXIT_OK` ...): 0 success; 2 bad input, the user can fix it (one line
        ``vcs <command>: error: ...`` on stderr; also an input or output the system refuses:
        permissions, a full disk); 3 out of memory (one line; the input is not wrong, it is too
        big for this machine: coarsen the mesh or the grid, or use more memory); 1 internal
        error, a bug (one line; with ``-v`` the exception propagates with its traceback); 130
        interrupted (Ctrl-C; temporary files removed, earlier outputs kept); 143 terminated (SIGTERM, as
        Ctrl-C). Invalid arguments (one line) and
        ``--help`` leave through argparse's ``SystemExit`` (codes 2 and 0).
    """
    args = parse_args(argv)
    _terminate_as_interrupt()
    with signals_held():  # a Ctrl-C inside a C extension's import crashes Python (SIGSEGV) or
        _import_heavy_modules(getattr(args, "heavy_modules", ()))  # leaves a half-imported module: import first
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    prefix = f"vcs {args.command}"
    with warnings.catch_warnings():
        if not args.verbose:  # numerical warnings are for developers; users get fit_report warnings
            warnings.simplefilter("ignore")
        try:
            args.func(args)
        except VCSInputError as exc:
            print(one_line(f"{prefix}: error: {exc}"), file=sys.stderr)
            return EXIT_INPUT
        except MemoryError:
            print(
                f"{prefix}: out of memory: the input or the requested grid is too large for this machine; "
                "coarsen the mesh or the grid, or run it with more memory (exit code 3)",
                file=sys.stderr,
            )
            return EXIT_MEMORY
        except OSError as exc:  # the system refused a file: permissions, a full disk, a vanished directory
            where = f" '{exc.filename}'" if exc.filename else ""
            print(one_line(f"{prefix}: error: cannot access{where}: {exc.strerror or exc}"), file=sys.stderr)
            return EXIT_INPUT
        except KeyboardInterrupt as exc:
            what = "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted"
            if getattr(exc, "after_outputs_complete", False):
                print(f"{prefix}: {what} just after its outputs were complete; they are in place", file=sys.stderr)
            else:
                print(f"{prefix}: {what}; no partial output left behind, earlier outputs kept", file=sys.stderr)
            code = EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
            if argv is None:  # the program itself: everything is cleaned up and said; skip the
                # interpreter's teardown, where VTK objects left mid-way have crashed it (SIGSEGV)
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code)
            return code
        except Exception as exc:  # a bug, not bad input: one line, the traceback only with -v
            if args.verbose:
                raise
            print(
                one_line(f"{prefix}: internal error: {type(exc).__name__}: {exc} (rerun with -v and report it)"),
                file=sys.stderr,
            )
            return EXIT_INTERNAL
    return EXIT_OK
