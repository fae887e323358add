"""Rule atlas_build: the cohort atlas (vcs.atlas.build_atlas) from every patient's fit report, model,
status and fields. A patient that failed at any stage (its fit outputs are a failure record,
its status.json says why, or its fields are a placeholder) is listed in atlas.json under
patients_excluded with the stage and the reason; the atlas is built from the others. The PNGs go
to the rule's figures/ directory (once), the VTP/VTU files beside atlas.json."""

import json
import sys
from pathlib import Path

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402
import _failure  # noqa: E402

log = _common.setup(snakemake, "atlas_build")  # noqa: F821


def main(smk):
    from vcs.atlas import build_atlas
    from vcs.vessel import VesselModel

    ids = list(smk.params.ids)
    reports, models, statuses = {}, {}, {}
    for pid, report, model, status in zip(ids, smk.input.reports, smk.input.models, smk.input.statuses):
        with open(report) as fh:
            reports[pid] = json.load(fh)  # a fit report, or the failure record of the fit
        if _failure.read_record(model) is None:
            models[pid] = VesselModel.load(model)
        with open(status) as fh:
            statuses[pid] = json.load(fh)
    fields = dict(zip(ids, smk.input.fields))
    options = json.loads(json.dumps(dict(smk.params.options)))
    figures = bool(options.pop("figures", True))
    out_dir = Path(smk.output.json).parent
    Path(smk.output.figures).mkdir(parents=True, exist_ok=True)
    atlas = build_atlas(
        models, fields, statuses, out_dir, reports=reports, figures=figures, figure_dir=smk.output.figures, **options
    )
    for pid, reason in atlas.excluded.items():
        log.warning("excluded %s (%s): %s", pid, atlas.exclusion_stages.get(pid), reason)
    for field, r in atlas.regression.items():
        if r["status"] != "ok":
            log.warning("shape -> flow regression of %s: %s (%s)", field, r["status"], r["status_reason"])
    knots = atlas.alignment_report.get("knots") or {}
    log.info(
        "cohort knots L=%s K=%s R=%s (fitted L: %s)",
        knots.get("L"),
        knots.get("K"),
        knots.get("R"),
        knots.get("L_fitted"),
    )
    log.info("atlas of %d patients (%d excluded) -> %s", len(atlas.patients), len(atlas.excluded), smk.output.json)


_common.run(main, snakemake, log)  # noqa: F821
