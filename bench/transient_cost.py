#!/usr/bin/env python3
"""The transient solve's cost and answers under several PIMPLE settings, from one SIMPLE state.

    .venv/bin/python bench/transient_cost.py CASE -d DIR [--variant NAME:key=value,...]...
    .venv/bin/python bench/transient_cost.py --jet-tube -d DIR [--variant ...]... [--json PATH]
    .venv/bin/python bench/transient_cost.py --at 1 1.5 2.3 -d DIR --variant default:  # re-judge

``--at F...`` re-reads a variant's records (finished or stopped) and prints its window's
relative 95 % half-widths (dp / mean TAWSS / U) and means after F flow-through times of
averaging, with the pimpleFoam time steps and CPU seconds up to then (the README's patient1
figures at 1, 1.5 and 2.3 flow-throughs).

CASE is a rendered case (``results/patients/<id>/case`` of a workflow run, or any
:func:`vcs.cfd.render_case` output). The case is copied to DIR/simple and solved there with
``fallback: none`` (meshing and SIMPLE, once: a finished DIR/simple is reused); then every variant
copies that SIMPLE state to DIR/<NAME> and runs :func:`vcs.cfd.transient.transient_fallback` with
its ``cfd.solver.transient`` keys changed (e.g. ``co1:max_co_end_cells=1`` holds every cell at
Co 1, the pre-issue-23 time step). Default variants: ``co1`` (Co <= 1 on every cell, PISO),
``default`` (the configuration's), ``outer2`` (the end-plane factor with 2 outer correctors).

``--jet-tube`` renders a cheap unsteady case instead: the paper's jet (1.2 m/s through a 0.2 cm2
disc, Re_jet ~1,800 at nu 3.37e-6) into a 12 mm tube 36 mm long at 1.5 mm cells (jet cylinder
one level finer), ~5k cells, so that long windows (the pre-issue-23 wash-out 1 + window 5
flow-through times at Co <= 1 everywhere: variant ``long``) cost minutes, not hours.

Prints, per variant: pimpleFoam CPU s (its logs' ExecutionTime), time steps, dt range, the
window in flow-through times, and each mean with its 95 % half-width (inlet-outlet pressure
difference, area-mean TAWSS) and the relative U half-width; then the machine and its load.
Variants run one after the other (one core each); a finished variant's DIR is re-read.
``--json PATH`` also writes the table without its "known" column in the docs' format
(docs/data/bench/transient_cost_jet_tube.json for ``--jet-tube``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
from datetime import date
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "bench"))

from jet_atlas import solver_cpu_s  # noqa: E402

from vcs.cfd.case import CASE_JSON, inlet_profile  # noqa: E402
from vcs.cfd.run import _read_state, run_case  # noqa: E402
from vcs.cfd.transient import transient_fallback  # noqa: E402
from vcs.cfd.utilities import _Runner  # noqa: E402

DEFAULT_VARIANTS = ["co1:max_co_end_cells=1,outer_correctors=1", "default:", "outer2:outer_correctors=2"]
JET_TUBE_VARIANTS = [
    # the pre-issue-23 solve: a fixed wash-out of 1 and window of 5 flow-through times, Co <= 1 on every cell
    "long:max_co_end_cells=1,washout_flow_throughs=1,min_washout_flow_throughs=1,min_flow_throughs=5,"
    "max_flow_throughs=5",
    "co1:max_co_end_cells=1",
    "default:",
    "outer2:outer_correctors=2",
]


def jet_tube(work: Path) -> Path:
    """The unsteady jet tube of ``--jet-tube``, rendered with config/config.yaml's cfd (SIMPLE
    stopped after 100 iterations: the jet is unsteady)."""
    import numpy as np
    import yaml

    from vcs.cfd import render_case
    from vcs.cfd.openfoam import deep_merge
    from vcs.phantoms.analytic import write_closed_tube_stl

    case = work / "jet_tube_case"
    if (case / CASE_JSON).exists():
        return case
    work.mkdir(parents=True, exist_ok=True)
    stl = write_closed_tube_stl(work / "jet_tube.stl", radius=0.006, length=0.036, n_theta=64, n_z=24,
                                axis=np.array([0.3, 0.2, 1.0]))  # fmt: skip
    cfg = yaml.safe_load((REPO / "config" / "config.yaml").read_text())["cfd"]
    cfg.pop("flavour", None)
    cfg = deep_merge(
        cfg,
        {
            "mesh": {"cell_size": 1.5e-3, "jet_refinement": {"cells_across": 6, "radius": 1.5, "length": 3.0}},
            "inlet": {"type": "jet", "velocity": 1.2, "valve_area": 2.0e-5, "flow_rate": None, "scaling": "fixed"},
            "solver": {"max_iterations": 100, "startup_iterations": 20, "plateau": {"iterations": 0}},
        },
    )
    render_case(case, stl, cfg)
    return case


def _value(v: str) -> float | int:
    return int(v) if v.isdigit() else float(v)


def parse_variant(text: str) -> tuple[str, dict[str, float | int]]:
    """``name:key=value,...`` -> (name, {key: value})."""
    name, _, rest = text.partition(":")
    keys = dict(kv.split("=", 1) for kv in rest.split(",") if kv)
    return name, {k: _value(v) for k, v in keys.items()}


def simple_state(case: Path, work: Path) -> tuple[Path, dict]:
    """The case meshed and solved by SIMPLE only (fallback none), in work/simple (reused)."""
    dst = work / "simple"
    if not (dst / "status.json").exists():
        shutil.rmtree(dst, ignore_errors=True)
        shutil.copytree(case, dst, ignore=shutil.ignore_patterns("processor*", "postProcessing"))
        st = json.loads((dst / CASE_JSON).read_text())
        st["cfd"]["solver"]["fallback"] = "none"
        (dst / CASE_JSON).write_text(json.dumps(st))
        run_case(dst, ranks=1)
    return dst, json.loads((dst / "status.json").read_text())


def run_variant(simple: Path, status: dict, work: Path, name: str, keys: dict) -> dict:
    """The transient solve of one variant from the SIMPLE state (re-read when finished)."""
    dst = work / name
    out = dst / "transient_status.json"
    if out.exists():
        return json.loads(out.read_text())
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(simple, dst)
    state = _read_state(dst, 1)
    state["cfd"]["solver"]["fallback"] = "transient"
    state["cfd"]["solver"]["transient"].update(keys)
    st = {**status, "timings_s": {}}
    prof = inlet_profile(dst, state)
    transient_fallback(dst, state, st, _Runner(dst, st["timings_s"], None), 1, prof)
    st["pimple_cpu_s"] = solver_cpu_s(dst) - solver_cpu_s(simple)
    out.write_text(json.dumps(st, indent=1, default=float))
    return st


#: the docs JSON's columns: the printed table's but its last ("known")
JSON_COLUMNS = [
    "variant",
    "maxCo / outer correctors",
    "pimpleFoam CPU s",
    "time steps",
    "dt ms",
    "wash-out + window (flow-throughs)",
    "dp Pa (95 %)",
    "mean TAWSS Pa (95 %)",
    "U +-%",
]
#: the printed table's columns
COLUMNS = [*JSON_COLUMNS[:5], "wash-out + window FT", *JSON_COLUMNS[6:], "known"]


def cells(name: str, st: dict) -> list[str]:
    """One variant's cells as printed: :data:`JSON_COLUMNS`, then "known" (a failed variant: two)."""
    tr = st.get("transient") or {}
    if not tr.get("evaluated"):
        return [name, f"failed: {st.get('reason')}"]
    s = tr["statistics"]
    dp, w = s["inlet_minus_outlet_pressure"], s["tawss_mean"]
    c = tr["courant"]
    return [
        name,
        f"{c['pimple_max_co']:.3g} / {c['outer_correctors']}",
        f"{st['pimple_cpu_s']:.0f}",
        f"{sum(tr['time_steps'].values()):,}",
        f"{1e3 * tr['delta_t_s']['min']:.3g}-{1e3 * tr['delta_t_s']['max']:.3g}",
        f"{tr['washout_flow_throughs']:.2g} + {tr['window_flow_throughs']:.3g}",
        f"{dp['mean_Pa']:.4g} +- {dp['half_width_Pa']:.2g}",
        f"{w['mean_Pa']:.4g} +- {w['half_width_Pa']:.2g}",
        f"{100 * tr['relative_errors'].get('U', float('nan')):.2g}",
        "yes" if tr["stationary"] else "no",
    ]


