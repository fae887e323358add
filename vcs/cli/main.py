"""Command line: `vcs fit|ends|coords|cartesian|wall|grid|phantom|sensitivity`.

Bad input ends with one line on stderr naming the problem and the fix, and exit code 2.
"""

from __future__ import annotations

import argparse
import logging
import sys
import warnings
from collections.abc import Sequence

from vcs.cli._args import join_point_values
from vcs.cli.ends import add_commands as add_ends_commands
from vcs.cli.fit import add_commands as add_fit_commands
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
    add_sensitivity_commands,
)


def build_parser() -> argparse.ArgumentParser:
    """The `vcs` argument parser with every subcommand.

    Returns
    -------
    argparse.ArgumentParser
        ``prog="vcs"``; each subcommand sets ``func`` (its ``cmd_*`` function) and ``command``.
    """
    p = argparse.ArgumentParser(prog="vcs", description=__doc__.splitlines()[0])
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    sub = p.add_subparsers(dest="command", required=True)
    for add_commands in _COMMAND_GROUPS:
        add_commands(sub)
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
    """
    parser = build_parser()
    return parser.parse_args(join_point_values(sys.argv[1:] if argv is None else list(argv)))


def main(argv: Sequence[str] | None = None) -> int:
    """Run the `vcs` command line.

    Parameters
    ----------
    argv : sequence of str, optional
        Arguments without the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit code: 0 success, 2 bad input (one line ``vcs <command>: error: ...`` on stderr),
        1 internal error (one line; with ``-v`` the exception propagates instead). Invalid
        arguments and ``--help`` leave through argparse's ``SystemExit`` (codes 2 and 0).
    """
    args = parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    if not args.verbose:  # numerical warnings are for developers; users get fit_report warnings
        warnings.simplefilter("ignore")
    try:
        args.func(args)
    except VCSInputError as exc:
        print(f"vcs {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"vcs {args.command}: error: out of memory; coarsen the input mesh or the grid", file=sys.stderr)
        return 2
    except Exception as exc:  # a bug, not bad input: one line, the traceback only with -v
        if args.verbose:
            raise
        print(
            f"vcs {args.command}: internal error: {type(exc).__name__}: {exc} (rerun with -v and report it)",
            file=sys.stderr,
        )
        return 1
    return 0
