"""Rule openfoam_case: render the OpenFOAM case of one patient (vcs.cfd.render_case).

A wall or lumen STL that is a failure record of an earlier stage (workflow/scripts/_failure.py), or a case
that cannot be set up, is written to SETUP_FAILED.json (stage, reason, log) for openfoam_solve:
a per-patient failure, not a job failure.
"""

import json
import sys
from pathlib import Path

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402
import _failure  # noqa: E402

log = _common.setup(snakemake, "openfoam_case")  # noqa: F821
SETUP_FAILED = "SETUP_FAILED.json"  # read by openfoam_solve.py


def main(smk):
    from vcs.cfd import render_case

    upstream = _failure.read_record(smk.input.stl)
    if upstream is not None:  # the fit, wall or lumen failed: pass it on
        log.warning(
            "%s: not set up, failed at the %s stage: %s", smk.wildcards.id, upstream["stage"], upstream["reason"]
        )
        Path(smk.output.case).mkdir(parents=True, exist_ok=True)
        (Path(smk.output.case) / SETUP_FAILED).write_text(json.dumps(upstream) + "\n")
        return
    cfd = json.loads(json.dumps(dict(smk.params.cfd)))  # plain dicts/lists
    patient = json.loads(json.dumps(dict(smk.params.patient)))
    flavour = cfd.pop("flavour", "auto")
    cfd["geometry"] = smk.params.geometry  # the patient's (recorded in status.json "geometry")
    try:
        state = render_case(
            smk.output.case,
            smk.input.stl,
            cfd,
            flavour=None if flavour == "auto" else flavour,
            model=smk.input.model,
            patient=patient,
        )
    except Exception as exc:  # this patient's geometry cannot be set up: a per-patient failure,
        # recorded for openfoam_solve -> status.json -> atlas exclusion, not a cohort stop
        reason = f"case set-up failed: {type(exc).__name__}: {' '.join(str(exc).split())}"
        log.error("%s: %s", smk.wildcards.id, reason)
        Path(smk.output.case).mkdir(parents=True, exist_ok=True)
        record = {"stage": "case", "reason": reason, "log": str(Path(smk.log[0]).resolve())}
        (Path(smk.output.case) / SETUP_FAILED).write_text(json.dumps(record) + "\n")
        return
    sizing = state["mesh_sizing"]
    log.info(
        "case for %s (flavour %s): cell size %.4g mm (%s); background %s; inside point %s; "
        "inflow %.4g L/min (%s) -> %s",
        smk.wildcards.id,
        state["flavour"],
        sizing["cell_size_m"] * 1e3,
        sizing["cell_size"]["why"],
        sizing["background"]["why"],
        state["inside_point"],
        state["inflow"]["flow_rate_l_min"],
        state["inflow"]["why"],
        smk.output.case,
    )


_common.run(main, snakemake, log)  # noqa: F821