def judge_at(dst: Path, fts: list[float]) -> None:
    """Print the window statistics of the variant in ``dst`` after each of ``fts`` flow-through times."""
    from vcs.cfd.foamfiles import function_series, parse_solver_log
    from vcs.cfd.transient import window_statistics

    state = _read_state(dst, 1)
    if (dst / "transient_status.json").exists():
        tr = json.loads((dst / "transient_status.json").read_text())["transient"]
        t0, t_ft = tr["averaging_start_time"], tr["flow_through_time_s"]
    else:  # a variant stopped before its end: the averaging stage's start folder, the SIMPLE status
        t0 = max(float(d.name) for d in (dst / "postProcessing" / "probes").iterdir())
        t_ft = json.loads((dst / "status.json").read_text())["lumen_volume_m3"] / float(state["flow_rate"])
    peak = float(inlet_profile(dst, state)["peak_velocity"])
    last = float(function_series(dst, "pressure_inlet")[-1, 0])
    for ft in fts:
        end = t0 + ft * t_ft
        if end > last:
            print(f"{dst.name}: {ft:g} flow-throughs not reached (record ends at {(last - t0) / t_ft:.3g})")
            continue
        st = window_statistics(dst, state, t0, end, peak)
        steps, cpu = 0, 0.0
        for log in ("log.pimpleFoam.washout", "log.pimpleFoam.average"):
            rows = [r for r in parse_solver_log(dst / "logs" / log)["rows"] if r["time"] <= end + 1e-12]
            steps += len(rows)
            with open(dst / "logs" / log) as fh:  # ExecutionTime of the last step at or before `end`
                t, cpu_log = None, 0.0
                for line in fh:
                    if line.startswith("Time = "):
                        t = float(line.split()[2].rstrip("s"))
                    elif line.startswith("ExecutionTime") and t is not None and t <= end + 1e-12:
                        cpu_log = float(line.split()[2])
                cpu += cpu_log
        rel, s = st["relative_errors"], st["statistics"]
        print(
            f"{dst.name} after {ft:g} flow-throughs: dp {s['inlet_minus_outlet_pressure']['mean_Pa']:.5g} Pa, "
            + ", ".join(f"{k} +-{100 * v:.2g} %" for k, v in rel.items())
            + f"; {steps:,} time steps, {cpu:.0f} CPU s of pimpleFoam"
        )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument("case", type=Path, nargs="?", help="a rendered case")
    ap.add_argument("--jet-tube", action="store_true", help="the cheap unsteady jet tube instead of CASE")
    ap.add_argument("--at", type=float, nargs="+", help="re-judge each --variant's window at these flow-throughs")
    ap.add_argument("-d", "--workdir", type=Path, required=True, help="where the copies are solved")
    ap.add_argument("--variant", action="append", help="NAME:key=value,... (cfd.solver.transient keys)")
    ap.add_argument("--json", type=Path, metavar="PATH", help="also write the table as docs JSON")
    a = ap.parse_args(argv)
    if a.json and a.at:
        ap.error("--json writes the variants' table, which --at does not print")
    if a.at:
        for text in a.variant or ["default:"]:
            judge_at(a.workdir.resolve() / parse_variant(text)[0], a.at)
        return 0
    a.workdir.mkdir(parents=True, exist_ok=True)
    if a.jet_tube:
        a.case = jet_tube(a.workdir.resolve())
    if a.case is None or not (a.case / CASE_JSON).exists():
        print(f"transient_cost: error: {a.case} is not a rendered case (no {CASE_JSON})", file=sys.stderr)
        return 2
    simple, status = simple_state(a.case.resolve(), a.workdir.resolve())
    print(
        f"SIMPLE state: {status['cells']:,} cells, {status['iterations']} iterations, converged "
        f"{status['converged']} ({status.get('reason')})"
    )
    from _table import emit

    emit(
        COLUMNS,
        (
            cells(name, run_variant(simple, status, a.workdir.resolve(), name, keys))
            for name, keys in map(parse_variant, a.variant or (JET_TUBE_VARIANTS if a.jet_tube else DEFAULT_VARIANTS))
        ),
        a.json,
        f"one run from one SIMPLE state ({status['cells']:,} cells), variants one after the other",
        json_columns=JSON_COLUMNS,
        json_row=lambda c: (c + ["-"] * len(JSON_COLUMNS))[: len(JSON_COLUMNS)],
    )
    print(f"{date.today()}, {platform.node()} ({os.cpu_count()} cores), load {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
