"""Per-outlet RCR tables (vcs.cfd.bc_tables) and the unit-carrying inflow formats (vcs.cfd.waveform)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from vcs.cfd.bc_tables import (
    MMHG,
    OutletRCR,
    PatchEnd,
    check_outlet_bc,
    match_outlet_table,
    outlet_rcrs,
    read_outlet_bc,
    read_outlet_table,
    read_rcrt_dat,
    solid_ends,
)
from vcs.cfd.waveform import load_waveform
from vcs.errors import VCSInputError

AORTACFD = Path(__file__).resolve().parents[3] / "shared" / "data" / "vessels" / "aortacfd_patient1"
needs_aortacfd = pytest.mark.skipif(
    not (AORTACFD / "wall_aorta.stl").is_file(), reason="shared data ../shared/data/vessels/aortacfd_patient1 absent"
)


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


# --------------------------------------------------------------------------- CSV table


def test_units_are_converted_to_si_by_hand(tmp_path):
    rows = read_outlet_table(
        _write(
            tmp_path / "t.csv",
            "# comment\n\nend,R_p,C,R_d,P_d,units\n"
            "a.stl,1000,1e-4,15000,10,cgs\n"
            '"1,2,3",2e8,3e-9,4e8,,SI\n'
            "end:2,1,2,3,5,mmHg\n",
        )
    )
    a, b, c = rows
    # 1000 dyn s/cm^5 = 1000 * 1e-5 N * s / (1e-10 m^5) = 1e8 Pa s/m^3
    assert (a.end, a.r_p, a.r_d) == ("a.stl", pytest.approx(1e8), pytest.approx(1.5e9))
    assert a.c == pytest.approx(1e-9) and a.p_d == pytest.approx(1.0)  # 1e-4 cm^5/dyn, 10 dyn/cm^2
    assert (b.end, b.r_p, b.c, b.r_d, b.p_d) == ("1,2,3", 2e8, 3e-9, 4e8, 0.0)
    # 1 mmHg s/mL = 133.322 Pa / 1e-6 m^3 * s; 2 mL/mmHg = 2e-6 / 133.322 m^3/Pa
    assert c.r_p == pytest.approx(1.33322387415e8) and c.c == pytest.approx(2e-6 / MMHG)
    assert c.r_d == pytest.approx(3 * 1.33322387415e8) and c.p_d == pytest.approx(5 * 133.322387415)
    assert c.to_dict() == {"r_p": c.r_p, "c": c.c, "r_d": c.r_d, "p_d": c.p_d}


def test_column_names_any_case_and_order_without_pd(tmp_path):
    (row,) = read_outlet_table(_write(tmp_path / "t.csv", "Units,END,rd,c,rp\nSI,end:1,3,2,1\n"))
    assert (row.end, row.r_p, row.c, row.r_d, row.p_d) == ("end:1", 1.0, 2.0, 3.0, 0.0)


HEADER = "end,R_p,C,R_d,P_d,units\n"
BAD_TABLES = {
    "empty": ("# only a comment\n", "empty"),
    "missing_column": ("end,R_p,C,units\na,1,1,SI\n", "lacks column(s) R_d"),
    "unknown_column": ("end,R_p,C,R_d,units,Z\na,1,1,1,SI,3\n", "unknown column(s) Z"),
    "bad_number": (HEADER + "a,1,x,1,0,SI\n", "C 'x' is not a number"),
    "nan": (HEADER + "a,1,nan,1,0,SI\n", "finite"),
    "zero_c": (HEADER + "a,1,0,1,0,SI\n", "C 0 m^3/Pa is not positive"),
    "negative_rd": (HEADER + "a,1,1,-1,0,SI\n", "R_d -1 Pa s/m^3 is not positive"),
    "negative_rp": (HEADER + "a,-1,1,1,0,cgs\n", "R_p -1 dyn s/cm^5 is negative"),
    "unknown_units": (HEADER + "a,1,1,1,0,furlong\n", "units 'furlong' is not known; give one of SI"),
    "duplicate": (HEADER + "end:1,1,1,1,0,SI\nEND : 1,1,1,1,0,SI\n", "already has a row"),
    "duplicate_point": (HEADER + '"1,2,3",1,1,1,0,SI\n"1.0, 2, 3",1,1,1,0,SI\n', "already has a row"),
    "unquoted_point": (HEADER + "1,2,3,1,1,1,0,SI\n", "quote an end"),
    "empty_end": (HEADER + ",1,1,1,0,SI\n", "the end is empty"),
    "no_rows": (HEADER, "no rows"),
}


@pytest.mark.parametrize("name", sorted(BAD_TABLES))
def test_bad_table_is_one_line_naming_the_problem(tmp_path, name):
    text, expect = BAD_TABLES[name]
    with pytest.raises(VCSInputError) as e:
        read_outlet_table(_write(tmp_path / "t.csv", text))
    msg = str(e.value)
    assert expect in msg and "\n" not in msg and "t.csv" in msg, msg


def test_units_error_lists_the_unit_systems(tmp_path):
    with pytest.raises(VCSInputError, match=r"SI \(Pa s/m\^3.*cgs \(dyn s/cm\^5.*mmHg \(mmHg s/mL"):
        read_outlet_table(_write(tmp_path / "t.csv", HEADER + "a,1,1,1,0,kPa\n"))


def test_missing_file_is_one_line(tmp_path):
    with pytest.raises(VCSInputError, match="cannot read outlet table"):
        read_outlet_table(tmp_path / "nope.csv")


# --------------------------------------------------------------------------- rcrt.dat

RCRT = """2
2
outlet1
1000
1.0e-4
15000
0.0 0
1.0 0
2
outlet2
500.0
2e-4
8000
0.0 1333.22
1.0 1333.22
"""


def test_rcrt_dat_is_read_and_converted_from_cgs(tmp_path):
    rows = read_outlet_bc(_write(tmp_path / "rcrt.dat", RCRT))
    assert [r.end for r in rows] == ["outlet1", "outlet2"]
    assert rows[0] == OutletRCR("outlet1", 1e8, 1e-9, 1.5e9, 0.0)
    assert rows[1].r_p == pytest.approx(5e7) and rows[1].c == pytest.approx(2e-9)
    assert rows[1].r_d == pytest.approx(8e8) and rows[1].p_d == pytest.approx(133.322)  # 1333.22 dyn/cm^2


BAD_RCRT = {
    "time_varying_pd": (RCRT.replace("1.0 1333.22", "1.0 2000"), "time-varying P_d is not supported"),
    "no_face_name": ("2\n2\n1000\n1e-4\n15000\n0 0\n1 0\n", "has no face name"),
    "truncated": ("2\n2\noutlet1\n1000\n1e-4\n", "the file ends"),
    "bad_count": ("two\n", "is not the largest number"),
    "too_many_points": ("2\n3\noutlet1\n1\n1\n1\n0 0\n1 0\n2 0\n", "more than the 2"),
    "zero_c": (RCRT.replace("1.0e-4", "0"), "C 0 cm^5/dyn is not positive"),
    "duplicate": (RCRT.replace("outlet2", "outlet1"), "already has a block"),
    "no_blocks": ("2\n", "no outlet blocks"),
}


@pytest.mark.parametrize("name", sorted(BAD_RCRT))
def test_bad_rcrt_dat_is_one_line(tmp_path, name):
    text, expect = BAD_RCRT[name]
    with pytest.raises(VCSInputError) as e:
        read_rcrt_dat(_write(tmp_path / "rcrt.dat", text))
    assert expect in str(e.value) and "\n" not in str(e.value), str(e.value)


# --------------------------------------------------------------------------- matching (analytic)


def _ends() -> list[PatchEnd]:
    return [
        PatchEnd("inlet", "inlet", np.array([0.0, 0.0, 0.0]), 10.0),
        PatchEnd("outlet", "outlet", np.array([0.0, 0.0, 100.0]), 8.0),
        PatchEnd("branch_1", "outlet", np.array([30.0, 0.0, 50.0]), 3.0),
    ]


def _row(end: str, k: float = 1.0) -> OutletRCR:
    return OutletRCR(end, k, 1e-9, 1e9, 0.0, f"t.csv line {int(k)}")


def test_points_in_mesh_units_and_cap_files_match_the_nearest_end():
    rows = [_row("0.1,0.2,10.3"), _row("cap.stl", 2)]
    got = match_outlet_table(rows, _ends(), units="cm", cap_centres={"cap.stl": [3.0, 0.1, 5.0]})
    assert got == {"outlet": rows[0], "branch_1": rows[1]}  # (1, 2, 103) mm and (30, 1, 50) mm


def test_end_index_and_label_and_rcrt_stem():
    cands = [([0.0, 0.0, 0.0], None), ([30.0, 0.0, 50.0], "ModelFaceID=3"), ([0.0, 0.0, 100.0], None)]
    rows = [_row("end:2"), _row("ModelFaceID=3", 2)]
    assert match_outlet_table(rows, _ends(), candidates=cands) == {"outlet": rows[0], "branch_1": rows[1]}
    rows = [_row("out"), _row("br", 2)]
    stems = {"out": [0.0, 1.0, 99.0], "br": [31.0, 0.0, 50.0]}
    assert match_outlet_table(rows, _ends(), cap_stems=stems) == {"outlet": rows[0], "branch_1": rows[1]}


MATCH_ERRORS = {
    "no_end": ([_row("0,0,50"), _row("30,0,50", 2)], "is at no end of the lumen; the ends: inlet at"),
    "inlet": ([_row("0,0,1"), _row("0,0,100", 2), _row("30,0,50", 3)], "is the inlet (inlet)"),
    "same_end": ([_row("0,0,100"), _row("1,0,99", 2), _row("30,0,50", 3)], "is the same end (outlet)"),
    "missing": ([_row("0,0,100")], "no row for outlet end(s) branch_1"),
    "index_out_of_range": ([_row("end:7")], "end:0 to end:2"),
    "unknown_label": ([_row("CapID=9")], "no cap labelled CapID=9"),
    "unresolvable": ([_row("nowhere.stl")], "not end:N, NAME=VALUE, a point x,y,z or a cap file"),
}


@pytest.mark.parametrize("name", sorted(MATCH_ERRORS))
def test_matching_errors_are_one_line(name):
    rows, expect = MATCH_ERRORS[name]
    cands = [([0.0, 0.0, 0.0], None), ([30.0, 0.0, 50.0], "ModelFaceID=3"), ([0.0, 0.0, 100.0], None)]
    with pytest.raises(VCSInputError) as e:
        match_outlet_table(rows, _ends(), candidates=cands)
    assert expect in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_end_index_without_the_surface_is_one_line():
    with pytest.raises(VCSInputError, match="give the mesh"):
        match_outlet_table([_row("end:1")], _ends())


def test_solid_ends_centroid_and_radius_of_a_square_patch():
    sq = np.array([[[0, 0, 0], [2, 0, 0], [2, 2, 0]], [[0, 0, 0], [2, 2, 0], [0, 2, 0]]], float) * 1e-3  # m
    (inlet, out) = solid_ends({"wall": sq, "inlet": sq, "outlet_a": sq + [0, 0, 0.01]})
    assert (inlet.name, inlet.role, out.name, out.role) == ("inlet", "inlet", "outlet_a", "outlet")
    assert np.allclose(out.center_mm, [1, 1, 10]) and math.isclose(out.radius_mm, math.sqrt(4 / math.pi))


# --------------------------------------------------------------------------- the real aorta


def _aortacfd_table(path: Path, names: list[str], first: str = "") -> Path:
    lines = [f"{AORTACFD / n},{1000 * (i + 1)},1e-4,15000,0,cgs" for i, n in enumerate(names)]
    return _write(path, "end,R_p,C,R_d,P_d,units\n" + first + "\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def aortacfd_lumen():
    """AortaCFD patient1's lumen as the case reads it: solids by patch name, m."""
    from vcs.cfd.bc_tables import cap_centroid
    from vcs.io import read_surface
    from vcs.lumen import build_lumen, read_lumen_surface

    caps = [read_surface(AORTACFD / f"{n}.stl", "mm", check_extent=False) for n in ("inlet", "outlet4")]
    c_in, c_out = (cap_centroid(c.vertices, c.faces) for c in caps)
    lumen = build_lumen(read_lumen_surface(AORTACFD / "wall_aorta.stl", "mm", c_in, c_out), c_in, c_out)
    return {k: t * 1e-3 for k, t in lumen.solids.items()}


