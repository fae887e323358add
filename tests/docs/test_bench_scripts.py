"""The bench scripts print their table and, with ``--json PATH``, write the docs' table
(bench/_table.py ``emit`` / ``save``): checked on small synthetic results, without OpenFOAM."""

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))  # the bench scripts and their shared table writer: _table


import _table


def test_emit_prints_the_table_and_writes_the_docs_columns(tmp_path, capsys):
    made = []

    def rows():  # each row printed before the next is made
        for i in range(2):
            made.append(i)
            yield [f"p{i}", str(i), "yes"]
            assert capsys.readouterr().out.endswith(f"| p{i} | {i} | yes |\n")

    out = _table.emit(
        ["id", "n", "ok"],
        rows(),
        tmp_path / "t.json",
        "one run",
        command="bench/x.py --json t.json",
        json_columns=["id", "n"],
        json_row=lambda c: c[:-1],
    )
    assert out == [["p0", "0", "yes"], ["p1", "1", "yes"]] and made == [0, 1]
    data = json.loads((tmp_path / "t.json").read_text())
    assert data["columns"] == ["id", "n"] and data["rows"] == [["p0", "0"], ["p1", "1"]]
    assert data["command"] == "bench/x.py --json t.json" and data["measured"].endswith("; one run")


def test_emit_without_a_path_only_prints(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _table.emit(["a", "b"], [["1", "2"]])
    assert capsys.readouterr().out == "| a | b |\n|---|---|\n| 1 | 2 |\n"
    assert _table.save(None, columns=["a"], rows=[["1"]], measured="m") is None
    assert list(tmp_path.iterdir()) == []


def test_save_names_this_process_command_by_default(tmp_path):
    path = _table.save(tmp_path / "t.json", columns=["a"], rows=[["1"]], measured="m")
    assert json.loads(path.read_text())["command"] == _table.command_line()


def docs_table(name: str) -> dict:
    return json.loads((ROOT / "docs" / "data" / "bench" / f"{name}.json").read_text())


def test_curved_pipe_writes_the_docs_row_of_its_figures():
    import curved_pipe as cp

    from vcs.cfd.verification import dean_number, ito_friction_ratio, white_friction_ratio

    docs = docs_table("curved_pipe")
    assert cp.JSON_COLUMNS == docs["columns"]
    de = dean_number(cp.RE, cp.A_MM, cp.R_MM)
    ito, white = ito_friction_ratio(de), white_friction_ratio(de)
    g = {  # the CI mesh's figures of the transcribed run
        "background_cell_mm": 1.0,
        "layers": 3,
        "cells": 26948,
        "iterations": 256,
        "solver_time_s": 328.4,
        "friction_ratio": 1.902,
        "volume_ratio": 1 - 0.0108,
        "friction_ratio_mesh_radius": 1.861,
    }
    assert cp.json_cells(g, ito, white) == [
        "1.00 mm (the CI test)",
        "3",
        "26,948",
        "256",
        "328",
        "1.902",
        "-1.0 %",
        "+2.9 %",
        "-1.08 %",
        "1.861",
    ]
    assert cp.json_cells({**g, "layers": 6}, ito, white)[:2] == ["1.00 mm", "6"]
    assert cp.parse_also("6:0.59,0.77") == (6, pytest.approx([0.77e-3, 0.59e-3]))


def test_pulsatile_womersley_writes_the_docs_row_of_its_figures():
    import pulsatile_womersley as pw

    docs = docs_table("pulsatile_womersley")
    assert pw.COLUMNS == docs["columns"]
    r = {  # the T / 800 run of the transcribed table
        "cell_mm": 0.75,
        "min_steps_per_cycle": 800,
        "cells": 14233,
        "steps_per_cycle": 804.3,
        "cpu_s_per_cycle": 107.2,
        "centreline": {"mean_rel": -0.0018, "amplitude_rel": -0.0009, "phase_deg": 0.11},
        "wss": {"mean_rel": 0.0114, "amplitude_rel": -0.0381, "phase_deg": -1.12},
        "tawss_rel": -0.0333,
        "osi": 0.3186,
        "osi_exact": 0.3284,
    }
    assert pw.cells(r) == [
        "0.75, dt / 4",
        "14233",
        "804",
        "107",
        "-0.18 / -0.09 / +0.11",
        "+1.14 / -3.81 / -1.12",
        "-3.33",
        "0.3186 (0.3284)",
    ]
    assert pw.cells({**r, "min_steps_per_cycle": 200})[0] == "0.75"
    assert pw.parse_also("0.75:800") == (0.75, 800)


def test_bench_cohort_writes_the_docs_row_of_a_status():
    import bench_cohort as bc

    docs = docs_table("demo_cohort")
    assert bc.JSON_COLUMNS == docs["columns"]
    st = {  # aorta_0 of the transcribed demo run
        "cells": 60031,
        "iterations": 169,
        "converged": True,
        "mesh": {"sizing": {"cell_size": {"cell_size_m": 2.08e-3}}, "layers": {"coverage": 0.991}},
        "timings_s": {"snappyHexMesh": 14.61, "simpleFoam.startup": 2.1, "simpleFoam": 27.2, "total": 50.0},
    }
    row = ["aorta_0", "2.08", "60,031", "0.99", "14.6", "169", "29.3", "yes", "3.6", "12 %"]
    assert bc.json_cells("aorta_0", st, 3.6) == row
    assert bc.json_cells("x", {"converged": False, "reason": "why"}, None)[-3:] == ["NO: why", "-", "-"]


def test_pulsatile_table_writes_the_docs_row_of_a_patient():
    import pulsatile_table as pt

    docs = docs_table("pulsatile_cost")
    assert pt.COLUMNS == docs["columns"]
    r = {  # aorta_0 of the transcribed run
        "id": "aorta_0",
        "converged": True,
        "cells": 60043,
        "cycles_run": 3,
        "dt_min_s": 0.132e-3,
        "dt_max_s": 4.04e-3,
        "steps_per_cycle": 501.0,
        "cpu_s_per_cycle": 401.3,
        "last_change": {"dp": 0.0011, "flow": 1.4e-7, "tawss": 0.048},
        "TAWSS": [0.49, 1.5],
        "OSI": [0.1, 0.45],
    }
    assert pt.cells(r) == [
        "aorta_0",
        "60043",
        "0.132-4.04",
        "501",
        "401",
        "3",
        "0.11 / 1.4e-05 / 4.8",
        "0.49-1.5",
        "0.1-0.45",
    ]
    assert pt.cells({**r, "converged": False})[5] == "3 (not periodic)"


def test_surface_vs_model_writes_the_docs_row_of_a_pair():
    import surface_vs_model as svm

    docs = docs_table("surface_vs_model")
    assert svm.JSON_COLUMNS == docs["columns"]
    bands = [(0.481, 0.480, -0.002), (1.32, 1.13, -0.14), (1.35, 1.07, -0.20), (1.26, 1.00, -0.21)]
    r = {  # VMR 0154 of the transcribed run
        "patient": "vmr0154",
        "cells": {"model": 32893, "surface": 32044},
        "dp_pa": {"model": 84.2, "surface": 56.3},
        "branches": 4,
        "branch_fraction": 0.165,
        "outlet_type": "murray",
        "bands": {b: {"model_pa": m, "surface_pa": s, "change": c} for b, (m, s, c) in zip(svm.BANDS, bands)},
    }
    assert svm.json_cells(r) == [
        "VMR 0154",
        "32,893 / 32,044",
        "murray (4, 16.5 %)",
        "84 / 56",
        "0.48 / 0.48 (-0 %)",
        "1.32 / 1.13 (-14 %)",
        "1.35 / 1.07 (-20 %)",
        "1.26 / 1.00 (-21 %)",
    ]
    assert svm.json_cells({**r, "branches": 0, "branch_fraction": 0.0})[2] == "murray (0, 0 %)"


def test_ci_layers_writes_the_docs_row_of_both_runs():
    import ci_layers

    docs = docs_table("ci_layers")
    assert ci_layers.COLUMNS == docs["columns"]
    off = {"cells": 11855, "iterations": 99, "timings_s": {"total": 62.91}}
    on = {"cells": 21859, "iterations": 105, "mesh": {"layers": {"coverage": 0.99}}, "timings_s": {"total": 33.2}}
    assert ci_layers.cells("demo_aorta_0", off, on) == [
        "demo_aorta_0",
        "11,855",
        "21,859 (0.99)",
        "99 / 105",
        "62.9",
        "33.2",
    ]
    assert ci_layers.cells("x", None, on)[1:4] == ["-", "21,859 (0.99)", "- / 105"]


def test_outlets_rcr_writes_the_docs_rows_of_its_figures():
    import outlets_rcr

    docs = docs_table("outlets_verification")
    assert outlets_rcr.JSON_COLUMNS == docs["columns"]
    ci = {"steady": {"rel": -1.0e-9}, "rcr": {100: {"of_max": 0.0032, "backward_euler": 2.6e-7}}}
    bench = {
        "steady": {"rel": 2.9e-9, "cells": 8520},
        "rcr": {100: {"of_max": 0.0056, "backward_euler": 1.3e-5}, 200: {"of_max": 0.0027, "backward_euler": 4e-6}},
    }
    murray = {"target": 0.7031, "error": 0.0042, "mass_balance": 2.1e-8}
    bif = {  # the vmtk bifurcation's status.json of the transcribed run
        "cells": 52843,
        "converged": True,
        "criterion_used": "residualControl",
        "iterations": 352,
        "inflow": {"flow_rate_l_min": 1.88},
        "timings_s": {"total": 201.2},
        "outlet_mass_balance": {"relative": -3.9e-8},
        "outlets": [
            {"name": "outlet", "fraction": 0.5071512, "target_fraction": 0.5071509},
            {"name": "branch_1", "fraction": 0.4928488, "target_fraction": 0.4928491},
        ],
    }
    rows = outlets_rcr.table_rows(ci, bench, murray, bif)
    assert [r[1] for r in rows[:1] + rows[2:3] + rows[4:]] == [
        "1e-9 (CI), 2.9e-9 (bench, 8,520 cells)",
        "2.6e-7 (CI), 1.3e-5 (bench)",
        "branch 0.492849 vs 0.492849 target, main 0.507151 vs 0.507151; mass balance 3.9e-8; "
        "converged (residualControl, 352 it., 201 s wall)",
    ]
    assert rows[1][1].startswith("0.32 % of the largest pressure (CI); 0.56 % / 0.27 % at 100 / 200 steps per cycle")
    assert rows[3] == [
        "murray, split-end tube (target 0.703), steady and every instant of a pulsatile inflow",
        "within 0.42 %, mass balance 2.1e-8",
    ]
    assert len(outlets_rcr.table_rows(ci, bench, murray)) == 4


def test_mesh_size_writes_the_docs_row_of_a_meshed_case():
    import mesh_size

    docs = docs_table("mesh_size_real")
    assert mesh_size.COLUMNS == docs["columns"]
    h, pad, n = 0.833e-3, 4, (112, 67, 67)  # 502,768 background cells at the lumen cell size
    state = {  # the helix phantom of the transcribed run
        "stl_bounds": [[0.0, 0.0, 0.0], [(k - 2 * pad) * h for k in n]],
        "cfd": {"mesh": {"pad_cells": pad}},
        "inflow": {"flow_rate_l_min": 0.7951},
        "mesh_sizing": {
            "cell_size_m": h,
            "cell_size": {"governed_by": "smallest end"},
            "vessel": {"inlet_diameter_m": 10.0e-3, "outlet_diameter_m": 10.01e-3, "narrowest_diameter_m": 9.996e-3},
            "background": {"level_offset": 1, "background_cells": 80771},
        },
    }
    st = {
        "state": state,
        "cells": 53248,
        "timings_s": {"snappyHexMesh": 16.81},
        "mesh": {"patches": {"wall": {"faces": 7729}, "inlet": {"faces": 601}, "outlet": {"faces": 186}}},
    }
    assert mesh_size.cells("helix_phantom", st, 14.0)[1:] == [
        "10.0 / 10.0",
        "0.833 (end)",
        "80,771 (1; 502,768 without the cap)",
        "53,248",
        "7,729 / 601 / 186",
        "16.8 (14.0)",
        "0.795",
    ]


def test_sig_writes_exponents_as_people_do():
    assert [_table.sig(x) for x in (1e-9, 1.2e-4, 0.0032, 12.4, 0.0009)] == ["1e-9", "1.2e-4", "0.0032", "12", "9e-4"]


def test_paper_jet_writes_a_row_per_stage_of_a_status():
    import paper_jet

    docs = docs_table("paper_jet")
    assert paper_jet.COLUMNS == docs["columns"]
    st = {  # figures of the transcribed run, in today's status.json
        "cells": 64979,
        "iterations": 1000,
        "converged": True,
        "criterion_used": "time_average_stationary",
        "final_residuals": {"p": 0.026, "U": 0.042},
        "lumen_volume_m3": 207.8e-6,
        "inflow": {"flow_rate_m3_s": 1.2e-4},
        "mass_imbalance": 2.2e-9,
        "timings_s": {"snappyHexMesh": 14.7},
        "mesh": {
            "jet_refinement": {"cells_across": 11.3},
            "layers": {"requested": 3, "mean_layers": 2.97, "coverage": 0.99},
        },
        "transient": {
            "flow_through_time_s": 1.73,
            "washout_s": 1.74,
            "washout_flow_throughs": 1.005,
            "window_s": 17.32,
            "window_flow_throughs": 10.01,
            "time_steps": {"washout": 3154, "average": 31317},
            "delta_t_s": {"min": 0.43e-3, "max": 0.63e-3},
            "courant_max": 1.07,
            "confidence": 0.95,
            "relative_errors": {"inlet_minus_outlet_pressure": 0.0075, "tawss_mean": 0.029, "U": 0.087},
            "tolerances": {"inlet_minus_outlet_pressure": 0.05, "tawss_mean": 0.05, "U": 0.1},
        },
        "inlet_minus_outlet_pressure": {"Pa": -133.6},
        "wall_shear_stress_Pa": {"mean": 0.87, "max": 3.05},
        "tawss_Pa": {"mean": 1.15, "max": 3.60},
        "osi": {"mean": 0.14, "max": 0.48},
    }
    rows = dict(paper_jet.rows(st, {"simple": 166.0, "washout": 885.0, "average": 8036.0}))
    assert rows["mesh"] == (
        "64,979 cells (11.3 cells across the jet); 3 prism layers: mean 2.97, coverage 0.99; snappyHexMesh 14.7 s"
    )
    assert rows["SIMPLE"] == "1,000 iterations, 166 s CPU; not converged (last initial residuals p 0.026, U 0.042)"
    assert rows["flow-through time"] == "lumen 207.8 cm3 / 1.2e-4 m3/s = 1.73 s"
    assert rows["wash-out"] == "1.74 s (1 flow-throughs), 3,154 time steps, 885 s CPU"
    assert rows["95 % half-widths of the window means"].startswith("inlet - outlet pressure 0.75 % (tolerance 5 %)")
    assert rows["verdict"] == "`converged: true` (`time_average_stationary`)"
    assert rows["window means"] == (
        "mass imbalance 2.2e-9; inlet - outlet pressure -133.6 Pa; magnitude of the mean WSS 0.87 Pa (max 3.05); "
        "TAWSS 1.15 Pa (max 3.6); OSI mean 0.14 (max 0.48)"
    )
    steady = {"cells": 1000, "iterations": 300, "converged": True, "criterion_used": "residualControl"}
    assert paper_jet.rows(steady, {"simple": 20.0, "washout": 0.0, "average": 0.0})[1] == [
        "SIMPLE",
        "300 iterations, 20 s CPU; `residualControl`",
    ]
