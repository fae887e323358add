"""Everything OpenFOAM (paper Section 2.4): render a case from the Eq. 8 wall STL, run it, read it,
and resample a finished case onto the vessel's (tau, theta, rho_n) grid.

Public API::

    from vcs.cfd import DEFAULTS, detect_openfoam, render_case, run_case, sample_case, write_fields

    state = render_case("case", "wall.stl", {"inlet": {"type": "parabolic", "flow_rate": 3e-5}})
    status = run_case("case", ranks=2)            # also written to case/status.json
    fields = sample_case("case", model)           # U, p, WSS on the measurement grid
    write_fields(fields, "fields.npz")

    # a cardiac cycle: the waveform CSV (time_s,flow_rate_l_min), whole cycles until periodic
    render_case("pcase", "wall.stl", {"inlet": {"waveform": "vcs/data/waveforms/ascending_aorta.csv"}})
    status = run_case("pcase")                    # status["pulsatile"]: cycles, changes, phases
    fields = sample_pulsatile("pcase", model, status["pulsatile"])   # + TAWSS, OSI, RRT, ECAP, phases

Modules: :mod:`vcs.cfd.openfoam` (defaults, flavour table, detection, templates),
:mod:`vcs.cfd.sizing` (cell size from the vessel, bounded background box, per-patient inflow),
:mod:`vcs.cfd.case` (rendering, inlet profile), :mod:`vcs.cfd.run` (run_case: the stages of a
run, composed), :mod:`vcs.cfd.utilities` (running OpenFOAM utilities: process groups, signals,
timeouts, failure reasons), :mod:`vcs.cfd.meshing` (meshing, checkMesh, patch check),
:mod:`vcs.cfd.steady` (SIMPLE, the plateau check), :mod:`vcs.cfd.transient` (the transient
solve, its time averages and their error bars), :mod:`vcs.cfd.pulsatile` (cardiac cycles until
periodic, the inlet's boundary data), :mod:`vcs.cfd.waveform` (the inflow waveform CSV),
:mod:`vcs.cfd.womersley` (the analytic Womersley flow; the inlet profile mapped to the inlet's
shape), :mod:`vcs.cfd.markers` (TAWSS, OSI, RRT, ECAP), :mod:`vcs.cfd.outlets` (Murray's law and the
three-element Windkessel: not yet wired into cases), :mod:`vcs.cfd.timeseries` (the error bar of a time
average), :mod:`vcs.cfd.status` (collecting ``status.json``),
:mod:`vcs.cfd.foamfiles` (polyMesh, logs, postProcessing readers), :mod:`vcs.cfd.resample`
(reading a finished case with pyvista and sampling it on :mod:`vcs.grid`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from vcs._lazy import lazy_exports

#: where each public name lives: imported on first use (PEP 562), so that the case job does not
#: import the solver's modules, nor the solve job pyvista's reader
_EXPORTS = {
    "render_case": "vcs.cfd.case",
    "DEFAULTS": "vcs.cfd.openfoam",
    "FLAVOURS": "vcs.cfd.openfoam",
    "detect_openfoam": "vcs.cfd.openfoam",
    "load_fields": "vcs.cfd.resample",
    "read_case": "vcs.cfd.resample",
    "sample_case": "vcs.cfd.resample",
    "sample_pulsatile": "vcs.cfd.resample",
    "write_fields": "vcs.cfd.resample",
    "run_case": "vcs.cfd.run",
}

if TYPE_CHECKING:  # the same names, for type checkers and editors
    from vcs.cfd.case import render_case
    from vcs.cfd.openfoam import DEFAULTS, FLAVOURS, detect_openfoam
    from vcs.cfd.resample import load_fields, read_case, sample_case, sample_pulsatile, write_fields
    from vcs.cfd.run import run_case


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

__all__ = [
    "DEFAULTS",
    "FLAVOURS",
    "detect_openfoam",
    "load_fields",
    "read_case",
    "render_case",
    "run_case",
    "sample_case",
    "sample_pulsatile",
    "write_fields",
]
