"""Subcommands built on the wall model: `vcs wall`, `vcs grid`, `vcs sensitivity`."""
from __future__ import annotations


def add_commands(sub) -> None:
    """Register the wall-model subcommands on an argparse subparsers object."""
