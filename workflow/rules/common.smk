# Validation, the patients sheet, wildcard constraints and named input/param functions.
# Every error about the configuration or the sheet is ONE line on stderr (sys.exit), no traceback.

import csv
import hashlib
import json
import math
import os
import re
import shlex
import sys
from pathlib import Path

from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

ID_PATTERN = r"[A-Za-z0-9_-]+"
DEMO_MESH = re.compile(r"results/demo/(?P<kind>aorta|tube|torus|helix)_seed(?P<seed>[0-9]+)\.stl")
SHEET_COLUMNS = (
    "id", "mesh", "units", "inlet", "outlet", "inlet_cap", "outlet_cap",
    "cell_size_mm", "flow_rate_l_min", "inlet_velocity_m_s", "valve_area_cm2", "inflow_waveform",
    "cfd_geometry", "outlets", "rcr_resistance_mmhg_s_ml", "rcr_compliance_ml_mmhg", "outlet_bc",
)
# optional per-patient CFD columns: number in the sheet's unit -> (key of vcs.cfd.render_case's
# `patient`, factor to SI); cell_size_mm may also be `auto`
PATIENT_CFD_COLUMNS = {
    "cell_size_mm": ("cell_size", 1e-3),
    "flow_rate_l_min": ("flow_rate", 1e-3 / 60.0),
    "inlet_velocity_m_s": ("velocity", 1.0),
    "valve_area_cm2": ("valve_area", 1e-4),
}
# optional per-patient Windkessel totals (outlets rcr): number in the sheet's clinical unit -> (key of
# cfd.outlets.rcr, factor to SI: 1 mmHg s/mL = 1.33322e8 Pa s/m3, 1 mL/mmHg = 7.50062e-9 m3/Pa)
PATIENT_RCR_COLUMNS = {
    "rcr_resistance_mmhg_s_ml": ("resistance", 133.322387415 / 1e-6),
    "rcr_compliance_ml_mmhg": ("compliance", 1e-6 / 133.322387415),
}

# The `vcs` console script lives beside this Python (the project's venv): put it on PATH so that
# shell rules work without an activated venv (also inside SLURM jobs, which run this file again).
# One BLAS thread per job (set before the jobs start; SLURM jobs run this file again): the jobs
# already run in parallel, and single-threaded sums are reproducible.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
_VENV_BIN = str(Path(sys.executable).parent)
if _VENV_BIN not in os.environ.get("PATH", "").split(os.pathsep):
    os.environ.update(PATH=os.pathsep.join([_VENV_BIN, os.environ.get("PATH", "")]))


def fail(message):
    """Stop with one line on stderr (Snakemake prints SystemExit messages as they are)."""
    sys.exit(f"vcs-atlas: error: {message}")


def _validation_message(exc):
    """One line from a WorkflowError raised by snakemake.utils.validate."""
    import jsonschema

    cause = exc.__cause__ or exc.__context__  # validate() raises WorkflowError inside `except ValidationError`
    if isinstance(cause, jsonschema.exceptions.ValidationError):
        where = " > ".join(str(p) for p in cause.absolute_path) or "top level"
        return f"{where}: {cause.message}"
    return " ".join(str(exc).split())[:300]


# --------------------------------------------------------------------------- config

def _non_finite(value, where=()):
    """The first (path, value) of a NaN or infinite number anywhere in the configuration
    (`.nan` and `.inf` are YAML numbers, and a NaN passes every minimum and maximum)."""
    if isinstance(value, float) and not math.isfinite(value):
        return where, value
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        found = _non_finite(item, (*where, str(key)))
        if found:
            return found
    return None


_bad = _non_finite(config)
if _bad:
    fail(f"invalid configuration ({' > '.join(_bad[0])}: {_bad[1]} is not a finite number); see config/config.yaml")
try:
    validate(config, schema="../schemas/config.schema.yaml")
except WorkflowError as exc:
    fail(f"invalid configuration ({_validation_message(exc)}); see config/config.yaml")