@needs_aortacfd
def test_cap_files_map_to_the_four_outlet_patches(tmp_path, aortacfd_lumen):
    table = _aortacfd_table(tmp_path / "t.csv", ["outlet1.stl", "outlet2.stl", "outlet3.stl", "outlet4.stl"])
    got = outlet_rcrs(table, aortacfd_lumen, units="mm")
    assert set(got) == {"outlet", "branch_1", "branch_2", "branch_3"}
    assert got["outlet"]["r_p"] == pytest.approx(4e8)  # outlet4.stl: the section's outlet (tau = 1)
    assert sorted(v["r_p"] for k, v in got.items() if k != "outlet") == pytest.approx([1e8, 2e8, 3e8])


@needs_aortacfd
def test_end_index_points_and_rcrt_stems_on_the_real_aorta(tmp_path, aortacfd_lumen):
    from vcs.cfd.bc_tables import surface_ends

    mesh = AORTACFD / "wall_aorta.stl"
    cands, ends, units = surface_ends(mesh, "mm")
    assert units == "mm" and len(ends) == 5  # end:0 (the largest) is the inlet
    point = ",".join(f"{x:.2f}" for x in cands[1][0])  # end:1 as a point, mm
    table = _write(
        tmp_path / "t.csv", f'end,R_p,C,R_d,units\n"{point}",1,1,1,SI\nend:2,2,1,1,SI\nend:3,3,1,1,SI\nend:4,4,1,1,SI\n'
    )
    got = outlet_rcrs(table, aortacfd_lumen, units="mm", mesh=mesh)
    assert set(got) == {"outlet", "branch_1", "branch_2", "branch_3"}
    assert sorted(v["r_p"] for v in got.values()) == [1.0, 2.0, 3.0, 4.0]
    # rcrt.dat face names are the stems of the cap files beside the mesh (outlet1.stl ...)
    dat = "2\n" + "".join(f"2\noutlet{k}\n{1000 * k}\n1e-4\n1\n0 0\n1 0\n" for k in (4, 1, 2, 3))
    got = outlet_rcrs(_write(tmp_path / "rcrt.dat", dat), aortacfd_lumen, units="mm", mesh=mesh)
    assert got["outlet"]["r_p"] == pytest.approx(4e8) and len(got) == 4


