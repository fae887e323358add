"""Rule openfoam_solve: mesh and solve one patient (vcs.cfd.run_case) in a copy of its case set-up.

A per-patient failure (meshing, divergence, not converged) is NOT a job failure: it is written to
status.json (converged false, reason) for the atlas to exclude the patient; so is a failure of an
earlier stage (fit, wall, case set-up: SETUP_FAILED.json of openfoam_case, with its stage), which
needs no OpenFOAM. Only a broken set-up (no OpenFOAM, missing case) fails the job, with one line in
the log.
"""

import json
import shutil
import sys
import traceback
from pathlib import Path

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402

log = _common.setup(snakemake, "openfoam_solve")  # noqa: F821


def _earlier_failure(smk, marker: Path) -> dict:
    """status.json of a patient whose fit, wall or case set-up failed (SETUP_FAILED.json)."""
    record = json.loads(marker.read_text())
    case_log = Path(smk.log[0]).parent.parent / "openfoam_case" / f"{smk.wildcards.id}.log"
    return {
        "converged": False,
        "failed": True,
        "stage": record.get("stage", "case"),
        "case": smk.output.case,
        "reason": record["reason"],
        "failed_log": record.get("log") or str(case_log.resolve()),
    }


def main(smk):
    from vcs.cfd import detect_openfoam, run_case

    marker = Path(smk.input.setup) / "SETUP_FAILED.json"  # written by openfoam_case.py
    if marker.exists():  # nothing to mesh or solve, and no OpenFOAM needed
        shutil.rmtree(smk.output.case, ignore_errors=True)
        Path(smk.output.case).mkdir(parents=True)
        shutil.copy2(marker, Path(smk.output.case) / marker.name)
        status = _earlier_failure(smk, marker)
        status["patient"] = smk.wildcards.id
        with open(smk.output.status, "w") as fh:
            json.dump(status, fh, indent=2)
        log.warning("%s: not solved, failed at the %s stage: %s", smk.wildcards.id, status["stage"], status["reason"])
        return
    if detect_openfoam()[0] is None:
        raise FileNotFoundError(
            "no OpenFOAM installation found (simpleFoam not on PATH); run `bash scripts/install.sh`"
        )
    # always a fresh copy of the rendered case: nothing of an interrupted or earlier run (time or
    # processor* directories, logs, polyMesh) may leak into this one (Snakemake normally removes
    # the output before the job starts; this also covers --touch/--notemp leftovers)
    shutil.rmtree(smk.output.case, ignore_errors=True)
    shutil.copytree(smk.input.setup, smk.output.case, ignore=shutil.ignore_patterns(".snakemake_timestamp"))
    try:
        status = run_case(smk.output.case, ranks=smk.threads)
    except Exception as exc:  # a crash on this patient must not stop the cohort: record it
        log.error("run_case crashed\n%s", traceback.format_exc())
        status = {
            "converged": False,
            "failed": True,
            "case": smk.output.case,
            "reason": f"vcs.cfd.run_case crashed: {type(exc).__name__}: {' '.join(str(exc).split())}",
            "failed_log": str(Path(smk.log[0]).resolve()),
        }
    status["patient"] = smk.wildcards.id
    with open(smk.output.status, "w") as fh:
        json.dump(status, fh, indent=2, default=float)
    log.info(
        "%s: converged %s after %s iterations, %s cells, %.1f s in OpenFOAM%s",
        smk.wildcards.id,
        status.get("converged"),
        status.get("iterations"),
        status.get("cells"),
        float(status.get("timings_s", {}).get("total", 0.0)),
        f"; reason: {status['reason']}" if status.get("reason") else "",
    )


_common.run(main, snakemake, log)  # noqa: F821
