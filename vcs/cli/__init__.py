"""Command line `vcs` (console script ``vcs = "vcs.cli:main"``; also ``python -m vcs.cli``).

One module per command group (:mod:`vcs.cli.fit`, :mod:`vcs.cli.ends`, :mod:`vcs.cli.points`, :mod:`vcs.cli.wall`,
:mod:`vcs.cli.phantom`, :mod:`vcs.cli.sensitivity`), their shared argument helpers in
:mod:`vcs.cli._args`, the parser and :func:`main` in :mod:`vcs.cli.main`. Command modules never
import this package or :mod:`vcs.cli.main`.
"""

from vcs.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