@needs_aortacfd
def test_real_aorta_errors_name_the_row_and_the_ends(tmp_path, aortacfd_lumen):
    table = _aortacfd_table(tmp_path / "t.csv", ["outlet1.stl", "outlet2.stl", "outlet3.stl", "inlet.stl"])
    with pytest.raises(VCSInputError, match=r"line 5: end '.*inlet.stl' is the inlet \(inlet\)"):
        outlet_rcrs(table, aortacfd_lumen, units="mm")
    table = _aortacfd_table(tmp_path / "t.csv", ["outlet1.stl", "outlet2.stl", "outlet3.stl"])
    with pytest.raises(VCSInputError, match=r"no row for outlet end\(s\) outlet;.*branch_3 at"):
        outlet_rcrs(table, aortacfd_lumen, units="mm")
    table = _aortacfd_table(tmp_path / "t.csv", ["outlet1.stl", "outlet1.stl"])
    with pytest.raises(VCSInputError, match="already has a row"):
        outlet_rcrs(table, aortacfd_lumen, units="mm")


@needs_aortacfd
def test_planning_check_finds_the_inlet_from_the_sheet(tmp_path):
    mesh, inlet = AORTACFD / "wall_aorta.stl", str(AORTACFD / "inlet.stl")
    table = _aortacfd_table(tmp_path / "t.csv", ["outlet1.stl", "outlet2.stl", "outlet3.stl", "outlet4.stl"])
    assert len(check_outlet_bc(table, mesh, units="mm", inlet=inlet, complete=True)) == 4
    table = _aortacfd_table(tmp_path / "t.csv", ["outlet1.stl", "inlet.stl"])
    with pytest.raises(VCSInputError, match=r"is the inlet \(end:0\)"):
        check_outlet_bc(table, mesh, units="mm", inlet=inlet)
    table = _aortacfd_table(tmp_path / "t.csv", ["outlet1.stl"])
    with pytest.raises(VCSInputError, match=r"no row for outlet end\(s\) end:1, end:3, end:4"):
        check_outlet_bc(table, mesh, units="mm", inlet=inlet, complete=True)


