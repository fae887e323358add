"""Rule atlas_build: the cohort atlas (vcs.atlas.build_atlas) from every patient's model, fields
and status; excluded patients are listed in atlas.json with the reason from their status."""

import json
import shutil
import sys
from pathlib import Path

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402

log = _common.setup(snakemake, "atlas_build")  # noqa: F821


def main(smk):
    from vcs.atlas import build_atlas, status_exclusion
    from vcs.vessel import VesselModel

    ids = list(smk.params.ids)
    models = {pid: VesselModel.load(path) for pid, path in zip(ids, smk.input.models)}
    statuses = {}
    for pid, path in zip(ids, smk.input.statuses):
        with open(path) as fh:
            statuses[pid] = json.load(fh)
    options = json.loads(json.dumps(dict(smk.params.options)))
    accept = bool(options.get("accept_relaxed", False))
    fields = {
        pid: path
        for pid, path in zip(ids, smk.input.fields)
        if status_exclusion(statuses[pid], accept_relaxed=accept) is None
    }
    figures = bool(options.pop("figures", True))
    out_dir = Path(smk.output.json).parent
    atlas = build_atlas(models, fields, statuses, out_dir, figures=figures, **options)
    figure_dir = Path(smk.output.figures)
    figure_dir.mkdir(parents=True, exist_ok=True)
    for png in sorted(out_dir.glob("*.png")):
        shutil.copy2(png, figure_dir / png.name)
    for pid, reason in atlas.excluded.items():
        log.warning("excluded %s: %s", pid, reason)
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