def config_hash(cfg):
    """sha256 of the configuration as canonical JSON (first 16 hex digits)."""
    text = json.dumps(cfg, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


# --------------------------------------------------------------------------- patients sheet


def _sheet_rows(path):
    """(line number, {column: value}) for the data rows of a TSV with '#' comment lines."""
    sheet = Path(path)
    if not sheet.is_file():
        fail(f"patients sheet '{path}' not found; set `patients:` in the config to an existing TSV")
    # utf-8-sig: the byte-order mark of Excel's "UTF-8 CSV" is not part of the header
    lines = [
        (n, line)
        for n, line in enumerate(sheet.read_text(encoding="utf-8-sig").splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        fail(f"patients sheet '{path}' is empty; it needs a header line and one row per patient")
    header = [h.strip() for h in lines[0][1].split("\t")]
    unknown = [h for h in header if h not in SHEET_COLUMNS]
    if unknown or "id" not in header or "mesh" not in header:
        fail(
            f"patients sheet '{path}' line {lines[0][0]}: header {header} must be tab separated with "
            f"columns id, mesh and optionally {', '.join(SHEET_COLUMNS[2:])} (unknown: {unknown})"
        )
    rows = []
    for n, line in lines[1:]:
        cells = next(csv.reader([line], delimiter="\t", quoting=csv.QUOTE_NONE))
        if len(cells) > len(header):
            if any(c.strip() for c in cells[len(header):]):
                fail(f"patients sheet '{path}' line {n}: {len(cells)} cells but {len(header)} columns")
        row = {h: (cells[i].strip() if i < len(cells) else "") for i, h in enumerate(header)}
        rows.append((n, row))
    if not rows:
        fail(f"patients sheet '{path}' has a header but no patients")
    return rows


def _check_file(path, sheet, n, pid, column):
    if not Path(path).is_file() and not DEMO_MESH.fullmatch(path):
        fail(f"patients sheet '{sheet}' line {n} (id {pid}): {column} '{path}' not found (paths are relative to {os.getcwd()})")


def _check_waveform(path, where):
    """An inflow waveform CSV is read and checked at planning time (vcs.cfd.waveform.load_waveform):
    a bad one stops the workflow with one line naming where it was given, the file and the row."""
    from vcs.cfd.waveform import load_waveform
    from vcs.errors import VCSInputError

    try:
        load_waveform(path)
    except VCSInputError as exc:
        fail(f"{where}: {exc}")


def _check_outlet_bc(record, where):
    """A patient's per-outlet RCR table (outlet_bc: CSV, or rcrt.dat by its .dat suffix) is read at
    planning time (vcs.cfd.bc_tables): a bad value, unknown units or two rows on one end stop the
    workflow with one line. In the main process (not again in every job) its rows are also matched
    to the surface's ends as `vcs ends` lists them (~1 s a patient): a row naming no end, the inlet
    or another row's end (and, for cfd geometry surface, an outlet end without a row) stops it
    with one line naming the row and the ends."""
    from vcs.cfd.bc_tables import check_outlet_bc, read_outlet_bc, surface_ends
    from vcs.errors import VCSInputError

    try:
        read_outlet_bc(record["outlet_bc"])
    except VCSInputError as exc:
        fail(f"{where}: {exc}")
    if not workflow.is_main_process or not Path(record["mesh"]).is_file():
        return
    try:
        surface = surface_ends(record["mesh"], record.get("units", "auto"))
    except Exception:  # an unreadable mesh is the fit's to report (a per-patient failure)
        return
    geometry = record.get("cfd_geometry") or config["cfd"].get("geometry", "model")
    try:
        check_outlet_bc(
            record["outlet_bc"], record["mesh"], units=surface[2], surface=surface,
            inlet=record.get("inlet") or record.get("inlet_cap"), complete=geometry == "surface",
        )
    except VCSInputError as exc:
        fail(f"{where}: {exc}")


def cfd_geometry(wildcards):
    """The lumen the patient's CFD runs on: the sheet's cfd_geometry, else cfd.geometry (model)."""
    return PATIENTS[wildcards.id].get("cfd_geometry") or config["cfd"].get("geometry", "model")


def case_stl(wildcards):
    """The closed multi-solid STL the case is meshed from: the Eq. 8 model wall (geometry model) or
    the patient's own lumen with every end a patch (geometry surface, rule vcs_lumen)."""
    if cfd_geometry(wildcards) == "surface":
        return f"results/patients/{wildcards.id}/lumen/lumen.stl"
    return f"results/patients/{wildcards.id}/wall/wall.stl"


def waveform_input(wildcards):
    """The patient's inflow waveform file (the sheet's, else cfd.inlet.waveform), or none: an input
    of the case, so that editing the CSV reruns the patients that use it."""
    own = PATIENTS[wildcards.id].get("inflow_waveform")
    path = own or config["cfd"].get("inlet", {}).get("waveform")
    return [path] if path else []


def outlet_bc_input(wildcards):
    """The patient's per-outlet RCR table and the cap files its rows name, or none: inputs of the
    case, so that editing them reruns that patient's CFD."""
    path = PATIENTS[wildcards.id].get("outlet_bc")
    if not path:
        return []
    from vcs.cfd.bc_tables import SURFACE_SUFFIXES, read_outlet_bc

    caps = [r.end for r in read_outlet_bc(path) if Path(r.end).suffix.lower() in SURFACE_SUFFIXES]
    return [path, *dict.fromkeys(c for c in caps if Path(c).is_file())]


def _number_range(column):
    """(lowest, highest, lowest excluded, also `auto`, unit) of a number column of the patients
    sheet, read from workflow/schemas/patients.schema.yaml (the one place that sets them)."""
    import yaml

    global _PATIENT_SCHEMA
    if _PATIENT_SCHEMA is None:
        _PATIENT_SCHEMA = yaml.safe_load((Path(VCS_REPO) / "workflow/schemas/patients.schema.yaml").read_text())
    prop = _PATIENT_SCHEMA["properties"][column]
    auto = any(alt.get("const") == "auto" for alt in prop.get("oneOf", []))
    num = next((alt for alt in prop.get("oneOf", []) if alt.get("type") == "number"), prop)
    low = num.get("exclusiveMinimum", num.get("minimum"))
    return low, num.get("maximum"), "exclusiveMinimum" in num, auto, column.rsplit("_", 1)[-1] if "_" in column else ""


_PATIENT_SCHEMA = None
_UNITS = {"mm": "mm", "min": "L/min", "s": "m/s", "cm2": "cm2", "ml": "mmHg s/mL", "mmhg": "mL/mmHg"}


def _sheet_number(text, column, where):
    """A number cell of the patients sheet as a float (or "auto" where the column allows it),
    checked to be finite and in the schema's range: nan, inf, -1, 1e9 or abc stop the plan with
    one line naming the patient, the column and the value."""
    low, high, open_low, auto, unit = _number_range(column)
    if auto and text == "auto":
        return text
    low = -math.inf if low is None else low
    high = math.inf if high is None else high
    interval = f"{'(' if open_low else '['}{low:g}, {high:g}] {_UNITS.get(unit, unit)}".rstrip()
    want = f"{'auto or ' if auto else ''}a number in {interval}"
    try:
        value = float(text)
    except ValueError:
        fail(f"{where}: {column} '{text}' is not a number; give {want}")
    if not math.isfinite(value) or value < low or (open_low and value == low) or value > high:
        fail(f"{where}: {column} '{text}' is out of range; give {want}")
    return value


def load_patients(sheet):
    """{id: row} of the patients sheet, validated; empty cells become None; units default to auto."""
    patients, first_line = {}, {}
    for n, row in _sheet_rows(sheet):
        pid = row.get("id", "")
        if not re.fullmatch(ID_PATTERN, pid):
            fail(
                f"patients sheet '{sheet}' line {n}: id '{pid}' must match ^{ID_PATTERN}$ "
                "(letters, digits, _ and -; it names results/patients/<id>/)"
            )
        if pid in first_line:
            fail(f"patients sheet '{sheet}' line {n}: id '{pid}' already used on line {first_line[pid]}; ids must be unique")
        first_line[pid] = n
        record = {k: v for k, v in row.items() if v != ""}
        for column in (*PATIENT_CFD_COLUMNS, *PATIENT_RCR_COLUMNS):
            if column in record:
                record[column] = _sheet_number(record[column], column, f"patients sheet '{sheet}' line {n} (id {pid})")
        try:
            validate(record, schema="../schemas/patients.schema.yaml")
        except WorkflowError as exc:
            msg = _validation_message(exc)
            if "should not be valid under" in msg and "flow_rate_l_min" in msg.split("should not be valid under")[1]:
                msg = "give the inflow either as flow_rate_l_min or as inlet_velocity_m_s + valve_area_cm2, not both"
            elif "should not be valid under" in msg:
                msg = "give the ends either as inlet/outlet points or as inlet_cap/outlet_cap files, not both"
            elif "is a dependency of" in msg and ("velocity" in msg or "valve_area" in msg):
                msg = f"{msg.split(': ', 1)[-1]}: the inflow needs both inlet_velocity_m_s and valve_area_cm2"
            elif "is a dependency of" in msg:
                msg = f"{msg.split(': ', 1)[-1]}: the ends need both inlet and outlet (points or caps)"
            elif msg.startswith("cell_size_mm:"):
                msg = f"cell_size_mm {record['cell_size_mm']} must be auto or a number of mm in [0.05, 50]"
            elif "does not match" in msg:
                column = msg.split(":", 1)[0]
                msg = (
                    f"{column} '{record[column]}' must be a point x,y,z (mesh units) or an end listed by "
                    "`vcs ends`: end:N or NAME=VALUE"
                )
            fail(f"patients sheet '{sheet}' line {n} (id {pid}): {msg}")
        for column in ("inlet", "outlet"):  # a point: three finite numbers (the pattern admits "e,e,e")
            if "," in record.get(column, ""):
                try:
                    xyz = [float(v) for v in record[column].split(",")]
                except ValueError:
                    xyz = []
                if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
                    fail(
                        f"patients sheet '{sheet}' line {n} (id {pid}): {column} '{record[column]}' is not a point of "
                        "three finite numbers x,y,z (mesh units); or give an end listed by `vcs ends`: end:N or NAME=VALUE"
                    )
        for column in ("mesh", "inlet_cap", "outlet_cap", "inflow_waveform", "outlet_bc"):
            if column in record:
                _check_file(record[column], sheet, n, pid, column)
        given = [c for c in PATIENT_RCR_COLUMNS if c in record]
        kind = record.get("outlets") or config["cfd"].get("outlets", {}).get("type", "free")
        if given and kind not in ("rcr", "rcr_fixed_share"):
            fail(
                f"patients sheet '{sheet}' line {n} (id {pid}): {given[0]} is given but this patient's outlets "
                f"are {kind}; set its outlets column to rcr (or leave {given[0]} empty)"
            )
        if "outlet_bc" in record:
            if kind != "rcr" and record.get("outlets"):
                fail(
                    f"patients sheet '{sheet}' line {n} (id {pid}): outlet_bc gives every outlet an RCR but this "
                    f"patient's outlets are {kind}; set its outlets column to rcr (or leave it empty)"
                )
            if given:
                fail(
                    f"patients sheet '{sheet}' line {n} (id {pid}): outlet_bc gives every outlet's RCR; "
                    f"leave {given[0]} empty (the totals split by Murray's law do not apply)"
                )
            _check_outlet_bc(record, f"patients sheet '{sheet}' line {n} (id {pid}): outlet_bc")
        if "inflow_waveform" in record:
            if "flow_rate_l_min" in record or "inlet_velocity_m_s" in record:
                fail(
                    f"patients sheet '{sheet}' line {n} (id {pid}): inflow_waveform is applied as given; "
                    "leave flow_rate_l_min and inlet_velocity_m_s empty for this patient"
                )
            _check_waveform(record["inflow_waveform"], f"patients sheet '{sheet}' line {n} (id {pid}): inflow_waveform")
        patients[pid] = {c: record.get(c) for c in SHEET_COLUMNS} | {"units": record.get("units", "auto")}
    return patients


if config["cfd"].get("inlet", {}).get("waveform"):
    _wf = config["cfd"]["inlet"]["waveform"]
    if not Path(_wf).is_file() and (Path(VCS_REPO) / _wf).is_file():
        # a path of the repository (the shipped vcs/data/waveforms/ascending_aorta.csv of
        # config/pulsatile.yaml) when the run is in another directory (snakemake -d)
        _wf = config["cfd"]["inlet"]["waveform"] = str(Path(VCS_REPO) / _wf)
    if not Path(_wf).is_file():
        fail(f"cfd.inlet.waveform '{_wf}' not found (paths are relative to {os.getcwd()}); give a CSV of one cycle or null")
    _check_waveform(_wf, "cfd.inlet.waveform")
PATIENTS = load_patients(config["patients"])
PATIENT_IDS = sorted(PATIENTS)
if not config["cfd"].get("inlet", {}).get("waveform"):
    _pulsatile = sorted(p for p, row in PATIENTS.items() if row.get("inflow_waveform"))
    if _pulsatile and len(_pulsatile) < len(PATIENTS):
        _steady = sorted(set(PATIENTS) - set(_pulsatile))
        fail(
            f"patients sheet '{config['patients']}': {', '.join(_pulsatile[:5])}{' ...' if len(_pulsatile) > 5 else ''} "
            f"have an inflow_waveform (pulsatile) but {', '.join(_steady[:5])}{' ...' if len(_steady) > 5 else ''} "
            "would be steady (cfd.inlet.waveform is null): an atlas never mixes them; give every patient a "
            "waveform or set cfd.inlet.waveform"
        )


wildcard_constraints:
    id=ID_PATTERN,
    kind="aorta|tube|torus|helix",
    seed="[0-9]+",


# --------------------------------------------------------------------------- input functions


def fit_input(wildcards):
    """Mesh (and cap surfaces, when the sheet gives them) of one patient."""
    row = PATIENTS[wildcards.id]
    files = {"mesh": row["mesh"]}
    if row["inlet_cap"]:
        files.update(inlet_cap=row["inlet_cap"], outlet_cap=row["outlet_cap"])
    return files


def lumen_input(wildcards):
    """The patient's mesh and its model.json (the section's ends) for rule vcs_lumen."""
    return {"mesh": PATIENTS[wildcards.id]["mesh"], "model": f"results/patients/{wildcards.id}/fit/model.json"}


def fit_ends(wildcards):
    """`vcs fit` options saying how the ends are given (shell quoted; empty = automatic).

    Points are passed as --inlet=VALUE: a value starting with a minus sign (-40,0,0) is then never
    taken for an option, and shlex.quote keeps spaces ("-40, 0, 0") in one argument."""
    row = PATIENTS[wildcards.id]
    if row["inlet"]:
        return f"--inlet={shlex.quote(row['inlet'])} --outlet={shlex.quote(row['outlet'])}"
    if row["inlet_cap"]:
        return f"--inlet-cap {shlex.quote(row['inlet_cap'])} --outlet-cap {shlex.quote(row['outlet_cap'])}"
    return ""


def fit_units(wildcards):
    return PATIENTS[wildcards.id]["units"]


def output_dir(wildcards, output):
    """Directory of the rule's first output (for tools that take -o DIR)."""
    return str(Path(output[0]).parent)


def wall_n_tau_option():
    """`--n-tau N` or nothing (square quads) for `vcs wall`."""
    n_tau = config["wall"]["n_tau"]
    return "" if n_tau is None else f"--n-tau {int(n_tau)}"


def cfd_params():
    """The cfd block as rendered (flavour auto -> detected at render time)."""
    return config["cfd"]


def patient_cfd(wildcards):
    """The patient's own CFD values from the sheet, in SI units (vcs.cfd.render_case `patient`):
    cell_size (m or "auto"), flow_rate (m3/s), velocity (m/s) + valve_area (m2), waveform, outlets,
    outlet_bc + mesh (paths: the per-outlet RCR table and the surface its end:N rows name). A param, so
    editing one patient's values reruns that patient's CFD only."""
    row = PATIENTS[wildcards.id]
    out = {"waveform": row["inflow_waveform"]} if row.get("inflow_waveform") else {}
    for column, (key, factor) in PATIENT_CFD_COLUMNS.items():
        value = row.get(column)
        if value == "auto" and config["cfd"].get("mesh", {}).get("cell_size", "auto") == "auto":
            continue  # the config's own value: no change (and no rerun)
        if value is not None:
            out[key] = value if value == "auto" else value * factor
    outlets = {"type": row["outlets"]} if row.get("outlets") else {}
    rcr = {key: row[c] * f for c, (key, f) in PATIENT_RCR_COLUMNS.items() if row.get(c) is not None}
    if rcr:
        outlets["rcr"] = rcr
    if outlets:
        out["outlets"] = outlets
    if row.get("outlet_bc"):  # the per-outlet RCR table, and the surface its end:N rows are ends of
        out.update(outlet_bc=row["outlet_bc"], mesh=row["mesh"])
    return out


def solve_ranks():
    return int(config["cfd"]["ranks"])


def patient_files(pattern):
    """`pattern` ({id}) expanded over every patient of the sheet."""
    return expand(pattern, id=PATIENT_IDS)


# The Snakemake report's place of each atlas figure (rule atlas_build's figures/, by file name).
_ATLAS_FIGURE = re.compile(r"(?P<kind>shape|flow_(?P<field>.+))_(?P<what>mean|mode(?P<k>[0-9]+))(?P<rest>_3d|_deformation)?")


def atlas_figure_place(name):
    """(category, subcategory, label) of the atlas figure ``{name}.png`` in the report: shape
    figures under Shape by mean / mode, flow figures under Flow by field, anything else (the
    explained variance) under Atlas."""
    m = _ATLAS_FIGURE.fullmatch(name)
    if m is None:
        return "Atlas", "Cohort", name.replace("_", " ")
    what = "mean" if m["what"] == "mean" else f"mode {m['k']}"
    view = "3-D" if m["rest"] == "_3d" else "flat"
    if m["kind"] == "shape":
        return "Shape", "mean shape" if what == "mean" else what, f"{what}, {view}"
    return "Flow", m["field"], f"{m['field']} {what}, {view}"


def atlas_figure_category(wildcards):
    return atlas_figure_place(wildcards.name)[0]


def atlas_figure_subcategory(wildcards):
    return atlas_figure_place(wildcards.name)[1]


def atlas_figure_labels(wildcards):
    return {"figure": atlas_figure_place(wildcards.name)[2]}