# --------------------------------------------------------------------------- inflow formats


def _cycle(n: int = 41) -> tuple[np.ndarray, np.ndarray]:
    t = np.linspace(0.0, 0.8, n)
    return t, 50.0 + 30.0 * np.sin(2 * np.pi * t / 0.8)  # mL/s, closed


def test_simvascular_flow_file_sign_flipped_and_ml_s(tmp_path):
    t, q = _cycle()
    path = _write(tmp_path / "inflow.flow", "".join(f"{a:.6f}   {-b:.10f}\n" for a, b in zip(t, q)))
    w = load_waveform(path)
    assert w.mean_m3_s == pytest.approx(50e-6, rel=1e-6) and w.peak_m3_s == pytest.approx(80e-6, rel=1e-4)
    assert w.period_s == pytest.approx(0.8)
    positive = _write(tmp_path / "out.flow", "".join(f"{a:.6f} {b:.10f}\n" for a, b in zip(t, q)))
    with pytest.raises(VCSInputError, match="negate the flows"):
        load_waveform(positive)
    with pytest.raises(VCSInputError, match="line 2: 3 values"):
        load_waveform(_write(tmp_path / "bad.flow", "0 -1\n0.1 -1 3\n"))


@pytest.mark.parametrize(
    "header, t_scale, q_scale",
    [
        ("time_s,flow_rate_l_min", 1.0, 0.06),  # 50 mL/s = 3 L/min
        ("time_ms,flow_ml_s", 1000.0, 1.0),
        ("time_s,flow_rate_ml_s", 1.0, 1.0),
        ("time_s,flow_m3_s", 1.0, 1e-6),
        ("time_ms,flow_rate_m3_s", 1000.0, 1e-6),
        ("Time [ms],Q (mL/s)", 1000.0, 1.0),
        ("t (s),flow [L/min]", 1.0, 0.06),
        ("time [s],flow rate [m3/s]", 1.0, 1e-6),
    ],
)
def test_csv_headers_carry_the_units(tmp_path, header, t_scale, q_scale):
    t, q = _cycle()
    rows = "".join(f"{a * t_scale!r},{b * q_scale!r}\n" for a, b in zip(t.tolist(), q.tolist()))
    w = load_waveform(_write(tmp_path / "w.csv", f"# c\n{header}\n{rows}"))
    assert w.period_s == pytest.approx(0.8) and w.mean_m3_s == pytest.approx(50e-6, rel=1e-6)


def test_unknown_header_lists_the_accepted_ones(tmp_path):
    t, q = _cycle()
    rows = "".join(f"{a},{b}\n" for a, b in zip(t, q))
    with pytest.raises(VCSInputError) as e:
        load_waveform(_write(tmp_path / "w.csv", f"time_h,flow_gal_min\n{rows}"))
    msg = str(e.value)
    assert "line 1" in msg and "time_ms" in msg and "flow_ml_s" in msg and "flow_m3_s" in msg and "\n" not in msg
