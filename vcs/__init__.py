"""Vessel Coordinate System (Romero et al., Applied Mathematics and Computation, 2024)."""
from vcs.errors import VCSInputError

__all__ = ["VCSInputError"]
