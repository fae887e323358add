"""Rule atlas_complete: the run's verdict, after the atlas was built.

Every patient of the sheet in the atlas: writes results/atlas/complete.txt, the run exits 0.
Otherwise the job fails (so the run exits non-zero) with ONE line on stderr and in its log naming
each patient left out, the stage at which it failed and the reason, e.g.

    vcs-atlas: 1 of 4 patients not in the atlas (built from the other 3: results/atlas/atlas.json):
    P3 at fit (fit failed: 'p3.stl' contains no surface triangles; export the surface again)

The atlas itself stays (it is correct: it lists the patient under patients_excluded); the next run
repeats only this check until the patient is fixed or removed from the sheet.
"""

import json
import os
import sys
from pathlib import Path

sys.path.insert(0, snakemake.scriptdir)  # noqa: F821 (snakemake is injected)
import _common  # noqa: E402

terminal = os.fdopen(os.dup(2), "w")  # the run's stderr, before _common.setup sends fd 2 to the log
log = _common.setup(snakemake, "atlas_complete")  # noqa: F821
MAX_REASON = 200


def verdict(atlas: dict, ids: list[str], where: str) -> str | None:
    """None when every id is included, else the one-line summary."""
    included = set(atlas.get("patients_included", []))
    excluded = {e["id"]: e for e in atlas.get("patients_excluded", [])}
    missing = [pid for pid in ids if pid not in included]
    if not missing:
        return None
    parts = []
    for pid in missing:
        e = excluded.get(pid, {"stage": "unknown", "reason": "not listed in atlas.json"})
        reason = " ".join(str(e.get("reason", "")).split())
        if len(reason) > MAX_REASON:
            reason = reason[: MAX_REASON - 3] + "..."
        parts.append(f"{pid} at {e.get('stage', 'unknown')} ({reason})")
    return (
        f"vcs-atlas: {len(missing)} of {len(ids)} patients not in the atlas (built from the other "
        f"{len(included)}: {where}): " + "; ".join(parts)
    )


def main(smk):
    with open(smk.input.json) as fh:
        atlas = json.load(fh)
    line = verdict(atlas, list(smk.params.ids), smk.input.json)
    if line is None:
        Path(smk.output.done).write_text(f"all {len(smk.params.ids)} patients of the sheet are in the atlas\n")
        log.info("all %d patients of the sheet are in the atlas", len(smk.params.ids))
        return
    log.error("%s", line)
    print(line, file=terminal, flush=True)
    sys.exit(1)


_common.run(main, snakemake, log)  # noqa: F821
