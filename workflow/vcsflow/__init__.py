"""vcsflow: workflow helpers for the VCS haemodynamic atlas (OpenFOAM case generation and runs)."""
from .openfoam import DEFAULTS, FLAVOURS, detect_openfoam, render_case, run_case  # noqa: F401

__all__ = ["DEFAULTS", "FLAVOURS", "detect_openfoam", "render_case", "run_case"]
