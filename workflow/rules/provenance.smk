# results/provenance.json: what produced the results (written after every run that executed
# jobs, successful or not; dry-runs and "nothing to be done" leave it alone), and after the same
# runs the removal of an atlas that no longer matches its patients (drop_stale_atlas).

import datetime
import importlib.metadata
import platform
import socket
import subprocess

PROVENANCE_FILE = Path("results") / "provenance.json"
PROVENANCE_PACKAGES = (
    "vcs-atlas", "numpy", "scipy", "pyvista", "vtk", "trimesh", "jinja2", "matplotlib",
    "snakemake", "snakemake-executor-plugin-slurm", "jsonschema", "PyYAML", "PyFoam",
)
_RUN = {"start": datetime.datetime.now(datetime.timezone.utc)}


def _git(*args):
    try:
        out = subprocess.run(["git", *args], cwd=VCS_REPO, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def _package_versions():
    versions = {}
    for name in PROVENANCE_PACKAGES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def _vcs_version():
    """The package version (one source: pyproject.toml), as vcs.__version__ and the docs show it."""
    try:
        return importlib.metadata.version("vcs-atlas")
    except importlib.metadata.PackageNotFoundError:
        return None


def _openfoam():
    try:
        from vcs.cfd import FLAVOURS, detect_openfoam

        flavour, version = detect_openfoam()
    except Exception as exc:  # provenance must never fail a run
        return {"error": f"{type(exc).__name__}: {exc}"}
    requested = config["cfd"]["flavour"]
    return {
        "flavour_installed": flavour,
        "flavour_requested": requested,
        "label": FLAVOURS.get(flavour, {}).get("label") if flavour else None,
        "version": version,
    }


def _sha256(path):
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def write_provenance(outcome, logfile):
    end = datetime.datetime.now(datetime.timezone.utc)
    start = _RUN["start"]
    status = _git("status", "--porcelain", "--untracked-files=no")
    record = {
        "outcome": outcome,
        "vcs_version": _vcs_version(),
        "start": start.isoformat(timespec="seconds"),
        "end": end.isoformat(timespec="seconds"),
        "duration_s": round((end - start).total_seconds(), 3),
        "command_line": shlex.join(sys.argv),
        "working_directory": os.getcwd(),
        "snakemake_log": str(logfile) if logfile else None,
        "git": {
            "commit": _git("rev-parse", "HEAD"),
            "describe": _git("describe", "--always", "--dirty"),
            "dirty": None if status is None else bool(status),
        },
        "config_hash": config_hash(config),
        "config": config,
        "patients_sheet": {"path": config["patients"], "sha256": _sha256(config["patients"])},
        "patients": PATIENT_IDS,
        "openfoam": _openfoam(),
        "python": {"version": platform.python_version(), "implementation": platform.python_implementation(),
                   "executable": sys.executable},
        "packages": _package_versions(),
        "platform": {"system": platform.platform(), "machine": platform.machine(),
                     "hostname": socket.gethostname(), "cpus": os.cpu_count()},
    }
    PROVENANCE_FILE.parent.mkdir(parents=True, exist_ok=True)
    PROVENANCE_FILE.write_text(json.dumps(record, indent=1, sort_keys=True, default=str) + "\n")


# The stale-atlas guard of both handlers below (the atlas itself: workflow/rules/atlas.smk).
ATLAS_INPUTS = (
    "results/patients/{id}/fit/fit_report.json",
    "results/patients/{id}/fit/model.json",
    "results/patients/{id}/fields.npz",
    "results/patients/{id}/status.json",
)
ATLAS_OUTPUTS = (
    "results/atlas/atlas.json",
    "results/atlas/atlas.npz",
    "results/atlas/figures",
    "results/atlas/patients.html",
    "results/atlas/patients.tsv",
    "results/atlas/complete.txt",
)


def drop_stale_atlas():
    """After a run (onsuccess/onerror): move aside an atlas that no longer matches its patients.

    When a patient's job failed outright (interrupted, no OpenFOAM, a bug) or a run stopped at a
    patient's file, the atlas is not rebuilt; the old one would still list that patient as
    included. If any input of atlas_build is missing or newer than atlas.json, atlas.json,
    atlas.npz, figures/, the cohort table (patients.html/.tsv) and complete.txt are moved to results/previous/atlas/ (one line on
    stderr; nothing the user had is lost); the next run builds the atlas again. Without atlas.json (atlas_build failed and Snakemake removed its outputs),
    what is left of an older atlas (complete.txt) goes too.
    """
    atlas = Path(ATLAS_OUTPUTS[0])
    had_atlas = atlas.is_file()
    if had_atlas:
        built = atlas.stat().st_mtime
        stale = [
            p
            for pattern in ATLAS_INPUTS
            for p in patient_files(pattern)
            if not Path(p).exists() or Path(p).stat().st_mtime > built
        ]
    else:  # e.g. atlas_build failed (fewer than 3 patients left): no complete.txt of an old run
        stale = [str(atlas)] if any(Path(out).exists() for out in ATLAS_OUTPUTS[1:]) else []
    if not stale:
        return
    for out in ATLAS_OUTPUTS:  # nothing the user had is lost: moved aside (workflow/rules/keep.smk)
        if Path(out).exists():
            move_to_previous(Path(out), out)
    more = f" and {len(stale) - 1} more" if len(stale) > 1 else ""
    why = (
        f"it no longer matches the patients' results ({stale[0]}{more} missing or newer than atlas.json)"
        if had_atlas
        else "what was left of an older atlas (no atlas.json)"
    )
    print(
        f"vcs-atlas: moved the atlas in results/atlas/ to results/previous/atlas/: {why}; the next run builds it again",
        file=sys.stderr,
    )


onstart:
    _RUN["start"] = datetime.datetime.now(datetime.timezone.utc)
    keep_outputs()  # workflow/rules/keep.smk


onsuccess:
    settle_kept()
    write_provenance("success", log)
    drop_stale_atlas()


onerror:
    settle_kept()
    write_provenance("failed", log)
    drop_stale_atlas()
