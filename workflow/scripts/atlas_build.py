"""Rule atlas_build: the cohort atlas (vcs.atlas.build_atlas) from every patient's fit report, model,
status and fields. A patient that failed at any stage (its fit outputs are a failure record,
its status.json says why, or its fields are a placeholder) is listed in atlas.json under
patients_excluded with the stage and the reason; the atlas is built from the others. The PNGs go
to the rule's figures/ directory (once), the VTP/VTU files beside atlas.json. A pulsatile cohort's
fields.npz (cycle averages, wall markers, phase fields) are passed as they are: build_atlas decides
which PCAs the cohort gets, and refuses a cohort that mixes pulsatile and steady patients. Last,
the report's cohort table (patients.html and patients.tsv, _cohort_table) from the atlas.json just
written, the statuses and the fit reports: every patient of the sheet, in the atlas or not."""

import json
import sys
from pathlib import Path

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _cohort_table  # noqa: E402
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
    weak = [field for field, r in atlas.regression.items() if r["status"] != "ok"]
    if weak:  # one status for the cohort: one line, however many flow PCAs (a pulsatile atlas has 16)
        r = atlas.regression[weak[0]]
        log.warning("shape -> flow regression of %s: %s (%s)", ", ".join(weak), r["status"], r["status_reason"])
    log.info(
        "flow: %s (%d PCAs: %s)%s",
        atlas.flow_kind,
        len(atlas.flow),
        ", ".join(atlas.flow),
        f", phases {', '.join(atlas.phase_names)}" if atlas.phase_names else "",
    )
    for marker, rec in atlas.wall_markers.items():
        if rec.get("excluded"):
            log.warning("wall marker %s has no PCA: %s", marker, rec["excluded"])
        elif rec["n_left_out"]:
            log.warning(
                "wall marker %s: %d of %d wall cells left out of its PCA (not finite for %s)",
                marker,
                rec["n_left_out"],
                rec["n_cells"],
                ", ".join(rec["non_finite_by_patient"]),
            )
    knots = atlas.alignment_report.get("knots") or {}
    log.info(
        "cohort knots L=%s K=%s R=%s (fitted L: %s)",
        knots.get("L"),
        knots.get("K"),
        knots.get("R"),
        knots.get("L_fitted"),
    )
    with open(smk.output.json) as fh:
        rows = _cohort_table.cohort_rows(ids, json.load(fh), statuses, reports)
    _cohort_table.write_tsv(rows, smk.output.patients_tsv)
    _cohort_table.write_html(rows, smk.output.patients_html)
    log.info("atlas of %d patients (%d excluded) -> %s", len(atlas.patients), len(atlas.excluded), smk.output.json)


_common.run(main, snakemake, log)  # noqa: F821
